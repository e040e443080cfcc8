// PgStore's catalog: jobs and their results listed and counted, devices and their latest
// calibrations, the acceptance gate's decisions, maintenance (integrity check).
#include <utility>
#include <vector>

#include "storage/pg_store_internal.h"

namespace calibd::storage {

namespace pg {

Status RememberDevice(PgConn* c, const std::string& serial, int64_t now) {
  if (serial.empty()) return Status::Ok();
  return c->Exec(
      "INSERT INTO devices (serial, first_seen) VALUES ($1, $2) ON CONFLICT (serial) DO NOTHING",
      {PgText(serial), PgInt(now)});
}

// Serialised per (device, method) by an advisory lock, so that concurrent completions on several
// hosts each see the other's committed result (READ COMMITTED: every statement after the lock takes
// a fresh snapshot) and never insert the same key twice.
Status RefreshLatest(PgConn* c, const std::string& device, const std::string& method) {
  Status s = c->Exec("SELECT pg_advisory_xact_lock(hashtextextended($1 || chr(31) || $2, 0))",
                     {PgText(device), PgText(method)});
  if (!s.ok()) return s;
  s = c->Exec("DELETE FROM device_calibrations WHERE device = $1 AND method = $2",
              {PgText(device), PgText(method)});
  if (!s.ok()) return s;
  return c->Exec(
      "INSERT INTO device_calibrations (device, method, job_id, calibrated_at) "
      "SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) "
      "FROM jobs j JOIN results r ON r.job_id = j.id "
      "WHERE j.device = $1 AND j.method = $2 AND j.status = 'succeeded' "
      "AND COALESCE(r.decision, r.verdict) = 'accepted' "
      "ORDER BY r.seq DESC, j.id DESC LIMIT 1",
      {PgText(device), PgText(method)});
}

}  // namespace pg

namespace {

// WHERE clause with $n placeholders; the values in the same order from FilterParams.
std::string FilterSql(const JobFilter& f, bool with_cursor, int* n) {
  std::string where = "WHERE TRUE ";
  if (!f.device.empty()) where += "AND j.device = $" + std::to_string(++*n) + " ";
  if (!f.method.empty()) where += "AND j.method = $" + std::to_string(++*n) + " ";
  if (f.status) where += "AND j.status = $" + std::to_string(++*n) + " ";
  if (f.state) {
    where += "AND j.status = 'succeeded' AND COALESCE(r.decision, r.verdict) = $" +
             std::to_string(++*n) + " ";
  }
  if (with_cursor && f.before > 0) where += "AND j.id < $" + std::to_string(++*n) + " ";
  return where;
}

std::vector<PgParam> FilterParams(const JobFilter& f, bool with_cursor) {
  std::vector<PgParam> p;
  if (!f.device.empty()) p.push_back(PgText(f.device));
  if (!f.method.empty()) p.push_back(PgText(f.method));
  if (f.status) p.push_back(PgText(Name(*f.status)));
  if (f.state) p.push_back(PgText(Name(*f.state)));
  if (with_cursor && f.before > 0) p.push_back(PgInt(f.before));
  return p;
}

}  // namespace

using pg::LoadJob;
using pg::PgRow;
using pg::RefreshLatest;

Status PgStore::GetJob(int64_t id, JobInfo* out) {
  return Read([&](PgConn* c) { return LoadJob(c, id, true, out); });
}

// A verdict filter joins the results (an inner join: jobs without one cannot match), so the
// planner may start from index results_by_state. PostgreSQL keeps a LEFT JOIN whose WHERE tests
// COALESCE(r...) (it cannot tell the test rejects a missing result), and then can only scan the
// jobs: every succeeded job for a rare verdict.
static const char* JobsFrom(const JobFilter& f) {
  return f.state ? " FROM jobs j JOIN results r ON r.job_id = j.id " : internal::kJobFrom;
}

std::string pg::ListJobsSql(const JobFilter& filter, std::vector<PgParam>* params) {
  int n = 0;
  const std::string where = FilterSql(filter, true, &n);
  *params = FilterParams(filter, true);
  params->push_back(PgInt(internal::PageLimit(filter)));
  std::string select = internal::JobSelect(filter.include_results);
  const std::string from = internal::kJobFrom;
  select.replace(select.rfind(from), from.size(), JobsFrom(filter));
  return select + where + "ORDER BY j.id DESC LIMIT $" + std::to_string(n + 1);
}

std::string pg::CountJobsSql(const JobFilter& filter, std::vector<PgParam>* params) {
  int n = 0;
  *params = FilterParams(filter, false);
  return std::string("SELECT COUNT(*)") + JobsFrom(filter) + FilterSql(filter, false, &n);
}

Status PgStore::ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) {
  out->clear();
  std::vector<PgParam> params;
  const std::string sql = pg::ListJobsSql(filter, &params);
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), params, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) {
      JobInfo job;
      internal::ReadJob(PgRow(res, i), &job);
      out->push_back(std::move(job));
    }
    return Status::Ok();
  });
}

Status PgStore::CountJobs(const JobFilter& filter, int64_t* count) {
  std::vector<PgParam> params;
  const std::string sql = pg::CountJobsSql(filter, &params);
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), params, &res);
    if (!s.ok()) return s;
    *count = res.rows() > 0 ? res.Int(0, 0) : 0;
    return Status::Ok();
  });
}

