// GET /api/v1/recordings/{id}/check?method=M&<config keys> (SPEC §10, issue #27 item 2): what a
// job of method M with that config would find in a stored inertial log before fitting, in well
// under a second for an hour of 400 Hz (bench/README.md, "Recording check").
//
// The config: the query's keys (as an upload's, SPEC §3), or `job=ID` for the config a stored
// job ran with (then no other key); the method's defaults otherwise. Not the recording's
// upload config: a recording may have been run with several. It is validated as a job's
// (ValidateConfig, errors naming the key). The recording is read as a job with that config reads
// it (PrepareParser, the upload's CSV dialect unless the config gives one), in doubles, from the
// parsed-columns cache (server/column_cache.h) when CheckRequest::cache holds it.
//
// What is computed where: the recording's own figures here (timing, units that look wrong,
// temperature range); the method's part (saturation, statics, coverage, what the job would fail
// with) by Method::Check, from the stages the method's Run runs, so those numbers are the
// job's. A method without a Check gives the recording's figures only, and the answer says so in
// `notes`. Methods that need t to increase refuse a log whose t does not, as their jobs do; the
// others (array) are checked as they read the log (`timing` null without a t). `predicted` (the σ
// the job would report, computed as the plan of issue #27 item 1 computes it, for the statics
// found) comes from Method::Check too: null where the method does not predict (a note says so) or
// the job would fail.
#ifndef CALIBD_SERVER_RECORDING_CHECK_H_
#define CALIBD_SERVER_RECORDING_CHECK_H_

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "base/status.h"
#include "core/stop_token.h"
#include "storage/store.h"

namespace calibd::server {

class ColumnCache;  // server/column_cache.h

// The request: recording, method and config (validated by ComputeCheck).
struct CheckRequest {
  int64_t recording_id = 0;
  nlohmann::json config;         // with "method"; acceptance and time_unit allowed as in a job
  int64_t job_memory_bytes = 0;  // the per-job budget (server/job_budget.h); <= 0: none
  const core::StopToken* stop = nullptr;  // may be null; polled by the method's stages
  ColumnCache* cache = nullptr;           // may be null: the stored bytes are parsed
};

// Reads the query of the check route into *request (config and recording id not touched
// otherwise): `method` and config keys, or `job` alone (its stored config). kInvalidInput naming
// the key; kNotFound for a job that does not exist.
Status ParseCheckQuery(const std::multimap<std::string, std::string>& params, storage::Store* store,
                       CheckRequest* request);

// The check's JSON:
//   {"recording_id", "method", "config", "samples", "start", "end", "time_origin",
//    "timing": {"rate" (Hz, mean), "sample_period" (s, median step), "jitter_rms",
//               "jitter_max" (s, |step - median| over steps that are not gaps), "gap_factor",
//               "gaps": [{"index", "start", "end"}] (at most 20), "gap_count", "longest_gap"},
//    "units": [{"quantity": "time" | "accelerometer" | "gyroscope", "key", "likely",
//               "message"}]  (empty: the units look right),
//    "temperature": [{"name", "min", "max"}] (°C; empty when the log has none),
//    the method's part (Method::Check): "saturation", "statics", "coverage",
//    "threshold_choice", "job_would_fail", "warnings" (absent keys: see notes),
//    "predicted": null or the method's {"uncertainty" (the result's shape), "basis", "how",
//                  its inputs; or "uncertainty": null and "reason"}, "notes": [...]}
// Times in seconds after time_origin. kNotFound (no such recording), kInvalidInput (config,
// method, or a log the job would refuse, naming why), kNotDeterminable (not an inertial log;
// over the memory budget), kBusy/kIoError from storage, kStopped.
Status ComputeCheck(storage::Store* store, const CheckRequest& request, nlohmann::json* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_RECORDING_CHECK_H_
