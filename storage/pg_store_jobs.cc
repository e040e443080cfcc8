// PgStore's job queue: enqueue, claim (SELECT ... FOR UPDATE SKIP LOCKED, with recovery of
// lapsed leases), lease renewal, complete, fail, release; every transition with the job row
// locked, so that hosts racing on one job are serialised.
#include <utility>

#include "storage/pg_store_internal.h"
#include "storage/sha256.h"

namespace calibd::storage {

namespace pg {

Status LoadJob(PgConn* c, int64_t id, bool with_result, JobInfo* out, bool for_update) {
  const std::string sql =
      internal::JobSelect(with_result) + "WHERE j.id = $1" + (for_update ? " FOR UPDATE OF j" : "");
  PgResult r;
  Status s = c->Exec(sql.c_str(), {PgInt(id)}, &r);
  if (!s.ok()) return s;
  if (r.rows() == 0) return Status::NotFound("job " + std::to_string(id) + " not found");
  internal::ReadJob(PgRow(r, 0), out);
  return Status::Ok();
}

}  // namespace pg

using pg::LoadJob;
using pg::LoadRecording;
using pg::NotifyJobs;
using pg::RefreshLatest;
using pg::RememberDevice;

Status PgStore::EnqueueJobLocked(PgConn* c, int64_t recording_id, const std::string& method,
                                 const std::string& device, const std::string& config_json,
                                 int64_t now, JobInfo* out, bool inherit_device) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  RecordingInfo rec;
  Status s = LoadRecording(c, recording_id, &rec);
  if (!s.ok()) return s;
  const std::string& job_device = device.empty() && inherit_device ? rec.device : device;
  PgResult res;
  s = c->Exec(
      "INSERT INTO jobs (recording_id, method, device, config_json, status, attempts, "
      "created_at, not_before) VALUES ($1, $2, $3, $4, 'queued', 0, $5, $5) RETURNING id",
      {PgInt(recording_id), PgText(method), PgText(job_device),
       PgText(config_json.empty() ? "{}" : config_json), PgInt(now)},
      &res);
  if (!s.ok()) return s;
  const int64_t id = res.Int(0, 0);
  s = RememberDevice(c, job_device, now);
  if (!s.ok()) return s;
  s = NotifyJobs(c);  // sent to listeners once the transaction commits
  if (!s.ok()) return s;
  return LoadJob(c, id, false, out);
}

