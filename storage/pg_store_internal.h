// What the files of PgStore share (not a public interface). PgStore is SqlStore (sql_store.h: the
// job queue, catalog and decisions, written once for both backends) over libpq, in two files:
//   pg_store.cc             the connection (PgSqlConn, the dialect), pool, transactions (Write,
//                           Read), LISTEN/NOTIFY, maintenance
//   pg_store_recordings.cc  recordings' bytes: stored as chunk rows (deduplicated across hosts),
//                           read back
#ifndef CALIBD_STORAGE_PG_STORE_INTERNAL_H_
#define CALIBD_STORAGE_PG_STORE_INTERNAL_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "storage/pg_conn.h"
#include "storage/pg_store.h"
#include "storage/sql_conn.h"
#include "storage/store_internal.h"

// The database server's clock in milliseconds since the Unix epoch, as an SQL expression
// (clock_timestamp(): the time when it is evaluated, not when the transaction began).
#define CALIBD_PG_NOW_MS "floor(extract(epoch FROM clock_timestamp()) * 1000)::bigint"

namespace calibd::storage {

// A pooled connection, returned on destruction.
class PgStore::Lease : public Borrowed<PgConn> {
 public:
  explicit Lease(PgStore* store) : Borrowed(&store->pool_) {}
  // The connection was idle in the pool (it may have died there: server restarted) and is
  // broken now: the call may run again on a fresh one, once, if nothing of it took effect.
  bool StaleFromPool() const { return pooled() && get() != nullptr && get()->broken(); }
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

// A PgConn as SqlStore's connection (sql_conn.h), inside the caller's transaction.
class PgSqlConn final : public SqlConn {
 public:
  explicit PgSqlConn(PgConn* c) : c_(c) {}
  Status Run(std::string_view sql, const SqlParams& params, const SqlRowFn& on_row = {},
             int64_t* changed = nullptr) override;
  // Listeners are woken after the transaction commits (PgStore::Write).
  void NotifyJobsAfterCommit() override { c_->notify_after_commit = true; }
  PgConn* conn() const { return c_; }

 private:
  PgConn* c_;
};

// PostgreSQL's statement fragments (sql_conn.h).
extern const SqlDialect kDialect;
// The parameters of SqlParams as libpq's.
std::vector<PgParam> PgParams(const SqlParams& params);

// The statements ListJobs and CountJobs run for `filter`, with their parameters in order (a
// test EXPLAINs them: ?verdict= must read index results_by_state).
std::string ListJobsSql(const JobFilter& filter, std::vector<PgParam>* params);
std::string CountJobsSql(const JobFilter& filter, std::vector<PgParam>* params);

}  // namespace pg
}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_PG_STORE_INTERNAL_H_
