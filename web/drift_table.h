// Drift between calibrations on the device page (`/devices/{serial}`, SPEC §5): the table cells,
// change figures and time axis that every method's drift tables share (the noise and imu
// methods' in methods/noise/noise_drift.cc and methods/imu/imu_drift.cc). Input: one method's
// accepted, not revoked jobs of one device, oldest first. A change of kSignificant or more
// standard deviations of the difference is marked (class drift-significant): more than the two
// calibrations' own uncertainty explains. Each calibration's cell holds its link and, below, its
// date; the tables use a smaller type and wrapping headings so that they fit a 1280 px wide window
// (tests/web/browser_pages.sh measures it). At most kMaxDriftCalibrations (the newest) are listed
// in the tables, with a note; the plots show every calibration. Every user-controlled string is
// escaped. Pure and thread-safe.
#ifndef CALIBD_WEB_DRIFT_TABLE_H_
#define CALIBD_WEB_DRIFT_TABLE_H_

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "web/pages.h"

namespace calibd::web::drift {

inline constexpr size_t kMaxDriftCalibrations = 40;
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr char kDash[] = "\xE2\x80\x93";
inline constexpr char kPlusMinus[] = " \xC2\xB1 ";
inline constexpr char kSigma[] = "\xCF\x83";
inline constexpr double kSignificant = 3;  // a change of this many σ of the difference is marked
// The change columns' heading: the note under each table says against what and in which units.
inline constexpr char kChangeHeading[] = "<th class=\"num\">change</th>";

std::string E(const std::string& s);  // EscapeText
std::string JobLink(int64_t id);
// A job's time (created, else finished), seconds since the epoch; NaN when neither parses.
double JobTime(const JobSummary& j);
std::string UtcDate(double t);
std::string Signed(double v, int sig);  // "+1.23" / "-1.23"
// "m/s^2" -> "m/s²" for headings.
std::string PrettyUnit(const std::string& unit);
// "v ± s" to `sig` significant digits; a dash for a missing value.
std::string ValueCell(double v, double s, int sig = 4);
// z = Δ / √(σ_before² + σ_now²); NaN when a σ is missing.
double ZScore(double delta, double s_before, double s_now);
std::string ZText(double z);
// A change cell: lines of "Δ (zσ)"; a single change has its (zσ) on a line of its own, which
// keeps the column narrow. Marked when any |z| reaches kSignificant.
std::string ChangeCell(const std::vector<std::pair<std::string, double>>& lines);
// One line of a change cell: now − before, relative to |before| times `per` (100: %, 1e6: ppm)
// or absolute when `per` is 0, followed by `unit`; with the change in σ of the difference.
std::pair<std::string, double> ChangeLine(double before, double s_before, double now, double s_now,
                                          double per, const std::string& unit);
std::string NoChangeCell(const std::string& why);

// x of each job for the plots: days since the first calibration (hours when they span less than
// two days), or the calibration number when a time is missing.
struct TimeAxis {
  std::string title;
  std::vector<double> x;
};
TimeAxis MakeTimeAxis(const std::vector<const JobSummary*>& jobs);
// The note under a table that lists only the newest kMaxDriftCalibrations ("" when all are).
std::string OmittedNote(size_t n);
// The calibration cell spanning a job's rows: its link, and below it its date and time (two short
// lines instead of a wide "when" column, so the drift tables fit 1280 px).
std::string CalibrationCell(const JobSummary& j, size_t rows);
// The calibrations whose result does not read, one line each ("" when every one reads).
std::string UnreadableNote(const std::vector<const JobSummary*>& jobs,
                           const std::vector<std::string>& problems);

}  // namespace calibd::web::drift

#endif  // CALIBD_WEB_DRIFT_TABLE_H_
