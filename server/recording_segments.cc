#include "server/recording_segments.h"

#include <cmath>
#include <mutex>

#include "formats/csv_dialect.h"
#include "formats/inertial_log.h"
#include "formats/recording.h"
#include "methods/imu/imu_method.h"
#include "server/column_cache.h"
#include "server/config.h"
#include "web/svg_plot.h"

namespace calibd::server {

using nlohmann::json;

namespace {

json Num(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }
json Vec(const Eigen::Vector3d& v) { return json::array({Num(v[0]), Num(v[1]), Num(v[2])}); }

// |row| of a triad's three columns, times `unit`, decimated to about `points` (min/max per
// bucket, so bumps survive).
RecordingSegments::Trace MakeTrace(const std::string& name, const Eigen::VectorXd& t,
                                   const Eigen::MatrixX3d& triad, double unit, size_t points) {
  std::vector<double> x(static_cast<size_t>(t.size())), y(x.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    x[static_cast<size_t>(i)] = t[i];
    y[static_cast<size_t>(i)] = unit * triad.row(i).norm();
  }
  RecordingSegments::Trace trace;
  trace.name = name;
  for (size_t i : web::DecimateMinMax(x, y, points)) {
    trace.t.push_back(x[i]);
    trace.norm.push_back(y[i]);
  }
  return trace;
}

}  // namespace

Status ParseSegmentsQuery(const std::multimap<std::string, std::string>& params,
                          SegmentsOptions* options) {
  json config;
  Status s = ConfigFromQuery(params, &config);
  if (!s.ok()) return s;
  for (const auto& [key, value] : config.items()) {
    if (key != "static_window" && key != "min_static" && key != "static_threshold" &&
        key != "accel_unit" && key != "gyro_unit" && key != "time_unit") {
      return Status::InvalidInput("query key '" + key +
                                  "' is not a segments option (known: static_window, "
                                  "min_static, static_threshold, accel_unit, gyro_unit, "
                                  "time_unit)")
          .WithField(key);
    }
  }
  bool time_unit_given = false;
  s = ParseTimeUnit(config, &options->time_unit, &time_unit_given);
  if (!s.ok()) return s;
  config.erase("time_unit");
  core::ImuOptions imu;
  s = ParseImuOptions(config, &imu);
  if (!s.ok()) return s;
  options->detection = imu.detection;
  options->accel_unit = imu.accel_unit;
  options->gyro_unit = imu.gyro_unit;
  return Status::Ok();
}

Status ComputeSegments(storage::Store* store, int64_t recording_id, const SegmentsOptions& options,
                       RecordingSegments* out, ColumnCache* cache) {
  // One at a time per process: a 2-hour 400 Hz log costs ~2 s and a few hundred MB while it is
  // read (bench/README.md), and page views must not multiply that.
  static std::mutex& one_at_a_time = *new std::mutex;
  std::lock_guard<std::mutex> lock(one_at_a_time);
  storage::RecordingInfo info;
  Status s = store->GetRecording(recording_id, &info);
  if (!s.ok()) return s;
  if (info.layout != LayoutName(Layout::kArray)) {
    return Status::InvalidInput("recording " + std::to_string(recording_id) + " has the " +
                                info.layout +
                                " layout; static intervals are found in inertial logs (t, aK_*, "
                                "gK_*)");
  }
  // Streamed from storage into the parser (the bytes are never held whole), or restored from the
  // parsed-columns cache.
  RecordingParser parser("recording " + std::to_string(recording_id), /*collect=*/true);
  parser.SetTimeUnit(options.time_unit);
  // A CSV from another tool is read as it was at upload (config columns/delimiter/decimal).
  const json read = json::parse(info.log_json, nullptr, /*allow_exceptions=*/false);
  CsvDialect dialect;
  if (read.is_object() && read.contains("csv") && ParseCsvDialect(read["csv"], &dialect).ok()) {
    parser.SetCsvDialect(dialect);
  }
  parser.ExpectRows(info.rows);
  const ColumnCache::Outcome got = FillParser(cache, store, info, &parser);
  if (!got.parse.ok()) return got.parse;
  if (!got.read.ok()) return got.read;
  ArrayRecording log;
  s = parser.TakeArray(&log);
  if (!s.ok()) return s;
  s = CheckLogTimes(log, "static detection", &parser.summary());
  if (!s.ok()) return s;
  std::vector<Eigen::MatrixX3d> triads;
  std::vector<core::TriadSeries> series;
  triads.reserve(log.accel_names.size() + log.gyro_names.size());
  for (size_t k = 0; k < log.accel_names.size(); ++k) {
    triads.emplace_back(log.accel.middleCols(3 * static_cast<Eigen::Index>(k), 3));
  }
  for (size_t k = 0; k < log.gyro_names.size(); ++k) {
    triads.emplace_back(log.gyro.middleCols(3 * static_cast<Eigen::Index>(k), 3));
  }
  log.accel.resize(0, 0);  // the triads hold the readings now
  log.gyro.resize(0, 0);
  for (size_t i = 0; i < triads.size(); ++i) {
    const bool accel = i < log.accel_names.size();
    core::TriadSeries ts;
    ts.name = accel ? log.accel_names[i] : log.gyro_names[i - log.accel_names.size()];
    ts.kind = accel ? core::TriadKind::kAccelerometer : core::TriadKind::kGyroscope;
    ts.readings = &triads[i];
    ts.unit = accel ? options.accel_unit : options.gyro_unit;
    series.push_back(ts);
  }
  if (series.empty()) {
    return Status::InvalidInput("recording " + std::to_string(recording_id) +
                                " has no accelerometer or gyroscope triad");
  }
  *out = RecordingSegments();
  out->recording_id = recording_id;
  out->time_origin = parser.summary().time_origin;
  out->samples = log.t.size();
  out->start = log.t.size() > 0 ? log.t[0] : 0;
  out->end = log.t.size() > 0 ? log.t[log.t.size() - 1] : 0;
  out->accel_names = log.accel_names;
  out->gyro_names = log.gyro_names;
  s = core::DetectStatics(log.t, series, options.detection, &out->detection);
  if (!s.ok()) return s;
  if (options.timeline_points > 0) {
    for (size_t i = 0; i < triads.size(); ++i) {
      const bool accel = i < log.accel_names.size();
      (accel ? out->accel_traces : out->gyro_traces)
          .push_back(MakeTrace(series[i].name, log.t, triads[i],
                               accel ? options.accel_unit : options.gyro_unit,
                               options.timeline_points));
    }
  }
  return Status::Ok();
}

json SegmentsJson(const RecordingSegments& r, const SegmentsOptions& options) {
  const core::StaticDetection& d = r.detection;
  json triads = json::array();
  for (size_t i = 0; i < d.triad_names.size(); ++i) {
    const bool accel = i < r.accel_names.size();
    triads.push_back(
        {{"name", d.triad_names[i]},
         {"kind", accel ? "accelerometer" : "gyroscope"},
         {"noise_floor", Num(d.noise_floor[i])},
         {"threshold", Num(d.threshold[i])},
         {"threshold_si", Num(d.threshold_si[i])},
         {"overridden", static_cast<bool>(d.threshold_overridden[i])},
         {"saturated_samples", i < d.saturated_per_triad.size() ? d.saturated_per_triad[i] : 0}});
  }
  json gaps = json::array();
  for (const auto& g : d.gaps) {
    gaps.push_back({{"index", g.index}, {"start", Num(g.start)}, {"end", Num(g.end)}});
  }
  json intervals = json::array();
  for (size_t n = 0; n < d.intervals.size(); ++n) {
    const core::StaticInterval& iv = d.intervals[n];
    json mean = json::object(), std = json::object();
    for (size_t i = 0; i < d.triad_names.size() && i < iv.mean.size(); ++i) {
      mean[d.triad_names[i]] = Vec(iv.mean[i]);
      std[d.triad_names[i]] = Vec(iv.std[i]);
    }
    intervals.push_back({{"number", n + 1},
                         {"start", Num(iv.start)},
                         {"end", Num(iv.end)},
                         {"samples", iv.samples},
                         {"mean", mean},
                         {"std", std}});
  }
  return {{"recording_id", r.recording_id},
          {"time_origin", r.time_origin},
          {"samples", r.samples},
          {"start", Num(r.start)},
          {"end", Num(r.end)},
          {"sample_period", Num(d.sample_period)},
          {"static_window", Num(options.detection.static_window)},
          {"min_static", Num(options.detection.min_static)},
          {"window_samples", d.window_samples},
          {"threshold_multiplier", Num(d.threshold_multiplier)},
          {"triads", triads},
          {"gaps", gaps},
          {"saturated_samples", d.saturated_samples},
          {"static_samples", d.static_samples},
          {"intervals", intervals}};
}

}  // namespace calibd::server
