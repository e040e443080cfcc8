#include "storage/schema.h"

#include <string>
#include <vector>

#include "storage/sha256.h"

namespace calibd::storage {
namespace {

// Version 1: the first schema. Kept verbatim: never edit a released step, add a new one.
constexpr const char* kV1 = R"sql(
CREATE TABLE recordings (
  id           INTEGER PRIMARY KEY,
  sha256       TEXT    NOT NULL UNIQUE,
  bytes        INTEGER NOT NULL,
  device       TEXT    NOT NULL DEFAULT '',
  layout       TEXT    NOT NULL DEFAULT '',
  rows         INTEGER NOT NULL DEFAULT 0,
  columns_json TEXT    NOT NULL DEFAULT '[]',
  sensors_json TEXT    NOT NULL DEFAULT '[]',
  file_name    TEXT    NOT NULL DEFAULT '',
  created_at   INTEGER NOT NULL
);
CREATE TABLE recording_data (
  recording_id INTEGER PRIMARY KEY REFERENCES recordings(id) ON DELETE CASCADE,
  data         BLOB    NOT NULL
);
CREATE TABLE jobs (
  id               INTEGER PRIMARY KEY,
  recording_id     INTEGER NOT NULL REFERENCES recordings(id),
  method           TEXT    NOT NULL,
  device           TEXT    NOT NULL DEFAULT '',
  config_json      TEXT    NOT NULL DEFAULT '{}',
  status           TEXT    NOT NULL
                   CHECK (status IN ('queued', 'running', 'succeeded', 'failed')),
  attempts         INTEGER NOT NULL DEFAULT 0,
  lease_owner      TEXT,
  lease_expires_at INTEGER,
  created_at       INTEGER NOT NULL,
  started_at       INTEGER,
  finished_at      INTEGER,
  error_code       TEXT,
  error_message    TEXT,
  result_json      TEXT
);
CREATE INDEX jobs_by_status    ON jobs(status, id);
CREATE INDEX jobs_by_device    ON jobs(device, id);
CREATE INDEX jobs_by_recording ON jobs(recording_id);
)sql";

// Version 2: retry back-off, results with their hash, devices and latest calibrations.
constexpr const char* kV2 = R"sql(
ALTER TABLE jobs ADD COLUMN not_before INTEGER NOT NULL DEFAULT 0;
CREATE INDEX jobs_by_lease  ON jobs(lease_expires_at) WHERE status = 'running';
CREATE INDEX jobs_by_method ON jobs(method, id);
CREATE INDEX jobs_by_device_method ON jobs(device, method, id);

CREATE TABLE results (
  job_id     INTEGER PRIMARY KEY REFERENCES jobs(id),
  result_json TEXT   NOT NULL,
  sha256     TEXT    NOT NULL,
  created_at INTEGER NOT NULL
);
INSERT INTO results (job_id, result_json, sha256, created_at)
  SELECT id, result_json, '', COALESCE(finished_at, created_at)
  FROM jobs WHERE status = 'succeeded' AND result_json IS NOT NULL;
ALTER TABLE jobs DROP COLUMN result_json;

CREATE TABLE devices (
  serial     TEXT PRIMARY KEY,
  first_seen INTEGER NOT NULL
) WITHOUT ROWID;
INSERT INTO devices (serial, first_seen)
  SELECT device, MIN(created_at) FROM (
    SELECT device, created_at FROM recordings WHERE device <> ''
    UNION ALL
    SELECT device, created_at FROM jobs WHERE device <> '')
  GROUP BY device;

CREATE TABLE device_calibrations (
  device        TEXT    NOT NULL,
  method        TEXT    NOT NULL,
  job_id        INTEGER NOT NULL REFERENCES jobs(id),
  calibrated_at INTEGER NOT NULL,
  PRIMARY KEY (device, method)
) WITHOUT ROWID;
INSERT INTO device_calibrations (device, method, job_id, calibrated_at)
  SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) FROM jobs j
  WHERE j.status = 'succeeded' AND j.device <> '' AND j.id = (
    SELECT k.id FROM jobs k
    WHERE k.device = j.device AND k.method = j.method AND k.status = 'succeeded'
    ORDER BY COALESCE(k.finished_at, k.created_at) DESC, k.id DESC LIMIT 1);
)sql";

