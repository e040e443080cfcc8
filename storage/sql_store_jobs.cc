// SqlStore's job queue: enqueue, claim (with recovery of lapsed leases), lease renewal, complete
// (with the gate's verdict), fail (retry and back-off), release, cancel. Every transition runs in
// the backend's write transaction with the job's row locked (SqlDialect::lock_job), so that
// callers racing on one job, in any thread, process or host, are serialised.
#include <algorithm>
#include <string>
#include <utility>

#include "storage/sha256.h"
#include "storage/sql_store.h"

namespace calibd::storage {

using internal::Backoff;
using sql::LoadRecording;

Status SqlStore::LoadJob(SqlConn* c, int64_t id, bool with_result, JobInfo* out, bool lock) {
  const std::string sql =
      internal::JobSelect(with_result) + "WHERE j.id = $1" + (lock ? dialect_.lock_job : "");
  bool found = false;
  Status s = c->Run(sql, {SqlInt(id)}, [&](const internal::Row& row) {
    internal::ReadJob(row, out);
    found = true;
  });
  if (!s.ok()) return s;
  if (!found) return Status::NotFound("job " + std::to_string(id) + " not found");
  return Status::Ok();
}

Status SqlStore::EnqueueJobLocked(SqlConn* c, int64_t recording_id, const std::string& method,
                                  const std::string& device, const std::string& config_json,
                                  int64_t now, JobInfo* out, bool inherit_device) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  RecordingInfo rec;
  Status s = LoadRecording(c, recording_id, &rec);
  if (!s.ok()) return s;
  const std::string& job_device = device.empty() && inherit_device ? rec.device : device;
  int64_t id = 0;
  s = c->Run(
      "INSERT INTO jobs (recording_id, method, device, config_json, status, attempts, "
      "created_at, not_before) VALUES ($1, $2, $3, $4, 'queued', 0, $5, $5) RETURNING id",
      {SqlInt(recording_id), SqlText(method), SqlText(job_device),
       SqlText(config_json.empty() ? "{}" : config_json), SqlInt(now)},
      [&](const internal::Row& row) { id = row.Int(0); });
  if (!s.ok()) return s;
  s = RememberDevice(c, job_device, now);
  if (!s.ok()) return s;
  c->NotifyJobsAfterCommit();
  return LoadJob(c, id, false, out);
}

