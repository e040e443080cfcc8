// SqliteStore's catalog: jobs and their results listed and counted, devices and their latest
// calibrations, the acceptance gate's decisions, maintenance (integrity check, checkpoint).
#include <sqlite3.h>

#include <utility>
#include <vector>

#include "storage/sqlite_store_internal.h"

namespace calibd::storage {

namespace sqlite {

Status RememberDevice(Db* db, const std::string& serial, int64_t now) {
  if (serial.empty()) return Status::Ok();
  Stmt st;
  Status s = db->Prepare("INSERT OR IGNORE INTO devices (serial, first_seen) VALUES (?1, ?2)", &st);
  if (!s.ok()) return s;
  st.BindText(1, serial).BindInt(2, now);
  return st.Run();
}

Status RefreshLatest(Db* db, const std::string& device, const std::string& method) {
  Stmt st;
  Status s = db->Prepare("DELETE FROM device_calibrations WHERE device = ?1 AND method = ?2", &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  s = st.Run();
  if (!s.ok()) return s;
  s = db->Prepare(
      "INSERT INTO device_calibrations (device, method, job_id, calibrated_at) "
      "SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) "
      "FROM jobs j JOIN results r ON r.job_id = j.id "
      "WHERE j.device = ?1 AND j.method = ?2 AND j.status = 'succeeded' "
      "AND COALESCE(r.decision, r.verdict) = 'accepted' "
      "ORDER BY r.seq DESC, j.id DESC LIMIT 1",
      &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  return st.Run();
}

}  // namespace sqlite

using sqlite::RefreshLatest;

Status SqliteStore::GetJob(int64_t id, JobInfo* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  return LoadJob(conn.db(), id, true, out);
}

namespace {

// A verdict filter without a device reads the matching results from index results_by_state,
// newest first, and their jobs (CROSS JOIN fixes that order: SQLite, without statistics, would
// otherwise scan every succeeded job for a rare verdict such as revoked). With a device, the
// device's jobs (jobs_by_device) are fewer.
bool ByState(const JobFilter& f) { return f.state.has_value() && f.device.empty(); }

std::string FromSql(const JobFilter& f, bool with_results) {
  std::string select = internal::JobSelect(with_results);
  if (!ByState(f)) return select;
  const std::string from = internal::kJobFrom;
  return select.replace(select.rfind(from), from.size(),
                        " FROM results r CROSS JOIN jobs j ON j.id = r.job_id ");
}

// WHERE clause from constant fragments; the values are bound by BindFilter in the same order.
std::string FilterSql(const JobFilter& f, bool with_cursor) {
  std::string where = "WHERE 1 ";
  int n = 0;
  if (!f.device.empty()) where += "AND j.device = ?" + std::to_string(++n) + " ";
  if (!f.method.empty()) where += "AND j.method = ?" + std::to_string(++n) + " ";
  if (f.status) where += "AND j.status = ?" + std::to_string(++n) + " ";
  if (f.state) {
    where += "AND j.status = 'succeeded' AND COALESCE(r.decision, r.verdict) = ?" +
             std::to_string(++n) + " ";
  }
  if (with_cursor && f.before > 0) {
    where +=
        std::string(ByState(f) ? "AND r.job_id < ?" : "AND j.id < ?") + std::to_string(++n) + " ";
  }
  return where;
}

int BindFilter(Stmt* st, const JobFilter& f, bool with_cursor) {
  int n = 0;
  if (!f.device.empty()) st->BindText(++n, f.device);
  if (!f.method.empty()) st->BindText(++n, f.method);
  if (f.status) st->BindText(++n, Name(*f.status));
  if (f.state) st->BindText(++n, Name(*f.state));
  if (with_cursor && f.before > 0) st->BindInt(++n, f.before);
  return n;
}

}  // namespace

std::string sqlite::ListJobsSql(const JobFilter& filter) {
  const int limit_param = 1 + (!filter.device.empty()) + (!filter.method.empty()) +
                          filter.status.has_value() + filter.state.has_value() +
                          (filter.before > 0);
  return FromSql(filter, filter.include_results) + FilterSql(filter, true) +
         (ByState(filter) ? "ORDER BY r.job_id DESC LIMIT ?" : "ORDER BY j.id DESC LIMIT ?") +
         std::to_string(limit_param);
}

std::string sqlite::CountJobsSql(const JobFilter& filter) {
  return std::string(ByState(filter) ? "SELECT COUNT(*) FROM results r CROSS JOIN jobs j ON j.id = "
                                       "r.job_id "
                                     : "SELECT COUNT(*) FROM jobs j LEFT JOIN results r ON "
                                       "r.job_id = j.id ") +
         FilterSql(filter, false);
}

Status SqliteStore::ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) {
  out->clear();
  const int limit = internal::PageLimit(filter);
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(sqlite::ListJobsSql(filter), &st);
  if (!s.ok()) return s;
  int n = BindFilter(&st, filter, true);
  st.BindInt(n + 1, limit);
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    JobInfo job;
    internal::ReadJob(sqlite::StmtRow(st), &job);
    out->push_back(std::move(job));
  }
  return Status::Ok();
}

Status SqliteStore::CountJobs(const JobFilter& filter, int64_t* count) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(sqlite::CountJobsSql(filter), &st);
  if (!s.ok()) return s;
  BindFilter(&st, filter, false);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  *count = row ? st.ColumnInt(0) : 0;
  return Status::Ok();
}