// Version 3: the acceptance gate (issue #11). results.verdict is the gate's verdict of the result
// ("accepted" | "rejected", from the result JSON's verdict.status; results stored before the gate
// have none and count as accepted); results.decision a person's later decision ("revoked" |
// "accepted", NULL: the gate's verdict stands), with every decision kept in job_events. A device's
// latest calibration (device_calibrations) is its latest served result: succeeded, and accepted
// by the gate or by a person, not revoked.
constexpr const char* kV3 = R"sql(
ALTER TABLE results ADD COLUMN verdict TEXT NOT NULL DEFAULT 'accepted'
  CHECK (verdict IN ('accepted', 'rejected'));
ALTER TABLE results ADD COLUMN decision TEXT CHECK (decision IN ('revoked', 'accepted'));
UPDATE results SET verdict = 'rejected'
  WHERE CASE WHEN json_valid(result_json)
             THEN json_extract(result_json, '$.verdict.status') END = 'rejected';

CREATE TABLE job_events (
  id         INTEGER PRIMARY KEY,
  job_id     INTEGER NOT NULL REFERENCES jobs(id),
  action     TEXT    NOT NULL CHECK (action IN ('revoke', 'accept')),
  reason     TEXT    NOT NULL,
  actor      TEXT    NOT NULL,
  created_at INTEGER NOT NULL
);
CREATE INDEX job_events_by_job ON job_events(job_id, id);

DELETE FROM device_calibrations;
INSERT INTO device_calibrations (device, method, job_id, calibrated_at)
  SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) FROM jobs j
  WHERE j.status = 'succeeded' AND j.device <> '' AND j.id = (
    SELECT k.id FROM jobs k JOIN results r ON r.job_id = k.id
    WHERE k.device = j.device AND k.method = j.method AND k.status = 'succeeded'
      AND COALESCE(r.decision, r.verdict) = 'accepted'
    ORDER BY COALESCE(k.finished_at, k.created_at) DESC, k.id DESC LIMIT 1);
)sql";

// Version 4: failure reasons (issue #14). jobs.error_reason is the failure's reason code
// (server/failure_reasons.h, e.g. "too_few_positions"; NULL: none recorded, as for every
// failure before v4) and jobs.error_detail_json the partial diagnostics the method found
// before failing (a JSON object's text, capped by the worker; NULL: none).
constexpr const char* kV4 = R"sql(
ALTER TABLE jobs ADD COLUMN error_reason TEXT;
ALTER TABLE jobs ADD COLUMN error_detail_json TEXT;
)sql";

// Version 5: stopping jobs (issue #20). A cancel request (POST /jobs/{id}/cancel) on a running
// job is kept on the job (cancel_requested_at, cancel_reason, cancel_actor; NULL: none), so the
// process computing it, on any host, sees it and stops; job_events gains the action 'cancel'
// (SQLite cannot change a CHECK: the table is rebuilt with its rows).
constexpr const char* kV5 = R"sql(
ALTER TABLE jobs ADD COLUMN cancel_requested_at INTEGER;
ALTER TABLE jobs ADD COLUMN cancel_reason TEXT;
ALTER TABLE jobs ADD COLUMN cancel_actor TEXT;
CREATE TABLE job_events_v5 (
  id         INTEGER PRIMARY KEY,
  job_id     INTEGER NOT NULL REFERENCES jobs(id),
  action     TEXT    NOT NULL CHECK (action IN ('revoke', 'accept', 'cancel')),
  reason     TEXT    NOT NULL,
  actor      TEXT    NOT NULL,
  created_at INTEGER NOT NULL
);
INSERT INTO job_events_v5 (id, job_id, action, reason, actor, created_at)
  SELECT id, job_id, action, reason, actor, created_at FROM job_events;
DROP TABLE job_events;
ALTER TABLE job_events_v5 RENAME TO job_events;
CREATE INDEX job_events_by_job ON job_events(job_id, id);
)sql";

