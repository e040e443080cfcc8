// SqlStore's catalog: recordings' metadata and the device an upload's job is for, jobs and their
// results listed and counted, devices and their latest calibrations, the acceptance gate's
// decisions and the job events.
#include <string>
#include <utility>
#include <vector>

#include "storage/sha256.h"
#include "storage/sql_store.h"

namespace calibd::storage {

SqlValue SqlInt(int64_t v) {
  SqlValue p;
  p.kind = SqlValue::Kind::kInt;
  p.integer = v;
  return p;
}

SqlValue SqlText(std::string_view v) {
  SqlValue p;
  p.kind = SqlValue::Kind::kText;
  p.text = std::string(v);
  return p;
}

SqlValue SqlTextOrNull(std::string_view v) { return v.empty() ? SqlValue() : SqlText(v); }

using sql::LoadRecording;

SqlStore::SqlStore(std::string path, StoreOptions options, const SqlDialect& dialect)
    : Store(std::move(path), std::move(options)), dialect_(dialect) {}

Status SqlStore::TxnNow(SqlConn* c, int64_t* now) {
  if (dialect_.db_now_ms == nullptr || clock_injected()) {
    *now = Now();
    return Status::Ok();
  }
  return c->Run(std::string("SELECT ") + dialect_.db_now_ms, {},
                [&](const internal::Row& row) { *now = row.Int(0); });
}

Status SqlStore::Ping() {
  return Read([&](SqlConn* c) { return c->Run(dialect_.ping, {}); });
}

// ---- recordings ---------------------------------------------------------------------------------

Status sql::LoadRecording(SqlConn* c, int64_t id, RecordingInfo* out) {
  bool found = false;
  Status s = c->Run(
      "SELECT id, sha256, bytes, rows, layout, device, file_name, created_at, columns_json, "
      "sensors_json, log_json FROM recordings WHERE id = $1",
      {SqlInt(id)}, [&](const internal::Row& row) {
        internal::ReadRecording(row, out);
        found = true;
      });
  if (!s.ok()) return s;
  if (!found) return Status::NotFound("recording " + std::to_string(id) + " not found");
  return Status::Ok();
}

Status sql::FindRecording(SqlConn* c, const std::string& sha, int64_t* id) {
  *id = 0;
  return c->Run("SELECT id FROM recordings WHERE sha256 = $1", {SqlText(sha)},
                [&](const internal::Row& row) { *id = row.Int(0); });
}

Status sql::InsertRecording(SqlConn* c, const NewRecording& r, const std::string& sha,
                            int64_t bytes, int64_t now, int64_t* id) {
  // A concurrent identical upload (another host) holds the key until it commits; then DO NOTHING
  // returns no row (*id = 0) and the caller finds its row instead.
  *id = 0;
  return c->Run(
      "INSERT INTO recordings (sha256, bytes, device, layout, rows, columns_json, sensors_json, "
      "file_name, created_at, log_json) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10) "
      "ON CONFLICT (sha256) DO NOTHING RETURNING id",
      {SqlText(sha), SqlInt(bytes), SqlText(r.device), SqlText(r.layout), SqlInt(r.rows),
       SqlText(r.columns_json.empty() ? "[]" : r.columns_json),
       SqlText(r.sensors_json.empty() ? "[]" : r.sensors_json), SqlText(r.file_name), SqlInt(now),
       SqlText(r.log_json)},
      [&](const internal::Row& row) { *id = row.Int(0); });
}

Status SqlStore::HashUpload(const NewRecording& r, std::string* sha) {
  *sha = r.path.empty() ? Sha256Hex(r.data) : r.sha256;
  return Status::Ok();
}

Status SqlStore::PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) {
  Status s = internal::ValidateNewRecording(r);
  if (!s.ok()) return s;
  std::string sha;
  s = HashUpload(r, &sha);  // on the calling thread, before the transaction
  if (!s.ok()) return s;
  RecordingInfo info;
  bool duplicate = false;
  s = Write([&](SqlConn* c) { return PutRecordingLocked(c, r, sha, &info, &duplicate); });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(info);
  if (existed != nullptr) *existed = duplicate;
  return Status::Ok();
}

Status SqlStore::PutRecordingLocked(SqlConn* c, const NewRecording& r, const std::string& sha,
                                    RecordingInfo* out, bool* existed) {
  int64_t now = 0;
  Status s = TxnNow(c, &now);
  if (!s.ok()) return s;
  int64_t id = 0;
  bool duplicate = false;
  s = StoreRecordingBytes(c, r, sha, now, &id, &duplicate);
  if (!s.ok()) return s;
  s = RememberDevice(c, r.device, now);
  if (!s.ok()) return s;
  RecordingInfo info;
  s = LoadRecording(c, id, &info);
  if (!s.ok()) return s;
  if (r.job) {
    JobInfo job;
    // The job is for the device this upload names, or none: never the device of identical bytes
    // uploaded before (a re-upload must not move a recording's calibrations to its old device).
    const std::string& device = !r.job->device.empty() ? r.job->device : r.device;
    s = EnqueueJobLocked(c, id, r.job->method, device, r.job->config_json, now, &job,
                         /*inherit_device=*/false);
    if (!s.ok()) return s;
    info.job = std::move(job);
  }
  *out = std::move(info);
  *existed = duplicate;
  return Status::Ok();
}

