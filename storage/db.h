// Db and Stmt: a thin RAII layer over one sqlite3 connection and its prepared statements.
//
// Every SQLite failure becomes a calibd::Status carrying SQLite's own message and the name of the
// result code, mapped as follows (see StatusFromSqlite):
//   SQLITE_BUSY, SQLITE_LOCKED                         -> kBusy       (transient, retry later)
//   SQLITE_FULL, SQLITE_IOERR*, SQLITE_READONLY*,
//   SQLITE_CANTOPEN, SQLITE_PERM, SQLITE_NOLFS         -> kIoError    (environment: disk,
//   permissions) SQLITE_CORRUPT*, SQLITE_NOTADB                     -> kCorruption (the file is
//   damaged) SQLITE_CONSTRAINT*                                 -> kConflict   (a uniqueness /
//   foreign key rule) SQLITE_TOOBIG                                      -> kTooLarge anything else
//   (SQLITE_ERROR, MISUSE, NOMEM, ...)   -> kInternal   (a bug on our side)
//
// SQLITE_FULL carries Reason::kDiskFull, SQLITE_CORRUPT/NOTADB Reason::kStorageDamaged. Messages
// name what a statement did (DescribeStatement), never its SQL text.
//
// Only prepared statements with bound parameters are used; no SQL text is ever built from user
// input. Statements prepared through Db::Prepare are cached per connection.
//
// Thread-safety: a Db and its Stmts belong to one thread at a time (thread-compatible, not
// thread-safe). Use one Db per thread; Store (store.h) keeps a pool of them. Never use a Db across
// fork(): the child must open its own.
#ifndef CALIBD_STORAGE_DB_H_
#define CALIBD_STORAGE_DB_H_

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <unordered_map>

#include "core/status.h"

struct sqlite3;
struct sqlite3_stmt;

namespace calibd::storage {

// Maps an SQLite result code (primary or extended) to a Status. `db` (may be null) supplies
// sqlite3_errmsg; `context` says what was being done ("claim job", ...). OK for SQLITE_OK/ROW/DONE.
Status StatusFromSqlite(int rc, sqlite3* db, std::string_view context);
// What a statement does, without its SQL text (messages never show SQL, which reaches HTTP
// answers): "writing jobs", "reading recordings", "a transaction", "a database setting".
std::string DescribeStatement(std::string_view sql);

// A prepared statement. Move-only. Parameters are 1-based, columns 0-based.
// A Stmt obtained from Db::Prepare is borrowed from the connection's cache: its destructor
// resets it and clears its bindings, so it can be reused; it must not outlive its Db.
// Bind* never fail immediately: the first binding error is remembered and returned by Step/Run.
class Stmt {
 public:
  Stmt() = default;
  ~Stmt();
  Stmt(Stmt&& other) noexcept;
  Stmt& operator=(Stmt&& other) noexcept;
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;

  bool valid() const { return stmt_ != nullptr; }

  Stmt& BindInt(int index, int64_t value);
  Stmt& BindDouble(int index, double value);
  Stmt& BindText(int index, std::string_view value);  // copied by SQLite (SQLITE_TRANSIENT)
  Stmt& BindBlob(int index, std::string_view value);  // copied by SQLite
  // Binds a blob the caller keeps alive and unchanged until the Stmt is stepped to completion
  // or reset (SQLITE_STATIC: no copy).
  Stmt& BindBlobNoCopy(int index, std::string_view value);
  Stmt& BindZeroBlob(int index, int64_t bytes);  // a blob of `bytes` zeros, not materialised
  Stmt& BindNull(int index);
  // Empty text binds NULL: for optional columns.
  Stmt& BindTextOrNull(int index, std::string_view value);

  // Advances one row: *row = true when a row is available, false when the statement is done.
  Status Step(bool* row);
  // Steps until done (for statements that return no rows, or whose rows are not wanted).
  Status Run();

