// Method: one calibration method as the server sees it: which recording layouts it reads, its
// config keys (checked before a job is queued), how it runs on a parsed recording, its gate, its
// exports and its simulation. The registry (methods/registry.h) pairs it with its report
// (web/method_report.h) in one MethodDescriptor.
//
// A method is one folder, methods/<name>/: its adapter <name>_method.{h,cc} (config keys to core
// options, core result to the SPEC §4 result JSON, a class implementing Method, its acceptance
// limits beside its Judge, its failure reasons), its typed result <name>_result.{h,cc}, its
// exports <name>_exports.cc, its report <name>_report.{h,cc} (and drift), its references to other
// jobs; its numerics live in core/. Adding one is that folder plus one line in
// methods/registry.cc: the CLI's `calibrate` and `simulate`, the upload, job and export routes,
// the job list filters, the OpenAPI document and the pages find methods through the registry.
#ifndef CALIBD_SERVER_METHOD_H_
#define CALIBD_SERVER_METHOD_H_

#include <atomic>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "base/status.h"
#include "core/block_lm.h"
#include "core/stop_token.h"
#include "formats/recording.h"
#include "methods/acceptance.h"
#include "methods/exports.h"
#include "methods/failure_reason.h"
#include "methods/plan.h"

namespace CLI {
class App;  // CLI11 (server/cli.cc)
}  // namespace CLI

namespace calibd::storage {
class Store;  // storage/store.h
}  // namespace calibd::storage