Status SqlStore::EnqueueJob(int64_t recording_id, const std::string& method,
                            const std::string& device, const std::string& config_json,
                            JobInfo* out) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  JobInfo job;
  Status s = Write([&](SqlConn* c) {
    int64_t now = 0;
    Status s = TxnNow(c, &now);
    if (!s.ok()) return s;
    return EnqueueJobLocked(c, recording_id, method, device, config_json, now, &job, true);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  return Status::Ok();
}

Status SqlStore::RecoverLocked(SqlConn* c, int64_t now, int64_t* recovered) {
  // Each statement picks the lapsed running jobs it changes; skip_locked leaves a row another
  // transaction is changing (its holder completing it, another host recovering it) to that one.
  const std::string lapsed = std::string("WHERE id IN (SELECT id FROM jobs WHERE ") +
                             "status = 'running' AND lease_expires_at <= $1 AND ";
  const std::string end = std::string(dialect_.skip_locked) + ")";
  int64_t cancelled = 0, exhausted = 0, requeued = 0;
  // Cancelled while running: failed as cancelled, never queued again.
  Status s = c->Run(
      "UPDATE jobs SET status = 'failed', finished_at = $1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = $2, error_reason = $3, error_detail_json = NULL, "
      "error_message = 'cancelled by ' || COALESCE(cancel_actor, '?') || ': ' || "
      "COALESCE(cancel_reason, '') || ' (the lease of ' || COALESCE(lease_owner, '?') || "
      "' lapsed before its run stopped)' " +
          lapsed + "cancel_requested_at IS NOT NULL" + end,
      {SqlInt(now), SqlText(internal::kCancelledCode), SqlText(internal::kCancelledReason)}, {},
      &cancelled);
  if (!s.ok()) return s;
  // Out of attempts: failed for good. (Each statement may read its own snapshot: a job cancelled
  // after the first one is left running here, and failed as cancelled by the next recovery.)
  s = c->Run(
      "UPDATE jobs SET status = 'failed', finished_at = $1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, error_message = 'the lease of ' || COALESCE(lease_owner, '?') "
      "|| ' expired on attempt ' || CAST(attempts AS TEXT) || ' of ' || "
      "CAST(CAST($2 AS BIGINT) AS TEXT) || '; giving up' " +
          lapsed + "attempts >= CAST($2 AS BIGINT) AND cancel_requested_at IS NULL" + end,
      {SqlInt(now), SqlInt(options_.max_attempts)}, {}, &exhausted);
  if (!s.ok()) return s;
  // Otherwise: back in the queue, claimable at once.
  s = c->Run(
      "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
      "started_at = NULL, not_before = $1, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || ' expired' " +
          lapsed + "cancel_requested_at IS NULL" + end,
      {SqlInt(now)}, {}, &requeued);
  if (!s.ok()) return s;
  if (requeued > 0) c->NotifyJobsAfterCommit();
  if (recovered != nullptr) *recovered = cancelled + exhausted + requeued;
  return Status::Ok();
}

Status SqlStore::RecoverExpiredLeases(int64_t* recovered) {
  int64_t n = 0;
  Status s = Write([&](SqlConn* c) {
    int64_t now = 0;
    Status s = TxnNow(c, &now);
    if (!s.ok()) return s;
    return RecoverLocked(c, now, &n);
  });
  if (!s.ok()) return s;
  if (recovered != nullptr) *recovered = n;
  return Status::Ok();
}

Status SqlStore::ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) {
  if (owner_prefix.empty()) return Status::InvalidInput("storage: owner_prefix must not be empty");
  int64_t n = 0;
  Status s = Write([&](SqlConn* c) {
    int64_t now = 0;
    Status s = TxnNow(c, &now);
    if (!s.ok()) return s;
    s = c->Run(
        "UPDATE jobs SET lease_expires_at = $1 WHERE status = 'running' AND "
        "substr(lease_owner, 1, length(CAST($2 AS TEXT))) = $2 AND lease_expires_at > $1",
        {SqlInt(now), SqlText(owner_prefix)}, {}, &n);
    if (!s.ok()) return s;
    return n > 0 ? RecoverLocked(c, now, nullptr) : Status::Ok();
  });
  if (!s.ok()) return s;
  if (taken_back != nullptr) *taken_back = n;
  return Status::Ok();
}

Status SqlStore::AnyClaimable(bool* any) {
  // One round trip: the time is the store's clock ($1) or the database's, computed once (a scalar
  // subquery: an index bound, which a volatile clock function is not).
  const bool db_clock = dialect_.db_now_ms != nullptr && !clock_injected();
  const std::string sql = std::string("WITH t AS (SELECT COALESCE(CAST($1 AS BIGINT), ") +
                          (dialect_.db_now_ms != nullptr ? dialect_.db_now_ms : "NULL") +
                          ") AS now) SELECT CASE WHEN EXISTS (SELECT 1 FROM jobs WHERE "
                          "status = 'queued' AND not_before <= (SELECT now FROM t)) "
                          "OR EXISTS (SELECT 1 FROM jobs WHERE status = 'running' AND "
                          "lease_expires_at <= (SELECT now FROM t)) THEN 1 ELSE 0 END";
  return Read([&](SqlConn* c) {
    *any = false;
    return c->Run(sql, {db_clock ? SqlValue() : SqlInt(Now())},
                  [&](const internal::Row& row) { *any = row.Int(0) != 0; });
  });
}

