#include "server/worker_pool.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "formats/recording.h"
#include "methods/method.h"
#include "methods/registry.h"
#include "server/column_cache.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "server/fleet.h"
#include "server/job_budget.h"

namespace calibd::server {

WorkerPool::WorkerPool(storage::Store* store, Metrics* metrics, WorkerPoolOptions options)
    : store_(store), metrics_(metrics), options_(std::move(options)) {
  if (options_.workers < 1) options_.workers = 1;
  if (options_.lease_ms < 300) options_.lease_ms = 300;
}

WorkerPool::~WorkerPool() {
  bool started;
  {
    std::lock_guard<std::mutex> lock(mu_);
    started = started_ && !stopping_;
  }
  if (started) Stop(std::chrono::milliseconds(0));
  // Threads of abandoned jobs (StopOutcome::kAbandoned): wait for their computations.
  for (size_t i = 0; i < threads_.size(); ++i) {
    if (!joined_[i] && threads_[i].joinable()) threads_[i].join();
  }
}

void WorkerPool::Start() {
  std::lock_guard<std::mutex> lock(mu_);
  if (started_) return;
  started_ = true;
  for (int i = 0; i < options_.workers; ++i) threads_.emplace_back([this, i] { WorkerLoop(i); });
  joined_.assign(threads_.size(), false);
  renewer_ = std::thread([this] { RenewLoop(); });
  cancel_watcher_ = std::thread([this] { CancelWatchLoop(); });
  // Jobs enqueued by other processes (PostgreSQL NOTIFY) wake every idle worker; the polling
  // stays as the fallback (back-off, lapsed leases, a listener reconnecting).
  listening_ = store_->SetJobListener([this] {
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++notifications_;
    }
    wake_.notify_all();
  });
}

void WorkerPool::Notify() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++notifications_;
  }
  wake_.notify_one();
}

int WorkerPool::running_jobs() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int>(active_.size());
}

bool WorkerPool::Cancel(int64_t job_id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = active_.find(job_id);
  if (it == active_.end()) return false;
  it->second.stop->RequestStop(core::StopReason::kCancelled);
  return true;
}

StopOutcome WorkerPool::Stop(std::chrono::milliseconds grace) {
  if (listening_.exchange(false)) store_->SetJobListener(nullptr);  // before mu_: it takes mu_
  std::unique_lock<std::mutex> lock(mu_);
  if (!started_ || stopping_) return StopOutcome::kFinished;
  stopping_ = true;
  wake_.notify_all();
  StopOutcome outcome = StopOutcome::kFinished;
  if (!finished_.wait_for(lock, grace, [this] { return busy_workers_ == 0; })) {
    // Past the grace period: stop the computations, and wait for them to return. Each worker
    // releases its job itself once its computation has returned (RunJob): the lease is never
    // given up while this process still computes the job.
    outcome = StopOutcome::kReleased;
    for (const auto& [job_id, active] : active_) {
      active.stop->RequestStop(core::StopReason::kShutdown);
    }
    if (!finished_.wait_for(lock, std::chrono::milliseconds(options_.stop_wait_ms),
                            [this] { return busy_workers_ == 0; })) {
      outcome = StopOutcome::kAbandoned;
      for (auto& [job_id, active] : active_) {
        active.abandoned = true;
        std::cerr << "calibd: shutdown: job " << job_id << " did not stop within "
                  << options_.stop_wait_ms
                  << " ms; it keeps its lease, which lapses (nobody computes it meanwhile)\n";
      }
    }
  }
  std::vector<int> stuck;
  for (const auto& [job_id, active] : active_) stuck.push_back(active.index);
  lock.unlock();
  for (size_t i = 0; i < threads_.size(); ++i) {
    if (std::find(stuck.begin(), stuck.end(), static_cast<int>(i)) != stuck.end()) continue;
    threads_[i].join();
    joined_[i] = true;
  }
  {
    std::lock_guard<std::mutex> stop_lock(mu_);
    renewer_stopping_ = true;
  }
  finished_.notify_all();  // wakes the renewer and the cancel watcher
  renewer_.join();
  cancel_watcher_.join();
  return outcome;
}