// Version 6: "latest" without host clocks (issue 27). results.seq numbers the results in the
// order they were stored (one more than the largest, under the write lock), and a device's latest
// served result is the one with the largest seq: a host whose clock is behind no longer keeps a
// newer result from being served. Results already stored are numbered in the order the old rule
// used (finished_at, then id). A unique index keeps MAX(seq) one index lookup.
constexpr const char* kV6 = R"sql(
ALTER TABLE results ADD COLUMN seq INTEGER;
UPDATE results SET seq = o.n FROM (
  SELECT r.job_id AS id,
         row_number() OVER (ORDER BY COALESCE(j.finished_at, j.created_at), j.id) AS n
  FROM results r JOIN jobs j ON j.id = r.job_id) AS o
WHERE results.job_id = o.id;
CREATE UNIQUE INDEX results_by_seq ON results(seq);
)sql";

// Version 7: lists (issue #27). An index of results by their standing (a person's decision, else
// the gate's verdict) so ?verdict= reads only the matching results, newest first.
constexpr const char* kV7 = R"sql(
CREATE INDEX results_by_state ON results(COALESCE(decision, verdict), job_id);
)sql";

// Version 8: sensor logs (issue #24, SPEC §9). What was read from a binary log (format, time base,
// streams, IMUs, warnings: formats/log_assembly.h) as JSON; '' for calibd's CSV.
constexpr const char* kV8 = R"sql(
ALTER TABLE recordings ADD COLUMN log_json TEXT NOT NULL DEFAULT '';
)sql";

// The hashes of results carried over from v1 are computed here (SQLite has no sha256()).
Status HashCarriedOverResults(Db* db) {
  Stmt select;
  Status s =
      db->PrepareUncached("SELECT job_id, result_json FROM results WHERE sha256 = ''", &select);
  if (!s.ok()) return s;
  std::vector<std::pair<int64_t, std::string>> rows;
  for (bool row = true;;) {
    s = select.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    rows.emplace_back(select.ColumnInt(0), select.ColumnText(1));
  }
  Stmt update;
  s = db->PrepareUncached("UPDATE results SET sha256 = ?1 WHERE job_id = ?2", &update);
  if (!s.ok()) return s;
  for (const auto& [id, json] : rows) {
    update.Reset();
    update.BindText(1, Sha256Hex(json)).BindInt(2, id);
    s = update.Run();
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

struct Step {
  const char* sql;
  Status (*after)(Db*);
};

const std::vector<Step>& Steps() {
  static const std::vector<Step>& steps = *new std::vector<Step>{
      {kV1, nullptr}, {kV2, &HashCarriedOverResults},
      {kV3, nullptr}, {kV4, nullptr},
      {kV5, nullptr}, {kV6, nullptr},
      {kV7, nullptr}, {kV8, nullptr},
  };
  return steps;
}

}  // namespace

Status SchemaVersion(Db* db, int64_t* version) {
  return db->QueryInt("PRAGMA user_version", version);
}

Status MigrateSchema(Db* db, int target) {
  if (target < 0 || target > kSchemaVersion) {
    return Status::Internal("storage: no schema version " + std::to_string(target));
  }
  // Fast path without the write lock: already current (the common case, and works read-only).
  int64_t version = 0;
  Status s = SchemaVersion(db, &version);
  if (!s.ok()) return s;
  if (version > kSchemaVersion) {
    return Status::Conflict("storage: " + db->path() + " has schema version " +
                            std::to_string(version) + ", newer than this calibd supports (" +
                            std::to_string(kSchemaVersion) + "); upgrade calibd");
  }
  if (version >= target) return Status::Ok();

  Transaction txn(db);
  s = txn.Begin(Transaction::Mode::kImmediate);
  if (!s.ok()) return s;
  s = SchemaVersion(db, &version);  // again, under the write lock: another process may have won
  if (!s.ok()) return s;
  for (int64_t v = version; v < target; ++v) {
    const Step& step = Steps()[static_cast<size_t>(v)];
    s = db->Exec(step.sql);
    if (!s.ok()) {
      return Status(s.code(), "storage: migrating schema to version " + std::to_string(v + 1) +
                                  ": " + s.message());
    }
    if (step.after != nullptr) {
      s = step.after(db);
      if (!s.ok()) return s;
    }
  }
  if (version < target) {
    s = db->Exec("PRAGMA user_version = " + std::to_string(target));
    if (!s.ok()) return s;
  }
  return txn.Commit();
}

}  // namespace calibd::storage