Status SqlStore::GetRecording(int64_t id, RecordingInfo* out) {
  return Read([&](SqlConn* c) { return LoadRecording(c, id, out); });
}

// ---- devices ------------------------------------------------------------------------------------

Status SqlStore::RememberDevice(SqlConn* c, const std::string& serial, int64_t now) {
  if (serial.empty()) return Status::Ok();
  return c->Run(
      "INSERT INTO devices (serial, first_seen) VALUES ($1, $2) ON CONFLICT (serial) DO NOTHING",
      {SqlText(serial), SqlInt(now)});
}

Status SqlStore::RefreshLatest(SqlConn* c, const std::string& device, const std::string& method) {
  const SqlParams key = {SqlText(device), SqlText(method)};
  Status s;
  // Serialised per (device, method) where transactions run side by side (PostgreSQL: concurrent
  // completions on several hosts then each see the other's committed result).
  if (*dialect_.lock_latest != '\0') s = c->Run(dialect_.lock_latest, key);
  if (!s.ok()) return s;
  s = c->Run("DELETE FROM device_calibrations WHERE device = $1 AND method = $2", key);
  if (!s.ok()) return s;
  return c->Run(
      "INSERT INTO device_calibrations (device, method, job_id, calibrated_at) "
      "SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) "
      "FROM jobs j JOIN results r ON r.job_id = j.id "
      "WHERE j.device = $1 AND j.method = $2 AND j.status = 'succeeded' "
      "AND COALESCE(r.decision, r.verdict) = 'accepted' "
      "ORDER BY r.seq DESC, j.id DESC LIMIT 1",
      key);
}

Status SqlStore::ListDevices(const DeviceFilter& filter, std::vector<DeviceInfo>* out) {
  // The page of devices first (a range scan of the serials' index in byte order), then their
  // calibrations. Two texts (> or >=), each a range over the index.
  const std::string bytes = dialect_.byte_order;
  const std::string sql =
      "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
      "FROM (SELECT serial, first_seen FROM devices WHERE serial" +
      bytes + (filter.from ? " >= $1" : " > $1") + " AND ($2 = '' OR serial = $2) ORDER BY serial" +
      bytes +
      " LIMIT $3) d LEFT JOIN device_calibrations c ON c.device = d.serial ORDER BY d.serial" +
      bytes + ", c.method" + bytes;
  return Read([&](SqlConn* c) {
    out->clear();
    return c->Run(
        sql, {SqlText(filter.after), SqlText(filter.serial), SqlInt(internal::PageLimit(filter))},
        [&](const internal::Row& row) { internal::AddDeviceRow(row, out); });
  });
}

// ---- jobs listed ----------------------------------------------------------------------------

Status SqlStore::GetJob(int64_t id, JobInfo* out) {
  return Read([&](SqlConn* c) { return LoadJob(c, id, true, out); });
}

namespace {

// Whether a ServeState filter reads the results first (SqlDialect::state_from).
bool ByState(const SqlDialect& d, const JobFilter& f) {
  return f.state.has_value() && (d.state_from_with_device || f.device.empty());
}

// The FROM clause, the WHERE clause (constant fragments) and its parameters in the same order.
std::string FilterSql(const SqlDialect& d, const JobFilter& f, bool with_cursor,
                      SqlParams* params) {
  std::string sql = ByState(d, f) ? d.state_from : internal::kJobFrom;
  sql += "WHERE TRUE ";
  auto add = [&](const std::string& test, SqlValue value) {
    params->push_back(std::move(value));
    sql += test + std::to_string(params->size()) + " ";
  };
  if (!f.device.empty()) add("AND j.device = $", SqlText(f.device));
  if (!f.method.empty()) add("AND j.method = $", SqlText(f.method));
  if (f.status) add("AND j.status = $", SqlText(Name(*f.status)));
  if (f.state) {
    add("AND j.status = 'succeeded' AND COALESCE(r.decision, r.verdict) = $",
        SqlText(Name(*f.state)));
  }
  if (with_cursor && f.before > 0) {
    add(std::string("AND ") + (ByState(d, f) ? d.state_id_column : "j.id") + " < $",
        SqlInt(f.before));
  }
  return sql;
}

}  // namespace