Status PgStore::EnqueueJob(int64_t recording_id, const std::string& method,
                           const std::string& device, const std::string& config_json,
                           JobInfo* out) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  JobInfo job;
  Status s = Txn([&](PgConn* c) {
    int64_t now = 0;
    Status s = DbNow(c, &now);
    if (!s.ok()) return s;
    return EnqueueJobLocked(c, recording_id, method, device, config_json, now, &job, true);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  return Status::Ok();
}

Status PgStore::RecoverLocked(PgConn* c, int64_t now, int64_t* recovered) {
  int64_t total = 0;
  PgResult res;
  // Cancelled while running: failed as cancelled, never queued again. SKIP LOCKED: a row another
  // transaction is changing (its holder completing it, another host recovering it) is left to
  // that transaction.
  Status s = c->Exec(
      "UPDATE jobs SET status = 'failed', finished_at = $1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = $2, error_reason = $3, error_detail_json = NULL, "
      "error_message = 'cancelled by ' || COALESCE(cancel_actor, '?') || ': ' || "
      "COALESCE(cancel_reason, '') || ' (the lease of ' || COALESCE(lease_owner, '?') || "
      "' lapsed before its run stopped)' "
      "WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at <= $1 "
      "AND cancel_requested_at IS NOT NULL FOR UPDATE SKIP LOCKED)",
      {PgInt(now), PgText(internal::kCancelledCode), PgText(internal::kCancelledReason)}, &res);
  if (!s.ok()) return s;
  total += res.Affected();
  // Out of attempts: failed for good. (Each statement reads its own snapshot: a job cancelled
  // after the first one is left running here, and failed as cancelled by the next recovery.)
  s = c->Exec(
      "UPDATE jobs SET status = 'failed', finished_at = $1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || "
      "' expired on attempt ' || attempts::text || ' of ' || $2::bigint::text || '; giving up' "
      "WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at <= $1 "
      "AND attempts >= $2::bigint AND cancel_requested_at IS NULL FOR UPDATE SKIP LOCKED)",
      {PgInt(now), PgInt(options_.max_attempts)}, &res);
  if (!s.ok()) return s;
  total += res.Affected();
  s = c->Exec(
      "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
      "started_at = NULL, not_before = $1, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || ' expired' "
      "WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at <= $1 "
      "AND cancel_requested_at IS NULL FOR UPDATE SKIP LOCKED)",
      {PgInt(now)}, &res);
  if (!s.ok()) return s;
  const int64_t requeued = res.Affected();
  total += requeued;
  if (requeued > 0) {
    s = NotifyJobs(c);
    if (!s.ok()) return s;
  }
  if (recovered != nullptr) *recovered = total;
  return Status::Ok();
}

Status PgStore::RecoverExpiredLeases(int64_t* recovered) {
  int64_t n = 0;
  Status s = Txn([&](PgConn* c) {
    int64_t now = 0;
    Status s = DbNow(c, &now);
    if (!s.ok()) return s;
    return RecoverLocked(c, now, &n);
  });
  if (!s.ok()) return s;
  if (recovered != nullptr) *recovered = n;
  return Status::Ok();
}

Status PgStore::ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) {
  if (owner_prefix.empty()) return Status::InvalidInput("storage: owner_prefix must not be empty");
  int64_t n = 0;
  Status s = Txn([&](PgConn* c) {
    int64_t now = 0;
    Status s = DbNow(c, &now);
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "UPDATE jobs SET lease_expires_at = $1 WHERE status = 'running' AND "
        "left(lease_owner, length($2)) = $2 AND lease_expires_at > $1",
        {PgInt(now), PgText(owner_prefix)}, &res);
    if (!s.ok()) return s;
    n = res.Affected();
    return n > 0 ? RecoverLocked(c, now, nullptr) : Status::Ok();
  });
  if (!s.ok()) return s;
  if (taken_back != nullptr) *taken_back = n;
  return Status::Ok();
}