  int ColumnCount() const;
  bool ColumnIsNull(int col) const;
  int64_t ColumnInt(int col) const;
  double ColumnDouble(int col) const;
  std::string ColumnText(int col) const;  // empty for NULL
  std::string ColumnBlob(int col) const;  // empty for NULL

  // Makes the statement reusable (keeps bindings unless ClearBindings).
  void Reset();
  void ClearBindings();

 private:
  friend class Db;
  Stmt(sqlite3_stmt* stmt, sqlite3* db, bool owned, bool* in_use = nullptr)
      : stmt_(stmt), db_(db), owned_(owned), in_use_(in_use) {}
  void Release();
  Stmt& CheckBind(int rc, int index);

  sqlite3_stmt* stmt_ = nullptr;
  sqlite3* db_ = nullptr;
  bool owned_ = false;
  bool* in_use_ = nullptr;  // the cache entry's flag, cleared on release (borrowed only)
  int bind_rc_ = 0;         // first binding error, SQLITE_OK if none
  int bind_index_ = 0;
};

class Db {
 public:
  struct Options {
    // How long a statement waits for another connection's lock before failing with kBusy.
    int busy_timeout_ms = 5000;
    // Open with SQLITE_OPEN_READONLY: every write fails with kIoError ("readonly database").
    bool read_only = false;
    // Create the file when it does not exist (ignored when read_only).
    bool create = true;
    // When > 0: PRAGMA max_page_count, a hard size limit (writes beyond it fail with kIoError
    // "database or disk is full"). Used to test a full disk; also usable as a quota.
    int64_t max_page_count = 0;
    // Whether to switch the file to WAL (journal_mode is persistent; a read-only open skips it).
    bool wal = true;
  };

  // Opens `path` and applies: journal_mode=WAL, synchronous=FULL, foreign_keys=ON,
  // busy_timeout, journal_size_limit=64 MiB, extended result codes. Does not touch the schema
  // (see schema.h). Fails with kIoError (cannot open), kCorruption (not a database), kBusy.
  static Status Open(const std::string& path, const Options& options, std::unique_ptr<Db>* out);

  ~Db();  // finalizes cached statements and closes the connection (sqlite3_close_v2)
  Db(const Db&) = delete;
  Db& operator=(const Db&) = delete;

  // Runs one or more statements without parameters (DDL, PRAGMA, BEGIN/COMMIT).
  Status Exec(std::string_view sql);

  // Prepares `sql` or takes it from this connection's cache. The returned Stmt is reset and has
  // no bindings. `sql` must be a constant, never built from user input. If a Stmt for the same
  // text is still alive (nested use), a fresh uncached one is returned instead.
  Status Prepare(std::string_view sql, Stmt* out);
  // Prepares an uncached statement (finalized by the Stmt's destructor).
  Status PrepareUncached(std::string_view sql, Stmt* out);

  // Convenience: a single integer from the first row's first column (e.g. PRAGMA user_version).
  Status QueryInt(std::string_view sql, int64_t* out);

  int64_t LastInsertRowid() const;
  int64_t Changes() const;  // rows changed by the last INSERT/UPDATE/DELETE
  bool InTransaction() const;
  sqlite3* handle() const { return db_; }
  const std::string& path() const { return path_; }

 private:
  Db() = default;
  sqlite3* db_ = nullptr;
  std::string path_;
  struct Cached {
    sqlite3_stmt* stmt = nullptr;
    bool in_use = false;
  };
  std::unordered_map<std::string, Cached> cache_;
};

// A transaction scope: Begin, then Commit; the destructor rolls back if not committed.
// kImmediate takes the write lock at once (waiting up to the busy timeout): use it for every
// read-modify-write so that two writers can never deadlock on a lock upgrade.
class Transaction {
 public:
  enum class Mode { kDeferred, kImmediate };
  explicit Transaction(Db* db) : db_(db) {}
  ~Transaction();
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;

  Status Begin(Mode mode = Mode::kImmediate);
  Status Commit();  // on failure the transaction is rolled back
  void Rollback();

 private:
  Db* db_;
  bool open_ = false;
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_DB_H_
