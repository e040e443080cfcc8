// Status: the outcome of an operation that can fail for a reason the caller must handle.
//
// Modelled on LevelDB's Status: cheap to return, `if (!s.ok()) return s;` to propagate.
// A failure carries a code (what kind of failure, which decides the exit code / HTTP status),
// a message in plain words, and optionally where in the input it happened (file, 1-based line
// and column, field name). Thread-compatible value type.
#ifndef CALIBD_BASE_STATUS_H_
#define CALIBD_BASE_STATUS_H_

#include <cstdint>
#include <cstring>
#include <string>
#include <utility>

namespace calibd {

enum class StatusCode {
  kOk = 0,
  kInvalidInput,      // malformed or invalid input (CLI exit 2, HTTP 400)
  kNotDeterminable,   // valid input that cannot determine the parameters (exit 3, HTTP 422)
  kNotFound,          // HTTP 404
  kConflict,          // illegal state transition, e.g. completing a job one does not lease
  kUnsupportedMedia,  // HTTP 415
  kTooLarge,          // HTTP 413
  kBusy,              // transient: database locked past the busy timeout (retryable)
  kIoError,           // transient or environmental: disk full, I/O error, read-only file
  kCorruption,        // the database file is damaged
  kInternal,          // a bug: never the user's fault
  kStopped,           // a computation stopped before it ended: cancelled, deadline, shutdown
};

// Stable machine-readable name of a code ("invalid_input", ...), used in JSON errors.
const char* StatusCodeName(StatusCode code);

// Why a calibration failed, finer than the StatusCode: what in the data (or the set-up) made it
// fail, so that advice can be looked up by it. A reason is its stable snake_case code, stored with
// a failed job and answered in GET /api/v1/jobs/{id} "error.reason" (README "Failure reasons").
// An open set: base/ defines the reasons any method or the server may meet (below); a method
// defines its own beside its numerics (core/<name>.h, e.g. core::kNoRankGap) and lists their
// catalog entries (title, advice) in its Method::FailureReasons() (methods/method.h). The catalog
// (server/failure_reasons.h) holds both; scripts/check_structure.py checks that every reason
// defined in product code has an entry. A failing method sets it with Status::WithReason at the
// site that decides; kUnspecified when the site has none (the server then derives one from the
// StatusCode). Compared by code. Trivially copyable value type.
class Reason {
 public:
  constexpr Reason() = default;  // kUnspecified
  // `code`: a string literal (static storage), snake_case, unique across calibd.
  explicit constexpr Reason(const char* code) : code_(code) {}
  // "" for kUnspecified.
  constexpr const char* code() const { return code_; }
  friend bool operator==(Reason a, Reason b) { return std::strcmp(a.code_, b.code_) == 0; }
  friend bool operator!=(Reason a, Reason b) { return !(a == b); }

  static const Reason kUnspecified;
  // The input as given cannot be used.
  static const Reason kInvalidConfig;        // a config key or option is wrong
  static const Reason kInvalidRecording;     // the recording parses but holds values that cannot be
                                             // used (NaN, ...)
  static const Reason kRecordingUnreadable;  // the recording does not parse (not a SPEC §2 layout)
  static const Reason kOverMemoryBudget;     // the job would exceed the server's memory budget
  static const Reason kProblemTooLarge;      // the problem exceeds the method's own size limits
  static const Reason kImplausibleTimeUnit;  // the time column's period is implausible in seconds
  // The data cannot determine the parameters (kNotDeterminable).
  static const Reason kNotDeterminable;  // generic: a kNotDeterminable failure without a finer one
  static const Reason kNoSignal;         // all readings equal or zero
  static const Reason kTooFewPositions;  // fewer static positions than the unknowns need
  static const Reason kPoorOrientationCoverage;  // orientations too few directions / on a plane,
                                                 // cone or quadric
  static const Reason kNotAnEllipsoid;  // the readings lie on no ellipsoid (biases, field changed)
  static const Reason kFieldDisturbed;  // the field changed during the log (iron, motors)
  static const Reason kTooFewStatics;   // too few static intervals found in a log
  static const Reason kUnknownNoise;    // noise levels zero / unknown (noise-free readings)
  static const Reason kSingularInformation;  // the Fisher information is singular
  static const Reason kImplausibleEstimate;  // an estimate far from the nominal (wrong unit?)
  static const Reason kIllConditioned;       // computed values not finite in double precision
  static const Reason kLogTooShort;          // fewer samples than the method needs
  static const Reason kNumericalFailure;     // the solver found no finite step
  // The job was stopped before it ended (core/stop_token.h); never retried automatically.
  static const Reason kDeadline;   // its time limit (--job-seconds, config job_seconds) ran out
  static const Reason kCancelled;  // POST /jobs/{id}/cancel
  // The server's side.
  static const Reason kLeaseExpired;    // the job ran out of attempts: its worker's lease lapsed
  static const Reason kStorageError;    // busy database or I/O error past the retries
  static const Reason kDiskFull;        // the disk (or quota) holding the database is full
  static const Reason kStorageDamaged;  // stored bytes are damaged (SHA-256 mismatch, bad page)
  static const Reason kInternal;        // a bug: never the user's fault

