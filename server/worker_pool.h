// WorkerPool: threads that claim calibration jobs from the store's queue, run them, and store the
// result or the reason for failure, renewing their leases while they compute.
//
// At least once, idempotent: a job whose lease lapses (process killed, machine hung) is taken
// back by the store and runs again; results are deterministic, so a second run stores the same
// result. Failures that are the input's fault (kInvalidInput, kNotDeterminable) fail the job at
// once; transient ones (kBusy, kIoError) go back to the queue with back-off (storage decides).
// Every job runs under a core::StopToken, which its computation polls (at least every 100 ms):
//  - its time limit (options.job_ms, lowered by the config's `job_seconds`) ends it as failed,
//    reason `deadline`, with its partial diagnostics; never retried;
//  - a cancel (Cancel() in this process, or Store::CancelJob from any process on the database,
//    seen within cancel_poll_ms) ends it as failed, reason `cancelled`, with its partial
//    diagnostics and who cancelled it and why;
//  - a lost lease (taken back by another process) stops it and stores nothing;
//  - Stop past its grace period stops it (kShutdown), and only once its computation has returned
//    is its lease released (queued again, not counted as an attempt): a restarted server never
//    computes a job this process still computes. A computation that does not stop within
//    stop_wait_ms keeps its lease, which lapses (nobody computes the job meanwhile).
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

class ColumnCache;  // server/column_cache.h

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
  // The time limit of every job, from its claim (reading the recording included); <= 0: none.
  // A config's `job_seconds` may only lower it.
  int64_t job_ms = 0;
  // How often the running jobs' cancel requests are read from the store (one query for all).
  int64_t cancel_poll_ms = 250;
  // Stop: how long, past the grace period, stopped computations get to return (they poll every
  // 100 ms at most) before their jobs are abandoned with their leases.
  int64_t stop_wait_ms = 1000;
  // Optional: told the outcome of the jobs' storage calls (StorageHealth::Note): reading the
  // recording `what` = "recording N" (write false), storing the result or failure `what` =
  // "job N" (write true). Must be thread-safe and quick.
  std::function<void(const Status& s, const std::string& what, bool write)> storage_outcome;
  // Optional: the parsed-columns cache a job's recording is read from when it holds it under
  // the job's reading rules (and written to otherwise); must outlive the pool.
  ColumnCache* column_cache = nullptr;
};

// What Stop did with the jobs still running.
enum class StopOutcome {
  kFinished,   // every job finished within the grace period
  kReleased,   // some were stopped; all their computations returned and their leases released
  kAbandoned,  // some computation did not return within stop_wait_ms: its job keeps its lease
               // (it lapses) and its thread still runs; the pool's destructor waits for it, so
               // a process that must exit now exits without destroying the pool (or the store)
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
  // Asks the job's computation to stop now with reason kCancelled if it runs in this pool (the
  // cancel request itself is in the store already: Store::CancelJob). False when it does not.
  bool Cancel(int64_t job_id);
  // Stops claiming, waits up to `grace` for running jobs to finish, then asks the rest to stop
  // (kShutdown) and waits up to stop_wait_ms for their computations to return; those that did
  // have their leases released (they run again on the next start). Unless kAbandoned, every
  // thread is joined: no thread of the pool touches the store once Stop returns. With
  // kAbandoned, the abandoned jobs' threads still run (see StopOutcome).
  StopOutcome Stop(std::chrono::milliseconds grace);

  int running_jobs() const;

 private:
  void WorkerLoop(int index);
  void RenewLoop();
  void CancelWatchLoop();
  // The failure of a cancelled job: who cancelled it and why (from the store), and where its
  // computation stopped (`run`, when kStopped).
  Status CancelledStatus(int64_t job_id, const Status& run);
  void RunJob(const std::string& worker_id, const storage::JobInfo& job, core::StopToken& stop);
  // Stores a finished job's result (Store::CompleteJob), telling options_.storage_outcome and
  // logging a failure; kConflict / kNotFound when the job is no longer this worker's.
  Status StoreResult(const std::string& worker_id, const storage::JobInfo& job,
                     const nlohmann::json& result);
  // Stores the failure of the holder's run. When that fails (other than "not yours": kConflict,
  // kNotFound), e.g. on a full disk: the failure without its diagnostics and with a shortened
  // message, else the job is released as kStoreFailed (its attempt counts, it backs off); only
  // when the store takes none of these does the lease decide. Whether a failure was stored.
  bool StoreFailure(const std::string& worker_id, const storage::JobInfo& job,
                    const storage::JobFailure& failure, bool transient);

  struct Active {
    std::string worker_id;
    int index = 0;                          // its worker thread
    std::shared_ptr<core::StopToken> stop;  // cancel, deadline, shutdown, lost lease
    bool abandoned = false;                 // Stop gave up waiting: never release its lease
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
  std::vector<bool> joined_;  // per worker thread: joined by Stop
  std::thread renewer_;
  std::thread cancel_watcher_;  // reads cancel requests of running jobs (cancel_poll_ms)
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_WORKER_POOL_H_
