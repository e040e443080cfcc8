// The parts of Store common to both backends: the choice of backend, timestamps, helpers.
#include "storage/store.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <nlohmann/json.hpp>
#include <utility>

#include "storage/pg_store.h"
#include "storage/sqlite_store.h"
#include "storage/store_internal.h"

namespace calibd {

void to_json(nlohmann::json& j, JobStatus v) { j = Name(v); }
void to_json(nlohmann::json& j, GateVerdict v) { j = Name(v); }
void to_json(nlohmann::json& j, Decision v) { j = Name(v); }
void to_json(nlohmann::json& j, ServeState v) { j = Name(v); }

}  // namespace calibd

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

int64_t Backoff(const StoreOptions& o, int64_t failures) {
  int64_t delay = std::max<int64_t>(o.backoff_base_ms, 0);
  for (int64_t i = 1; i < failures && delay < o.backoff_max_ms; ++i) delay *= 2;
  return std::min(delay, o.backoff_max_ms);
}

GateVerdict VerdictOf(const std::string& result_json) {
  auto j = nlohmann::json::parse(result_json, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !j.is_object()) return GateVerdict::kAccepted;
  auto v = j.find("verdict");
  if (v == j.end() || !v->is_object()) return GateVerdict::kAccepted;
  auto status = v->find("status");
  if (status != v->end() && status->is_string() && status->get<std::string>() == "rejected") {
    return GateVerdict::kRejected;
  }
  return GateVerdict::kAccepted;
}

int PageLimit(const JobFilter& f) { return std::clamp(f.limit <= 0 ? 50 : f.limit, 1, 500); }

StagedFile::~StagedFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status StagedFile::Open(const std::string& path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) return Status::IoError("storage: cannot open " + path + ": " + std::strerror(errno));
  struct stat st;
  if (::fstat(fd_, &st) != 0) {
    return Status::IoError("storage: cannot stat " + path + ": " + std::strerror(errno));
  }
  size_ = static_cast<int64_t>(st.st_size);
  return Status::Ok();
}

Status StagedFile::OpenUpload(const NewRecording& r) {
  size_ = static_cast<int64_t>(r.data.size());
  return r.path.empty() ? Status::Ok() : Open(r.path);
}

Status CheckRecordingDigest(const RecordingInfo& info, int64_t bytes, const std::string& sha) {
  if (bytes == info.bytes && sha == info.sha256) return Status::Ok();
  return Status::Corruption("storage: recording " + std::to_string(info.id) +
                            " is damaged: its stored bytes (" + std::to_string(bytes) +
                            ") have SHA-256 " + sha + ", not the " + info.sha256 + " of the " +
                            std::to_string(info.bytes) +
                            " bytes uploaded; upload the original file again to repair it")
      .WithReason(Reason::kStorageDamaged);
}

int PageLimit(const DeviceFilter& f) { return std::clamp(f.limit <= 0 ? 100 : f.limit, 1, 1000); }

Status ValidateNewRecording(const NewRecording& r) {
  if (!r.columns_json.empty() && !IsJsonArray(r.columns_json)) {
    return Status::InvalidInput("storage: columns_json is not a JSON array");
  }
  if (!r.sensors_json.empty() && !IsJsonArray(r.sensors_json)) {
    return Status::InvalidInput("storage: sensors_json is not a JSON array");
  }
  if (r.job && r.job->method.empty()) return Status::InvalidInput("storage: a job needs a method");
  return Status::Ok();
}

Status ValidateClaim(const std::string& worker_id, int64_t lease_ms) {
  if (worker_id.empty()) return Status::InvalidInput("storage: worker_id must not be empty");
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Status::Ok();
}

// ---- rows ---------------------------------------------------------------------------------------

std::string JobSelect(bool with_result) {
  return std::string(kJobColumns) + (with_result ? "r.result_json" : "NULL") +
         ", j.error_reason, " + (with_result ? "j.error_detail_json" : "NULL") +
         ", j.cancel_requested_at, j.cancel_reason, j.cancel_actor" + kJobFrom;
}

