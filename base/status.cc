#include "base/status.h"

namespace calibd {

const char* StatusCodeName(StatusCode code) {
  switch (code) {
    case StatusCode::kOk:
      return "ok";
    case StatusCode::kInvalidInput:
      return "invalid_input";
    case StatusCode::kNotDeterminable:
      return "not_determinable";
    case StatusCode::kNotFound:
      return "not_found";
    case StatusCode::kConflict:
      return "conflict";
    case StatusCode::kUnsupportedMedia:
      return "unsupported_media_type";
    case StatusCode::kTooLarge:
      return "too_large";
    case StatusCode::kBusy:
      return "busy";
    case StatusCode::kIoError:
      return "io_error";
    case StatusCode::kCorruption:
      return "corruption";
    case StatusCode::kInternal:
      return "internal";
    case StatusCode::kStopped:
      return "stopped";
  }
  return "unknown";
}

std::string Status::ToString() const {
  if (ok()) return "OK";
  std::string out;
  if (!file_.empty()) out += file_ + ":";
  if (line_ > 0) out += std::to_string(line_) + ":";
  if (column_ > 0) out += std::to_string(column_) + ":";
  if (!out.empty()) out += " ";
  if (!field_.empty()) out += "field '" + field_ + "': ";
  out += message_;
  return out;
}

}  // namespace calibd
