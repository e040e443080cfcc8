#include "core/task_pool.h"

#include <atomic>

namespace calibd::core {

struct TaskPool::Batch {
  const std::function<void(int64_t)>* run = nullptr;
  int64_t tasks = 0;
  std::atomic<int64_t> next{0};  // the next unclaimed task
  std::mutex mu;
  std::condition_variable done_cv;
  int64_t done = 0;  // finished tasks; guarded by mu
};

TaskPool::TaskPool(int threads) {
  threads_.reserve(static_cast<size_t>(threads > 0 ? threads : 0));
  for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { ThreadLoop(); });
}

TaskPool::~TaskPool() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (auto& t : threads_) t.join();
}

void TaskPool::Work(Batch* batch) {
  int64_t finished = 0;
  for (;;) {
    const int64_t c = batch->next.fetch_add(1);
    if (c >= batch->tasks) break;
    (*batch->run)(c);
    ++finished;
  }
  if (finished == 0) return;
  std::lock_guard<std::mutex> lock(batch->mu);
  batch->done += finished;
  if (batch->done == batch->tasks) batch->done_cv.notify_all();
}

void TaskPool::ThreadLoop() {
  for (;;) {
    std::shared_ptr<Batch> batch;
    {
      std::unique_lock<std::mutex> lock(mu_);
      wake_.wait(lock, [this] { return stopping_ || !pending_.empty(); });
      if (pending_.empty()) return;  // stopping, nothing left
      batch = pending_.front();
      // Every task of the front batch claimed: it leaves the queue (its caller waits for it).
      if (batch->next.load() >= batch->tasks) {
        pending_.pop_front();
        continue;
      }
    }
    Work(batch.get());
  }
}

void TaskPool::Run(int64_t tasks, const std::function<void(int64_t)>& run) {
  if (tasks <= 0) return;
  if (threads_.empty() || tasks == 1) {
    for (int64_t c = 0; c < tasks; ++c) run(c);
    return;
  }
  auto batch = std::make_shared<Batch>();
  batch->run = &run;
  batch->tasks = tasks;
  {
    std::lock_guard<std::mutex> lock(mu_);
    pending_.push_back(batch);
  }
  wake_.notify_all();
  Work(batch.get());  // the caller works too, so its batch always makes progress
  std::unique_lock<std::mutex> lock(batch->mu);
  batch->done_cv.wait(lock, [&] { return batch->done == batch->tasks; });
  // `run` may be destroyed after this returns: no thread can still call it, since every task
  // was claimed and finished (a thread that later takes this batch from the queue claims none).
}

TaskExecutor TaskPool::Executor() {
  return [this](int64_t tasks, const std::function<void(int64_t)>& run) { Run(tasks, run); };
}

}  // namespace calibd::core
