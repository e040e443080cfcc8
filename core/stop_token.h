// StopToken: asks a long computation to stop early, and says why (SPEC §6: every job ends).
//
// Who stops a computation sets a reason once (the first reason wins) or gives it a deadline;
// the computation polls `stop_requested()` inside every loop whose body can take long, at least
// every 100 ms of work, and returns at once when it is true (a core solver with termination
// kUserStopped, a method with StopStatus()). A stopped computation's result is never used as a
// calibration.
//
// Polling is cheap (one relaxed atomic load, and one steady_clock read when a deadline is set:
// about 20 ns), so a loop may poll once per iteration of work worth a microsecond or more.
// Thread-safe: any thread may request a stop while others poll. The token must outlive every
// computation that polls it.
#ifndef CALIBD_CORE_STOP_TOKEN_H_
#define CALIBD_CORE_STOP_TOKEN_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>

#include "base/status.h"

namespace calibd::core {

// Why a computation was asked to stop.
enum class StopReason : int {
  kNone = 0,
  kCancelled,  // a person or a script asked for it (POST /jobs/{id}/cancel)
  kDeadline,   // the job's time limit (--job-seconds, config job_seconds) ran out
  kShutdown,   // the process is stopping (SIGTERM past the grace period)
  kLeaseLost,  // another process took the job back: whatever this run computes is refused
};

class StopToken {
 public:
  using Clock = std::chrono::steady_clock;

  StopToken() = default;
  StopToken(const StopToken&) = delete;
  StopToken& operator=(const StopToken&) = delete;

  // Asks for a stop with `reason` (not kNone). The first reason wins; later ones are ignored.
  void RequestStop(StopReason reason) {
    int expected = static_cast<int>(StopReason::kNone);
    reason_.compare_exchange_strong(expected, static_cast<int>(reason), std::memory_order_acq_rel);
  }

  // From `deadline` on, stop_requested() is true with reason kDeadline (unless another reason
  // came first). Set before the computation starts; a later call replaces the deadline.
  void SetDeadline(Clock::time_point deadline) {
    deadline_ns_.store(
        deadline.time_since_epoch().count() > 0
            ? std::chrono::duration_cast<std::chrono::nanoseconds>(deadline.time_since_epoch())
                  .count()
            : 1,
        std::memory_order_release);
  }

  // True once a stop was requested or the deadline has passed.
  bool stop_requested() const {
    if (reason_.load(std::memory_order_acquire) != static_cast<int>(StopReason::kNone)) {
      return true;
    }
    const int64_t deadline = deadline_ns_.load(std::memory_order_acquire);
    if (deadline == 0) return false;
    const int64_t now =
        std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count();
    if (now < deadline) return false;
    int expected = static_cast<int>(StopReason::kNone);
    reason_.compare_exchange_strong(expected, static_cast<int>(StopReason::kDeadline),
                                    std::memory_order_acq_rel);
    return true;
  }

  // Why the computation was stopped (kNone while it was not). Calls stop_requested() first, so a
  // deadline that has passed is reported even if nothing polled since.
  StopReason reason() const {
    stop_requested();
    return static_cast<StopReason>(reason_.load(std::memory_order_acquire));
  }

 private:
  mutable std::atomic<int> reason_{// a StopReason; set once
                                   static_cast<int>(StopReason::kNone)};
  std::atomic<int64_t> deadline_ns_{0};  // steady clock, ns since its epoch; 0: none
};

// True when `token` (may be null: never stops) asks to stop.
inline bool StopRequested(const StopToken* token) {
  return token != nullptr && token->stop_requested();
}

// The Status a computation returns when it stopped because `token` asked it to: kStopped with
// Reason::kCancelled or kDeadline (or no reason for a shutdown or a lost lease: the job is
// then given back to the queue, not failed). `what` says where it stopped ("imu: accelerometer
// fit"), so a partial result can say how far it got.
inline Status StoppedStatus(const StopToken& token, const std::string& what) {
  switch (token.reason()) {
    case StopReason::kCancelled:
      return Status(StatusCode::kStopped, what + ": cancelled").WithReason(Reason::kCancelled);
    case StopReason::kDeadline:
      return Status(StatusCode::kStopped, what + ": stopped at the job's time limit")
          .WithReason(Reason::kDeadline);
    case StopReason::kShutdown:
      return Status(StatusCode::kStopped, what + ": stopped, the server is shutting down");
    case StopReason::kLeaseLost:
      return Status(StatusCode::kStopped, what + ": stopped, another process took the job");
    case StopReason::kNone:
      break;
  }
  return Status(StatusCode::kStopped, what + ": stopped");
}

}  // namespace calibd::core

#endif  // CALIBD_CORE_STOP_TOKEN_H_
