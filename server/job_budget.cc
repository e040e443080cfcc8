#include "server/job_budget.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace calibd::server {
namespace {

// What every job holds whatever its size: the result JSON, the method's small matrices, the
// thread's stack and allocator slack.
constexpr double kFixedBytes = 16.0 * 1024 * 1024;

std::string MiB(double bytes) {
  return std::to_string(static_cast<int64_t>(std::ceil(bytes / (1024.0 * 1024.0)))) + " MiB";
}

}  // namespace

int64_t EstimateJobBytes(const Method& method, const RecordingShape& shape,
                         const nlohmann::json& config) {
  const double values =
      static_cast<double>(std::max<int64_t>(0, shape.rows)) * std::max<int64_t>(0, shape.columns);
  const double bytes = kFixedBytes + values * method.PeakBytesPerValue(config);
  return bytes >= 9.0e18 ? INT64_MAX : static_cast<int64_t>(bytes);
}

Status CheckJobBudget(const Method& method, const RecordingShape& shape,
                      const nlohmann::json& config, int64_t budget_bytes) {
  if (budget_bytes <= 0) return Status::Ok();
  const int64_t need = EstimateJobBytes(method, shape, config);
  if (need <= budget_bytes) return Status::Ok();
  return Status::NotDeterminable(
             Reason::kOverMemoryBudget,
             std::string("a ") + method.name() + " job on this recording (" +
                 std::to_string(shape.rows) + " rows x " + std::to_string(shape.columns) +
                 " columns) needs about " + MiB(static_cast<double>(need)) +
                 ", more than the per-job memory budget of " +
                 MiB(static_cast<double>(budget_bytes)) +
                 ": split the log into shorter recordings, or start the server with a larger "
                 "--job-memory-bytes")
      .WithField("job_memory");
}

int64_t DefaultJobMemoryBytes(int workers) {
  const long pages = ::sysconf(_SC_PHYS_PAGES);
  const long page_size = ::sysconf(_SC_PAGE_SIZE);
  const double physical =
      pages > 0 && page_size > 0 ? static_cast<double>(pages) * page_size : 4.0 * (1 << 30);
  const double share = physical / 2 / std::max(1, workers);
  return static_cast<int64_t>(std::clamp(share, 256.0 * (1 << 20), 8.0 * (1 << 30)));
}

int64_t DefaultJobSeconds(int64_t job_memory_bytes) {
  const double mib = static_cast<double>(std::max<int64_t>(job_memory_bytes, 0)) / (1 << 20);
  return std::max(kMinJobSeconds, static_cast<int64_t>(std::ceil(mib * kJobSecondsPerMiB)));
}

}  // namespace calibd::server
