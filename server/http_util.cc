#include "server/http_util.h"

#include <unistd.h>

#include <exception>
#include <regex>
#include <vector>

#include "server/failure_reasons.h"

namespace calibd::server {

using nlohmann::json;

bool SplitHostPort(const std::string& listen, std::string* host, int* port) {
  std::string h, p;
  if (!listen.empty() && listen[0] == '[') {
    const size_t close = listen.find(']');
    if (close == std::string::npos || close + 1 >= listen.size() || listen[close + 1] != ':') {
      return false;
    }
    h = listen.substr(1, close - 1);
    p = listen.substr(close + 2);
  } else {
    const size_t colon = listen.rfind(':');
    if (colon == std::string::npos || colon == 0) return false;
    h = listen.substr(0, colon);
    p = listen.substr(colon + 1);
    if (h.find(':') != std::string::npos) return false;
  }
  if (p.empty() || p.size() > 5 || p.find_first_not_of("0123456789") != std::string::npos) {
    return false;
  }
  const int v = std::stoi(p);
  if (v > 65535) return false;
  *host = h;
  *port = v;
  return true;
}

std::string JsonBody(const json& value) {
  return value.dump(2, ' ', false, json::error_handler_t::replace) + "\n";
}

namespace {

json ErrorObject(const std::string& code, const std::string& message, int64_t line, int64_t column,
                 const std::string& field) {
  json error = {{"code", code}, {"message", message}};
  if (line > 0) error["line"] = line;
  if (column > 0) error["column"] = column;
  if (!field.empty()) error["field"] = field;
  return error;
}

void SendErrorObject(httplib::Response& res, int status, const json& error) {
  res.status = status;
  // dump with replacement: user text in messages may hold invalid UTF-8.
  res.set_content(JsonBody(json{{"error", error}}), "application/json");
}

}  // namespace

void SendError(httplib::Response& res, int status, const std::string& code,
               const std::string& message, int64_t line, int64_t column, const std::string& field) {
  SendErrorObject(res, status, ErrorObject(code, message, line, column, field));
}

int SendStatus(httplib::Response& res, const Status& s) {
  int status = 500;
  switch (s.code()) {
    case StatusCode::kOk:
      status = 200;
      break;
    case StatusCode::kInvalidInput:
      status = 400;
      break;
    case StatusCode::kNotDeterminable:
      status = 422;
      break;
    case StatusCode::kNotFound:
      status = 404;
      break;
    case StatusCode::kConflict:
      status = 409;
      break;
    case StatusCode::kUnsupportedMedia:
      status = 415;
      break;
    case StatusCode::kTooLarge:
      status = 413;
      break;
    case StatusCode::kBusy:
      status = 503;
      break;
    case StatusCode::kIoError:
      // A full disk is not a moment's unavailability: 507 (RFC 4918) with reason disk_full.
      status = s.reason() == Reason::kDiskFull ? 507 : 503;
      break;
    case StatusCode::kCorruption:
      status = 500;
      break;
    case StatusCode::kInternal:
      status = 500;
      break;
    case StatusCode::kStopped:  // a request's own computation stopped (shutdown): try again
      status = 503;
      break;
  }
  std::string message = s.message();
  // No internals to clients; damaged storage is named (its messages never hold SQL: storage/db.h).
  if (status == 500 && s.code() != StatusCode::kCorruption) message = "internal server error";
  if (status == 503) res.set_header("Retry-After", "1");
  json error = ErrorObject(StatusCodeName(s.code()), message, s.line(), s.column(), s.field());
  if (s.reason() != Reason::kUnspecified &&
      (status != 500 || s.code() == StatusCode::kCorruption)) {
    // A refusal with a failure reason (e.g. over_memory_budget, invalid_config): its code and
    // advice as in a failed job's error (README "Failure reasons").
    const FailureReason& reason = DescribeReason(s.reason());
    error["reason"] = reason.code;
    error["advice"] = reason.advice;
  }
  SendErrorObject(res, status, error);
  return status;
}

std::string ToLower(std::string s) {
  for (char& c : s) c = static_cast<char>(tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string RouteLabel(const std::string& path) {
  // Never destroyed: request threads may still run while exit() destroys statics.
  using Routes = std::vector<std::pair<std::regex, const char*>>;
  static const Routes& kRoutes = *new Routes{
      {std::regex(R"(/api/v1/recordings)"), "/api/v1/recordings"},
      {std::regex(R"(/api/v1/recordings/[^/]+)"), "/api/v1/recordings/{id}"},
      {std::regex(R"(/api/v1/recordings/[^/]+/data)"), "/api/v1/recordings/{id}/data"},
      {std::regex(R"(/api/v1/recordings/[^/]+/segments)"), "/api/v1/recordings/{id}/segments"},
      {std::regex(R"(/recordings/[^/]+)"), "/recordings/{id}"},
      {std::regex(R"(/api/v1/jobs)"), "/api/v1/jobs"},
      {std::regex(R"(/api/v1/jobs/[^/]+)"), "/api/v1/jobs/{id}"},
      {std::regex(R"(/api/v1/jobs/[^/]+/revoke)"), "/api/v1/jobs/{id}/revoke"},
      {std::regex(R"(/api/v1/jobs/[^/]+/accept)"), "/api/v1/jobs/{id}/accept"},
      {std::regex(R"(/api/v1/jobs/[^/]+/cancel)"), "/api/v1/jobs/{id}/cancel"},
      {std::regex(R"(/api/v1/devices)"), "/api/v1/devices"},
      {std::regex(R"(/api/v1/devices/[^/]+/calibration)"), "/api/v1/devices/{serial}/calibration"},
      {std::regex(R"((/api/v1)?/healthz)"), "/healthz"},
      {std::regex(R"((/api/v1)?/metrics)"), "/metrics"},
      {std::regex(R"(/api/v1/openapi\.json)"), "/api/v1/openapi.json"},
      {std::regex(R"(/)"), "/"},
      {std::regex(R"(/jobs/[^/]+)"), "/jobs/{id}"},
      {std::regex(R"(/devices/[^/]+)"), "/devices/{serial}"},
      {std::regex(R"(/style\.css)"), "/style.css"},
  };
  if (path.size() > 512) return "other";
  for (const auto& [re, label] : kRoutes) {
    if (std::regex_match(path, re)) return label;
  }
  return "other";
}

std::string AllowedMethods(const std::string& path) {
  const std::string route = RouteLabel(path);
  if (route == "/api/v1/recordings") return "POST";
  if (route == "/api/v1/jobs") return "GET, POST";
  if (route == "/api/v1/jobs/{id}/revoke" || route == "/api/v1/jobs/{id}/accept" ||
      route == "/api/v1/jobs/{id}/cancel") {
    return "POST";
  }
  if (route == "other") return "";
  return "GET";
}

std::string SanitizeForLog(const std::string& s) {
  std::string out;
  for (unsigned char c : s.substr(0, 200))
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  if (s.size() > 200) out += "...";
  return out;
}

void AnswerException(const httplib::Request& req, httplib::Response& res,
                     std::exception_ptr error) {
  std::string what = "an exception that is not a std::exception";
  try {
    if (error) std::rethrow_exception(error);
  } catch (const std::exception& e) {
    what = e.what();
  } catch (...) {
  }
  const std::string line = "calibd: internal error in " + SanitizeForLog(req.method) + " " +
                           SanitizeForLog(req.path) + ": " + SanitizeForLog(what) + "\n";
  [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, line.data(), line.size());
  SendError(res, 500, "internal", "internal server error");
}

bool IfNoneMatchHits(const std::string& header, const std::string& etag) {
  if (header.empty()) return false;
  size_t pos = 0;
  while (pos < header.size()) {
    size_t comma = header.find(',', pos);
    if (comma == std::string::npos) comma = header.size();
    std::string item = header.substr(pos, comma - pos);
    while (!item.empty() && item.front() == ' ') item.erase(0, 1);
    while (!item.empty() && item.back() == ' ') item.pop_back();
    if (item.rfind("W/", 0) == 0) item = item.substr(2);
    if (item == "*" || item == etag) return true;
    pos = comma + 1;
  }
  return false;
}

}  // namespace calibd::server
