#include "server/cli.h"

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <thread>

#include "core/stop_token.h"
#include "methods/acceptance.h"
#include "methods/method.h"
#include "methods/registry.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "server/plan.h"
#include "server/serve.h"

namespace calibd::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

int ExitCodeFor(const Status& s) {
  switch (s.code()) {
    case StatusCode::kOk:
      return kExitOk;
    case StatusCode::kInvalidInput:
      return kExitBadInput;
    case StatusCode::kNotDeterminable:
      return kExitNotDeterminable;
    case StatusCode::kStopped:
      return kExitTimeLimit;
    default:
      return kExitFailure;
  }
}

int Report(const Status& s) {
  std::cerr << "calibd: " << s.ToString() << "\n";
  return ExitCodeFor(s);
}

// A failed calibration: the message, then its reason code and the catalog's advice (the same
// as GET /api/v1/jobs/{id} "error.reason" and "error.advice").
int ReportFailure(const Status& s) {
  const FailureReason& reason = DescribeReason(ReasonOf(s));
  std::cerr << "calibd: " << s.ToString() << "\n"
            << "calibd: reason: " << reason.code << " (" << reason.title << ")\n"
            << "calibd: advice: " << reason.advice << "\n";
  return ExitCodeFor(s);
}

Status ReadFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidInput("cannot open file").WithFile(path);
  out->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  if (in.bad()) return Status::InvalidInput("cannot read file").WithFile(path);
  return Status::Ok();
}

// Streams a recording file through a collecting parser in 1 MiB chunks.
Status ParseRecordingFile(const std::string& path, RecordingParser* parser) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidInput("cannot open file").WithFile(path);
  std::string buffer(1 << 20, '\0');
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize got = in.gcount();
    if (got > 0) {
      Status s = parser->Feed(std::string_view(buffer.data(), static_cast<size_t>(got)));
      if (!s.ok()) return s;
    }
  }
  if (in.bad()) return Status::InvalidInput("cannot read file").WithFile(path);
  return parser->Finish();
}

// Offline, `accelerometer_calibration` may be a path to a result JSON file: inline it.
Status InlineCalibrationFile(const std::string& config_path, json* config) {
  auto it = config->find("accelerometer_calibration");
  if (it == config->end() || !it->is_string()) return Status::Ok();
  fs::path path = it->get<std::string>();
  if (path.is_relative()) path = fs::path(config_path).parent_path() / path;
  std::string text;
  Status s = ReadFile(path.string(), &text);
  if (!s.ok()) return s.WithField("accelerometer_calibration");
  json result;
  s = ParseJsonText(text, path.string(), &result);
  if (!s.ok()) return s;
  *it = std::move(result);
  return Status::Ok();
}

