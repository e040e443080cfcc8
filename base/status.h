// Status: the outcome of an operation that can fail for a reason the caller must handle.
//
// Modelled on LevelDB's Status: cheap to return, `if (!s.ok()) return s;` to propagate.
// A failure carries a code (what kind of failure, which decides the exit code / HTTP status),
// a message in plain words, and optionally where in the input it happened (file, 1-based line
// and column, field name). Thread-compatible value type.
#ifndef CALIBD_BASE_STATUS_H_
#define CALIBD_BASE_STATUS_H_

#include <cstdint>
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
// fail, so that advice can be looked up by it (server/failure_reasons.h holds the catalog: its
// stable snake_case code, a title and the generic advice). A failing method sets it with
// Status::WithReason at the site that decides; kUnspecified when the site has none (the server
// then derives one from the StatusCode). Adding one: a value here and an entry in the catalog
// (a unit test checks that every value has one).
enum class Reason {
  kUnspecified = 0,
  // The input as given cannot be used.
  kInvalidConfig,        // a config key or option is wrong
  kInvalidRecording,     // the recording parses but holds values that cannot be used (NaN, ...)
  kRecordingUnreadable,  // the recording does not parse (stored bytes not in a SPEC §2 layout)
  kOverMemoryBudget,     // the job would exceed the server's memory budget per job
  kProblemTooLarge,      // the problem exceeds the method's own size limits (pca max_flops)
  // The data cannot determine the parameters (kNotDeterminable).
  kNotDeterminable,          // generic: a kNotDeterminable failure without a finer reason
  kNoSignal,                 // all readings equal or zero
  kTooFewSensors,            // fewer sensors than the dimension
  kTooFewPositions,          // fewer static positions than the unknowns need
  kPoorOrientationCoverage,  // orientations too few directions / on a plane, cone or quadric
  kNoRankGap,                // no clear gap between the singular values d and d+1 (pca)
  kNotAnEllipsoid,           // the readings lie on no ellipsoid (biases, field changed, noise)
  kDeadSensor,               // a sensor whose readings do not change with the orientation
  kIllConditioned,           // computed values not finite in double precision
  kTooFewStatics,            // too few static intervals found in a log
  kTooFewRotations,          // too few rotations between statics for the gyroscope
  kNoDynamicPhase,           // no motion after the statics (array full model)
  kUnknownNoise,             // noise levels zero / unknown (noise-free readings)
  kSingularInformation,      // the Fisher information is singular: some parameter undetermined
  kImplausibleEstimate,      // an estimate far from the nominal (wrong unit?)
  kLogTooShort,              // fewer samples than the method needs
  kIrregularSampling,        // sample times jitter too much for the Allan deviation
  kNotStationary,            // a noise log that moves
  kNoGyroscope,              // array: no gyroscope triad
  kTooFewTriads,             // array: fewer than 3 accelerometer triads
  kTriadsCollinear,          // array: the triads lie on one line
  kTooFewSamples,            // array: fewer usable samples than needed
  kWeakExcitation,           // array: the motion does not excite every direction
  kNumericalFailure,         // the solver found no finite step
  kImplausibleTimeUnit,      // the time column's sample period is implausible in seconds
  // The job was stopped before it ended (core/stop_token.h); never retried automatically.
  kDeadline,   // its time limit (--job-seconds, config job_seconds) ran out
  kCancelled,  // POST /jobs/{id}/cancel
  // The server's side.
  kLeaseExpired,    // the job ran out of attempts because its worker's lease lapsed
  kStorageError,    // busy database or I/O error past the retries
  kDiskFull,        // the disk (or quota) holding the database or the staging folder is full
  kStorageDamaged,  // stored bytes are damaged (SHA-256 mismatch, a corrupt database page)
  kInternal,        // a bug: never the user's fault
  kCount,           // sentinel: the number of values
};

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