namespace calibd::server {

// The files of `calibd simulate NAME` (server/cli.cc writes them into --out).
struct SimulatedFiles {
  std::string csv;        // recording.csv
  nlohmann::json config;  // config.json
  nlohmann::json truth;   // truth.json: the parameters the simulation used
  std::vector<std::pair<std::string, std::string>> extra;  // further files: name, content
};

// What a run may consult besides its inputs.
struct RunContext {
  // Asks the method to stop early (cancel, deadline, shutdown); its result is then discarded.
  // Methods poll it in every long loop (core/stop_token.h). May be null: never stops.
  const core::StopToken* stop = nullptr;
  // Runs a method's parallel numerics (the server's one shared core::TaskPool, so concurrent
  // jobs never start cores × cores threads). Empty: the method starts its own threads.
  core::TaskExecutor executor;
};

class Method {
 public:
  virtual ~Method() = default;
  // The config's `method` value, e.g. pca.
  virtual const char* name() const = 0;
  // One line for people: what it estimates from what.
  virtual const char* summary() const = 0;
  // Whether it can calibrate a recording of this layout (a log may suit several methods).
  virtual bool Reads(Layout layout) const = 0;
  // Whether its recordings need a time column `t` that increases strictly (the raw-log methods):
  // an upload with a `t` that repeats or goes back is then refused at once (400 naming the line).
  virtual bool NeedsIncreasingTime() const { return false; }
  // Whether its run with this config reads the time column's values (then a `t` that does not
  // look like seconds is refused when `time_unit` is not given: formats/inertial_log.h
  // CheckTimeUnit). `config` has been validated, `acceptance` and `time_unit` removed.
  virtual bool ReadsTime(const nlohmann::json& config) const {
    (void)config;
    return NeedsIncreasingTime();
  }
  // The method's own config keys (the common keys method and device are checked by the caller;
  // unknown keys are errors). kInvalidInput naming the key (Status::field()).
  virtual Status ValidateConfig(const nlohmann::json& config) const = 0;
  // Takes the recording from a finished, collecting parser of a layout it Reads(), and writes the
  // SPEC §4 result. kInvalidInput (config or data that cannot be used as given),
  // kNotDeterminable (the data cannot determine the parameters; the message says what to record).
  // A failure carries its Reason (Status::reason(), catalog in server/failure_reasons.h and
  // FailureReasons():
  // kInvalidConfig for a config key) and, once the numerics have run, leaves the partial
  // diagnostics in `result`: {"method", "usable": false, "diagnostics": {what was found before
  // failing}, "warnings"}, which the worker keeps with the failed job and the method's report
  // renders (web::MethodReport::Partial). A failure before the numerics leaves `result` as is.
  virtual Status Run(RecordingParser* parser, const nlohmann::json& config, const RunContext& ctx,
                     nlohmann::json* result) const = 0;
  // Over HTTP, before a job is stored (upload, POST /jobs): replaces the config's references to
  // other jobs ({"job": ID} where the method takes another calibration's result, SPEC §7) by what
  // the job needs of those jobs' stored results, so the queued job is self-contained (a later job
  // cannot change it) and says which jobs it used. `config` has not been validated yet (its
  // `method` names this method); a malformed reference, a job that does not exist or is not a
  // succeeded (and, where the result is served to a device, accepted) job of the right method is
  // kInvalidInput naming the key; storage errors as they are. Offline there are no jobs: the CLI
  // inlines files instead. Default: the method takes no references.
  virtual Status ResolveReferences(storage::Store* store, nlohmann::json* config) const {
    (void)store;
    (void)config;
    return Status::Ok();
  }
  // GET /api/v1/recordings/{id}/check (SPEC §10; server/recording_check.h): what Run with this
  // config would find before fitting, computed by the stages Run itself runs (so the numbers are
  // the job's by construction). Writes the method's part into *check (an object the caller made):
  //   "saturation": diagnostics.saturation as Run writes it (results/saturation.h),
  //   "statics": [{"start", "end", "samples", "up": [x, y, z]}] (the gravity direction read with
  //       the nominal units, body frame), "coverage": {"sufficient", "verdict", "missing_up",
  //       "min_eigenvalue"}, "threshold_choice", and "job_would_fail": the message Run would stop
  //       with at that stage (absent when it would go on);
  // keys a method does not compute are left out (the check then says so). `log` is the whole
  // inertial log in seconds (never the float form: PrepareParser is not applied); `config` has
  // been validated, `acceptance` and `time_unit` removed. kInvalidInput for a log Run would
  // refuse outright (its message); kStopped when ctx.stop asks. Default: adds nothing.
  virtual Status Check(const ArrayRecording& log, const nlohmann::json& config,
                       const RunContext& ctx, nlohmann::json* check) const {
    (void)log;
    (void)config;
    (void)ctx;
    (void)check;
    return Status::Ok();
  }
  // Called before the recording is fed to the collecting parser that Run will take it from
  // (server/config.h PrepareParser): a method may ask for a leaner collection, e.g.
  // RecordingParser::CollectArrayAsFloat. `config` may be invalid (Run reports that); Run must
  // also accept a parser that was not prepared.
  virtual void PrepareParser(const nlohmann::json& config, RecordingParser* parser) const {
    (void)config;
    (void)parser;
  }
  // The acceptance gate (SPEC §4 `verdict`): judges a result this method's Run wrote (with the
  // config it ran with, `acceptance` removed) against the limits in force (methods/acceptance.h),
  // calling verdict->Reject once per failed rule with words a line operator understands (what is
  // wrong and what to do). Never fails: what cannot be judged (an undefined uncertainty) is a
  // rejection. Deterministic.
  virtual void Judge(const nlohmann::json& result, const nlohmann::json& config,
                     const AcceptanceLimits& limits, Verdict* verdict) const = 0;
  // The limits its Judge reads, each with its meaning and built-in default (nullopt: no limit
  // unless set); keys several methods share come from methods/acceptance.h (limit_keys). A config's
  // `acceptance` object and the server-wide defaults (`serve --acceptance`) may set only these
  // keys: any other is refused naming it. The order is the one error messages list them in.
  // Never empty; the vector lives for the process.
  virtual const std::vector<AcceptanceKey>& AcceptanceKeys() const = 0;
  // The catalog entries (title, generic advice) of the failure reasons it defines itself beside its
  // numerics (core/<name>.h <name>_reason::); the generic ones (base/status.h) are the server's.
  // Every reason a method's Run can set has an entry here or there (scripts/check_structure.py).
  virtual std::vector<FailureReason> FailureReasons() const { return {}; }
  // The parameters that characterise a unit, compared across a product's fleet (server/fleet.h):
  // paths into the result's `parameters` (objects by key, named array entries by name, other
  // arrays by index), '*' matching one segment. Derived values (unit-vector components, products
  // of others) are left out: their fleet distribution is skewed and flags units falsely. Empty:
  // every number.
  virtual std::vector<std::string> FleetParameters() const { return {}; }
  // The formats its results export to besides JSON, in the order the pages offer them.
  virtual std::vector<ExportFormat> ExportFormats() const = 0;
  // Writes a result this method's Run wrote (as stored) in one of its ExportFormats().
  // kInvalidInput naming `format` for a format it does not have; kNotDeterminable when the result
  // lacks a value the format needs (an undefined figure is never written as 0); kInternal when
  // the result lacks its SPEC keys.
  virtual Status Export(const std::string& format, const nlohmann::json& result,
                        const ExportContext& context, std::string* out) const = 0;
  // `calibd simulate NAME`: one line for its --help ("" when the method has no simulation).
  virtual const char* simulate_summary() const { return ""; }
  // Adds the simulation's options (all but --out, which the CLI adds) to `command`, the
  // subcommand the CLI made with the method's name and simulate_summary(), and returns what
  // makes the files once the command line has been parsed (deterministic per seed). Called once
  // per process; the options it binds live as long as the returned function.
  virtual std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const {
    (void)command;
    return {};
  }
  // ---- Plan (SPEC §10, issue #27 item 1; methods/plan.h) ----
  // POST /api/v1/plan and `calibd plan`: what a calibration of a recording made with `protocol`
  // would report, computed with the method's own numerics at nominal values: {"uncertainty" (the
  // shape of the result's, null where undetermined), "undetermined": [{"parameters": [...],
  // "missing": [...]}] (empty when the protocol determines everything), "suggested":
  // {"design", "orientations", "uncertainty", "meets_limits", "unmet"}, "notes": [...]}.
  // `config` has been validated (ValidateConfig) with its references resolved; `limits` are the
  // ones in force for the config (the suggestion's target). kInvalidInput naming the field for
  // what the plan needs and the config lacks. Default: no plan for this method yet (400 naming
  // `method`).
  virtual Status Plan(const nlohmann::json& config, const PlanProtocol& protocol,
                      const AcceptanceLimits& limits, nlohmann::json* out) const {
    (void)config;
    (void)protocol;
    (void)limits;
    (void)out;
    return Status::InvalidInput(std::string("the plan is not available for method ") + name() +
                                " yet")
        .WithField("method");
  }
  // ---- end Plan ----
  // The job's peak memory per value of the recording (rows x columns), in bytes: the parser's
  // doubles (8) plus what the method's run holds at its peak, measured on large recordings
  // (bench/README.md, "Memory budget per job"). Used by the per-job budget (server/job_budget.h)
  // to refuse, before any work, a job that would not fit. `config` has been validated.
  virtual double PeakBytesPerValue(const nlohmann::json& config) const {
    (void)config;
    return 24;
  }
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_METHOD_H_
