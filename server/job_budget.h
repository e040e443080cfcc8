// The memory budget per job (issue #10): a job whose recording would need more memory than the
// budget is refused before any work, at enqueue time (upload with a method, POST /jobs: 422 with
// the reason) and again by the worker that claims it (a job queued under a larger budget fails
// with the same reason instead of taking the process down).
//
// The estimate is the method's peak bytes per value (Method::PeakBytesPerValue, measured) times
// rows x columns of the recording, plus a fixed allowance: an upper bound for the methods'
// linear memory. What grows faster than the recording (pca's information matrix in the number of
// sensors) has its own budget inside the method (core::PcaOptions::max_memory_bytes).
#ifndef CALIBD_SERVER_JOB_BUDGET_H_
#define CALIBD_SERVER_JOB_BUDGET_H_

#include <cstdint>
#include <nlohmann/json.hpp>

#include "base/status.h"
#include "methods/method.h"

namespace calibd::server {

// What the budget needs to know of a recording (from the upload's parser summary or the stored
// recording's row).
struct RecordingShape {
  int64_t rows = 0;     // data rows
  int64_t columns = 0;  // header fields
};

// Bytes a job of `method` with `config` needs at its peak on a recording of `shape`.
int64_t EstimateJobBytes(const Method& method, const RecordingShape& shape,
                         const nlohmann::json& config);

// OK when the estimate fits `budget_bytes` (<= 0: no budget). Otherwise kNotDeterminable (HTTP
// 422, CLI exit 3) with field "job_memory", naming the estimate, the budget, the recording's
// size and what to do (split the log, or raise --job-memory-bytes).
Status CheckJobBudget(const Method& method, const RecordingShape& shape,
                      const nlohmann::json& config, int64_t budget_bytes);

// The default budget for `workers` concurrent jobs: half the machine's physical memory shared
// among the workers, at least 256 MiB and at most 8 GiB each.
int64_t DefaultJobMemoryBytes(int workers);

// The time limit per job (`serve --job-seconds`) when none is given, proportional to the memory
// budget (a job's input, and so its work, is bounded by the budget): kJobSecondsPerMiB seconds
// per MiB of `job_memory_bytes`, at least kMinJobSeconds. A config's `job_seconds` may only
// lower it.
inline constexpr double kJobSecondsPerMiB = 0.5;
inline constexpr int64_t kMinJobSeconds = 60;
int64_t DefaultJobSeconds(int64_t job_memory_bytes);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_JOB_BUDGET_H_