int Calibrate(const std::string& recording_path, const std::string& config_path, bool compact,
              const std::string& acceptance_path, double job_seconds) {
  const auto start = std::chrono::steady_clock::now();
  json acceptance;
  if (!acceptance_path.empty()) {
    Status s = LoadAcceptanceFile(acceptance_path, &acceptance);
    if (!s.ok()) return Report(s);
  }
  std::string config_text;
  Status s = ReadFile(config_path, &config_text);
  if (!s.ok()) return Report(s);
  json config;
  s = ParseJsonText(config_text, config_path, &config);
  if (!s.ok()) return Report(s);
  if (config.is_object()) {
    s = InlineCalibrationFile(config_path, &config);
    if (!s.ok()) return Report(s);
  }
  CommonConfig common;
  s = ValidateConfig(config, &common);
  if (!s.ok()) return Report(s.WithFile(config_path));
  // The time limit from the start: --job-seconds, or the config's job_seconds when lower.
  double limit = job_seconds;
  if (common.job_seconds > 0 && (limit <= 0 || common.job_seconds < limit)) {
    limit = common.job_seconds;
  }
  core::StopToken stop;
  if (limit > 0) {
    stop.SetDeadline(start + std::chrono::microseconds(static_cast<int64_t>(limit * 1e6)));
  }
  auto time_limit_reached = [&](const Status& run) {
    char text[160];
    std::snprintf(text, sizeof text, "the time limit of %g s (%s) was reached after %.1f s", limit,
                  limit == job_seconds ? "--job-seconds" : "config job_seconds",
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    std::string message = text;
    if (run.code() == StatusCode::kStopped) message += " (" + run.message() + ")";
    return ReportFailure(Status(StatusCode::kStopped, message + "; the calibration was stopped")
                             .WithReason(Reason::kDeadline));
  };
  RecordingParser parser(recording_path, /*collect=*/true);
  PrepareParser(config, &parser);
  s = ParseRecordingFile(recording_path, &parser);
  if (!s.ok()) {
    return ReportFailure(s.reason() == Reason::kUnspecified && s.code() == StatusCode::kInvalidInput
                             ? s.WithReason(Reason::kRecordingUnreadable)
                             : s);
  }
  if (stop.stop_requested()) return time_limit_reached(Status::Ok());
  json result;
  s = CalibrateParsed(&parser, recording_path, config, &result, &stop, acceptance);
  if (stop.stop_requested()) return time_limit_reached(s);
  if (!s.ok()) return ReportFailure(s);
  std::cout << (compact ? result.dump() : result.dump(2)) << "\n";
  // The verdict for people too (the exit code stays 0: a result was computed; a rejected one is
  // what a server would not serve).
  const json& verdict = result["verdict"];
  std::cerr << "calibd: verdict: " << verdict.value("status", std::string("?")) << "\n";
  for (const json& reason : verdict.value("reasons", json::array())) {
    std::cerr << "calibd:   - " << reason.get<std::string>() << "\n";
  }
  return kExitOk;
}

// `calibd plan`: the plan of a protocol (SPEC §10, server/plan.h) printed as JSON.
int Plan(const std::string& method, const std::string& config_path,
         const std::string& protocol_path, const std::string& acceptance_path) {
  json acceptance;
  if (!acceptance_path.empty()) {
    if (Status s = LoadAcceptanceFile(acceptance_path, &acceptance); !s.ok()) return Report(s);
  }
  json request = {{"method", method}, {"config", json::object()}};
  for (const auto& [path, key] :
       {std::pair<std::string, const char*>{config_path, "config"}, {protocol_path, "protocol"}}) {
    if (path.empty()) continue;
    std::string text;
    if (Status s = ReadFile(path, &text); !s.ok()) return Report(s);
    if (Status s = ParseJsonText(text, path, &request[key]); !s.ok()) return Report(s);
  }
  json& config = request["config"];
  if (config.is_object()) {
    if (!config.contains("method")) config["method"] = method;
    if (Status s = InlineCalibrationFile(config_path, &config); !s.ok()) return Report(s);
  }
  json out;
  if (Status s = PlanJson(request, acceptance, &out); !s.ok()) return Report(s);
  std::cout << out.dump(2) << "\n";
  return kExitOk;
}

// Writes `content` to dir/name atomically (temporary file, then rename).
Status WriteFileAtomically(const fs::path& dir, const std::string& name,
                           const std::string& content) {
  const fs::path target = dir / name;
  const fs::path temp = dir / ("." + name + ".tmp");
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    if (!out) return Status::IoError("cannot write").WithFile(temp.string());
    out << content;
    out.flush();
    if (!out) return Status::IoError("cannot write").WithFile(temp.string());
  }
  std::error_code ec;
  fs::rename(temp, target, ec);
  if (ec) return Status::IoError("cannot rename: " + ec.message()).WithFile(target.string());
  return Status::Ok();
}

int WriteSimulation(const std::string& out_dir, const std::string& csv, const json& config,
                    const json& truth) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec)
    return Report(Status::IoError("cannot create directory: " + ec.message()).WithFile(out_dir));
  for (const auto& [name, content] : {std::pair<std::string, std::string>{"recording.csv", csv},
                                      {"config.json", config.dump(2) + "\n"},
                                      {"truth.json", truth.dump(2) + "\n"}}) {
    Status s = WriteFileAtomically(out_dir, name, content);
    if (!s.ok()) return Report(s);
  }
  std::cerr << "calibd: wrote " << (fs::path(out_dir) / "recording.csv").string() << ", "
            << "config.json and truth.json\n";
  return kExitOk;
}