Status SqliteStore::ListDevices(const DeviceFilter& filter, std::vector<DeviceInfo>* out) {
  out->clear();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  // The page of devices first (a range scan of the serial's primary key: BINARY = byte order),
  // then their calibrations.
  // Two texts (> or >=), each a range over the index.
  s = conn.db()->Prepare(filter.from
                             ? "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
                               "FROM (SELECT serial, first_seen FROM devices WHERE serial >= ?1 "
                               "AND (?2 = '' OR serial = ?2) ORDER BY serial LIMIT ?3) d "
                               "LEFT JOIN device_calibrations c ON c.device = d.serial "
                               "ORDER BY d.serial, c.method"
                             : "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
                               "FROM (SELECT serial, first_seen FROM devices WHERE serial > ?1 "
                               "AND (?2 = '' OR serial = ?2) ORDER BY serial LIMIT ?3) d "
                               "LEFT JOIN device_calibrations c ON c.device = d.serial "
                               "ORDER BY d.serial, c.method",
                         &st);
  if (!s.ok()) return s;
  st.BindText(1, filter.after).BindText(2, filter.serial).BindInt(3, internal::PageLimit(filter));
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    internal::AddDeviceRow(sqlite::StmtRow(st), out);
  }
  return Status::Ok();
}

Status SqliteStore::LatestResult(const std::string& device, const std::string& method,
                                 JobInfo* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      internal::JobSelect(true) +
          "WHERE j.id = (SELECT job_id FROM device_calibrations WHERE device = ?1 AND method = ?2)",
      &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) {
    return Status::NotFound("no succeeded " + method + " calibration for device " + device);
  }
  internal::ReadJob(sqlite::StmtRow(st), out);
  return Status::Ok();
}

Status SqliteStore::QueueDepth(QueueCounts* out) {
  *out = QueueCounts();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare("SELECT status, COUNT(*) FROM jobs GROUP BY status", &st);
  if (!s.ok()) return s;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    internal::AddQueueCount(sqlite::StmtRow(st), out);
  }
  return Status::Ok();
}

// ---- the acceptance gate's decisions ------------------------------------------------------------

Status SqliteStore::Decide(int64_t job_id, bool revoke, const std::string& reason,
                           const std::string& actor, JobEvent* out) {
  JobEvent event;
  Status s = Write([&](Db* db) {
    JobInfo job;
    Status s = LoadJob(db, job_id, false, &job);
    if (!s.ok()) return s;
    s = internal::CheckDecision(job, revoke);
    if (!s.ok()) return s;
    const int64_t now = Now();
    Stmt st;
    s = db->Prepare("UPDATE results SET decision = ?2 WHERE job_id = ?1", &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, internal::DecisionValue(revoke));
    s = st.Run();
    if (!s.ok()) return s;
    s = db->Prepare(
        "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
        "VALUES (?1, ?2, ?3, ?4, ?5)",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id)
        .BindText(2, internal::DecisionAction(revoke))
        .BindText(3, reason)
        .BindText(4, actor)
        .BindInt(5, now);
    s = st.Run();
    if (!s.ok()) return s;
    event = internal::MakeDecisionEvent(db->LastInsertRowid(), job_id, revoke, reason, actor, now);
    if (!job.device.empty()) return RefreshLatest(db, job.device, job.method);
    return Status::Ok();
  });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status SqliteStore::ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  JobInfo job;
  s = LoadJob(conn.db(), job_id, false, &job);
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      "SELECT id, job_id, action, reason, actor, created_at FROM job_events WHERE job_id = ?1 "
      "ORDER BY id",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, job_id);
  std::vector<JobEvent> events;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    JobEvent e;
    internal::ReadJobEvent(sqlite::StmtRow(st), &e);
    events.push_back(std::move(e));
  }
  *out = std::move(events);
  return Status::Ok();
}

Status SqliteStore::IntegrityCheck(std::string* result) {
  result->clear();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->PrepareUncached("PRAGMA integrity_check", &st);
  if (!s.ok()) return s;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    if (!result->empty()) *result += "\n";
    *result += st.ColumnText(0);
  }
  return Status::Ok();
}

Status SqliteStore::QuickCheck(std::string* result) {
  // A connection of its own, not a pooled one: a pooled connection's page cache may still hold
  // pages as they were before the file was damaged (nothing written since tells it otherwise).
  std::unique_ptr<Db> db;
  Status s = Db::Open(path_, db_options_, &db);
  if (s.code() == StatusCode::kCorruption) {
    *result = s.message();
    return Status::Ok();
  }
  if (!s.ok()) return s;
  Stmt st;
  s = db->PrepareUncached("PRAGMA quick_check(20)", &st);
  std::string report;
  for (bool row = s.ok(); row;) {
    s = st.Step(&row);
    if (!s.ok() || !row) break;
    if (!report.empty()) report += "\n";
    report += st.ColumnText(0);
  }
  if (s.code() == StatusCode::kCorruption) {
    report = s.message();  // too damaged to check
  } else if (!s.ok()) {
    return s;
  }
  *result = report.empty() ? "ok" : report;
  return Status::Ok();
}

Status SqliteStore::Checkpoint() {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  int busy = 0, log = 0, done = 0;
  int rc = sqlite3_wal_checkpoint_v2(conn.db()->handle(), nullptr, SQLITE_CHECKPOINT_TRUNCATE, &log,
                                     &done);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, conn.db()->handle(), "checkpoint");
  (void)busy;
  return Status::Ok();
}

}  // namespace calibd::storage