Status SqlStore::ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                          bool* claimed) {
  *claimed = false;
  Status valid = internal::ValidateClaim(worker_id, lease_ms);
  if (!valid.ok()) return valid;
  bool any = false;
  Status s = AnyClaimable(&any);  // without the write lock: idle workers do not serialise on it
  if (!s.ok() || !any) return s;
  JobInfo job;
  bool got = false;
  s = Write([&](SqlConn* c) {
    got = false;
    int64_t now = 0;
    Status s = TxnNow(c, &now);
    if (!s.ok()) return s;
    s = RecoverLocked(c, now, nullptr);
    if (!s.ok()) return s;
    // The oldest claimable job nobody else is claiming right now (skip_locked: claimers on
    // every host proceed in parallel, each with a different job).
    int64_t id = 0;
    s = c->Run(std::string("UPDATE jobs SET status = 'running', lease_owner = $2, "
                           "lease_expires_at = $3, attempts = attempts + 1, started_at = $1, "
                           "finished_at = NULL WHERE id = (SELECT id FROM jobs WHERE status = "
                           "'queued' AND not_before <= $1 ORDER BY id LIMIT 1") +
                   dialect_.skip_locked + ") RETURNING id",
               {SqlInt(now), SqlText(worker_id), SqlInt(now + lease_ms)},
               [&](const internal::Row& row) { id = row.Int(0); });
    if (!s.ok() || id == 0) return s;
    s = LoadJob(c, id, false, &job);
    got = s.ok();
    return s;
  });
  if (!s.ok()) return s;
  if (got) {
    *claimed = true;
    if (out != nullptr) *out = std::move(job);
  }
  return Status::Ok();
}

Status SqlStore::RequireHolder(SqlConn* c, int64_t job_id, const std::string& worker_id,
                               const char* action, JobInfo* job) {
  Status s = LoadJob(c, job_id, false, job, /*lock=*/true);
  if (!s.ok()) return s;
  return internal::CheckHolder(*job, worker_id, action);
}

Status SqlStore::RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) {
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Write([&](SqlConn* c) {
    int64_t now = 0;
    Status s = TxnNow(c, &now);
    if (!s.ok()) return s;
    int64_t changed = 0;
    s = c->Run(
        "UPDATE jobs SET lease_expires_at = $3 "
        "WHERE id = $1 AND status = 'running' AND lease_owner = $2",
        {SqlInt(job_id), SqlText(worker_id), SqlInt(now + lease_ms)}, {}, &changed);
    if (!s.ok()) return s;
    if (changed == 1) return Status::Ok();
    JobInfo job;
    s = RequireHolder(c, job_id, worker_id, "renew the lease of", &job);
    if (!s.ok()) return s;
    return Status::Conflict("cannot renew the lease of job " + std::to_string(job_id));
  });
}

Status SqlStore::StoreResult(SqlConn* c, const JobInfo& job, const std::string& result_json,
                             const std::string& sha) {
  int64_t now = 0;
  Status s = TxnNow(c, &now);
  if (!s.ok()) return s;
  // The gate's verdict, read from the result (anything but "rejected" counts as accepted), and
  // the result's place in the order of storing (seq: "latest" never compares host clocks).
  s = c->Run(std::string("INSERT INTO results (job_id, result_json, sha256, created_at, verdict") +
                 dialect_.result_seq_column + ") VALUES ($1, $2, $3, $4, $5" +
                 dialect_.result_seq_value + ")",
             {SqlInt(job.id), SqlText(result_json), SqlText(sha), SqlInt(now),
              SqlText(Name(internal::VerdictOf(result_json)))});
  if (!s.ok()) return s;
  s = c->Run(
      "UPDATE jobs SET status = 'succeeded', finished_at = $2, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = NULL, error_message = NULL, error_reason = NULL, "
      "error_detail_json = NULL WHERE id = $1",
      {SqlInt(job.id), SqlInt(now)});
  if (!s.ok() || job.device.empty()) return s;
  s = RememberDevice(c, job.device, now);
  if (!s.ok()) return s;
  return RefreshLatest(c, job.device, job.method);
}

