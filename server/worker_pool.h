// WorkerPool: threads that claim calibration jobs from the store's queue, run them, and store the
// result or the reason for failure, renewing their leases while they compute.
//
// At least once, idempotent: a job whose lease lapses (process killed, machine hung) is taken
// back by the store and runs again; results are deterministic, so a second run stores the same
// result. Failures that are the input's fault (kInvalidInput, kNotDeterminable) fail the job at
// once; transient ones (kBusy, kIoError) go back to the queue with back-off (storage decides).
// A running job is cancelled (its computation stops at the next check, nothing is stored) when
// its lease is lost (taken back by another process) and on Stop after the grace period.
// Thread-safe; never blocks the caller of Notify().
#ifndef CALIBD_SERVER_WORKER_POOL_H_
#define CALIBD_SERVER_WORKER_POOL_H_

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "core/block_lm.h"
#include "core/stop_token.h"
#include "server/metrics.h"
#include "storage/store.h"

namespace calibd::server {

struct WorkerPoolOptions {
  int workers = 1;           // threads; >= 1
  int64_t lease_ms = 30000;  // lease length; renewed every lease_ms / 3 while a job runs
  int64_t poll_ms = 500;     // idle workers look for jobs at least this often (Notify wakes);
                             // 4x less often when the store notifies (PostgreSQL LISTEN)
  std::string id_prefix;     // worker ids are "<id_prefix>-<n>"; should be unique per process
  // Optional: run by the lease renewer thread every lease_ms / 3 (e.g. taking back the jobs of
  // dead processes). Must not block for long.
  std::function<void()> housekeeping;
  // Optional: runs the jobs' parallel numerics (RunContext::executor); the caller keeps what it
  // refers to alive until Stop has returned.
  core::TaskExecutor executor;
  // Server-wide acceptance limits per method (`serve --acceptance`; null: built-in defaults),
  // passed to Calibrate for every job's verdict.
  nlohmann::json acceptance;
  // Per-job memory budget (server/job_budget.h), checked before a claimed job reads its
  // recording; <= 0: none.
  int64_t job_memory_bytes = 0;
};

class WorkerPool {
 public:
  // `store` and `metrics` must outlive the pool.
  WorkerPool(storage::Store* store, Metrics* metrics, WorkerPoolOptions options);
  ~WorkerPool();  // Stop(0) if still running
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  void Start();
  // A job was enqueued: wake an idle worker.
  void Notify();
  // Stops claiming, waits up to `grace` for running jobs to finish, then releases the leases of
  // those still running (they run again on the next start), cancels them, and joins every
  // thread: when Stop returns, no thread of the pool touches the store. Returns true when every
  // job finished within the grace period, false when some were released.
  bool Stop(std::chrono::milliseconds grace);

  int running_jobs() const;

 private:
  void WorkerLoop(int index);
  void RenewLoop();
  void RunJob(const std::string& worker_id, const storage::JobInfo& job,
              core::StopToken& stop);

  struct Active {
    std::string worker_id;
    std::shared_ptr<core::StopToken> stop;  // asked on shutdown or when the lease is lost
  };

  storage::Store* store_;
  Metrics* metrics_;
  WorkerPoolOptions options_;

  mutable std::mutex mu_;
  std::condition_variable wake_;      // workers wait here for jobs
  std::condition_variable finished_;  // Stop waits here for running jobs
  bool stopping_ = false;
  // The renewer outlives the workers: leases are renewed through Stop's grace period too (a job
  // computing longer than a lease would otherwise be taken back by another process).
  bool renewer_stopping_ = false;
  bool started_ = false;
  uint64_t notifications_ = 0;
  std::atomic<bool> listening_{false};  // the store calls us when jobs arrive (SetJobListener)
  std::map<int64_t, Active> active_;    // job id -> its worker, guarded by mu_
  int busy_workers_ = 0;
  std::vector<std::thread> threads_;
  std::thread renewer_;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_WORKER_POOL_H_
