// Calibration configs (SPEC §3): JSON text, or HTTP query parameters, to a validated JSON object;
// and the one entry point that runs a calibration of a recording's bytes with such a config.
#ifndef CALIBD_SERVER_CONFIG_H_
#define CALIBD_SERVER_CONFIG_H_

#include <atomic>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "base/status.h"
#include "core/block_lm.h"
#include "core/stop_token.h"
#include "formats/recording.h"
#include "results/json_text.h"
#include "storage/store.h"

namespace calibd::server {

// JSON text to a document (results/json_text.h), as every route and the CLI read it.
using results::kMaxJsonDepth;
using results::ParseJsonText;

// Builds a config object from query parameters. Values that read as JSON numbers, booleans,
// arrays or objects become those; everything else stays a string (so device=123 is "123" only
// for the keys that are names by the SPEC: method, device, bias, solver). Keys that take a
// number or a name (accel_unit, gyro_unit, accel_noise, ...) get the number when it is one.
// Parameters in `ignore` (e.g. "format") are skipped. A repeated key is an error.
Status ConfigFromQuery(const std::multimap<std::string, std::string>& params,
                       nlohmann::json* config);

// The common keys of every config.
struct CommonConfig {
  std::string method;  // a registered method's name (methods/registry.h)
  std::string device;  // serial number; empty when not given
  // The product the device is a unit of (server/fleet.h), as stored; empty when not given.
  std::string product;
  // The config's own time limit (`job_seconds`, > 0); 0 when not given: the server's
  // --job-seconds (or the CLI's) applies. It may only lower the server's limit
  // (CheckJobSeconds).
  double job_seconds = 0;
};

// Checks the whole config: an object, `method` known, `device` and `product` non-empty strings
// of at most 128 printable characters when present (server/device_lookup.h NormalizeSerial),
// `acceptance` (limits of the method's acceptance gate, methods/acceptance.h) when present,
// `time_unit` (s, ms, us, ns; only for methods reading the array layout) when present, and the
// method's own keys (unknown keys are errors). Errors name the key (Status::field(),
// "acceptance.<limit>" for a limit).
Status ValidateConfig(const nlohmann::json& config, CommonConfig* common);

// The config without the keys the server handles for every method, `acceptance`, `job_seconds`,
// `product` and `time_unit` (the parser applies it): what a Method's ValidateConfig, Run and
// Judge see.
nlohmann::json WithoutAcceptance(const nlohmann::json& config);

// OK when the config's job_seconds (common.job_seconds, 0: none) does not ask for more than the
// server's limit `max_seconds` (<= 0: no limit); else kInvalidInput with field "job_seconds"
// naming the server's limit.
Status CheckJobSeconds(const CommonConfig& common, double max_seconds);

class Method;
// Judges a result `method` computed with `config` and writes (*result)["verdict"] (SPEC §4):
// limits = built-in defaults < acceptance_defaults[method] (server-wide, `serve --acceptance`;
// null for none) < config["acceptance"]. The config must have been validated.
void JudgeResult(const Method& method, const nlohmann::json& config,
                 const nlohmann::json& acceptance_defaults, nlohmann::json* result);

// Parses the recording bytes (collecting), checks the layout matches the config's method, runs the
// calibration and writes the result JSON (SPEC §4) with its verdict (JudgeResult; a rejected
// result is still OK: it is computed, only not served). kInvalidInput for bad bytes or config,
// kNotDeterminable when the data cannot determine the parameters.
// `stop` (optional): when it asks to stop, the computation stops early (the result is then
// meaningless and must be discarded). `acceptance_defaults`: the server-wide limits per method
// (`serve --acceptance`), null for the built-in defaults.
Status Calibrate(std::string_view recording, const std::string& file_name,
                 const nlohmann::json& config, nlohmann::json* result,
                 const core::StopToken* stop = nullptr,
                 const nlohmann::json& acceptance_defaults = nlohmann::json());

// A sensor log (summary.format other than "csv") defines its units and time stamps (SPEC §9):
// the CSV keys time_unit, accel_unit, gyro_unit and mag_unit would rescale what is already SI,
// so they are kInvalidInput naming the key. OK for CSV.
Status CheckLogConfig(const RecordingSummary& summary, const nlohmann::json& config,
                      const std::string& file_name);

// Before feeding a collecting parser for CalibrateParsed: sets the parser's time unit from the
// config's `time_unit` (RecordingParser::SetTimeUnit), then lets the config's method choose how
// the numbers are held (Method::PrepareParser). Does nothing for an unknown method or a config
// that is not an object (CalibrateParsed then reports the error).
void PrepareParser(const nlohmann::json& config, RecordingParser* parser);

// A job, a check or a cache build on a stored CSV from another tool reads it as its upload did:
// when `config` gives none of the reading rules (columns, delimiter, decimal), they are taken
// from the recording's stored description (its log_json "csv", validated at upload). A config
// that gives any of them is taken as it is.
void InheritCsvDialect(const storage::RecordingInfo& recording, nlohmann::json* config);

// The same, from a parser that has already been fed and finished (collecting), and prepared by
// PrepareParser. Without `time_unit`, a method that reads the times (Method::ReadsTime) first
// refuses a time column that does not look like seconds (CheckTimeUnit, formats/inertial_log.h;
// Reason::kImplausibleTimeUnit). Epoch stamps: the result's diagnostics get `time_origin`, the
// whole second (of the log's clock) its times count from (RecordingSummary::time_origin).
// `executor` (optional): see RunContext::executor.
Status CalibrateParsed(RecordingParser* parser, const std::string& file_name,
                       const nlohmann::json& config, nlohmann::json* result,
                       const core::StopToken* stop = nullptr,
                       const nlohmann::json& acceptance_defaults = nlohmann::json(),
                       core::TaskExecutor executor = {});

}  // namespace calibd::server

#endif  // CALIBD_SERVER_CONFIG_H_
