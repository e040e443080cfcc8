// The static intervals of a stored inertial log (SPEC §7: GET /api/v1/recordings/{id}/segments
// and the recording's HTML page): the log is read back from storage in pieces through the
// validating parser, and core::DetectStatics runs on every accelerometer and gyroscope triad
// with the options of the query (`static_window`, `min_static`, `static_threshold`, and
// `accel_unit`/`gyro_unit` for the SI figures; the imu method's keys and defaults). Unlike the
// imu method, which tries several threshold multipliers and keeps the best accelerometer fit,
// this is the detector alone with its default multiplier, so the answer does not depend on a
// calibration.
#ifndef CALIBD_SERVER_RECORDING_SEGMENTS_H_
#define CALIBD_SERVER_RECORDING_SEGMENTS_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/static_detection.h"
#include "formats/recording.h"
#include "storage/store.h"

namespace calibd::server {

class ColumnCache;  // server/column_cache.h

struct SegmentsOptions {
  core::StaticDetectionOptions detection;   // static_window, min_static, static_threshold
  double accel_unit = 1;                    // m/s² per reading unit
  double gyro_unit = 1;                     // rad/s per reading unit
  TimeUnit time_unit = TimeUnit::kSeconds;  // the t column's unit (config time_unit)
  size_t timeline_points = 0;  // > 0: also a timeline of |a| and |ω| (SI) of about this many
                               // points per triad (min and max per bucket: peaks survive)
};

// Options from the request's query keys; kInvalidInput naming the key for a bad value or a key
// that is not one of static_window, min_static, static_threshold, accel_unit, gyro_unit,
// time_unit.
Status ParseSegmentsQuery(const std::multimap<std::string, std::string>& params,
                          SegmentsOptions* options);

struct RecordingSegments {
  int64_t recording_id = 0;
  int64_t samples = 0;
  double start = 0, end = 0;  // first and last t, s (after time_origin)
  // Epoch stamps are counted from this whole second (RecordingSummary::time_origin; 0: the log's
  // own times): every time in the answer is seconds after it.
  int64_t time_origin = 0;
  std::vector<std::string> accel_names, gyro_names;
  core::StaticDetection detection;  // triads: accelerometers, then gyroscopes
  // Timeline (when asked for): per triad, times and norms in SI, decimated.
  struct Trace {
    std::string name;  // "a0", "g0", ...
    std::vector<double> t, norm;
  };
  std::vector<Trace> accel_traces, gyro_traces;
};

// kNotFound: no such recording; kInvalidInput: not an inertial log (the array layout with `t`
// strictly increasing, at least one triad), naming why; kIoError/kBusy from storage. `cache`
// (may be null): the parsed-columns cache the log is read from when it holds it.
Status ComputeSegments(storage::Store* store, int64_t recording_id, const SegmentsOptions& options,
                       RecordingSegments* out, ColumnCache* cache = nullptr);

// The JSON answer: {"recording_id", "samples", "start", "end", "sample_period", "static_window",
// "min_static", "window_samples", "threshold_multiplier", "triads": [{"name", "kind",
// "noise_floor", "threshold", "threshold_si", "overridden", "saturated_samples"}], "gaps":
// [{"index", "start", "end"}], "saturated_samples", "static_samples", "intervals": [{"number"
// (1-based), "start", "end", "samples", "mean": {triad: [x,y,z]}, "std": {triad: [x,y,z]}}]}
// (reading units, except *_si).
nlohmann::json SegmentsJson(const RecordingSegments& segments, const SegmentsOptions& options);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_RECORDING_SEGMENTS_H_
