// TaskPool: a fixed set of threads that every job of a process shares for its parallel numerics,
// so W concurrent jobs use about W + threads cores' worth of threads instead of W × cores (each
// job starting its own threads per solver iteration).
//
// Executor() returns a core::TaskExecutor (block_lm.h) for the solvers' options: Run(tasks, fn)
// runs fn(0) ... fn(tasks - 1), each exactly once, on the pool's threads and on the calling
// thread, and returns when all have finished. Several callers may run at once: their batches are
// served in arrival order, and each caller also works on its own batch, so a caller always makes
// progress even when every pool thread is busy with others' batches (no deadlock, also with
// threads = 0). Results do not depend on which thread ran a task (the solvers reduce in order).
//
// Thread-safety: all members are thread-safe. The destructor waits for the threads; no Run may
// be in progress then. fn must not throw (a throwing task terminates the process).
#ifndef CALIBD_CORE_TASK_POOL_H_
#define CALIBD_CORE_TASK_POOL_H_

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "core/block_lm.h"

namespace calibd::core {

class TaskPool {
 public:
  // threads >= 0 helper threads (0: every task runs on its caller's thread).
  explicit TaskPool(int threads);
  ~TaskPool();
  TaskPool(const TaskPool&) = delete;
  TaskPool& operator=(const TaskPool&) = delete;

  int threads() const { return static_cast<int>(threads_.size()); }
  void Run(int64_t tasks, const std::function<void(int64_t)>& run);
  // A TaskExecutor that calls Run on this pool; valid while the pool lives.
  TaskExecutor Executor();

 private:
  struct Batch;
  void ThreadLoop();
  // Claims and runs tasks of `batch` until none is left unclaimed.
  static void Work(Batch* batch);

  std::mutex mu_;
  std::condition_variable wake_;
  std::deque<std::shared_ptr<Batch>> pending_;  // batches with unclaimed tasks; guarded by mu_
  bool stopping_ = false;                       // guarded by mu_
  std::vector<std::thread> threads_;
};

}  // namespace calibd::core

#endif  // CALIBD_CORE_TASK_POOL_H_
