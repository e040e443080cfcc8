#include "core/block_lm.h"

#include <atomic>
#include <cstdio>
#include <thread>

namespace calibd::core {

void RunTasksOnThreads(int threads, int64_t tasks, const std::function<void(int64_t)>& run) {
  if (threads <= 0) threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const int workers = static_cast<int>(std::min<int64_t>(threads, tasks));
  if (workers <= 1) {
    for (int64_t c = 0; c < tasks; ++c) run(c);
    return;
  }
  std::atomic<int64_t> next{0};
  auto work = [&]() {
    for (;;) {
      const int64_t c = next.fetch_add(1);
      if (c >= tasks) return;
      run(c);
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (int i = 1; i < workers; ++i) pool.emplace_back(work);
  work();
  for (auto& t : pool) t.join();
}

bool BlockLmOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (!(cost_tolerance >= 0 && cost_tolerance < 1))
    return fail("cost_tolerance must be >= 0 and < 1");
  if (!(step_tolerance >= 0 && step_tolerance < 1))
    return fail("step_tolerance must be >= 0 and < 1");
  if (!(gradient_tolerance >= 0 && gradient_tolerance < 1))
    return fail("gradient_tolerance must be >= 0 and < 1");
  if (!(min_damping > 0 && min_damping <= initial_damping && initial_damping <= max_damping &&
        std::isfinite(max_damping)))
    return fail("damping must satisfy 0 < min_damping <= initial_damping <= max_damping < inf");
  if (!(damping_decrease > 1) || !(damping_increase > 1) || !std::isfinite(damping_decrease) ||
      !std::isfinite(damping_increase))
    return fail("damping_decrease and damping_increase must be finite and > 1");
  if (chunk < 1) return fail("chunk must be >= 1");
  if (threads < 0) return fail("threads must be >= 0 (0: hardware concurrency)");
  return true;
}

const char* BlockLmTerminationName(BlockLmTermination t) {
  switch (t) {
    case BlockLmTermination::kNotRun:
      return "not_run";
    case BlockLmTermination::kCostTolerance:
      return "cost_tolerance";
    case BlockLmTermination::kStepTolerance:
      return "step_tolerance";
    case BlockLmTermination::kGradientTolerance:
      return "gradient_tolerance";
    case BlockLmTermination::kNoProgress:
      return "no_progress";
    case BlockLmTermination::kMaxIterations:
      return "max_iterations";
    case BlockLmTermination::kUserStopped:
      return "user_stopped";
    case BlockLmTermination::kNumericalFailure:
      return "numerical_failure";
  }
  return "unknown";
}

bool BlockLmSummary::converged() const {
  return termination == BlockLmTermination::kCostTolerance ||
         termination == BlockLmTermination::kStepTolerance ||
         termination == BlockLmTermination::kGradientTolerance ||
         termination == BlockLmTermination::kNoProgress;
}

bool BlockLmSummary::usable() const {
  return converged() || termination == BlockLmTermination::kMaxIterations ||
         termination == BlockLmTermination::kUserStopped;
}

std::string BlockLmSummary::BriefReport() const {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "block LM: termination %s, %d iterations (%d accepted), cost %.6g -> %.6g",
                BlockLmTerminationName(termination), iterations, accepted_iterations,
                initial_cost(), final_cost());
  return buf;
}

bool InvertInformation(const Eigen::MatrixXd& information, Eigen::MatrixXd* covariance) {
  covariance->resize(0, 0);
  const Eigen::LLT<Eigen::MatrixXd> llt(information);
  if (llt.info() != Eigen::Success) return false;
  Eigen::MatrixXd inverse =
      llt.solve(Eigen::MatrixXd::Identity(information.rows(), information.cols()));
  if (!inverse.allFinite()) return false;
  *covariance = std::move(inverse);
  return true;
}

}  // namespace calibd::core