// Adds `serve` and its flags to `app`; parsing fills *serve.
CLI::App* AddServeCommand(CLI::App* app, ServeOptions* serve) {
  CLI::App* serve_cmd = app->add_subcommand("serve", "HTTP server plus job workers");
  serve_cmd
      ->add_option("--db", serve->db_path,
                   "SQLite database file (created with its folder), or a PostgreSQL "
                   "connection URI postgresql://USER@HOST/DB shared by several calibd")
      ->capture_default_str();
  serve_cmd->add_option("--listen", serve->listen, "HOST:PORT to listen on")->capture_default_str();
  serve_cmd->add_option("--workers", serve->workers, "calibration worker threads (0: one per core)")
      ->check(CLI::Range(0, 256))
      ->capture_default_str();
  serve_cmd->add_option("--token-file", serve->token_file,
                        "file holding the bearer token that writes require");
  serve_cmd->add_option("--acceptance", serve->acceptance_file,
                        "JSON file of server-wide acceptance limits per method, e.g. "
                        "{\"pca\": {\"max_scale_std\": 0.005}} (a config's `acceptance` overrides "
                        "them per key)");
  serve_cmd->add_flag("--insecure", serve->insecure,
                      "allow a non-loopback --listen without a token");
  serve_cmd
      ->add_option("--max-upload-bytes", serve->max_upload_bytes,
                   "largest accepted upload (a gzip'd recording: compressed and decompressed)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40))
      ->capture_default_str();
  serve_cmd
      ->add_option("--max-gzip-ratio", serve->max_gzip_ratio,
                   "a gzip'd recording expanding more than this is refused (413)")
      ->check(CLI::Range(1.0, 1e6))
      ->capture_default_str();
  serve_cmd
      ->add_option("--job-memory-bytes", serve->job_memory_bytes,
                   "memory one job may use; larger jobs are refused with 422 (0: half the "
                   "machine's memory shared among the workers, 256 MiB to 8 GiB each)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 50))
      ->capture_default_str();
  serve_cmd
      ->add_option("--http-threads", serve->http_threads,
                   "threads that process requests (slow and idle connections hold none)")
      ->check(CLI::Range(4, 1024))
      ->capture_default_str();
  serve_cmd
      ->add_option("--head-timeout-seconds", serve->head_timeout_seconds,
                   "a request's line and headers must arrive within this (else 408)")
      ->check(CLI::Range(1, 300))
      ->capture_default_str();
  serve_cmd
      ->add_option("--max-connections-per-client", serve->max_connections_per_client,
                   "open connections per client address (503 beyond)")
      ->check(CLI::Range(1, 900))
      ->capture_default_str();
  serve_cmd
      ->add_option("--max-requests-per-client", serve->max_requests_per_client,
                   "requests in progress per client address (more wait their turn)")
      ->check(CLI::Range(1, 1024))
      ->capture_default_str();
  serve_cmd
      ->add_option("--grace-seconds", serve->shutdown_grace_seconds,
                   "on SIGTERM, how long running jobs may finish before their leases "
                   "are released")
      ->check(CLI::Range(0, 3600))
      ->capture_default_str();
  serve_cmd
      ->add_option("--job-seconds", serve->job_seconds,
                   "time limit of every job; a job past it fails with reason deadline (0: "
                   "0.5 s per MiB of the per-job memory budget, at least 60 s; a config's "
                   "job_seconds may lower it)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 31))
      ->capture_default_str();
  serve_cmd
      ->add_option("--check-seconds", serve->check_seconds,
                   "how often the database's structure is checked (SQLite quick_check) besides "
                   "at start; damage makes /healthz answer 503 (0: only at start)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 31))
      ->capture_default_str();
  serve_cmd
      ->add_option("--db-max-pages", serve->db_max_pages,
                   "a quota on the SQLite file in pages of 4 KiB; writes beyond it answer 507 "
                   "like a full disk (0: none)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 40))
      ->capture_default_str();
  serve_cmd
      ->add_option("--column-cache-bytes", serve->column_cache_bytes,
                   "disk for the parsed-columns cache of stored inertial logs (beside the SQLite "
                   "file in columns/; least recently used removed first; 0: no cache)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 50))
      ->capture_default_str();
  serve_cmd->add_flag("!--no-access-log", serve->access_log, "do not log requests to stderr");
  return serve_cmd;
}

}  // namespace

int RunCli(int argc, char** argv) {
  CLI::App app{"calibd: calibration server for multi-sensor inertial systems"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "calibd 0.1.0");

  ServeOptions serve;
  CLI::App* serve_cmd = AddServeCommand(&app, &serve);

  // calibrate
  std::string recording_path, config_path, acceptance_path;
  bool compact = false;
  CLI::App* calibrate_cmd =
      app.add_subcommand("calibrate", "run one calibration offline and print the result JSON");
  calibrate_cmd->add_option("recording", recording_path, "recording CSV (SPEC §2)")->required();
  calibrate_cmd->add_option("--config", config_path, "config JSON (SPEC §3)")->required();
  calibrate_cmd->add_flag("--compact", compact, "print the JSON on one line");
  calibrate_cmd->add_option("--acceptance", acceptance_path,
                            "JSON file of acceptance limits per method, as for serve");
  double calibrate_seconds = 0;
  calibrate_cmd
      ->add_option("--job-seconds", calibrate_seconds,
                   "stop the calibration after this many seconds (exit 4; 0: no limit; the "
                   "config's job_seconds may lower it)")
      ->check(CLI::Range(0.0, 1e9));
  calibrate_cmd->footer(
      "Exit codes: 0 a result was computed (its \"verdict\" says whether the acceptance gate "
      "accepts it; also printed on stderr), 2 bad input (file, line, column on stderr), 3 the "
      "data cannot determine the parameters (the message says what to record instead), 4 the "
      "time limit (--job-seconds or the config's job_seconds) was reached.");

  // plan
  std::string plan_method, plan_config, plan_protocol, plan_acceptance;
  CLI::App* plan_cmd = app.add_subcommand(
      "plan", "predict the σ a protocol would give, what it cannot determine, and a suggestion");
  plan_cmd->add_option("--method", plan_method, "the method")->required();
  plan_cmd->add_option("--config", plan_config, "config JSON (SPEC §3)");
  plan_cmd
      ->add_option("--protocol", plan_protocol,
                   "protocol JSON: {\"orientations\": [\"+x\", [0, 0, 1], ...], "
                   "\"static_duration\", \"rate\", \"rotation_duration\"}")
      ->required();
  plan_cmd->add_option("--acceptance", plan_acceptance,
                       "JSON file of acceptance limits per method, as for serve");

  // simulate
  CLI::App* simulate_cmd =
      app.add_subcommand("simulate",
                         "write DIR/recording.csv, DIR/config.json and DIR/truth.json of a paper's "
                         "simulation set-up (deterministic per seed)");
  simulate_cmd->require_subcommand(1);
  // One subcommand per method that has a simulation (Method::AddSimulateOptions).
  std::string out_dir;
  std::vector<std::pair<CLI::App*, std::function<Status(SimulatedFiles*)>>> simulations;
  for (const Method* method : AllMethods()) {
    if (*method->simulate_summary() == '\0') continue;
    CLI::App* command = simulate_cmd->add_subcommand(method->name(), method->simulate_summary());
    command->add_option("--out", out_dir, "output directory")->required();
    simulations.emplace_back(command, method->AddSimulateOptions(command));
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? kExitOk : kExitBadInput;
  }

  if (*serve_cmd) return RunServe(serve);
  if (*calibrate_cmd) {
    return Calibrate(recording_path, config_path, compact, acceptance_path, calibrate_seconds);
  }
  if (*plan_cmd) return Plan(plan_method, plan_config, plan_protocol, plan_acceptance);
  for (const auto& [command, simulate] : simulations) {
    if (!*command) continue;
    SimulatedFiles files;
    Status s = simulate(&files);
    if (!s.ok()) return Report(s);
    const int code = WriteSimulation(out_dir, files.csv, files.config, files.truth);
    if (code != kExitOk || files.extra.empty()) return code;
    std::string names;
    for (const auto& [name, content] : files.extra) {
      s = WriteFileAtomically(out_dir, name, content);
      if (!s.ok()) return Report(s);
      names += (names.empty() ? "" : " and ") + name;
    }
    std::cerr << "calibd: wrote " << names << "\n";
    return kExitOk;
  }
  return kExitFailure;
}

}  // namespace calibd::server
