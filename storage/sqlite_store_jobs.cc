// SqliteStore's job queue: enqueue, claim (with recovery of lapsed leases), lease renewal,
// complete, fail, release. Every transition runs in the group-commit write queue (Write), which
// serialises it with every other write of the process, and BEGIN IMMEDIATE with other processes.
#include <utility>

#include "storage/sha256.h"
#include "storage/sqlite_store_internal.h"

namespace calibd::storage {

using internal::Backoff;
using sqlite::LoadRecording;
using sqlite::RefreshLatest;
using sqlite::RememberDevice;

Status SqliteStore::LoadJob(Db* db, int64_t id, bool with_result, JobInfo* out) {
  Stmt st;
  Status s = db->Prepare(internal::JobSelect(with_result) + "WHERE j.id = ?1", &st);
  if (!s.ok()) return s;
  st.BindInt(1, id);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) return Status::NotFound("job " + std::to_string(id) + " not found");
  internal::ReadJob(sqlite::StmtRow(st), out);
  return Status::Ok();
}

Status SqliteStore::EnqueueJobLocked(Db* db, int64_t recording_id, const std::string& method,
                                     const std::string& device, const std::string& config_json,
                                     int64_t now, JobInfo* out, bool inherit_device) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  RecordingInfo rec;
  Status s = LoadRecording(db, recording_id, &rec);
  if (!s.ok()) return s;
  const std::string& job_device = device.empty() && inherit_device ? rec.device : device;
  Stmt st;
  s = db->Prepare(
      "INSERT INTO jobs (recording_id, method, device, config_json, status, attempts, "
      "created_at, not_before) VALUES (?1, ?2, ?3, ?4, 'queued', 0, ?5, ?5)",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, recording_id)
      .BindText(2, method)
      .BindText(3, job_device)
      .BindText(4, config_json.empty() ? "{}" : config_json)
      .BindInt(5, now);
  s = st.Run();
  if (!s.ok()) return s;
  int64_t id = db->LastInsertRowid();
  s = RememberDevice(db, job_device, now);
  if (!s.ok()) return s;
  return LoadJob(db, id, false, out);
}

Status SqliteStore::EnqueueJob(int64_t recording_id, const std::string& method,
                               const std::string& device, const std::string& config_json,
                               JobInfo* out) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  JobInfo job;
  Status s = Write([&](Db* db) {
    return EnqueueJobLocked(db, recording_id, method, device, config_json, Now(), &job);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  return Status::Ok();
}

Status SqliteStore::RecoverLocked(Db* db, int64_t now, int64_t* recovered) {
  int64_t total = 0;
  Stmt st;
  // Cancelled while running: failed as cancelled, never queued again.
  Status s = db->Prepare(
      "UPDATE jobs SET status = 'failed', finished_at = ?1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = ?2, error_reason = ?3, error_detail_json = NULL, "
      "error_message = 'cancelled by ' || COALESCE(cancel_actor, '?') || ': ' || "
      "COALESCE(cancel_reason, '') || ' (the lease of ' || COALESCE(lease_owner, '?') || "
      "' lapsed before its run stopped)' "
      "WHERE status = 'running' AND lease_expires_at <= ?1 AND cancel_requested_at IS NOT NULL",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, now).BindText(2, internal::kCancelledCode).BindText(3, internal::kCancelledReason);
  s = st.Run();
  if (!s.ok()) return s;
  total += db->Changes();
  // Out of attempts: failed for good.
  s = db->Prepare(
      "UPDATE jobs SET status = 'failed', finished_at = ?1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || "
      "' expired on attempt ' || attempts || ' of ' || ?2 || '; giving up' "
      "WHERE status = 'running' AND lease_expires_at <= ?1 AND attempts >= ?2",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, now).BindInt(2, options_.max_attempts);
  s = st.Run();
  if (!s.ok()) return s;
  total += db->Changes();
  // Otherwise: back in the queue, claimable at once.
  s = db->Prepare(
      "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
      "started_at = NULL, not_before = ?1, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || ' expired' "
      "WHERE status = 'running' AND lease_expires_at <= ?1",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, now);
  s = st.Run();
  if (!s.ok()) return s;
  total += db->Changes();
  if (recovered != nullptr) *recovered = total;
  return Status::Ok();
}

Status SqliteStore::RecoverExpiredLeases(int64_t* recovered) {
  int64_t n = 0;
  Status s = Write([&](Db* db) { return RecoverLocked(db, Now(), &n); });
  if (!s.ok()) return s;
  if (recovered != nullptr) *recovered = n;
  return Status::Ok();
}

Status SqliteStore::ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) {
  if (owner_prefix.empty()) return Status::InvalidInput("storage: owner_prefix must not be empty");
  int64_t n = 0;
  Status s = Write([&](Db* db) {
    const int64_t now = Now();
    Stmt st;
    Status s = db->Prepare(
        "UPDATE jobs SET lease_expires_at = ?1 WHERE status = 'running' AND "
        "substr(lease_owner, 1, length(?2)) = ?2 AND lease_expires_at > ?1",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, now).BindText(2, owner_prefix);
    s = st.Run();
    if (!s.ok()) return s;
    n = db->Changes();
    return n > 0 ? RecoverLocked(db, now, nullptr) : Status::Ok();
  });
  if (!s.ok()) return s;
  if (taken_back != nullptr) *taken_back = n;
  return Status::Ok();
}