void WorkerPool::WorkerLoop(int index) {
  const std::string worker_id = options_.id_prefix + "-" + std::to_string(index);
  uint64_t seen_notifications = 0;
  while (true) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_) return;
      seen_notifications = notifications_;
    }
    storage::JobInfo job;
    bool claimed = false;
    Status s = store_->ClaimJob(worker_id, options_.lease_ms, &job, &claimed);
    if (!s.ok()) std::cerr << "calibd: " << worker_id << ": claim failed: " << s.ToString() << "\n";
    if (s.ok() && claimed) {
      auto stop = std::make_shared<core::StopToken>();
      {
        std::lock_guard<std::mutex> lock(mu_);
        if (stopping_) {
          store_->ReleaseJob(job.id, worker_id, storage::ReleaseKind::kShutdown);
          return;
        }
        active_[job.id] = Active{worker_id, index, stop, false};
        ++busy_workers_;
      }
      RunJob(worker_id, job, *stop);
      {
        std::lock_guard<std::mutex> lock(mu_);
        active_.erase(job.id);
        --busy_workers_;
      }
      finished_.notify_all();
      continue;  // look for the next job at once
    }
    std::unique_lock<std::mutex> lock(mu_);
    // With a listener, jobs from anywhere wake us: poll 4x less often.
    wake_.wait_for(lock, std::chrono::milliseconds(options_.poll_ms * (listening_ ? 4 : 1)),
                   [&] { return stopping_ || notifications_ != seen_notifications; });
  }
}

void WorkerPool::RenewLoop() {
  const auto period = std::chrono::milliseconds(options_.lease_ms / 3);
  std::unique_lock<std::mutex> lock(mu_);
  while (!renewer_stopping_) {
    finished_.wait_for(lock, period, [this] { return renewer_stopping_; });
    if (renewer_stopping_) break;
    const auto active = active_;
    lock.unlock();
    for (const auto& [job_id, job] : active) {
      // Lost already: said once, not again every renewal while the computation winds down.
      if (job.stop->reason() == core::StopReason::kLeaseLost) continue;
      Status s = store_->RenewLease(job_id, job.worker_id, options_.lease_ms);
      if (!s.ok()) {
        std::cerr << "calibd: " << job.worker_id << ": lease of job " << job_id
                  << " not renewed: " << s.ToString() << "\n";
      }
      if (s.code() == StatusCode::kConflict || s.code() == StatusCode::kNotFound) {
        // Taken back (the lease lapsed and another worker claimed it, or it was released):
        // whatever this run computes would be refused, so stop computing.
        job.stop->RequestStop(core::StopReason::kLeaseLost);
      }
    }
    if (options_.housekeeping) options_.housekeeping();
    lock.lock();
  }
}

void WorkerPool::CancelWatchLoop() {
  const auto period = std::chrono::milliseconds(std::max<int64_t>(options_.cancel_poll_ms, 10));
  std::unique_lock<std::mutex> lock(mu_);
  while (!renewer_stopping_) {
    finished_.wait_for(lock, period, [this] { return renewer_stopping_; });
    if (renewer_stopping_) break;
    std::vector<int64_t> ids;
    for (const auto& [job_id, active] : active_) {
      if (!active.stop->stop_requested()) ids.push_back(job_id);
    }
    if (ids.empty()) continue;
    lock.unlock();
    std::vector<int64_t> requested;
    Status s = store_->CancelRequests(ids, &requested);
    lock.lock();
    if (!s.ok()) {
      std::cerr << "calibd: reading the cancel requests of running jobs failed: " << s.ToString()
                << "\n";
      continue;
    }
    for (int64_t job_id : requested) {
      auto it = active_.find(job_id);
      if (it != active_.end()) it->second.stop->RequestStop(core::StopReason::kCancelled);
    }
  }
}