void ReadJob(const Row& row, JobInfo* job) {
  *job = JobInfo();
  job->id = row.Int(0);
  job->recording_id = row.Int(1);
  job->method = row.Text(2);
  job->device = row.Text(3);
  job->config_json = row.Text(4);
  Parse(row.Text(5), &job->status);  // the schema's CHECK admits only the four
  job->attempts = row.Int(6);
  job->lease_owner = row.Text(7);
  auto ms = [&](int col, int64_t* raw, std::string* text) {
    *raw = row.Int(col);
    *text = row.IsNull(col) ? std::string() : FormatTimestamp(*raw);
  };
  ms(8, &job->lease_expires_at_ms, &job->lease_expires_at);
  ms(9, &job->created_at_ms, &job->created_at);
  ms(10, &job->started_at_ms, &job->started_at);
  ms(11, &job->finished_at_ms, &job->finished_at);
  job->error_code = row.Text(12);
  job->error_message = row.Text(13);
  job->not_before_ms = row.Int(14);
  if (job->status == JobStatus::kSucceeded) {
    job->result_sha256 = row.Text(15);
    Parse(row.Text(16), &job->verdict);
    Parse(row.Text(17), &job->decision);
    if (job->decision != Decision::kNone) {
      job->state =
          job->decision == Decision::kRevoked ? ServeState::kRevoked : ServeState::kAccepted;
    } else if (job->verdict != GateVerdict::kNone) {
      job->state =
          job->verdict == GateVerdict::kRejected ? ServeState::kRejected : ServeState::kAccepted;
    }
    job->result_json = row.Text(18);
  }
  job->error_reason = row.Text(19);
  job->error_detail_json = row.Text(20);
  if (!row.IsNull(21)) {
    job->cancel_requested_at_ms = row.Int(21);
    job->cancel_requested_at = FormatTimestamp(job->cancel_requested_at_ms);
    job->cancel_reason = row.Text(22);
    job->cancel_actor = row.Text(23);
  }
}

void ReadRecording(const Row& row, RecordingInfo* out) {
  RecordingInfo info;
  info.id = row.Int(0);
  info.sha256 = row.Text(1);
  info.bytes = row.Int(2);
  info.rows = row.Int(3);
  info.layout = row.Text(4);
  info.device = row.Text(5);
  info.file_name = row.Text(6);
  info.created_at_ms = row.Int(7);
  info.created_at = FormatTimestamp(info.created_at_ms);
  info.columns_json = row.Text(8);
  info.sensors_json = row.Text(9);
  info.log_json = row.Text(10);
  nlohmann::json summary;
  summary["layout"] = info.layout;
  summary["rows"] = info.rows;
  auto columns = nlohmann::json::parse(info.columns_json, nullptr, false);
  auto sensors = nlohmann::json::parse(info.sensors_json, nullptr, false);
  summary["columns"] = columns.is_discarded() ? nlohmann::json::array() : columns;
  summary["sensors"] = sensors.is_discarded() ? nlohmann::json::array() : sensors;
  info.summary_json = summary.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  *out = std::move(info);
}

void ReadJobEvent(const Row& row, JobEvent* out) {
  JobEvent e;
  e.id = row.Int(0);
  e.job_id = row.Int(1);
  e.action = row.Text(2);
  e.reason = row.Text(3);
  e.actor = row.Text(4);
  e.created_at_ms = row.Int(5);
  e.created_at = FormatTimestamp(e.created_at_ms);
  *out = std::move(e);
}

void AddDeviceRow(const Row& row, std::vector<DeviceInfo>* devices) {
  std::string serial = row.Text(0);
  if (devices->empty() || devices->back().serial != serial) {
    DeviceInfo d;
    d.serial = std::move(serial);
    d.first_seen_ms = row.Int(1);
    d.first_seen = FormatTimestamp(d.first_seen_ms);
    devices->push_back(std::move(d));
  }
  if (!row.IsNull(2)) {
    DeviceCalibration c;
    c.method = row.Text(2);
    c.job_id = row.Int(3);
    c.calibrated_at_ms = row.Int(4);
    c.calibrated_at = FormatTimestamp(c.calibrated_at_ms);
    devices->back().latest.push_back(std::move(c));
  }
}

void AddQueueCount(const Row& row, QueueCounts* out) {
  JobStatus status;
  if (!Parse(row.Text(0), &status)) return;
  const int64_t n = row.Int(1);
  switch (status) {
    case JobStatus::kQueued:
      out->queued = n;
      break;
    case JobStatus::kRunning:
      out->running = n;
      break;
    case JobStatus::kSucceeded:
      out->succeeded = n;
      break;
    case JobStatus::kFailed:
      out->failed = n;
      break;
  }
}

// ---- job state rules ----------------------------------------------------------------------------

Status CheckHolder(const JobInfo& job, const std::string& worker_id, const char* action) {
  if (job.status != JobStatus::kRunning) {
    return Status::Conflict("cannot " + std::string(action) + " job " + std::to_string(job.id) +
                            ": it is " + Name(job.status) + ", not running");
  }
  if (job.lease_owner != worker_id) {
    return Status::Conflict("cannot " + std::string(action) + " job " + std::to_string(job.id) +
                            ": it is leased by " + job.lease_owner + ", not " + worker_id);
  }
  return Status::Ok();
}

Status CheckCompletion(const JobInfo& job, const std::string& worker_id, const std::string& sha,
                       bool* done) {
  *done = false;
  if (job.status == JobStatus::kSucceeded) {
    if (job.result_sha256 == sha) {  // the same run again: nothing to do
      *done = true;
      return Status::Ok();
    }
    return Status::Conflict("job " + std::to_string(job.id) +
                            " already succeeded with a different result");
  }
  return CheckHolder(job, worker_id, "complete");
}

