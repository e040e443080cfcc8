// What the files of PgStore share (not a public interface). PgStore is one class in four files
// along its seams, as SqliteStore:
//   pg_store.cc             connections, transactions (Txn, Read), LISTEN/NOTIFY, Ping
//   pg_store_recordings.cc  recordings: storing as chunk rows (deduplicated across hosts), reading
//   pg_store_jobs.cc        the job queue: enqueue, claim, leases, complete, fail, release
//   pg_store_catalog.cc     jobs and results listed, devices, decisions, maintenance
// The rules that do not depend on SQL are in store_internal.h, shared with SqliteStore.
#ifndef CALIBD_STORAGE_PG_STORE_INTERNAL_H_
#define CALIBD_STORAGE_PG_STORE_INTERNAL_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "storage/pg_conn.h"
#include "storage/pg_store.h"
#include "storage/store_internal.h"

// The database server's clock in milliseconds since the Unix epoch, as an SQL expression
// (clock_timestamp(): the time when it is evaluated, not when the transaction began).
#define CALIBD_PG_NOW_MS "floor(extract(epoch FROM clock_timestamp()) * 1000)::bigint"

namespace calibd::storage {

// A pooled connection, returned on destruction.
class PgStore::Lease {
 public:
  explicit Lease(PgStore* store) : store_(store) {}
  ~Lease() {
    if (conn_) store_->Return(std::move(conn_));
  }
  Status Open() { return store_->Acquire(&conn_, &pooled_); }
  PgConn* get() { return conn_.get(); }
  // The connection was idle in the pool (it may have died there: server restarted) and is
  // broken now: the call may run again on a fresh one, once, if nothing of it took effect.
  bool StaleFromPool() const { return pooled_ && conn_ && conn_->broken(); }

 private:
  PgStore* store_;
  std::unique_ptr<PgConn> conn_;
  bool pooled_ = false;
};

namespace pg {

// The current row of a result, for the readers of store_internal.h.
class PgRow final : public internal::Row {
 public:
  PgRow(const PgResult& r, int row) : r_(r), row_(row) {}
  bool IsNull(int col) const override { return r_.IsNull(row_, col); }
  int64_t Int(int col) const override { return r_.Int(row_, col); }
  std::string Text(int col) const override { return r_.Text(row_, col); }

 private:
  const PgResult& r_;
  int row_;
};

// The job (internal::ReadJob); kNotFound. for_update: lock the job row (SELECT ... FOR UPDATE
// OF j) until the transaction ends. (pg_store_jobs.cc)
Status LoadJob(PgConn* c, int64_t id, bool with_result, JobInfo* out, bool for_update = false);
// The recording's metadata (internal::ReadRecording); kNotFound. (pg_store_recordings.cc)
Status LoadRecording(PgConn* c, int64_t id, RecordingInfo* out);
// Adds the serial to devices unless empty or known. (pg_store_catalog.cc)
Status RememberDevice(PgConn* c, const std::string& serial, int64_t now);
// Makes device_calibrations hold the device's latest served result for the method, serialised
// per (device, method) across hosts. (pg_store_catalog.cc)
Status RefreshLatest(PgConn* c, const std::string& device, const std::string& method);
// Listeners are woken after the transaction commits (PgStore::Txn). (pg_store.cc)
Status NotifyJobs(PgConn* c);

// The statements ListJobs and CountJobs run for `filter`, with their parameters in order (a
// test EXPLAINs them: ?verdict= must read index results_by_state). (pg_store_catalog.cc)
std::string ListJobsSql(const JobFilter& filter, std::vector<PgParam>* params);
std::string CountJobsSql(const JobFilter& filter, std::vector<PgParam>* params);

}  // namespace pg
}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_PG_STORE_INTERNAL_H_