Status SqliteStore::ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                             bool* claimed) {
  *claimed = false;
  Status valid = internal::ValidateClaim(worker_id, lease_ms);
  if (!valid.ok()) return valid;
  {
    // Cheap check without the write lock, so idle workers polling do not serialise on it.
    Conn conn(this);
    Status s = conn.Open();
    if (!s.ok()) return s;
    Stmt st;
    s = conn.db()->Prepare(
        "SELECT EXISTS (SELECT 1 FROM jobs WHERE status = 'queued' AND not_before <= ?1) "
        "OR EXISTS (SELECT 1 FROM jobs WHERE status = 'running' AND lease_expires_at <= ?1)",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, Now());
    bool row = false;
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row || st.ColumnInt(0) == 0) return Status::Ok();
  }
  JobInfo job;
  bool got = false;
  Status s = Write([&](Db* db) {
    got = false;
    const int64_t now = Now();
    Status s = RecoverLocked(db, now, nullptr);
    if (!s.ok()) return s;
    int64_t id = 0;
    {
      Stmt st;
      s = db->Prepare(
          "SELECT id FROM jobs WHERE status = 'queued' AND not_before <= ?1 ORDER BY id LIMIT 1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, now);
      bool row = false;
      s = st.Step(&row);
      if (!s.ok()) return s;
      if (row) id = st.ColumnInt(0);
    }
    if (id == 0) return Status::Ok();
    Stmt st;
    s = db->Prepare(
        "UPDATE jobs SET status = 'running', lease_owner = ?2, lease_expires_at = ?3, "
        "attempts = attempts + 1, started_at = ?4, finished_at = NULL "
        "WHERE id = ?1 AND status = 'queued'",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, id).BindText(2, worker_id).BindInt(3, now + lease_ms).BindInt(4, now);
    s = st.Run();
    if (!s.ok()) return s;
    s = LoadJob(db, id, false, &job);
    if (!s.ok()) return s;
    got = true;
    return Status::Ok();
  });
  if (!s.ok()) return s;
  if (got) {
    *claimed = true;
    if (out != nullptr) *out = std::move(job);
  }
  return Status::Ok();
}

Status SqliteStore::RequireHolder(Db* db, int64_t job_id, const std::string& worker_id,
                                  const char* action, JobInfo* job) {
  Status s = LoadJob(db, job_id, false, job);
  if (!s.ok()) return s;
  return internal::CheckHolder(*job, worker_id, action);
}

Status SqliteStore::RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) {
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Write([&](Db* db) {
    Stmt st;
    Status s = db->Prepare(
        "UPDATE jobs SET lease_expires_at = ?3 "
        "WHERE id = ?1 AND status = 'running' AND lease_owner = ?2",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, worker_id).BindInt(3, Now() + lease_ms);
    s = st.Run();
    if (!s.ok()) return s;
    if (db->Changes() == 1) return Status::Ok();
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "renew the lease of", &job);
    if (!s.ok()) return s;
    return Status::Conflict("cannot renew the lease of job " + std::to_string(job_id));
  });
}