Status PgStore::ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                         bool* claimed) {
  *claimed = false;
  Status valid = internal::ValidateClaim(worker_id, lease_ms);
  if (!valid.ok()) return valid;
  {
    // Cheap check without a transaction, so idle workers polling cost one indexed lookup.
    bool any = false;
    Status s = Read([&](PgConn* c) {
      PgResult res;
      // One round trip: the time is the injected clock ($1) or the database's, computed once
      // (a scalar subquery: an index bound, which the volatile clock_timestamp() is not).
      Status s = c->Exec("WITH t AS (SELECT COALESCE($1::bigint, " CALIBD_PG_NOW_MS
                         ") AS now) "
                         "SELECT EXISTS (SELECT 1 FROM jobs WHERE status = 'queued' AND "
                         "not_before <= (SELECT now FROM t)) "
                         "OR EXISTS (SELECT 1 FROM jobs WHERE status = 'running' AND "
                         "lease_expires_at <= (SELECT now FROM t))",
                         {clock_injected() ? PgInt(Now()) : PgTextOrNull("")}, &res);
      if (!s.ok()) return s;
      any = res.Text(0, 0) == "t";
      return Status::Ok();
    });
    if (!s.ok()) return s;
    if (!any) return Status::Ok();
  }
  JobInfo job;
  bool got = false;
  Status s = Txn([&](PgConn* c) {
    got = false;
    int64_t now = 0;
    Status s = DbNow(c, &now);
    if (!s.ok()) return s;
    s = RecoverLocked(c, now, nullptr);
    if (!s.ok()) return s;
    PgResult res;
    // The oldest claimable job nobody else is claiming right now (SKIP LOCKED: claimers on
    // every host proceed in parallel, each with a different job).
    s = c->Exec(
        "UPDATE jobs SET status = 'running', lease_owner = $2, lease_expires_at = $3, "
        "attempts = attempts + 1, started_at = $1, finished_at = NULL "
        "WHERE id = (SELECT id FROM jobs WHERE status = 'queued' AND not_before <= $1 "
        "ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING id",
        {PgInt(now), PgText(worker_id), PgInt(now + lease_ms)}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) return Status::Ok();
    s = LoadJob(c, res.Int(0, 0), false, &job);
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

Status PgStore::RequireHolder(PgConn* c, int64_t job_id, const std::string& worker_id,
                              const char* action, JobInfo* job) {
  Status s = LoadJob(c, job_id, false, job, /*for_update=*/true);
  if (!s.ok()) return s;
  return internal::CheckHolder(*job, worker_id, action);
}

Status PgStore::RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) {
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Txn([&](PgConn* c) {
    int64_t now = 0;
    Status s = DbNow(c, &now);
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "UPDATE jobs SET lease_expires_at = $3 "
        "WHERE id = $1 AND status = 'running' AND lease_owner = $2",
        {PgInt(job_id), PgText(worker_id), PgInt(now + lease_ms)}, &res);
    if (!s.ok()) return s;
    if (res.Affected() == 1) return Status::Ok();
    JobInfo job;
    s = RequireHolder(c, job_id, worker_id, "renew the lease of", &job);
    if (!s.ok()) return s;
    return Status::Conflict("cannot renew the lease of job " + std::to_string(job_id));
  });
}

Status PgStore::CompleteJob(int64_t job_id, const std::string& worker_id,
                            const std::string& result_json) {
  if (result_json.empty()) return Status::InvalidInput("storage: empty result");
  const std::string sha = Sha256Hex(result_json);
  const char* verdict = Name(internal::VerdictOf(result_json));
  std::string cancelled;  // set when the job was cancelled while it ran: failed, not completed
  Status written = Txn([&](PgConn* c) {
    cancelled.clear();
    JobInfo job;
    // The row lock serialises every transition of this job across hosts.
    Status s = LoadJob(c, job_id, false, &job, /*for_update=*/true);
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
    int64_t now = 0;
    s = DbNow(c, &now);
    if (!s.ok()) return s;
    s = c->Exec(
        "INSERT INTO results (job_id, result_json, sha256, created_at, verdict) "
        "VALUES ($1, $2, $3, $4, $5)",
        {PgInt(job_id), PgText(result_json), PgText(sha), PgInt(now), PgText(verdict)});
    if (!s.ok()) return s;
    s = c->Exec(
        "UPDATE jobs SET status = 'succeeded', finished_at = $2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = NULL, error_message = NULL, error_reason = NULL, "
        "error_detail_json = NULL WHERE id = $1",
        {PgInt(job_id), PgInt(now)});
    if (!s.ok()) return s;
    if (!job.device.empty()) {
      s = RememberDevice(c, job.device, now);
      if (!s.ok()) return s;
      s = RefreshLatest(c, job.device, job.method);
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

Status PgStore::FailCancelledLocked(PgConn* c, int64_t job_id, const std::string& message) {
  int64_t now = 0;
  Status s = DbNow(c, &now);
  if (!s.ok()) return s;
  return c->Exec(
      "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = $3, error_reason = $4, error_message = $5, "
      "error_detail_json = NULL WHERE id = $1",
      {PgInt(job_id), PgInt(now), PgText(internal::kCancelledCode),
       PgText(internal::kCancelledReason), PgText(message)});
}

Status PgStore::FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                        bool transient) {
  return Txn([&](PgConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "fail", &job);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = DbNow(c, &now);
    if (!s.ok()) return s;
    const std::string error_code = failure.code.empty() ? std::string("error") : failure.code;
    const PgParam reason = PgTextOrNull(failure.reason);
    const PgParam detail = PgTextOrNull(failure.detail_json);
    // A cancelled job is never queued again, even after a transient failure.
    if (transient && job.attempts < options_.max_attempts && job.cancel_requested_at_ms == 0) {
      return c->Exec(
          "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
          "started_at = NULL, not_before = $2, error_code = $3, error_message = $4, "
          "error_reason = $5, error_detail_json = $6 WHERE id = $1",
          {PgInt(job_id), PgInt(now + internal::Backoff(options_, job.attempts)),
           PgText(error_code), PgText(failure.message), reason, detail});
    }
    std::string final_message = failure.message;
    if (transient) {
      final_message =
          "gave up after " + std::to_string(job.attempts) + " attempts: " + failure.message;
    }
    return c->Exec(
        "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = $3, error_message = $4, error_reason = $5, "
        "error_detail_json = $6 WHERE id = $1",
        {PgInt(job_id), PgInt(now), PgText(error_code), PgText(final_message), reason, detail});
  });
}

Status PgStore::ReleaseJob(int64_t job_id, const std::string& worker_id, ReleaseKind kind) {
  return Txn([&](PgConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "release", &job);
    if (!s.ok()) return s;
    if (job.cancel_requested_at_ms != 0) {  // cancelled while running: it ends here
      return FailCancelledLocked(c, job_id,
                                 internal::CancelledMessage(job.cancel_actor, job.cancel_reason));
    }
    int64_t now = 0;
    s = DbNow(c, &now);
    if (!s.ok()) return s;
    // Shutdown: the run does not count, claimable at once. After a store failure: it counts
    // and backs off.
    const bool shutdown = kind == ReleaseKind::kShutdown;
    s = c->Exec(
        "UPDATE jobs SET status = 'queued', attempts = GREATEST(attempts - $3, 0), "
        "lease_owner = NULL, lease_expires_at = NULL, started_at = NULL, not_before = $2 "
        "WHERE id = $1",
        {PgInt(job_id), PgInt(shutdown ? now : now + internal::Backoff(options_, job.attempts)),
         PgInt(shutdown ? 1 : 0)});
    if (!s.ok()) return s;
    return NotifyJobs(c);
  });
}

Status PgStore::CancelRequests(const std::vector<int64_t>& job_ids,
                               std::vector<int64_t>* requested) {
  requested->clear();
  if (job_ids.empty()) return Status::Ok();
  std::vector<int64_t> ids;
  Status s = Read([&](PgConn* c) {
    ids.clear();
    PgResult res;
    Status s = c->Exec(
        "SELECT id FROM jobs WHERE id = ANY($1::bigint[]) AND status = 'running' "
        "AND cancel_requested_at IS NOT NULL ORDER BY id",
        {PgText("{" + internal::IdList(job_ids) + "}")}, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) ids.push_back(res.Int(i, 0));
    return Status::Ok();
  });
  if (!s.ok()) return s;
  *requested = std::move(ids);
  return Status::Ok();
}

Status PgStore::Cancel(int64_t job_id, const std::string& reason, const std::string& actor,
                       JobInfo* out, JobEvent* event) {
  JobInfo job;
  JobEvent cancel_event;
  Status s = Txn([&](PgConn* c) {
    Status s = LoadJob(c, job_id, false, &job, /*for_update=*/true);
    if (!s.ok()) return s;
    s = internal::CheckCancel(job);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = DbNow(c, &now);
    if (!s.ok()) return s;
    if (job.status == JobStatus::kQueued) {
      s = c->Exec(
          "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
          "lease_expires_at = NULL, error_code = $3, error_reason = $4, error_message = $5, "
          "error_detail_json = NULL, cancel_requested_at = $2, cancel_reason = $6, "
          "cancel_actor = $7 WHERE id = $1",
          {PgInt(job_id), PgInt(now), PgText(internal::kCancelledCode),
           PgText(internal::kCancelledReason), PgText(internal::CancelledMessage(actor, reason)),
           PgText(reason), PgText(actor)});
    } else {  // running: the first request's words are kept
      s = c->Exec(
          "UPDATE jobs SET cancel_requested_at = COALESCE(cancel_requested_at, $2), "
          "cancel_reason = COALESCE(cancel_reason, $3), "
          "cancel_actor = COALESCE(cancel_actor, $4) WHERE id = $1",
          {PgInt(job_id), PgInt(now), PgText(reason), PgText(actor)});
    }
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
        "VALUES ($1, 'cancel', $2, $3, $4) RETURNING id",
        {PgInt(job_id), PgText(reason), PgText(actor), PgInt(now)}, &res);
    if (!s.ok()) return s;
    cancel_event = internal::MakeCancelEvent(res.Int(0, 0), job_id, reason, actor, now);
    return LoadJob(c, job_id, false, &job, /*for_update=*/false);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  if (event != nullptr) *event = std::move(cancel_event);
  return Status::Ok();
}

}  // namespace calibd::storage
