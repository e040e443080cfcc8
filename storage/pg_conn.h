// PgConn and PgResult: a thin RAII layer over one libpq connection, for PgStore (pg_store.h).
//
// Only parameterised statements (PQexecParams) are used; no SQL text is ever built from user
// input. Every failure becomes a calibd::Status carrying the server's message and SQLSTATE:
//   class 08, 57P01-57P03 (connection lost, server shutting down),
//   40001, 40P01, 55P03, 57014 (serialization, deadlock, lock/statement timeout) -> kBusy
//   class 23 (unique, foreign key, check)                                          -> kConflict
//   class 53, 58, 25006 (disk full, out of memory, I/O, read-only transaction)     -> kIoError
//   54000 (program limit exceeded)                                                 -> kTooLarge
//   class 22 (data exception, e.g. invalid UTF-8)                                   ->
//   kInvalidInput XX001, XX002 (data corrupted)                                                  ->
//   kCorruption anything else                                                                  ->
//   kInternal
// A connection that fails (PQstatus CONNECTION_BAD) is marked broken(): drop it.
//
// Thread-compatible: one thread at a time per PgConn.
#ifndef CALIBD_STORAGE_PG_CONN_H_
#define CALIBD_STORAGE_PG_CONN_H_

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/status.h"

struct pg_conn;
struct pg_result;

namespace calibd::storage {

// One statement parameter: text (or NULL), or binary bytes borrowed from the caller.
struct PgParam {
  std::string text;
  std::string_view bytes;  // binary parameter (bytea), borrowed
  bool is_null = false;
  bool is_binary = false;
};
PgParam PgInt(int64_t v);
PgParam PgText(std::string_view v);
PgParam PgTextOrNull(std::string_view v);  // "" binds NULL
PgParam PgBytes(std::string_view v);       // binary; the caller keeps it alive during Exec

class PgResult {
 public:
  PgResult() = default;
  ~PgResult();
  PgResult(PgResult&& o) noexcept;
  PgResult& operator=(PgResult&& o) noexcept;
  PgResult(const PgResult&) = delete;
  PgResult& operator=(const PgResult&) = delete;

  int rows() const;
  bool IsNull(int row, int col) const;
  std::string Text(int row, int col) const;        // "" for NULL
  int64_t Int(int row, int col) const;             // 0 for NULL
  std::string_view Bytes(int row, int col) const;  // valid while the result lives
  int64_t Affected() const;                        // rows changed by INSERT/UPDATE/DELETE

 private:
  friend class PgConn;
  pg_result* res_ = nullptr;
};

class PgConn {
 public:
  // Connects (libpq URI or keyword string; connect_timeout 5 s unless the target sets one).
  // kBusy with libpq's reason when the server cannot be reached.
  static Status Connect(const std::string& target, const std::string& display,
                        std::unique_ptr<PgConn>* out);
  ~PgConn();
  PgConn(const PgConn&) = delete;
  PgConn& operator=(const PgConn&) = delete;

  // Runs one statement. `out` may be null. binary_result: columns in binary (bytea as bytes).
  Status Exec(const char* sql, const std::vector<PgParam>& params = {}, PgResult* out = nullptr,
              bool binary_result = false);
  // Runs statements without parameters (DDL, BEGIN/COMMIT), possibly several at once.
  Status ExecScript(const char* sql);

  bool broken() const;
  // Set by a statement that wants listeners woken once its transaction commits (PgStore sends
  // the NOTIFY after COMMIT: a NOTIFY inside the transaction would hold PostgreSQL's global
  // notify lock across the commit's WAL flush and serialise every enqueue).
  bool notify_after_commit = false;
  bool InTransaction() const;  // inside BEGIN (idle or failed transaction)
  pg_conn* handle() const { return conn_; }

 private:
  PgConn() = default;
  Status StatusFrom(pg_result* res, std::string_view what);
  pg_conn* conn_ = nullptr;
  std::string display_;
  bool broken_ = false;
};

// Brings the PostgreSQL schema up to kPgSchemaVersion (pg_schema.cc): one transaction under
// pg_advisory_xact_lock. read_only: only checks the version (kIoError if a migration is needed).
// kConflict for a database newer than this build.
Status MigratePgSchema(PgConn* conn, const std::string& display, bool read_only);
// The schema version recorded in the database (0: none yet).
Status PgSchemaVersion(PgConn* conn, int64_t* version);

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_PG_CONN_H_