Status SqliteStore::CompleteJob(int64_t job_id, const std::string& worker_id,
                                const std::string& result_json) {
  if (result_json.empty()) return Status::InvalidInput("storage: empty result");
  const std::string sha = Sha256Hex(result_json);
  std::string cancelled;  // set when the job was cancelled while it ran: failed, not completed
  Status written = Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = LoadJob(db, job_id, false, &job);
    if (!s.ok()) return s;
    bool done = false;
    s = internal::CheckCompletion(job, worker_id, sha, &done);
    if (!s.ok() || done) return s;
    if (job.cancel_requested_at_ms != 0) {
      // A cancel answered "stopping it" wins over a run that finished meanwhile: the job ends
      // as cancelled (committed here), and the caller hears kConflict below.
      cancelled = internal::CancelledMessage(job.cancel_actor, job.cancel_reason);
      return FailCancelledLocked(db, job_id, cancelled);
    }
    const int64_t now = Now();
    Stmt st;
    // The gate's verdict, read from the result (anything but "rejected" counts as accepted), and
    // the result's place in the order of storing (seq: "latest" never compares host clocks).
    s = db->Prepare(
        "INSERT INTO results (job_id, result_json, sha256, created_at, verdict, seq) VALUES (?1, "
        "?2, ?3, ?4, CASE WHEN (CASE WHEN json_valid(?2) THEN json_extract(?2, '$.verdict.status') "
        "END) = 'rejected' THEN 'rejected' ELSE 'accepted' END, "
        "(SELECT COALESCE(MAX(seq), 0) + 1 FROM results))",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, result_json).BindText(3, sha).BindInt(4, now);
    s = st.Run();
    if (!s.ok()) return s;
    s = db->Prepare(
        "UPDATE jobs SET status = 'succeeded', finished_at = ?2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = NULL, error_message = NULL, error_reason = NULL, "
        "error_detail_json = NULL WHERE id = ?1",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindInt(2, now);
    s = st.Run();
    if (!s.ok()) return s;
    if (!job.device.empty()) {
      s = RememberDevice(db, job.device, now);
      if (!s.ok()) return s;
      s = RefreshLatest(db, job.device, job.method);
      if (!s.ok()) return s;
    }
    return Status::Ok();
  });
  if (written.ok() && !cancelled.empty()) {
    return Status::Conflict("job " + std::to_string(job_id) + " was " + cancelled +
                            ": its result is not stored");
  }
  return written;
}

Status SqliteStore::FailCancelledLocked(Db* db, int64_t job_id, const std::string& message) {
  Stmt st;
  Status s = db->Prepare(
      "UPDATE jobs SET status = 'failed', finished_at = ?2, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = ?3, error_reason = ?4, error_message = ?5, "
      "error_detail_json = NULL WHERE id = ?1",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, job_id)
      .BindInt(2, Now())
      .BindText(3, internal::kCancelledCode)
      .BindText(4, internal::kCancelledReason)
      .BindText(5, message);
  return st.Run();
}

Status SqliteStore::FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                            bool transient) {
  return Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "fail", &job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    const std::string error_code = failure.code.empty() ? std::string("error") : failure.code;
    auto bind_failure = [&](Stmt* st, const std::string& message) {
      st->BindText(3, error_code).BindText(4, message);
      if (failure.reason.empty()) {
        st->BindNull(5);
      } else {
        st->BindText(5, failure.reason);
      }
      if (failure.detail_json.empty()) {
        st->BindNull(6);
      } else {
        st->BindText(6, failure.detail_json);
      }
    };
    Stmt st;
    // A cancelled job is never queued again, even after a transient failure.
    if (transient && job.attempts < options_.max_attempts && job.cancel_requested_at_ms == 0) {
      s = db->Prepare(
          "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
          "started_at = NULL, not_before = ?2, error_code = ?3, error_message = ?4, "
          "error_reason = ?5, error_detail_json = ?6 WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id).BindInt(2, now + Backoff(options_, job.attempts));
      bind_failure(&st, failure.message);
    } else {
      std::string final_message = failure.message;
      if (transient) {
        final_message =
            "gave up after " + std::to_string(job.attempts) + " attempts: " + failure.message;
      }
      s = db->Prepare(
          "UPDATE jobs SET status = 'failed', finished_at = ?2, lease_owner = NULL, "
          "lease_expires_at = NULL, error_code = ?3, error_message = ?4, error_reason = ?5, "
          "error_detail_json = ?6 WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id).BindInt(2, now);
      bind_failure(&st, final_message);
    }
    s = st.Run();
    if (!s.ok()) return s;
    return Status::Ok();
  });
}