const char* DecisionValue(bool revoke) {
  return Name(revoke ? Decision::kRevoked : Decision::kAccepted);
}
const char* DecisionAction(bool revoke) { return revoke ? "revoke" : "accept"; }

Status ValidateDecision(bool revoke, const std::string& reason) {
  if (!reason.empty()) return Status::Ok();
  return Status::InvalidInput(revoke ? "a revocation needs a reason"
                                     : "an acceptance needs a reason")
      .WithField("reason");
}

Status CheckDecision(const JobInfo& job, bool revoke) {
  const std::string id = "job " + std::to_string(job.id);
  if (job.status != JobStatus::kSucceeded) {
    return Status::Conflict(id + " is " + Name(job.status) + ": it has no result to " +
                            DecisionAction(revoke));
  }
  if (revoke && job.state == ServeState::kRevoked) {
    return Status::Conflict(id + " is already revoked");
  }
  if (revoke && job.state == ServeState::kRejected) {
    return Status::Conflict(id +
                            " was rejected by the acceptance gate and is not served: "
                            "there is nothing to revoke");
  }
  if (!revoke && job.state == ServeState::kAccepted) {
    return Status::Conflict(
        id + " is already accepted" +
        (job.decision == Decision::kNone ? std::string(" by the acceptance gate") : std::string()));
  }
  return Status::Ok();
}

JobEvent MakeDecisionEvent(int64_t id, int64_t job_id, bool revoke, const std::string& reason,
                           const std::string& actor, int64_t now) {
  JobEvent event;
  event.id = id;
  event.job_id = job_id;
  event.action = DecisionAction(revoke);
  event.reason = reason;
  event.actor = actor;
  event.created_at_ms = now;
  event.created_at = FormatTimestamp(now);
  return event;
}

std::string CancelledMessage(const std::string& actor, const std::string& reason) {
  return "cancelled by " + actor + ": " + reason;
}

Status ValidateCancel(const std::string& reason) {
  if (!reason.empty()) return Status::Ok();
  return Status::InvalidInput("a cancel request needs a reason").WithField("reason");
}

Status CheckCancel(const JobInfo& job) {
  if (job.status == JobStatus::kQueued || job.status == JobStatus::kRunning) return Status::Ok();
  return Status::Conflict("job " + std::to_string(job.id) + " is " + Name(job.status) +
                          ": it has already finished, there is nothing to cancel");
}

JobEvent MakeCancelEvent(int64_t id, int64_t job_id, const std::string& reason,
                         const std::string& actor, int64_t now) {
  JobEvent event;
  event.id = id;
  event.job_id = job_id;
  event.action = "cancel";
  event.reason = reason;
  event.actor = actor;
  event.created_at_ms = now;
  event.created_at = FormatTimestamp(now);
  return event;
}

std::string IdList(const std::vector<int64_t>& ids) {
  std::string out;
  for (int64_t id : ids) {
    if (!out.empty()) out += ",";
    out += std::to_string(id);
  }
  return out;
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
    : path_(std::move(path)),
      options_(std::move(options)),
      clock_injected_(static_cast<bool>(options_.now_ms)) {
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

Status Store::ListDevices(std::vector<DeviceInfo>* out) {
  out->clear();
  DeviceFilter filter;
  filter.limit = 1000;
  std::vector<DeviceInfo> page;
  for (;;) {
    Status s = ListDevices(filter, &page);
    if (!s.ok()) return s;
    const bool last = static_cast<int>(page.size()) < filter.limit;
    if (!page.empty()) filter.after = page.back().serial;
    for (auto& d : page) out->push_back(std::move(d));
    if (last) return Status::Ok();
  }
}

Status Store::RevokeJob(int64_t job_id, const std::string& reason, const std::string& actor,
                        JobEvent* out) {
  Status s = internal::ValidateDecision(/*revoke=*/true, reason);
  if (!s.ok()) return s;
  return Decide(job_id, /*revoke=*/true, reason, actor, out);
}

Status Store::AcceptJob(int64_t job_id, const std::string& reason, const std::string& actor,
                        JobEvent* out) {
  Status s = internal::ValidateDecision(/*revoke=*/false, reason);
  if (!s.ok()) return s;
  return Decide(job_id, /*revoke=*/false, reason, actor, out);
}

Status Store::CancelJob(int64_t job_id, const std::string& reason, const std::string& actor,
                        JobInfo* out, JobEvent* event) {
  Status s = internal::ValidateCancel(reason);
  if (!s.ok()) return s;
  return Cancel(job_id, reason, actor, out, event);
}

Status Store::ReadRecordingBytes(int64_t id, std::string* out) {
  out->clear();
  return ReadRecordingData(id, [out](std::string_view chunk) {
    out->append(chunk);
    return true;
  });
}

}  // namespace calibd::storage
