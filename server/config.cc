#include "server/config.h"

#include <cctype>
#include <cstdio>

#include "formats/csv_dialect.h"
#include "formats/inertial_log.h"
#include "formats/log_assembly.h"
#include "methods/method.h"
#include "methods/registry.h"
#include "server/device_lookup.h"
#include "server/fleet.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// Keys whose values are names only (never numbers): a value that reads as JSON stays a string
// (device=123 is the serial "123"). Keys that take a number or a name (accel_unit, gyro_unit,
// accel_noise, ...) are not here: "0.0001598" becomes the number, "deg/s" stays the name.
bool IsStringKey(const std::string& key) {
  return key == "method" || key == "device" || key == "product" || key == "bias" || key == "solver";
}

}  // namespace

Status ConfigFromQuery(const std::multimap<std::string, std::string>& params, json* config) {
  *config = json::object();
  for (const auto& [key, value] : params) {
    if (!IsValidUtf8(key) || !IsValidUtf8(value)) {
      return Status::InvalidInput("query parameter '" + std::string(IsValidUtf8(key) ? key : "?") +
                                  "' is not valid UTF-8")
          .WithField(IsValidUtf8(key) ? key : "");
    }
    if (config->contains(key)) {
      return Status::InvalidInput("query parameter '" + key + "' given more than once")
          .WithField(key);
    }
    if (IsStringKey(key)) {
      (*config)[key] = value;
      continue;
    }
    json parsed;
    Status s = ParseJsonText(value, "query parameter '" + key + "'", &parsed);
    if (s.ok() && !parsed.is_string()) {
      (*config)[key] = std::move(parsed);
    } else {
      (*config)[key] = value;
    }
  }
  return Status::Ok();
}

Status ValidateConfig(const json& config, CommonConfig* common) {
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  auto method = config.find("method");
  if (method == config.end()) {
    return Status::InvalidInput("missing key 'method' (" + MethodNamesForMessage() + ")")
        .WithField("method");
  }
  const Method* m =
      method->is_string() ? FindMethod(method->get_ref<const std::string&>()) : nullptr;
  if (m == nullptr) {
    return Status::InvalidInput("'method' must be " + MethodNamesForMessage() + ", not " +
                                method->dump().substr(0, 60))
        .WithField("method");
  }
  common->method = method->get<std::string>();
  common->device.clear();
  if (auto device = config.find("device"); device != config.end()) {
    if (!device->is_string()) {
      return Status::InvalidInput("'device' must be a string (the serial number)")
          .WithField("device");
    }
    // Stored in NFC; invisible, bidi-control and edge white-space characters refused.
    Status s = NormalizeSerial(device->get_ref<const std::string&>(), &common->device);
    if (!s.ok()) return s;
  }
  common->product.clear();
  if (auto product = config.find("product"); product != config.end()) {
    if (!product->is_string()) {
      return Status::InvalidInput("'product' must be a string (the product's name)")
          .WithField("product");
    }
    Status s = NormalizeProduct(product->get_ref<const std::string&>(), &common->product);
    if (!s.ok()) return s;
  }
  common->job_seconds = 0;
  if (auto limit = config.find("job_seconds"); limit != config.end()) {
    if (!limit->is_number() || !(limit->get<double>() > 0) || limit->get<double>() > 1e9) {
      return Status::InvalidInput(
                 "'job_seconds' must be a number of seconds > 0 (the job's time limit, at most "
                 "the server's --job-seconds), not " +
                 limit->dump().substr(0, 60))
          .WithField("job_seconds");
    }
    common->job_seconds = limit->get<double>();
  }
  if (auto acceptance = config.find("acceptance"); acceptance != config.end()) {
    Status s =
        ValidateAcceptance(*acceptance, common->method, "config key 'acceptance'", "acceptance");
    if (!s.ok()) return s;
  }
  // time_unit: for every method whose recordings have a time column (the array layout); the
  // parser applies it (PrepareParser), so the methods never see it.
  if (config.contains("time_unit")) {
    if (!m->Reads(Layout::kArray)) {
      return Status::InvalidInput(
                 "'time_unit' is for methods whose recording has a time column "
                 "'t'; method '" +
                 common->method + "' reads none")
          .WithField("time_unit");
    }
    TimeUnit unit;
    bool given;
    Status s = ParseTimeUnit(config, &unit, &given);
    if (!s.ok()) return s;
  }
  // columns, delimiter, decimal: how a CSV from another tool is read; the parser applies them.
  if (HasCsvDialectKeys(config)) {
    CsvDialect dialect;
    Status s = ParseCsvDialect(config, &dialect);
    if (!s.ok()) return s;
  }
  // streams: which streams of a sensor log form the IMUs (SPEC §9); the parser applies it.
  if (config.contains("streams")) {
    if (!m->Reads(Layout::kArray)) {
      return Status::InvalidInput("'streams' chooses a sensor log's IMUs; method '" +
                                  common->method + "' reads no inertial log")
          .WithField("streams");
    }
    LogStreamSelection streams;
    Status s = ParseLogStreams(config, &streams);
    if (!s.ok()) return s;
  }
  return m->ValidateConfig(WithoutAcceptance(config));
}

