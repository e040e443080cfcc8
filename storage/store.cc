// The parts of Store common to both backends: the choice of backend, timestamps, helpers.
#include "storage/store.h"

#include <cctype>
#include <chrono>
#include <ctime>
#include <nlohmann/json.hpp>
#include <utility>

#include "storage/pg_store.h"
#include "storage/sqlite_store.h"
#include "storage/store_internal.h"

namespace calibd::storage {

namespace internal {

int64_t SystemNowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

bool IsJsonArray(const std::string& text) {
  auto j = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  return !j.is_discarded() && j.is_array();
}

bool IsValidStatus(const std::string& s) {
  return s == "queued" || s == "running" || s == "succeeded" || s == "failed";
}

int64_t Backoff(const StoreOptions& o, int64_t failures) {
  int64_t delay = std::max<int64_t>(o.backoff_base_ms, 0);
  for (int64_t i = 1; i < failures && delay < o.backoff_max_ms; ++i) delay *= 2;
  return std::min(delay, o.backoff_max_ms);
}

std::string VerdictOf(const std::string& result_json) {
  auto j = nlohmann::json::parse(result_json, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return "accepted";
  auto v = j.find("verdict");
  if (v == j.end() || !v->is_object()) return "accepted";
  auto status = v->find("status");
  if (status != v->end() && status->is_string() && status->get<std::string>() == "rejected") {
    return "rejected";
  }
  return "accepted";
}

Status ValidateFilter(const JobFilter& f) {
  if (!f.status.empty() && !IsValidStatus(f.status)) {
    return Status::InvalidInput("unknown job status '" + f.status +
                                "' (queued, running, succeeded or failed)")
        .WithField("status");
  }
  if (!f.state.empty() && f.state != "accepted" && f.state != "rejected" && f.state != "revoked") {
    return Status::InvalidInput("unknown verdict '" + f.state + "' (accepted, rejected or revoked)")
        .WithField("verdict");
  }
  return Status::Ok();
}

}  // namespace internal

std::string FormatTimestamp(int64_t ms) {
  int64_t secs = ms / 1000;
  int64_t millis = ms % 1000;
  if (millis < 0) {
    millis += 1000;
    secs -= 1;
  }
  time_t t = static_cast<time_t>(secs);
  struct tm tm;
  gmtime_r(&t, &tm);
  char buf[64];
  std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", tm.tm_year + 1900,
                tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec,
                static_cast<int>(millis));
  return buf;
}

Store::Store(std::string path, StoreOptions options)
    : path_(std::move(path)), options_(std::move(options)) {
  if (!options_.now_ms) options_.now_ms = &internal::SystemNowMs;
}

bool Store::IsPostgresTarget(const std::string& target) {
  auto starts = [&](const char* prefix) { return target.rfind(prefix, 0) == 0; };
  if (starts("postgresql://") || starts("postgres://")) return true;
  // A libpq keyword/value string starts with a keyword and '=' ("host=/run/postgresql
  // dbname=calibd"). An SQLite file whose path starts so is written "./NAME=...".
  size_t i = target.find_first_not_of(' ');
  if (i == std::string::npos) return false;
  const size_t word = i;
  while (i < target.size() &&
         (std::isalnum(static_cast<unsigned char>(target[i])) || target[i] == '_')) {
    ++i;
  }
  while (i < target.size() && target[i] == ' ') ++i;
  return i > word && i < target.size() && target[i] == '=';
}

Status Store::Open(const std::string& target, StoreOptions options, std::unique_ptr<Store>* out) {
  out->reset();
  if (IsPostgresTarget(target)) return PgStore::Connect(target, std::move(options), out);
  return SqliteStore::OpenFile(target, std::move(options), out);
}

Status Store::ReadRecordingBytes(int64_t id, std::string* out) {
  out->clear();
  return ReadRecordingData(id, [out](std::string_view chunk) {
    out->append(chunk);
    return true;
  });
}

}  // namespace calibd::storage
