// SqlConn and SqlDialect: what SqlStore (sql_store.h) needs of a database, so that the store's
// rules are written once over both backends, as LevelDB's DB sits on Env (not a public interface).
//
//   SqlConn     one connection inside the caller's transaction (or a read): runs one statement
//               with bound parameters and hands its rows over one at a time. SqliteStore adapts
//               a Db (db.h), PgStore a PgConn (pg_conn.h).
//   SqlDialect  the few pieces of statement text in which SQLite and PostgreSQL differ (row
//               locks, the database's clock, byte-order collation, ...), as constant fragments.
//
// Statement text is written once, with PostgreSQL's placeholders $1..$n; the SQLite adapter turns
// them into ?1..?n (the same numbered parameters). Only constant text and these fragments make up
// a statement: values are always bound, never spliced into SQL.
#ifndef CALIBD_STORAGE_SQL_CONN_H_
#define CALIBD_STORAGE_SQL_CONN_H_

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

#include "core/status.h"
#include "storage/store_internal.h"

namespace calibd::storage {

// One bound parameter: NULL, an integer or text (copied: a value outlives no statement).
struct SqlValue {
  enum class Kind { kNull, kInt, kText };
  Kind kind = Kind::kNull;
  int64_t integer = 0;
  std::string text;
};
SqlValue SqlInt(int64_t v);
SqlValue SqlText(std::string_view v);
SqlValue SqlTextOrNull(std::string_view v);  // "" binds NULL
using SqlParams = std::vector<SqlValue>;

// Called once per row of a statement's result; the row is valid only during the call.
using SqlRowFn = std::function<void(const internal::Row& row)>;

// One connection, used by one thread at a time, inside the transaction (or read) its store runs
// the caller's operation in; the store owns it and its lifetime.
class SqlConn {
 public:
  virtual ~SqlConn() = default;
  // Runs one statement (placeholders $1..$n, bound from `params` in order). `on_row` (may be
  // empty) sees each row; *changed (may be null) = rows the statement inserted, updated or
  // deleted. Errors carry the database's text (db.h, pg_conn.h map them to Status codes).
  virtual Status Run(std::string_view sql, const SqlParams& params, const SqlRowFn& on_row = {},
                     int64_t* changed = nullptr) = 0;
  // Jobs became claimable in this transaction: wake listeners once it commits (PostgreSQL's
  // NOTIFY; SQLite has none: idle workers poll).
  virtual void NotifyJobsAfterCommit() {}
};

// The statement fragments in which the dialects differ. Each is "" where a dialect needs none.
struct SqlDialect {
  // A cheap statement that reads the database (Store::Ping).
  const char* ping;
  // Appended to the SELECT of one job that locks its row until the transaction ends
  // (PostgreSQL: " FOR UPDATE OF j"; SQLite's write transaction already excludes other writers).
  const char* lock_job;
  // Appended to a subquery picking rows to change, so that rows another transaction is changing
  // are left to it (PostgreSQL: " FOR UPDATE SKIP LOCKED").
  const char* skip_locked;
  // An SQL expression for the database server's clock in ms since the epoch, or nullptr when the
  // store's own clock (StoreOptions::now_ms) is the time (SQLite: one host).
  const char* db_now_ms;
  // results.seq, the order results were stored in: the column and its value for INSERT INTO
  // results, appended after its other columns and values ("" when the column has a default).
  const char* result_seq_column;
  const char* result_seq_value;
  // A statement of ($1 device, $2 method) that serialises refreshing the device's latest
  // calibration for the method with other transactions ("" when the transaction already is).
  const char* lock_latest;
  // Appended to serials compared and sorted in byte order (SQLite's BINARY is already).
  const char* byte_order;
  // ListJobs/CountJobs with a ServeState filter: the FROM clause joining results first (so that
  // index results_by_state is read), whether it applies with a device filter too (else the
  // device's jobs, fewer, are read from jobs_by_device), and the job id column it orders by.
  const char* state_from;
  bool state_from_with_device;
  const char* state_id_column;
};

namespace internal {

// The statements ListJobs and CountJobs run for `filter` in `dialect`, with their parameters in
// order (tests EXPLAIN them: ?verdict= must read index results_by_state).
std::string ListJobsSql(const SqlDialect& dialect, const JobFilter& filter, SqlParams* params);
std::string CountJobsSql(const SqlDialect& dialect, const JobFilter& filter, SqlParams* params);

}  // namespace internal
}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQL_CONN_H_