Status SqlStore::CompleteJob(int64_t job_id, const std::string& worker_id,
                             const std::string& result_json) {
  if (result_json.empty()) return Status::InvalidInput("storage: empty result");
  const std::string sha = Sha256Hex(result_json);
  std::string cancelled;  // set when the job was cancelled while it ran: failed, not completed
  Status written = Write([&](SqlConn* c) {
    cancelled.clear();
    JobInfo job;
    // The row lock serialises every transition of this job across hosts.
    Status s = LoadJob(c, job_id, false, &job, /*lock=*/true);
    if (!s.ok()) return s;
    bool done = false;
    s = internal::CheckCompletion(job, worker_id, sha, &done);
    if (!s.ok() || done) return s;
    if (job.cancel_requested_at_ms != 0) {
      // A cancel answered "stopping it" wins over a run that finished meanwhile: the job ends
      // as cancelled (committed here), and the caller hears kConflict below.
      cancelled = internal::CancelledMessage(job.cancel_actor, job.cancel_reason);
      return FailCancelledLocked(c, job_id, cancelled);
    }
    return StoreResult(c, job, result_json, sha);
  });
  if (written.ok() && !cancelled.empty()) {
    return Status::Conflict("job " + std::to_string(job_id) + " was " + cancelled +
                            ": its result is not stored");
  }
  return written;
}

Status SqlStore::FailCancelledLocked(SqlConn* c, int64_t job_id, const std::string& message) {
  int64_t now = 0;
  Status s = TxnNow(c, &now);
  if (!s.ok()) return s;
  return c->Run(
      "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = $3, error_reason = $4, error_message = $5, "
      "error_detail_json = NULL WHERE id = $1",
      {SqlInt(job_id), SqlInt(now), SqlText(internal::kCancelledCode),
       SqlText(internal::kCancelledReason), SqlText(message)});
}

Status SqlStore::FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                         bool transient) {
  return Write([&](SqlConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "fail", &job);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = TxnNow(c, &now);
    if (!s.ok()) return s;
    const std::string error_code = failure.code.empty() ? std::string("error") : failure.code;
    // A cancelled job is never queued again, even after a transient failure.
    const bool retry =
        transient && job.attempts < options_.max_attempts && job.cancel_requested_at_ms == 0;
    std::string message = failure.message;
    if (transient && !retry) {
      message = "gave up after " + std::to_string(job.attempts) + " attempts: " + failure.message;
    }
    // Retried: queued again, not claimable before the back-off ends. Else failed for good.
    return c->Run(
        retry ? "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
                "started_at = NULL, not_before = $2, error_code = $3, error_message = $4, "
                "error_reason = $5, error_detail_json = $6 WHERE id = $1"
              : "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
                "lease_expires_at = NULL, error_code = $3, error_message = $4, error_reason = $5, "
                "error_detail_json = $6 WHERE id = $1",
        {SqlInt(job_id), SqlInt(retry ? now + Backoff(options_, job.attempts) : now),
         SqlText(error_code), SqlText(message), SqlTextOrNull(failure.reason),
         SqlTextOrNull(failure.detail_json)});
  });
}

Status SqlStore::ReleaseJob(int64_t job_id, const std::string& worker_id, ReleaseKind kind) {
  return Write([&](SqlConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "release", &job);
    if (!s.ok()) return s;
    if (job.cancel_requested_at_ms != 0) {  // cancelled while running: it ends here
      return FailCancelledLocked(c, job_id,
                                 internal::CancelledMessage(job.cancel_actor, job.cancel_reason));
    }
    int64_t now = 0;
    s = TxnNow(c, &now);
    if (!s.ok()) return s;
    // Shutdown: the run does not count, claimable at once. After a store failure: it counts
    // and backs off (the row changes in place: no new text, so it fits on a full disk).
    const bool shutdown = kind == ReleaseKind::kShutdown;
    s = c->Run(
        "UPDATE jobs SET status = 'queued', attempts = $3, lease_owner = NULL, "
        "lease_expires_at = NULL, started_at = NULL, not_before = $2 WHERE id = $1",
        {SqlInt(job_id), SqlInt(shutdown ? now : now + Backoff(options_, job.attempts)),
         SqlInt(shutdown ? std::max<int64_t>(job.attempts - 1, 0) : job.attempts)});
    if (!s.ok()) return s;
    c->NotifyJobsAfterCommit();
    return Status::Ok();
  });
}

