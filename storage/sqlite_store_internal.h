// What the files of SqliteStore share (not a public interface). SqliteStore is one class in four
// files along its seams:
//   sqlite_store.cc             connection pool, opening, the group-commit write queue, Ping
//   sqlite_store_recordings.cc  recordings: storing (streamed, deduplicated), reading
//   sqlite_store_jobs.cc        the job queue: enqueue, claim, leases, complete, fail, release
//   sqlite_store_catalog.cc     jobs and results listed, devices, decisions, maintenance
// The rules that do not depend on SQL are in store_internal.h, shared with PgStore.
#ifndef CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_
#define CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_

#include <cstdint>
#include <memory>
#include <string>

#include "storage/db.h"
#include "storage/sqlite_store.h"
#include "storage/store_internal.h"

namespace calibd::storage {

// A pooled connection, returned to the pool on destruction.
class SqliteStore::Conn {
 public:
  explicit Conn(SqliteStore* store) : store_(store) {}
  ~Conn() {
    if (db_) store_->Return(std::move(db_));
  }
  Status Open() { return store_->Acquire(&db_); }
  Db* db() { return db_.get(); }

 private:
  SqliteStore* store_;
  std::unique_ptr<Db> db_;
};

namespace sqlite {

// The current row of a statement, for the readers of store_internal.h.
class StmtRow final : public internal::Row {
 public:
  explicit StmtRow(const Stmt& st) : st_(st) {}
  bool IsNull(int col) const override { return st_.ColumnIsNull(col); }
  int64_t Int(int col) const override { return st_.ColumnIsNull(col) ? 0 : st_.ColumnInt(col); }
  std::string Text(int col) const override { return st_.ColumnText(col); }

 private:
  const Stmt& st_;
};

// The recording's metadata (internal::ReadRecording). kNotFound. (sqlite_store_recordings.cc)
Status LoadRecording(Db* db, int64_t id, RecordingInfo* out);
// Adds the serial to devices unless empty or known. (sqlite_store_catalog.cc)
Status RememberDevice(Db* db, const std::string& serial, int64_t now);
// Makes device_calibrations hold the device's latest served result for the method (succeeded,
// accepted by the gate or a person, not revoked), or nothing. (sqlite_store_catalog.cc)
Status RefreshLatest(Db* db, const std::string& device, const std::string& method);

// The statements ListJobs and CountJobs prepare for `filter` (a test EXPLAINs them: ?verdict=
// must read index results_by_state). (sqlite_store_catalog.cc)
std::string ListJobsSql(const JobFilter& filter);
std::string CountJobsSql(const JobFilter& filter);

}  // namespace sqlite
}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_
