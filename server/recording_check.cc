#include "server/recording_check.h"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <vector>

#include "core/static_detection.h"
#include "formats/inertial_log.h"
#include "formats/log_assembly.h"
#include "formats/recording.h"
#include "methods/acceptance.h"
#include "methods/registry.h"
#include "server/column_cache.h"
#include "server/config.h"
#include "server/job_budget.h"

namespace calibd::server {

using nlohmann::json;

namespace {

json Num(double x) { return std::isfinite(x) ? json(x) : json(nullptr); }

// Gravity at rest and the fastest rotation a hand or a rate table gives (2000 deg/s, the
// largest full scale of MEMS gyroscopes): what a log in the declared units must look like.
constexpr double kGravity = 9.80665;         // m/s²
constexpr double kMaxPlausibleRate = 35;     // rad/s
constexpr double kRotationQuantile = 0.999;  // of |ω|: a few spikes do not count
constexpr size_t kMaxGapsListed = 20;

// The q-quantile of `v` (reordered), NaN when empty.
double Quantile(std::vector<double>* v, double q) {
  if (v->empty()) return std::nan("");
  const size_t k = std::min(v->size() - 1, static_cast<size_t>(q * static_cast<double>(v->size())));
  std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(k), v->end());
  return (*v)[k];
}

// Per-row norms of triad k of `columns` (N × 3K) times `unit`.
std::vector<double> RowNorms(const Eigen::MatrixXd& columns, size_t k, double unit) {
  std::vector<double> out(static_cast<size_t>(columns.rows()));
  const auto triad = columns.middleCols(3 * static_cast<Eigen::Index>(k), 3);
  for (Eigen::Index i = 0; i < triad.rows(); ++i)
    out[static_cast<size_t>(i)] = unit * triad.row(i).norm();
  return out;
}

// Rate, jitter and gaps of strictly increasing times (the detector's gap rule).
json Timing(const Eigen::VectorXd& t) {
  const Eigen::Index n = t.size();
  std::vector<double> steps;
  steps.reserve(static_cast<size_t>(std::max<Eigen::Index>(n - 1, 0)));
  for (Eigen::Index i = 1; i < n; ++i) steps.push_back(t[i] - t[i - 1]);
  std::vector<double> sorted = steps;
  const double median = Quantile(&sorted, 0.5);
  const double gap_factor = core::StaticDetectionOptions().gap_factor;
  json gaps = json::array();
  int64_t gap_count = 0;
  double longest = 0, sum2 = 0, worst = 0;
  int64_t regular = 0;
  for (size_t i = 0; i < steps.size(); ++i) {
    if (steps[i] > gap_factor * median) {
      if (gaps.size() < kMaxGapsListed) {
        gaps.push_back({{"index", i + 1},
                        {"start", t[static_cast<Eigen::Index>(i)]},
                        {"end", t[static_cast<Eigen::Index>(i + 1)]}});
      }
      ++gap_count;
      longest = std::max(longest, steps[i]);
      continue;
    }
    const double d = steps[i] - median;
    sum2 += d * d;
    worst = std::max(worst, std::abs(d));
    ++regular;
  }
  const double duration = n > 1 ? t[n - 1] - t[0] : 0;
  return {{"rate", Num(duration > 0 ? static_cast<double>(n - 1) / duration : std::nan(""))},
          {"sample_period", Num(median)},
          {"jitter_rms", Num(regular > 0 ? std::sqrt(sum2 / static_cast<double>(regular)) : 0)},
          {"jitter_max", Num(worst)},
          {"gap_factor", gap_factor},
          {"gaps", gaps},
          {"gap_count", gap_count},
          {"longest_gap", Num(longest)}};
}

// An accelerometer whose magnitude at rest is not gravity in the declared unit, or a gyroscope
// turning faster than any hand-held rotation: units that look wrong. `rest` the norms (m/s² as
// declared) of the statics the method found (empty: the whole log's median is taken instead).
void CheckReadingUnits(const ArrayRecording& log, const InertialUnits& units,
                       const std::vector<double>& rest, json* findings) {
  if (!log.accel_names.empty()) {
    std::vector<double> norms = rest.empty() ? RowNorms(log.accel, 0, units.accel) : rest;
    const double g = Quantile(&norms, 0.5);
    const std::string where =
        rest.empty() ? "the log's median |a|" : "|a| over the statics (median)";
    if (std::isfinite(g) && std::abs(g / kGravity - 1) > 0.3) {
      std::string likely, message;
      if (std::abs(g - 1) < 0.3) {
        likely = "g";
        message = where + " is " + Fmt(g) + " " + units.accel_text +
                  ", not gravity (9.81 m/s^2): the accelerometer is most likely in g; set "
                  "accel_unit to \"g\"";
      } else {
        likely = "";
        message = where + " is " + Fmt(g) + " m/s^2 with accel_unit " + units.accel_text +
                  ", not gravity (9.81): set accel_unit to the m/s^2 per reading unit (" +
                  Fmt(kGravity / g * units.accel) + " would make it gravity)";
      }
      findings->push_back({{"quantity", "accelerometer"},
                           {"key", "accel_unit"},
                           {"likely", likely.empty() ? json(nullptr) : json(likely)},
                           {"message", message}});
    }
  }
  if (!log.gyro_names.empty()) {
    std::vector<double> norms = RowNorms(log.gyro, 0, units.gyro);
    const double w = Quantile(&norms, kRotationQuantile);
    if (std::isfinite(w) && w > kMaxPlausibleRate) {
      const bool degrees = w * M_PI / 180 <= kMaxPlausibleRate;
      findings->push_back(
          {{"quantity", "gyroscope"},
           {"key", "gyro_unit"},
           {"likely", degrees ? json("deg/s") : json(nullptr)},
           {"message",
            "the gyroscope turns at " + Fmt(w) + " rad/s (99.9 % of |omega|) with " + "gyro_unit " +
                units.gyro_text + ", faster than any sensor measures (" + Fmt(kMaxPlausibleRate) +
                " rad/s = 2000 deg/s): " +
                (degrees ? std::string("it is most likely in deg/s; set gyro_unit to "
                                       "\"deg/s\"")
                         : std::string("set gyro_unit to the rad/s per reading unit"))}});
    }
  }
}

json TemperatureRange(const ArrayRecording& log) {
  json out = json::array();
  for (size_t j = 0; j < log.temp_names.size(); ++j) {
    const auto col = log.temperature.col(static_cast<Eigen::Index>(j));
    out.push_back({{"name", log.temp_names[j]},
                   {"min", Num(col.size() ? col.minCoeff() : std::nan(""))},
                   {"max", Num(col.size() ? col.maxCoeff() : std::nan(""))}});
  }
  return out;
}

}  // namespace