Status SqlStore::CancelRequests(const std::vector<int64_t>& job_ids,
                                std::vector<int64_t>* requested) {
  requested->clear();
  if (job_ids.empty()) return Status::Ok();
  // One placeholder per id: the text differs only by their number (bounded by the jobs one
  // process runs at once), so the statement caches stay small.
  std::string list;
  SqlParams params;
  for (int64_t id : job_ids) {
    params.push_back(SqlInt(id));
    list += (list.empty() ? "$" : ", $") + std::to_string(params.size());
  }
  std::vector<int64_t> ids;
  Status s = Read([&](SqlConn* c) {
    ids.clear();
    return c->Run("SELECT id FROM jobs WHERE id IN (" + list +
                      ") AND status = 'running' AND cancel_requested_at IS NOT NULL ORDER BY id",
                  params, [&](const internal::Row& row) { ids.push_back(row.Int(0)); });
  });
  if (!s.ok()) return s;
  *requested = std::move(ids);
  return Status::Ok();
}

Status SqlStore::InsertJobEvent(SqlConn* c, int64_t job_id, const char* action,
                                const std::string& reason, const std::string& actor, int64_t now,
                                int64_t* id) {
  return c->Run(
      "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
      "VALUES ($1, $2, $3, $4, $5) RETURNING id",
      {SqlInt(job_id), SqlText(action), SqlText(reason), SqlText(actor), SqlInt(now)},
      [&](const internal::Row& row) { *id = row.Int(0); });
}

Status SqlStore::Cancel(int64_t job_id, const std::string& reason, const std::string& actor,
                        JobInfo* out, JobEvent* event) {
  JobInfo job;
  JobEvent cancel_event;
  Status s = Write([&](SqlConn* c) {
    Status s = LoadJob(c, job_id, false, &job, /*lock=*/true);
    if (!s.ok()) return s;
    s = internal::CheckCancel(job);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = TxnNow(c, &now);
    if (!s.ok()) return s;
    if (job.status == JobStatus::kQueued) {
      s = c->Run(
          "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
          "lease_expires_at = NULL, error_code = $3, error_reason = $4, error_message = $5, "
          "error_detail_json = NULL, cancel_requested_at = $2, cancel_reason = $6, "
          "cancel_actor = $7 WHERE id = $1",
          {SqlInt(job_id), SqlInt(now), SqlText(internal::kCancelledCode),
           SqlText(internal::kCancelledReason), SqlText(internal::CancelledMessage(actor, reason)),
           SqlText(reason), SqlText(actor)});
    } else {  // running: the first request's words are kept
      s = c->Run(
          "UPDATE jobs SET cancel_requested_at = COALESCE(cancel_requested_at, $2), "
          "cancel_reason = COALESCE(cancel_reason, $3), "
          "cancel_actor = COALESCE(cancel_actor, $4) WHERE id = $1",
          {SqlInt(job_id), SqlInt(now), SqlText(reason), SqlText(actor)});
    }
    if (!s.ok()) return s;
    int64_t event_id = 0;
    s = InsertJobEvent(c, job_id, "cancel", reason, actor, now, &event_id);
    if (!s.ok()) return s;
    cancel_event = internal::MakeCancelEvent(event_id, job_id, reason, actor, now);
    return LoadJob(c, job_id, false, &job);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  if (event != nullptr) *event = std::move(cancel_event);
  return Status::Ok();
}

}  // namespace calibd::storage
