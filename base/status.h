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
};

// Stable machine-readable name of a code ("invalid_input", ...), used in JSON errors.
const char* StatusCodeName(StatusCode code);

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
};

}  // namespace calibd

#endif  // CALIBD_BASE_STATUS_H_
