// Shared helpers of the HTML pages (web/pages.h) and the per-method report sections
// (methods/reports.h): defensive JSON access, HTML fragments, key-figure formatting, the generic
// diagnostics table and the device page's drift scaffolding. Internal to web/: not for other
// layers. Every function is pure and thread-safe; JSON readers never throw (a missing key or a
// key of the wrong type reads as absent: nullptr, NaN, "").
#ifndef CALIBD_WEB_REPORT_COMMON_H_
#define CALIBD_WEB_REPORT_COMMON_H_

#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/html.h"
#include "web/pages.h"

namespace calibd::web::internal {

using json = nlohmann::json;
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kPi = 3.14159265358979323846;
inline constexpr const char* kDash = "\xE2\x80\x93";  // –
inline constexpr const char* kSigma = "\xCF\x83";     // σ
inline constexpr const char* kTimes = "\xC3\x97";     // ×

// --- Defensive JSON access.
const json* Get(const json* j, const char* key);  // member `key` of an object, else null
const json* Get(const json& j, const char* key);
double Num(const json* j);       // a number, else NaN
std::string Str(const json* j);  // a string, else ""
// A scalar of any type as text (numbers with `sig` digits; null as a dash).
std::string ScalarText(const json* j, int sig = 6);
std::vector<double> NumArray(const json* j);    // an array's numbers (NaN for non-numbers)
const json* Array(const json* j);               // j when it is an array, else null
bool HasNumbers(const std::vector<double>& v);  // any finite value
// Pretty JSON with arrays of scalars kept on one line (configs hold long numeric lists).
std::string PrettyJson(const json& j);
std::string Dump(const json& j, int indent);  // never throws ("(not available)")

// --- Small HTML helpers.
std::string E(const std::string& s);  // escaped text
std::string A(const std::string& s);  // escaped attribute value
std::string NumCell(const std::string& text);
inline std::string NumCell(double v, int sig = 4) { return NumCell(FormatSig(v, sig)); }
std::string DeviceLink(const std::string& serial);
std::string JobLink(int64_t id);
std::string FormatUnixTime(double t, bool seconds);
// A stored timestamp shown uniformly; unparseable ones are shown as stored (escaped).
std::string TimeHtml(const std::string& stored, bool seconds = false);
double Seconds(const std::string& stored);  // Unix seconds of a stored timestamp, else NaN
std::string Section(const std::string& id, const std::string& title, const std::string& body);
std::string Figure(const std::string& svg, const std::string& caption);
std::string NotAvailable(const std::string& what);  // "<what>: not available."
// Runs a section renderer; a failure there (an unexpected JSON shape, a bug) costs that section
// only.
template <typename F>
std::string Guard(const std::string& what, F&& f) {
  try {
    return f();
  } catch (const std::exception&) {
    return NotAvailable(what);
  } catch (...) {
    return NotAvailable(what);
  }
}
double NiceFactorBelow(double v);          // largest 1-2-5 number <= v (>= 1)
std::string FactorText(double k);          // "×20"
std::string Warnings(const json& result);  // the result's warnings as a callout ("" none)
size_t WarningCount(const json& result);
std::string Percent(double rel);  // "0.12 %" or "35 ppm"

// --- The diagnostics table (in the spirit of Ceres' FullReport), every method.
std::string DiagnosticsSection(const json& result);

// --- Geometry of axes.
std::vector<double> Unit(const std::vector<double>& a);  // NaN when not available
double AngleBetween(const std::vector<double>& a, const std::vector<double>& b);  // rad
double Norm3(const double* v);

// A badge for a result the gate rejected or a person revoked, or one a person accepted (an accept
// decision in job.events, or a gate verdict of "rejected" that is served anyway: "accepted by a
// person"), with the reason in words; "" for a result the gate accepted (the usual case needs no
// mark).
std::string VerdictBadge(const JobSummary& job);
std::string WarningsCell(const JobSummary& j);
// A complete page; a failure while rendering the body becomes a short error body.
std::string SafePage(const std::string& title, const std::string& cls,
                     const std::function<std::string()>& body);

// --- Drift scaffolding (device page).
double JobTime(const JobSummary& j);  // created (else finished) time, Unix seconds, else NaN
bool OlderFirst(const JobSummary& a, const JobSummary& b);
struct TimeAxis {
  std::string title;
  std::vector<double> x;  // per job, in the chosen unit
};
TimeAxis MakeTimeAxis(const std::vector<const JobSummary*>& jobs);
std::string PairLabel(const JobSummary& a, const JobSummary& b);
std::string PairTimeCell(const JobSummary& a, const JobSummary& b);
// Drift tables list at most the newest kMaxDriftPairs pairs (the plots show all calibrations).
inline constexpr size_t kMaxDriftPairs = 60;
size_t FirstDriftPair(size_t n);
std::string OmittedPairsNote(size_t n);

}  // namespace calibd::web::internal

#endif  // CALIBD_WEB_REPORT_COMMON_H_
