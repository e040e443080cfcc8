// What the files of SqliteStore share (not a public interface). SqliteStore is SqlStore
// (sql_store.h: the job queue, catalog and decisions, written once for both backends) over an
// SQLite connection, in two files:
//   sqlite_store.cc             the connection (SqliteConn, the dialect), pool, opening, the
//                               group-commit write queue, maintenance
//   sqlite_store_recordings.cc  recordings' bytes: stored as one blob (streamed), read back
#ifndef CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_
#define CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "storage/db.h"
#include "storage/sql_conn.h"
#include "storage/sqlite_store.h"
#include "storage/store_internal.h"

namespace calibd::storage {

// A pooled connection, returned to the pool on destruction.
class SqliteStore::Conn : public Borrowed<Db> {
 public:
  explicit Conn(SqliteStore* store) : Borrowed(&store->pool_) {}
  Db* db() const { return get(); }
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

// A Db as SqlStore's connection (sql_conn.h), inside the caller's transaction.
class SqliteConn final : public SqlConn {
 public:
  explicit SqliteConn(Db* db) : db_(db) {}
  Status Run(std::string_view sql, const SqlParams& params, const SqlRowFn& on_row = {},
             int64_t* changed = nullptr) override;
  Db* db() const { return db_; }

 private:
  Db* db_;
};

// SQLite's statement fragments (sql_conn.h).
extern const SqlDialect kDialect;
// `sql` with PostgreSQL's placeholders $1..$n written as SQLite's ?1..?n.
std::string SqliteText(std::string_view sql);

// The statements ListJobs and CountJobs prepare for `filter` (a test EXPLAINs them: ?verdict=
// must read index results_by_state).
std::string ListJobsSql(const JobFilter& filter);
std::string CountJobsSql(const JobFilter& filter);

}  // namespace sqlite
}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQLITE_STORE_INTERNAL_H_
