// The recording page `/recordings/{id}` (SPEC §7): the recording's metadata, links to its data
// and to the jobs that used it, and, for an inertial log, a timeline of the accelerometer norm
// and the gyroscope norm against time with the static intervals the detector found shaded and
// numbered (1, 2, ... as in the segments answer and the imu diagnostics), plus the table of
// intervals and the thresholds used; for a sensor log (ULog, DataFlash, bags) what was read: its
// streams with their rates, spans and gaps, the streams of each IMU, and the log's warnings.
// Pure rendering; every user string is escaped.
#ifndef CALIBD_WEB_RECORDING_PAGE_H_
#define CALIBD_WEB_RECORDING_PAGE_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "web/pages.h"

namespace calibd::web {

struct RecordingPageView {
  int64_t id = 0;
  std::string sha256, layout, device, file_name, created_at;
  int64_t bytes = 0, rows = 0;
  std::vector<std::string> columns;
  std::vector<JobSummary> jobs;  // the jobs of this recording, newest first
  // Inertial logs: the segments answer (server/recording_segments.h SegmentsJson), or null with
  // `segments_note` saying why there is none (not an inertial log, a bad time column...).
  nlohmann::json segments;
  std::string segments_note;
  std::string query;  // the detection options of the request, shown and linked ("" = defaults)
  struct Trace {
    std::string name;             // "a0", "g0", ...
    std::vector<double> t, norm;  // s, norm × the unit (1 unless given; decimated)
  };
  std::vector<Trace> accel, gyro;
  // Whether the request gave accel_unit / gyro_unit (the norms are then SI). Without them the
  // norms are the readings as logged: the page labels them m/s² and rad/s only when the
  // accelerometer norm at rest is about 1 g (RestNorm), else "reading units", saying why and
  // which accel_unit would convert them.
  bool accel_unit_given = false, gyro_unit_given = false;
  // The check before fitting (GET /api/v1/recordings/{id}/check, server/recording_check.h) of
  // `check_method` when the page was asked for one (?check=METHOD&<config keys>), else null;
  // `check_note` says why there is none (a bad config, not an inertial log). `check_methods`:
  // the methods the form offers (those that read inertial logs, in the registry's order).
  nlohmann::json check;
  std::string check_method, check_note;
  std::vector<std::string> check_methods;
  // A sensor log (SPEC §9): what was read, as stored (formats/log_assembly.h
  // AssembledLog::description: format, time_base, streams, imus, warnings); null for CSV.
  nlohmann::json log;
};

// The accelerometer norm at rest: the median of the accelerometer norms inside the static
// intervals of `view.segments` (all of them when there are none); NaN without samples.
double RestNorm(const RecordingPageView& view);

std::string RenderRecordingPage(const RecordingPageView& view);

// The page's "Check before fitting" section (web/pages/check_section.cc): a form picking the
// method, and for a check its verdicts (units, timing, saturation, coverage, what the job would
// fail with), its statics' gravity directions on the two hemispheres (equal-area projection), and
// the job's predicted σ (the largest of every σ in the check's `predicted.uncertainty`, per IMU,
// the primary ones: `crb` entries left out), or why there is none.
std::string CheckSection(const RecordingPageView& view);

}  // namespace calibd::web

#endif  // CALIBD_WEB_RECORDING_PAGE_H_