Status ParseCheckQuery(const std::multimap<std::string, std::string>& params, storage::Store* store,
                       CheckRequest* request) {
  if (auto it = params.find("job"); it != params.end()) {
    if (params.size() != 1) {
      return Status::InvalidInput(
                 "give job alone (its config is the check's) or method and "
                 "config keys, not both")
          .WithField("job");
    }
    const std::string& text = it->second;
    if (text.empty() || text.size() > 18 ||
        text.find_first_not_of("0123456789") != std::string::npos) {
      return Status::InvalidInput("job must be a job id").WithField("job");
    }
    storage::JobInfo job;
    Status s = store->GetJob(std::stoll(text), &job);
    if (s.code() == StatusCode::kNotFound) return Status::NotFound("no such job " + text);
    if (!s.ok()) return s;
    return ParseJsonText(job.config_json, "config of job " + text, &request->config);
  }
  Status s = ConfigFromQuery(params, &request->config);
  if (!s.ok()) return s;
  if (!request->config.contains("method")) {
    return Status::InvalidInput("method must be given: " + MethodNamesForMessage())
        .WithField("method");
  }
  return Status::Ok();
}

Status ComputeCheck(storage::Store* store, const CheckRequest& request, json* out) {
  CommonConfig common;
  Status s = ValidateConfig(request.config, &common);
  if (!s.ok()) return s;
  const Method* method = FindMethod(common.method);
  if (!method->Reads(Layout::kArray)) {
    return Status::InvalidInput("the check reads inertial logs; method '" + common.method +
                                "' does not calibrate from one")
        .WithField("method");
  }
  // One at a time per process: it holds the whole log, as a job does.
  static std::mutex& one_at_a_time = *new std::mutex;
  std::lock_guard<std::mutex> lock(one_at_a_time);
  storage::RecordingInfo info;
  s = store->GetRecording(request.recording_id, &info);
  if (!s.ok()) return s;
  const std::string name = "recording " + std::to_string(request.recording_id);
  if (info.layout != LayoutName(Layout::kArray)) {
    return Status::NotDeterminable(name + " has the " + info.layout +
                                   " layout; the check reads inertial logs (t, aK_*, gK_*)");
  }
  const json method_config = WithoutAcceptance(request.config);
  const json columns = json::parse(info.columns_json, nullptr, /*allow_exceptions=*/false);
  s = CheckJobBudget(*method,
                     {info.rows, columns.is_array() ? static_cast<int64_t>(columns.size()) : 0},
                     method_config, request.job_memory_bytes);
  if (!s.ok()) return s;
  // Read as the job reads it (PrepareParser: time unit, the upload's CSV dialect unless the
  // config gives one, log streams, the method's time base), in doubles: from the parsed-columns
  // cache when it holds the recording under these rules.
  json read_config = request.config;
  InheritCsvDialect(info, &read_config);
  RecordingParser parser(name, /*collect=*/true);
  parser.ExpectRows(info.rows);
  PrepareParser(read_config, &parser);
  parser.CollectArrayAsDouble();
  const core::StopToken* stop = request.stop;
  const ColumnCache::Outcome read = FillParser(
      request.cache, store, info, &parser,
      stop == nullptr ? std::function<bool()>{} : [stop] { return !stop->stop_requested(); });
  if (!read.parse.ok()) return read.parse;
  if (!read.read.ok()) return read.read;
  s = CheckLogConfig(parser.summary(), request.config, name);
  if (!s.ok()) return s;
  ArrayRecording log;
  s = parser.TakeArray(&log);
  if (!s.ok()) return s;
  // A method that needs t to increase refuses such a log, as its job does; the array method
  // reads t only for its full model's statics, and its positions model not at all.
  if (method->NeedsIncreasingTime()) {
    s = CheckLogTimes(log, common.method, &parser.summary());
    if (!s.ok()) return s;
  }
  json& o = *out;
  o = {{"recording_id", request.recording_id},
       {"method", common.method},
       {"config", request.config},
       {"samples", log.t.size()},
       {"start", Num(log.t.size() ? log.t[0] : std::nan(""))},
       {"end", Num(log.t.size() ? log.t[log.t.size() - 1] : std::nan(""))},
       {"time_origin", parser.summary().time_origin},
       {"timing", log.t.size() >= 2 ? Timing(log.t) : json()},
       {"units", json::array()},
       {"temperature", TemperatureRange(log)},
       {"warnings", json::array()},
       {"predicted", nullptr},
       {"notes", json::array()}};
  // A time column that does not look like seconds: the job would refuse it, and statics found
  // on it would be meaningless.
  TimeUnit unit;
  bool unit_given = false;
  (void)ParseTimeUnit(request.config, &unit, &unit_given);
  const bool sensor_log = parser.summary().format != "csv";
  Status time_unit = Status::Ok();
  if (!sensor_log && !unit_given && method->ReadsTime(method_config)) {
    time_unit = CheckTimeUnit(parser.summary(), name);
  }
  if (!time_unit.ok()) {
    const std::string text = time_unit.message();
    json likely = nullptr;
    for (TimeUnit u : {TimeUnit::kMilliseconds, TimeUnit::kMicroseconds, TimeUnit::kNanoseconds}) {
      if (text.find("set the config key time_unit to \"" + std::string(TimeUnitName(u)) + "\"") !=
          std::string::npos) {
        likely = TimeUnitName(u);
      }
    }
    o["units"].push_back(
        {{"quantity", "time"}, {"key", "time_unit"}, {"likely", likely}, {"message", text}});
    o["job_would_fail"] = text;
    o["notes"].push_back(
        "no statics or saturation: set time_unit first (the job would refuse "
        "the log as it is)");
  } else {
    RunContext context;
    context.stop = request.stop;
    s = method->Check(log, method_config, context, &o);
    if (!s.ok()) return s;
  }
  if (o["predicted"].is_null() && time_unit.ok() && !o.contains("job_would_fail")) {
    o["notes"].push_back("predicted: the " + common.method +
                         " method's check does not predict its σ (POST /api/v1/plan does, "
                         "for a protocol)");
  }
  for (const char* key : {"saturation", "statics"}) {
    if (!o.contains(key)) {
      o[key] = nullptr;
      if (time_unit.ok()) {
        o["notes"].push_back(std::string(key) + ": the " + common.method +
                             " method's check does not report it");
      }
    }
  }
  InertialUnits units;
  (void)ParseInertialUnits(method_config, &units);
  std::vector<double> rest;
  if (o["statics"].is_array()) {
    for (const json& st : o["statics"]) {
      if (st.contains("accel_norm") && st["accel_norm"].is_number()) {
        rest.push_back(st["accel_norm"].get<double>());
      }
    }
  }
  CheckReadingUnits(log, units, rest, &o["units"]);
  return Status::Ok();
}

}  // namespace calibd::server