json WithoutAcceptance(const json& config) {
  if (!config.is_object() || (!config.contains("acceptance") && !config.contains("time_unit") &&
                              !config.contains("job_seconds") && !config.contains("product") &&
                              !config.contains("streams") && !HasCsvDialectKeys(config))) {
    return config;
  }
  json out = config;
  for (const char* key : kCsvDialectKeys) out.erase(key);
  out.erase("streams");
  out.erase("product");
  out.erase("acceptance");
  out.erase("time_unit");
  out.erase("job_seconds");
  return out;
}

Status CheckJobSeconds(const CommonConfig& common, double max_seconds) {
  if (common.job_seconds <= 0 || max_seconds <= 0 || common.job_seconds <= max_seconds) {
    return Status::Ok();
  }
  char text[96];
  std::snprintf(text, sizeof text, "%g s; this server allows at most %g s (--job-seconds)",
                common.job_seconds, max_seconds);
  return Status::InvalidInput(std::string("'job_seconds' asks for ") + text +
                              ": ask for less, or run it on a server with a larger limit")
      .WithField("job_seconds");
}

void JudgeResult(const Method& method, const json& config, const json& acceptance_defaults,
                 json* result) {
  const AcceptanceLimits limits = EffectiveAcceptance(method.name(), acceptance_defaults, config);
  Verdict verdict;
  try {
    method.Judge(*result, WithoutAcceptance(config), limits, &verdict);
  } catch (const nlohmann::json::exception&) {
    // A result of an unexpected shape: fail closed, never serve what could not be judged.
    verdict.Reject("the result could not be judged (unexpected shape); please report it");
  }
  (*result)["verdict"] = verdict.ToJson(limits);
}

Status CheckLogConfig(const RecordingSummary& summary, const json& config,
                      const std::string& file_name) {
  if (summary.format == "csv" || !config.is_object()) return Status::Ok();
  for (const char* key :
       {"time_unit", "accel_unit", "gyro_unit", "mag_unit", "columns", "delimiter", "decimal"}) {
    if (config.contains(key)) {
      return Status::InvalidInput(Reason::kInvalidConfig,
                                  std::string("'") + key + "' is for CSV recordings; this " +
                                      summary.format +
                                      " log defines its own units (SI; µT for magnetic field)")
          .WithFile(file_name)
          .WithField(key);
    }
  }
  return Status::Ok();
}

void InheritCsvDialect(const storage::RecordingInfo& recording, json* config) {
  if (HasCsvDialectKeys(*config)) return;
  const json read = json::parse(recording.log_json, nullptr, /*allow_exceptions=*/false);
  if (!read.is_object() || !read.contains("csv") || !read["csv"].is_object()) return;
  CsvDialect dialect;
  if (!ParseCsvDialect(read["csv"], &dialect).ok() || dialect.IsDefault()) return;
  const json rules = dialect.ToJson();
  for (const char* key : kCsvDialectKeys)
    if (rules.contains(key)) (*config)[key] = rules[key];
}

void PrepareParser(const json& config, RecordingParser* parser) {
  if (!config.is_object()) return;
  CsvDialect dialect;
  if (ParseCsvDialect(config, &dialect).ok()) parser->SetCsvDialect(dialect);
  const auto it = config.find("method");
  if (it == config.end() || !it->is_string()) return;
  TimeUnit unit;
  bool given;
  if (ParseTimeUnit(config, &unit, &given).ok()) parser->SetTimeUnit(unit);
  LogStreamSelection streams;
  if (ParseLogStreams(config, &streams).ok()) parser->SetLogStreams(streams);
  const Method* method = FindMethod(it->get_ref<const std::string&>());
  if (method != nullptr) method->PrepareParser(WithoutAcceptance(config), parser);
}