std::string internal::ListJobsSql(const SqlDialect& dialect, const JobFilter& filter,
                                  SqlParams* params) {
  params->clear();
  std::string sql = internal::JobSelect(filter.include_results);
  sql.erase(sql.rfind(internal::kJobFrom));
  sql += FilterSql(dialect, filter, true, params);
  params->push_back(SqlInt(internal::PageLimit(filter)));
  return sql + "ORDER BY " + (ByState(dialect, filter) ? dialect.state_id_column : "j.id") +
         " DESC LIMIT $" + std::to_string(params->size());
}

std::string internal::CountJobsSql(const SqlDialect& dialect, const JobFilter& filter,
                                   SqlParams* params) {
  params->clear();
  return "SELECT COUNT(*)" + FilterSql(dialect, filter, false, params);
}

Status SqlStore::ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) {
  SqlParams params;
  const std::string sql = internal::ListJobsSql(dialect_, filter, &params);
  return Read([&](SqlConn* c) {
    out->clear();
    return c->Run(sql, params, [&](const internal::Row& row) {
      JobInfo job;
      internal::ReadJob(row, &job);
      out->push_back(std::move(job));
    });
  });
}

Status SqlStore::CountJobs(const JobFilter& filter, int64_t* count) {
  SqlParams params;
  const std::string sql = internal::CountJobsSql(dialect_, filter, &params);
  return Read([&](SqlConn* c) {
    *count = 0;
    return c->Run(sql, params, [&](const internal::Row& row) { *count = row.Int(0); });
  });
}

Status SqlStore::LatestResult(const std::string& device, const std::string& method, JobInfo* out) {
  const std::string sql =
      internal::JobSelect(true) +
      "WHERE j.id = (SELECT job_id FROM device_calibrations WHERE device = $1 AND method = $2)";
  return Read([&](SqlConn* c) {
    bool found = false;
    Status s = c->Run(sql, {SqlText(device), SqlText(method)}, [&](const internal::Row& row) {
      internal::ReadJob(row, out);
      found = true;
    });
    if (!s.ok() || found) return s;
    return Status::NotFound("no succeeded " + method + " calibration for device " + device);
  });
}

Status SqlStore::QueueDepth(QueueCounts* out) {
  return Read([&](SqlConn* c) {
    *out = QueueCounts();
    return c->Run("SELECT status, COUNT(*) FROM jobs GROUP BY status", {},
                  [&](const internal::Row& row) { internal::AddQueueCount(row, out); });
  });
}

// ---- the acceptance gate's decisions ------------------------------------------------------------

Status SqlStore::Decide(int64_t job_id, bool revoke, const std::string& reason,
                        const std::string& actor, JobEvent* out) {
  JobEvent event;
  Status s = Write([&](SqlConn* c) {
    JobInfo job;
    // Lock the job row first, then read the job and its result's decision in a statement of its
    // own: under PostgreSQL's READ COMMITTED a statement reads the snapshot taken when it
    // started, so a decision read by the locking statement itself may predate a concurrent
    // decision that held the lock while this one waited (then every racing revoke succeeded).
    Status s = LoadJob(c, job_id, false, &job, /*lock=*/true);
    if (!s.ok()) return s;
    s = LoadJob(c, job_id, false, &job);
    if (!s.ok()) return s;
    s = internal::CheckDecision(job, revoke);
    if (!s.ok()) return s;
    int64_t now = 0;
    s = TxnNow(c, &now);
    if (!s.ok()) return s;
    s = c->Run("UPDATE results SET decision = $2 WHERE job_id = $1",
               {SqlInt(job_id), SqlText(internal::DecisionValue(revoke))});
    if (!s.ok()) return s;
    int64_t event_id = 0;
    s = InsertJobEvent(c, job_id, internal::DecisionAction(revoke), reason, actor, now, &event_id);
    if (!s.ok()) return s;
    event = internal::MakeDecisionEvent(event_id, job_id, revoke, reason, actor, now);
    if (!job.device.empty()) return RefreshLatest(c, job.device, job.method);
    return Status::Ok();
  });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status SqlStore::ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) {
  std::vector<JobEvent> events;
  Status s = Read([&](SqlConn* c) {
    events.clear();
    JobInfo job;
    Status s = LoadJob(c, job_id, false, &job);
    if (!s.ok()) return s;
    return c->Run(
        "SELECT id, job_id, action, reason, actor, created_at FROM job_events WHERE job_id = $1 "
        "ORDER BY id",
        {SqlInt(job_id)}, [&](const internal::Row& row) {
          JobEvent e;
          internal::ReadJobEvent(row, &e);
          events.push_back(std::move(e));
        });
  });
  if (s.ok()) *out = std::move(events);
  return s;
}

}  // namespace calibd::storage