 private:
  const char* code_ = "";
};

inline constexpr Reason Reason::kUnspecified{};
inline constexpr Reason Reason::kInvalidConfig{"invalid_config"};
inline constexpr Reason Reason::kInvalidRecording{"invalid_recording"};
inline constexpr Reason Reason::kRecordingUnreadable{"recording_unreadable"};
inline constexpr Reason Reason::kOverMemoryBudget{"over_memory_budget"};
inline constexpr Reason Reason::kProblemTooLarge{"problem_too_large"};
inline constexpr Reason Reason::kImplausibleTimeUnit{"implausible_time_unit"};
inline constexpr Reason Reason::kNotDeterminable{"not_determinable"};
inline constexpr Reason Reason::kNoSignal{"no_signal"};
inline constexpr Reason Reason::kTooFewPositions{"too_few_positions"};
inline constexpr Reason Reason::kPoorOrientationCoverage{"poor_orientation_coverage"};
inline constexpr Reason Reason::kNotAnEllipsoid{"not_an_ellipsoid"};
inline constexpr Reason Reason::kFieldDisturbed{"field_disturbed"};
inline constexpr Reason Reason::kTooFewStatics{"too_few_statics"};
inline constexpr Reason Reason::kUnknownNoise{"unknown_noise"};
inline constexpr Reason Reason::kSingularInformation{"singular_information"};
inline constexpr Reason Reason::kImplausibleEstimate{"implausible_estimate"};
inline constexpr Reason Reason::kIllConditioned{"ill_conditioned"};
inline constexpr Reason Reason::kLogTooShort{"log_too_short"};
inline constexpr Reason Reason::kNumericalFailure{"numerical_failure"};
inline constexpr Reason Reason::kDeadline{"deadline"};
inline constexpr Reason Reason::kCancelled{"cancelled"};
inline constexpr Reason Reason::kLeaseExpired{"lease_expired"};
inline constexpr Reason Reason::kStorageError{"storage_error"};
inline constexpr Reason Reason::kDiskFull{"disk_full"};
inline constexpr Reason Reason::kStorageDamaged{"storage_damaged"};
inline constexpr Reason Reason::kInternal{"internal"};

class Status {
 public:
  Status() = default;  // OK
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }
  static Status InvalidInput(std::string msg) {
    return {StatusCode::kInvalidInput, std::move(msg)};
  }
  static Status NotDeterminable(std::string msg) {
    return {StatusCode::kNotDeterminable, std::move(msg)};
  }
  // A failure of a calibration with its reason (see Reason).
  static Status InvalidInput(Reason reason, std::string msg) {
    return InvalidInput(std::move(msg)).WithReason(reason);
  }
  static Status NotDeterminable(Reason reason, std::string msg) {
    return NotDeterminable(std::move(msg)).WithReason(reason);
  }
  static Status NotFound(std::string msg) { return {StatusCode::kNotFound, std::move(msg)}; }
  static Status Conflict(std::string msg) { return {StatusCode::kConflict, std::move(msg)}; }
  static Status Busy(std::string msg) { return {StatusCode::kBusy, std::move(msg)}; }
  static Status IoError(std::string msg) { return {StatusCode::kIoError, std::move(msg)}; }
  static Status Corruption(std::string msg) { return {StatusCode::kCorruption, std::move(msg)}; }
  static Status Internal(std::string msg) { return {StatusCode::kInternal, std::move(msg)}; }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }

  // Where in the input the failure is; 0 / empty when it does not apply.
  const std::string& file() const { return file_; }
  int64_t line() const { return line_; }
  int64_t column() const { return column_; }
  const std::string& field() const { return field_; }

  Status& WithFile(std::string file) {
    file_ = std::move(file);
    return *this;
  }
  Status& WithLocation(int64_t line, int64_t column) {
    line_ = line;
    column_ = column;
    return *this;
  }
  Status& WithField(std::string field) {
    field_ = std::move(field);
    return *this;
  }
  // Why, for a failure of a calibration (see Reason); kUnspecified unless set.
  Reason reason() const { return reason_; }
  Status& WithReason(Reason reason) {
    reason_ = reason;
    return *this;
  }

  // "file:line:column: message" (the parts that are known), for a terminal.
  std::string ToString() const;

  // True for failures worth retrying later (busy database, I/O error).
  bool IsTransient() const { return code_ == StatusCode::kBusy || code_ == StatusCode::kIoError; }

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
  std::string file_;
  int64_t line_ = 0;
  int64_t column_ = 0;
  std::string field_;
  Reason reason_ = Reason::kUnspecified;
};

}  // namespace calibd

#endif  // CALIBD_BASE_STATUS_H_