Status CalibrateParsed(RecordingParser* parser, const std::string& file_name, const json& config,
                       json* result, const core::StopToken* stop, const json& acceptance_defaults,
                       core::TaskExecutor executor) {
  CommonConfig common;
  Status s = ValidateConfig(config, &common);
  if (!s.ok()) return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
  const Method* method = FindMethod(common.method);
  const Layout layout = parser->summary().layout;
  if (!method->Reads(layout)) {
    return Status::InvalidInput(Reason::kInvalidConfig,
                                std::string("the config says method '") + common.method +
                                    "' but the recording has the " + LayoutName(layout) +
                                    " layout, which it cannot read (SPEC §2)")
        .WithFile(file_name)
        .WithField("method");
  }
  const bool log = parser->summary().format != "csv";
  s = CheckLogConfig(parser->summary(), config, file_name);
  if (!s.ok()) return s;
  // The time column's unit: as configured (the parser was told, PrepareParser; one that was not
  // is refused rather than read in the wrong unit), or, when not configured, seconds that must
  // look like seconds (CheckTimeUnit) for a method that reads the times.
  TimeUnit unit;
  bool unit_given;
  s = ParseTimeUnit(config, &unit, &unit_given);
  if (!s.ok()) return s.WithReason(Reason::kInvalidConfig);
  if (parser->summary().t_column != 0 && parser->time_unit() != unit) {
    return Status::Internal("the recording was parsed with time unit " +
                            std::string(TimeUnitName(parser->time_unit())) + ", the config says " +
                            TimeUnitName(unit) + " (PrepareParser not called)");
  }
  if (!log && !unit_given && method->ReadsTime(WithoutAcceptance(config))) {
    s = CheckTimeUnit(parser->summary(), file_name);
    if (!s.ok()) return s;
  }
  const int64_t time_origin = parser->summary().time_origin;
  RunContext context;
  context.stop = stop;
  context.executor = std::move(executor);
  s = method->Run(parser, WithoutAcceptance(config), context, result);
  if (s.code() == StatusCode::kStopped) {
    // A stop can land in a stage shared by the methods (static detection, the saturation search)
    // whose message does not name the method, and before the method wrote its partial document:
    // the job's error still names the method, and its partial diagnostics say it was not usable.
    if (s.message().rfind(common.method + ":", 0) != 0) {
      s = Status(StatusCode::kStopped, common.method + ": " + s.message()).WithReason(s.reason());
    }
    if (!result->is_object()) {
      *result = json{{"method", common.method},
                     {"usable", false},
                     {"diagnostics", json::object()},
                     {"warnings", json::array()}};
    }
  }
  // Epoch stamps were counted from this second (RecordingParser): the times in the result are
  // seconds after it.
  if (time_origin != 0 && result->is_object() && result->contains("diagnostics") &&
      (*result)["diagnostics"].is_object()) {
    (*result)["diagnostics"]["time_origin"] = time_origin;
  }
  // A sensor log: the job says what it read (format, time base and time source, the streams of
  // each IMU, what was resampled or dropped), and the log's warnings join the result's.
  if (log && result->is_object()) {
    json read = json::parse(parser->summary().log_description, nullptr, false);
    if (read.is_object()) {
      if (result->contains("diagnostics") && (*result)["diagnostics"].is_object()) {
        (*result)["diagnostics"]["log"] = {{"format", read.value("format", "")},
                                           {"time_base", read.value("time_base", "")},
                                           {"imus", read.value("imus", json::array())}};
      }
      if (read.contains("warnings") && read["warnings"].is_array() &&
          result->contains("warnings") && (*result)["warnings"].is_array()) {
        for (const json& w : read["warnings"]) (*result)["warnings"].push_back(w);
      }
    }
  }
  if (!s.ok()) return s;
  JudgeResult(*method, config, acceptance_defaults, result);
  return Status::Ok();
}

Status Calibrate(std::string_view recording, const std::string& file_name, const json& config,
                 json* result, const core::StopToken* stop, const json& acceptance_defaults) {
  RecordingParser parser(file_name, /*collect=*/true);
  PrepareParser(config, &parser);
  Status s = ParseRecording(recording, &parser);
  if (!s.ok()) {
    return s.reason() == Reason::kUnspecified && s.code() == StatusCode::kInvalidInput
               ? s.WithReason(Reason::kRecordingUnreadable)
               : s;
  }
  return CalibrateParsed(&parser, file_name, config, result, stop, acceptance_defaults);
}

}  // namespace calibd::server