namespace {

// The job's time limit in ms: the server's `server_ms` (<= 0: none), or the config's
// job_seconds when lower (ValidateConfig refused a config asking more at upload; a job queued
// under a larger server limit gets this server's).
double JobLimitMs(const nlohmann::json& config, int64_t server_ms) {
  double limit = server_ms > 0 ? static_cast<double>(server_ms) : 0;
  if (config.is_object()) {
    auto it = config.find("job_seconds");
    if (it != config.end() && it->is_number() && it->get<double>() > 0) {
      const double own = it->get<double>() * 1e3;
      limit = limit > 0 ? std::min(limit, own) : own;
    }
  }
  return limit;
}

// The failure of a job stopped at its time limit: what the computation said when it stopped
// (where it was), the limit and what to do.
Status DeadlineStatus(const Status& run, double limit_ms, double seconds) {
  char text[160];
  std::snprintf(text, sizeof text,
                "the job reached its time limit of %g s (after %.1f s) and was stopped",
                limit_ms / 1e3, seconds);
  std::string message = text;
  if (run.code() == StatusCode::kStopped) message += " (" + run.message() + ")";
  message +=
      "; give it more time (config job_seconds, at most the server's --job-seconds) or calibrate "
      "a shorter recording";
  return Status(StatusCode::kStopped, message).WithReason(Reason::kDeadline);
}

}  // namespace

Status WorkerPool::CancelledStatus(int64_t job_id, const Status& run) {
  storage::JobInfo info;
  std::string who = "cancelled";
  if (store_->GetJob(job_id, &info).ok() && info.cancel_requested_at_ms != 0) {
    who = "cancelled by " + info.cancel_actor + ": " + info.cancel_reason;
  }
  if (run.code() == StatusCode::kStopped) who += " (" + run.message() + ")";
  return Status(StatusCode::kStopped, who).WithReason(Reason::kCancelled);
}

// Cuts `text` to at most `bytes` bytes on a character boundary (it is stored as UTF-8 text).
static void ShortenUtf8(std::string* text, size_t bytes) {
  if (text->size() <= bytes) return;
  while (bytes > 0 && (static_cast<unsigned char>((*text)[bytes]) & 0xC0) == 0x80) --bytes;
  text->resize(bytes);
}

// A run's failure as stored: its code, reason code and message, and the partial diagnostics the
// method left in `result` (capped: kMaxPartialDiagnosticsBytes).
static storage::JobFailure FailureOf(const Status& s, const nlohmann::json& result) {
  storage::JobFailure failure;
  failure.code = StatusCodeName(s.code());
  failure.reason = DescribeReason(ReasonOf(s)).code;
  failure.message = s.ToString();
  failure.detail_json = PartialDiagnosticsText(result, kMaxPartialDiagnosticsBytes);
  return failure;
}

bool WorkerPool::StoreFailure(const std::string& worker_id, const storage::JobInfo& job,
                              const storage::JobFailure& failure, bool transient) {
  Status f = store_->FailJob(job.id, worker_id, failure, transient);
  const bool not_mine = f.code() == StatusCode::kConflict || f.code() == StatusCode::kNotFound;
  if (options_.storage_outcome && !not_mine) {
    options_.storage_outcome(f, "job " + std::to_string(job.id), true);
  }
  if (f.ok()) return true;
  std::cerr << "calibd: " << worker_id << ": recording the failure of job " << job.id
            << " failed: " << f.ToString() << "\n";
  if (not_mine) return false;  // taken back or gone: its new holder decides
  // A full disk or quota: a failure without its diagnostics may still fit (it rewrites the row
  // in place); else give the job back, its attempt counted and backing off, so that it neither
  // stays running until its lease lapses nor is claimed again at once, forever.
  storage::JobFailure small = failure;
  small.detail_json.clear();
  ShortenUtf8(&small.message, 200);
  f = store_->FailJob(job.id, worker_id, small, transient);
  if (f.ok()) return true;
  const Status r = store_->ReleaseJob(job.id, worker_id, storage::ReleaseKind::kStoreFailed);
  std::cerr << "calibd: " << worker_id << ": job " << job.id
            << (r.ok() ? ": released to the queue instead (the attempt counts; it backs off)"
                       : ": cannot release it either (" + r.ToString() +
                             "): it runs again when its lease lapses")
            << "\n";
  return false;
}