Status PgStore::ListDevices(const DeviceFilter& filter, std::vector<DeviceInfo>* out) {
  out->clear();
  return Read([&](PgConn* c) {
    PgResult res;
    // COLLATE "C": byte order, as SQLite sorts, whatever the database's locale (the page is a
    // range scan of index devices_by_serial_bytes).
    Status s = c->Exec(
        filter.from ? "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
                      "FROM (SELECT serial, first_seen FROM devices "
                      "WHERE serial COLLATE \"C\" >= $1 AND ($2 = '' OR serial = $2) "
                      "ORDER BY serial COLLATE \"C\" LIMIT $3) d "
                      "LEFT JOIN device_calibrations c ON c.device = d.serial "
                      "ORDER BY d.serial COLLATE \"C\", c.method COLLATE \"C\""
                    : "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
                      "FROM (SELECT serial, first_seen FROM devices "
                      "WHERE serial COLLATE \"C\" > $1 AND ($2 = '' OR serial = $2) "
                      "ORDER BY serial COLLATE \"C\" LIMIT $3) d "
                      "LEFT JOIN device_calibrations c ON c.device = d.serial "
                      "ORDER BY d.serial COLLATE \"C\", c.method COLLATE \"C\"",
        {PgText(filter.after), PgText(filter.serial), PgInt(internal::PageLimit(filter))}, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) internal::AddDeviceRow(PgRow(res, i), out);
    return Status::Ok();
  });
}

Status PgStore::LatestResult(const std::string& device, const std::string& method, JobInfo* out) {
  const std::string sql =
      internal::JobSelect(true) +
      "WHERE j.id = (SELECT job_id FROM device_calibrations WHERE device = $1 AND method = $2)";
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), {PgText(device), PgText(method)}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      return Status::NotFound("no succeeded " + method + " calibration for device " + device);
    }
    internal::ReadJob(PgRow(res, 0), out);
    return Status::Ok();
  });
}

Status PgStore::QueueDepth(QueueCounts* out) {
  *out = QueueCounts();
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec("SELECT status, COUNT(*) FROM jobs GROUP BY status", {}, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) internal::AddQueueCount(PgRow(res, i), out);
    return Status::Ok();
  });
}

// ---- the acceptance gate's decisions -----------------------------------------------------------

Status PgStore::Decide(int64_t job_id, bool revoke, const std::string& reason,
                       const std::string& actor, JobEvent* out) {
  JobEvent event;
  Status s = Txn([&](PgConn* c) {
    JobInfo job;
    // Lock the job row first, then read the job and its result's decision in a statement of
    // its own: under READ COMMITTED a statement reads the snapshot taken when it started, so a
    // decision read by the locking statement itself may predate a concurrent decision that held
    // the lock while this one waited (then every racing revoke succeeded; issue 27).
    Status s = LoadJob(c, job_id, false, &job, /*for_update=*/true);
    if (!s.ok()) return s;
    s = LoadJob(c, job_id, false, &job);
    if (!s.ok()) return s;
    s = internal::CheckDecision(job, revoke);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = DbNow(c, &now);
    if (!s.ok()) return s;
    s = c->Exec("UPDATE results SET decision = $2 WHERE job_id = $1",
                {PgInt(job_id), PgText(internal::DecisionValue(revoke))});
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
        "VALUES ($1, $2, $3, $4, $5) RETURNING id",
        {PgInt(job_id), PgText(internal::DecisionAction(revoke)), PgText(reason), PgText(actor),
         PgInt(now)},
        &res);
    if (!s.ok()) return s;
    event = internal::MakeDecisionEvent(res.Int(0, 0), job_id, revoke, reason, actor, now);
    if (!job.device.empty()) return RefreshLatest(c, job.device, job.method);
    return Status::Ok();
  });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status PgStore::ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) {
  return Read([&](PgConn* c) {
    JobInfo job;
    Status s = LoadJob(c, job_id, false, &job);
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "SELECT id, job_id, action, reason, actor, created_at FROM job_events WHERE job_id = $1 "
        "ORDER BY id",
        {PgInt(job_id)}, &res);
    if (!s.ok()) return s;
    std::vector<JobEvent> events;
    for (int i = 0; i < res.rows(); ++i) {
      JobEvent e;
      internal::ReadJobEvent(PgRow(res, i), &e);
      events.push_back(std::move(e));
    }
    *out = std::move(events);
    return Status::Ok();
  });
}

// ---- maintenance -------------------------------------------------------------------------------

Status PgStore::IntegrityCheck(std::string* result) {
  result->clear();
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(
        "SELECT r.id FROM recordings r LEFT JOIN (SELECT recording_id, SUM(length(data)) AS n, "
        "COUNT(*) AS k, MAX(seq) AS last FROM recording_chunks GROUP BY recording_id) c "
        "ON c.recording_id = r.id WHERE r.bytes <> COALESCE(c.n, 0) "
        "OR COALESCE(c.k, 0) <> COALESCE(c.last + 1, 0) ORDER BY r.id LIMIT 100",
        {}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      *result = "ok";
      return Status::Ok();
    }
    *result = "recordings whose stored bytes do not add up to their size:";
    for (int i = 0; i < res.rows(); ++i) *result += " " + res.Text(i, 0);
    return Status::Ok();
  });
}

Status PgStore::Checkpoint() { return Status::Ok(); }

}  // namespace calibd::storage