Status SqliteStore::ReleaseJob(int64_t job_id, const std::string& worker_id, ReleaseKind kind) {
  return Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "release", &job);
    if (!s.ok()) return s;
    Stmt st;
    if (job.cancel_requested_at_ms != 0) {  // cancelled while running: it ends here
      return FailCancelledLocked(db, job_id,
                                 internal::CancelledMessage(job.cancel_actor, job.cancel_reason));
    }
    // Shutdown: the run does not count, claimable at once. After a store failure: it counts
    // and backs off (the row changes in place: no new text, so it fits on a full disk).
    const bool shutdown = kind == ReleaseKind::kShutdown;
    s = db->Prepare(
        "UPDATE jobs SET status = 'queued', attempts = MAX(attempts - ?3, 0), lease_owner = NULL, "
        "lease_expires_at = NULL, started_at = NULL, not_before = ?2 WHERE id = ?1",
        &st);
    if (!s.ok()) return s;
    const int64_t now = Now();
    st.BindInt(1, job_id)
        .BindInt(2, shutdown ? now : now + Backoff(options_, job.attempts))
        .BindInt(3, shutdown ? 1 : 0);
    s = st.Run();
    if (!s.ok()) return s;
    return Status::Ok();
  });
}

Status SqliteStore::CancelRequests(const std::vector<int64_t>& job_ids,
                                   std::vector<int64_t>* requested) {
  requested->clear();
  if (job_ids.empty()) return Status::Ok();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  // Uncached: the IN list differs from call to call.
  s = conn.db()->PrepareUncached(
      "SELECT id FROM jobs WHERE id IN (" + internal::IdList(job_ids) +
          ") AND status = 'running' AND cancel_requested_at IS NOT NULL ORDER BY id",
      &st);
  if (!s.ok()) return s;
  std::vector<int64_t> ids;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    ids.push_back(st.ColumnInt(0));
  }
  *requested = std::move(ids);
  return Status::Ok();
}

Status SqliteStore::Cancel(int64_t job_id, const std::string& reason, const std::string& actor,
                           JobInfo* out, JobEvent* event) {
  JobInfo job;
  JobEvent cancel_event;
  Status s = Write([&](Db* db) {
    Status s = LoadJob(db, job_id, false, &job);
    if (!s.ok()) return s;
    s = internal::CheckCancel(job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    Stmt st;
    if (job.status == JobStatus::kQueued) {
      s = db->Prepare(
          "UPDATE jobs SET status = 'failed', finished_at = ?2, lease_owner = NULL, "
          "lease_expires_at = NULL, error_code = ?3, error_reason = ?4, error_message = ?5, "
          "error_detail_json = NULL, cancel_requested_at = ?2, cancel_reason = ?6, "
          "cancel_actor = ?7 WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id)
          .BindInt(2, now)
          .BindText(3, internal::kCancelledCode)
          .BindText(4, internal::kCancelledReason)
          .BindText(5, internal::CancelledMessage(actor, reason))
          .BindText(6, reason)
          .BindText(7, actor);
    } else {  // running: the first request's words are kept
      s = db->Prepare(
          "UPDATE jobs SET cancel_requested_at = COALESCE(cancel_requested_at, ?2), "
          "cancel_reason = COALESCE(cancel_reason, ?3), "
          "cancel_actor = COALESCE(cancel_actor, ?4) WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id).BindInt(2, now).BindText(3, reason).BindText(4, actor);
    }
    s = st.Run();
    if (!s.ok()) return s;
    s = db->Prepare(
        "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
        "VALUES (?1, 'cancel', ?2, ?3, ?4)",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, reason).BindText(3, actor).BindInt(4, now);
    s = st.Run();
    if (!s.ok()) return s;
    cancel_event = internal::MakeCancelEvent(db->LastInsertRowid(), job_id, reason, actor, now);
    return LoadJob(db, job_id, false, &job);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  if (event != nullptr) *event = std::move(cancel_event);
  return Status::Ok();
}

}  // namespace calibd::storage