Status WorkerPool::StoreResult(const std::string& worker_id, const storage::JobInfo& job,
                               const nlohmann::json& result) {
  Status s = store_->CompleteJob(
      job.id, worker_id, result.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  if (options_.storage_outcome && s.code() != StatusCode::kConflict &&
      s.code() != StatusCode::kNotFound) {
    options_.storage_outcome(s, "job " + std::to_string(job.id), true);
  }
  if (!s.ok()) {
    std::cerr << "calibd: " << worker_id << ": storing the result of job " << job.id
              << " failed: " << s.ToString() << "\n";
  }
  return s;
}

void WorkerPool::RunJob(const std::string& worker_id, const storage::JobInfo& job,
                        core::StopToken& stop) {
  const auto start = std::chrono::steady_clock::now();
  auto seconds = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  nlohmann::json config, result;
  // The failure with its reason code and, when the method got as far as its numerics, the
  // partial diagnostics it left in `result` (capped: kMaxPartialDiagnosticsBytes).
  auto fail = [&](const Status& s, bool transient) {
    const storage::JobFailure failure = FailureOf(s, result);
    if (!StoreFailure(worker_id, job, failure, transient)) {
      return metrics_->ObserveJob(job.method, "released", seconds());
    }
    // A transient failure on the last attempt fails the job for good (the store's rule).
    const bool final = !transient || job.attempts >= store_->options().max_attempts;
    metrics_->ObserveJob(job.method, final ? "failed" : "retried", seconds());
    if (final) metrics_->ObserveFailure(job.method, failure.reason);
  };

  Status s = ParseJsonText(job.config_json, "config of job " + std::to_string(job.id), &config);
  if (!s.ok()) s.WithReason(Reason::kInvalidConfig);
  // The job's time limit from its start: the server's, or the config's job_seconds when lower.
  const double limit_ms = JobLimitMs(config, options_.job_ms);
  if (limit_ms > 0) {
    stop.SetDeadline(start + std::chrono::microseconds(static_cast<int64_t>(limit_ms * 1e3)));
  }
  if (s.ok()) {
    try {
      // The stored bytes stream through the collecting parser in the store's 1 MiB pieces, so
      // a job holds the recording's numbers (8 bytes a value, 4 for a method that collects
      // floats), never its text as well. The read
      // keeps one snapshot of the recording for the whole parse.
      const std::string file_name = "recording " + std::to_string(job.recording_id);
      storage::RecordingInfo recording;
      s = store_->GetRecording(job.recording_id, &recording);
      if (!s.ok()) return fail(s, s.IsTransient());
      // The budget again: the job may have been queued by a server with a larger one.
      if (const Method* method = FindMethod(job.method);
          method != nullptr && options_.job_memory_bytes > 0) {
        const nlohmann::json columns =
            nlohmann::json::parse(recording.columns_json, nullptr, /*allow_exceptions=*/false);
        const RecordingShape shape{recording.rows,
                                   columns.is_array() ? static_cast<int64_t>(columns.size()) : 0};
        s = CheckJobBudget(*method, shape, WithoutAcceptance(config), options_.job_memory_bytes);
        if (!s.ok()) return fail(s, /*transient=*/false);
      }
      RecordingParser parser(file_name, /*collect=*/true);
      parser.ExpectRows(recording.rows);
      PrepareParser(config, &parser);  // e.g. noise: the samples as float
      // From the parsed-columns cache when it holds the recording under the job's rules.
      const ColumnCache::Outcome read = FillParser(options_.column_cache, store_, recording,
                                                   &parser, [&] { return !stop.stop_requested(); });
      s = read.read;
      Status parsed = read.parse;
      // Stopped mid-read: by the job's own stop (then already requested), or by the cache's
      // Stop at shutdown while the job waited for another's build (then released to the queue).
      if (s.code() == StatusCode::kStopped) {
        stop.RequestStop(core::StopReason::kShutdown);
        s = Status::Ok();
      }
      if (options_.storage_outcome) {
        options_.storage_outcome(s, "recording " + std::to_string(job.recording_id), false);
      }
      // Damaged stored bytes (their SHA-256 is not the stored one): never calibrated, and not
      // retried until a re-upload repairs them.
      if (!s.ok()) return fail(s, s.IsTransient() && s.code() != StatusCode::kCorruption);
      if (!parsed.ok() && parsed.reason() == Reason::kUnspecified) {
        parsed.WithReason(Reason::kRecordingUnreadable);
      }
      // Cancelled mid-read: the parser was never finished; nothing to calibrate (see below).
      if (stop.stop_requested()) {
        s = Status::Ok();
      } else {
        s = parsed.ok() ? CalibrateParsed(&parser, file_name, config, &result, &stop,
                                          options_.acceptance, options_.executor)
                        : parsed;
      }
    } catch (const std::bad_alloc&) {
      s = Status::IoError("out of memory while calibrating").WithReason(Reason::kOverMemoryBudget);
    } catch (const std::exception& e) {
      // Never leak exception text to clients: the job says only that it was our fault; the
      // operator's log has what was thrown, to find the bug.
      std::cerr << "calibd: " << worker_id << ": job " << job.id << " (" << job.method
                << "): exception while calibrating: " << e.what() << "\n";
      s = Status::Internal("internal error while calibrating; please report it");
    }
  }
  // Stopped (or past its time limit) while it ran: the reason decides what becomes of the job.
  const core::StopReason why = stop.reason();
  if ((why == core::StopReason::kDeadline || why == core::StopReason::kCancelled) && s.ok() &&
      result.is_object() && !result.empty()) {
    // A method that ended its stopped solver as if finished: what it computed is kept as the
    // partial diagnostics (never as parameters: a stopped computation is no calibration).
    result["usable"] = false;
    result.erase("parameters");
    result.erase("uncertainty");
    result.erase("verdict");
  }
  switch (why) {
    case core::StopReason::kNone:
      break;
    case core::StopReason::kDeadline:
      return fail(DeadlineStatus(s, limit_ms, seconds()), /*transient=*/false);
    case core::StopReason::kCancelled:
      return fail(CancelledStatus(job.id, s), /*transient=*/false);
    case core::StopReason::kShutdown: {
      // The computation has returned: only now may the job go back to the queue (unless Stop
      // gave up waiting for it: then its lease lapses).
      bool abandoned;
      {
        std::lock_guard<std::mutex> lock(mu_);
        auto it = active_.find(job.id);
        abandoned = it != active_.end() && it->second.abandoned;
      }
      if (!abandoned) {
        Status r = store_->ReleaseJob(job.id, worker_id, storage::ReleaseKind::kShutdown);
        std::cerr << "calibd: shutdown: released job " << job.id << " after its computation "
                  << "stopped (" << (r.ok() ? "it runs again after the restart" : r.ToString())
                  << ")\n";
      }
      metrics_->ObserveJob(job.method, "released", seconds());
      return;
    }
    case core::StopReason::kLeaseLost:
      // Taken back: the job runs again elsewhere; whatever this run computed is refused.
      metrics_->ObserveJob(job.method, "cancelled", seconds());
      return;
  }
  if (!s.ok()) return fail(s, s.IsTransient());
  // The gate's fleet rule needs the store (the product's other devices), so it is judged here.
  s = ApplyFleetGate(store_, job.method, job.device, config, options_.acceptance, FleetOptions{},
                     &result);
  if (!s.ok()) return fail(s, s.IsTransient());
  s = StoreResult(worker_id, job, result);
  // Taken back (the lease was lost) or gone: another worker owns the outcome. Anything else
  // (the result too large for the store, corruption) fails the job with its reason instead of
  // leaving it running until its lease lapses and it is recomputed.
  if (s.code() == StatusCode::kConflict || s.code() == StatusCode::kNotFound) {
    metrics_->ObserveJob(job.method, "released", seconds());
    return;
  }
  if (!s.ok()) return fail(s, s.IsTransient());
  metrics_->ObserveJob(job.method, "succeeded", seconds());
  if (result.contains("verdict") && result["verdict"].is_object()) {
    metrics_->ObserveVerdict(job.method, result["verdict"].value("status", std::string("?")));
  }
}

}  // namespace calibd::server
