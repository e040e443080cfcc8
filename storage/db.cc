#include "storage/db.h"

#include <sqlite3.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <thread>
#include <utility>
#include <vector>

namespace calibd::storage {

std::string DescribeStatement(std::string_view sql) {
  // Words of the statement, upper-cased, without its parameters or literals.
  std::vector<std::string> words;
  std::string word;
  for (size_t i = 0; i <= sql.size() && words.size() < 8; ++i) {
    const char c = i < sql.size() ? sql[i] : ' ';
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '_') {
      word += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    } else if (!word.empty()) {
      words.push_back(std::move(word));
      word.clear();
    }
  }
  if (words.empty()) return "a statement";
  auto table_after = [&](const char* keyword) -> std::string {
    for (size_t i = 0; i + 1 < words.size(); ++i) {
      if (words[i] == keyword) {
        std::string t = words[i + 1];
        for (char& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
        return t;
      }
    }
    return "";
  };
  const std::string& verb = words[0];
  std::string table;
  const char* what = "a statement";
  if (verb == "SELECT" || verb == "WITH") {
    what = "reading";
    table = table_after("FROM");
  } else if (verb == "INSERT" || verb == "REPLACE") {
    what = "writing";
    table = table_after("INTO");
  } else if (verb == "UPDATE") {
    what = "writing";
    table = words.size() > 1 ? table_after("UPDATE") : "";
  } else if (verb == "DELETE") {
    what = "deleting from";
    table = table_after("FROM");
  } else if (verb == "BEGIN" || verb == "COMMIT" || verb == "END" || verb == "ROLLBACK" ||
             verb == "SAVEPOINT" || verb == "RELEASE") {
    return "a transaction";
  } else if (verb == "PRAGMA") {
    return "a database setting";
  } else if (verb == "CREATE" || verb == "ALTER" || verb == "DROP") {
    return "the schema";
  }
  if (table.empty()) return what;
  return std::string(what) + " " + table;
}

Status StatusFromSqlite(int rc, sqlite3* db, std::string_view context) {
  if (rc == SQLITE_OK || rc == SQLITE_ROW || rc == SQLITE_DONE) return Status::Ok();
  std::string msg = "storage: ";
  msg.append(context);
  msg += ": ";
  // sqlite3_errmsg describes the most recent failure on the connection; when it does not
  // correspond to `rc` (e.g. a failure reported by sqlite3_blob_*), fall back to errstr.
  const char* detail = nullptr;
  if (db != nullptr && sqlite3_extended_errcode(db) == rc) detail = sqlite3_errmsg(db);
  if (detail == nullptr) detail = sqlite3_errstr(rc);
  msg += detail;
  msg += " (";
  msg += sqlite3_errstr(rc & 0xff);
  msg += ", code ";
  msg += std::to_string(rc);
  msg += ")";
  switch (rc & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return Status::Busy(std::move(msg));
    case SQLITE_FULL:
      return Status::IoError(std::move(msg)).WithReason(Reason::kDiskFull);
    case SQLITE_IOERR:
    case SQLITE_READONLY:
    case SQLITE_CANTOPEN:
    case SQLITE_PERM:
    case SQLITE_NOLFS:
      return Status::IoError(std::move(msg));
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return Status::Corruption(std::move(msg)).WithReason(Reason::kStorageDamaged);
    case SQLITE_CONSTRAINT:
      return Status::Conflict(std::move(msg));
    case SQLITE_TOOBIG:
      return Status(StatusCode::kTooLarge, std::move(msg));
    default:
      return Status::Internal(std::move(msg));
  }
}

// ---- Stmt -------------------------------------------------------------------------------------

Stmt::~Stmt() { Release(); }

Stmt::Stmt(Stmt&& other) noexcept
    : stmt_(std::exchange(other.stmt_, nullptr)),
      db_(other.db_),
      owned_(other.owned_),
      in_use_(std::exchange(other.in_use_, nullptr)),
      bind_rc_(other.bind_rc_),
      bind_index_(other.bind_index_) {}

Stmt& Stmt::operator=(Stmt&& other) noexcept {
  if (this != &other) {
    Release();
    stmt_ = std::exchange(other.stmt_, nullptr);
    db_ = other.db_;
    owned_ = other.owned_;
    in_use_ = std::exchange(other.in_use_, nullptr);
    bind_rc_ = other.bind_rc_;
    bind_index_ = other.bind_index_;
  }
  return *this;
}

void Stmt::Release() {
  if (stmt_ == nullptr) return;
  if (owned_) {
    sqlite3_finalize(stmt_);
  } else {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
    if (in_use_ != nullptr) *in_use_ = false;
  }
  stmt_ = nullptr;
  in_use_ = nullptr;
}

Stmt& Stmt::CheckBind(int rc, int index) {
  if (rc != SQLITE_OK && bind_rc_ == SQLITE_OK) {
    bind_rc_ = rc;
    bind_index_ = index;
  }
  return *this;
}

Stmt& Stmt::BindInt(int index, int64_t value) {
  return CheckBind(sqlite3_bind_int64(stmt_, index, value), index);
}
Stmt& Stmt::BindDouble(int index, double value) {
  return CheckBind(sqlite3_bind_double(stmt_, index, value), index);
}
Stmt& Stmt::BindText(int index, std::string_view value) {
  return CheckBind(
      sqlite3_bind_text64(stmt_, index, value.data(), value.size(), SQLITE_TRANSIENT, SQLITE_UTF8),
      index);
}
Stmt& Stmt::BindTextOrNull(int index, std::string_view value) {
  return value.empty() ? BindNull(index) : BindText(index, value);
}
Stmt& Stmt::BindBlob(int index, std::string_view value) {
  return CheckBind(sqlite3_bind_blob64(stmt_, index, value.data(), value.size(), SQLITE_TRANSIENT),
                   index);
}
Stmt& Stmt::BindBlobNoCopy(int index, std::string_view value) {
  // A zero-length blob with a null pointer would bind NULL; keep it a blob.
  static const char kEmpty = 0;
  const char* data = value.data() != nullptr ? value.data() : &kEmpty;
  return CheckBind(sqlite3_bind_blob64(stmt_, index, data, value.size(), SQLITE_STATIC), index);
}
Stmt& Stmt::BindZeroBlob(int index, int64_t bytes) {
  return CheckBind(sqlite3_bind_zeroblob64(stmt_, index, static_cast<sqlite3_uint64>(bytes)),
                   index);
}
Stmt& Stmt::BindNull(int index) { return CheckBind(sqlite3_bind_null(stmt_, index), index); }

Status Stmt::Step(bool* row) {
  *row = false;
  if (stmt_ == nullptr) return Status::Internal("storage: step on an unprepared statement");
  if (bind_rc_ != SQLITE_OK) {
    return StatusFromSqlite(bind_rc_, nullptr,
                            "binding parameter " + std::to_string(bind_index_) + " for " +
                                DescribeStatement(sqlite3_sql(stmt_)));
  }
  int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) {
    *row = true;
    return Status::Ok();
  }
  if (rc == SQLITE_DONE) return Status::Ok();
  Status s = StatusFromSqlite(rc, db_, DescribeStatement(sqlite3_sql(stmt_)));
  sqlite3_reset(stmt_);
  return s;
}

Status Stmt::Run() {
  bool row = true;
  while (row) {
    Status s = Step(&row);
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

int Stmt::ColumnCount() const { return sqlite3_column_count(stmt_); }
bool Stmt::ColumnIsNull(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
int64_t Stmt::ColumnInt(int col) const { return sqlite3_column_int64(stmt_, col); }
double Stmt::ColumnDouble(int col) const { return sqlite3_column_double(stmt_, col); }
std::string Stmt::ColumnText(int col) const {
  const unsigned char* p = sqlite3_column_text(stmt_, col);
  if (p == nullptr) return {};
  return std::string(reinterpret_cast<const char*>(p),
                     static_cast<size_t>(sqlite3_column_bytes(stmt_, col)));
}
std::string Stmt::ColumnBlob(int col) const {
  const void* p = sqlite3_column_blob(stmt_, col);
  if (p == nullptr) return {};
  return std::string(static_cast<const char*>(p),
                     static_cast<size_t>(sqlite3_column_bytes(stmt_, col)));
}

void Stmt::Reset() {
  if (stmt_ != nullptr) sqlite3_reset(stmt_);
}
void Stmt::ClearBindings() {
  if (stmt_ != nullptr) sqlite3_clear_bindings(stmt_);
  bind_rc_ = SQLITE_OK;
}

// ---- Db ---------------------------------------------------------------------------------------

Status Db::Open(const std::string& path, const Options& options, std::unique_ptr<Db>* out) {
  out->reset();
  std::unique_ptr<Db> db(new Db());
  db->path_ = path;
  int flags = SQLITE_OPEN_NOMUTEX;  // one thread at a time per connection (see header)
  if (options.read_only) {
    flags |= SQLITE_OPEN_READONLY;
  } else {
    flags |= SQLITE_OPEN_READWRITE;
    if (options.create) flags |= SQLITE_OPEN_CREATE;
  }
  int rc = sqlite3_open_v2(path.c_str(), &db->db_, flags, nullptr);
  if (rc != SQLITE_OK) {
    Status s = StatusFromSqlite(rc, db->db_, "open " + path);
    return s;  // ~Db closes the half-open handle
  }
  sqlite3_extended_result_codes(db->db_, 1);
  sqlite3_busy_timeout(db->db_, options.busy_timeout_ms);

  // Reading the schema forces SQLite to look at the file: a non-database fails here, clearly.
  int64_t ignored = 0;
  Status s = db->QueryInt("PRAGMA schema_version", &ignored);
  if (!s.ok()) return s;
  if (options.wal && !options.read_only) {
    Stmt st;
    s = db->PrepareUncached("PRAGMA journal_mode=WAL", &st);
    if (!s.ok()) return s;
    bool row = false;
    // SQLite may answer SQLITE_BUSY here without calling the busy handler while another
    // connection switches a fresh file to WAL or migrates it (seen about once in 50 runs of
    // Schema.ConcurrentOpenersMigrateOnce on a loaded machine): retry within the busy timeout.
    const auto give_up = std::chrono::steady_clock::now() +
                         std::chrono::milliseconds(std::max(options.busy_timeout_ms, 0));
    for (;;) {
      s = st.Step(&row);
      if (s.code() != StatusCode::kBusy || std::chrono::steady_clock::now() >= give_up) break;
      st.Reset();
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (!s.ok()) return s;
    std::string mode = row ? st.ColumnText(0) : "";
    if (mode != "wal") {
      return Status::IoError("storage: open " + path +
                             ": cannot switch to WAL (journal_mode=" + mode + ")");
    }
  }
  s = db->Exec(
      "PRAGMA synchronous=FULL;"
      "PRAGMA foreign_keys=ON;"
      "PRAGMA journal_size_limit=67108864;");
  if (!s.ok()) return s;
  if (options.max_page_count > 0) {
    s = db->Exec("PRAGMA max_page_count=" + std::to_string(options.max_page_count));
    if (!s.ok()) return s;
  }
  *out = std::move(db);
  return Status::Ok();
}

Db::~Db() {
  for (auto& [sql, cached] : cache_) sqlite3_finalize(cached.stmt);
  cache_.clear();
  if (db_ != nullptr) sqlite3_close_v2(db_);
}

Status Db::Exec(std::string_view sql) {
  std::string text(sql);
  char* err = nullptr;
  int rc = sqlite3_exec(db_, text.c_str(), nullptr, nullptr, &err);
  if (err != nullptr) sqlite3_free(err);
  if (rc == SQLITE_OK) return Status::Ok();
  return StatusFromSqlite(rc, db_, DescribeStatement(text));
}

Status Db::Prepare(std::string_view sql, Stmt* out) {
  *out = Stmt();
  std::string key(sql);
  auto it = cache_.find(key);
  if (it == cache_.end()) {
    sqlite3_stmt* stmt = nullptr;
    int rc = sqlite3_prepare_v3(db_, key.data(), static_cast<int>(key.size()),
                                SQLITE_PREPARE_PERSISTENT, &stmt, nullptr);
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db_, "preparing " + DescribeStatement(key));
    it = cache_.emplace(std::move(key), Cached{stmt, false}).first;
  }
  if (it->second.in_use) return PrepareUncached(sql, out);
  it->second.in_use = true;
  *out = Stmt(it->second.stmt, db_, /*owned=*/false, &it->second.in_use);
  return Status::Ok();
}

Status Db::PrepareUncached(std::string_view sql, Stmt* out) {
  *out = Stmt();
  sqlite3_stmt* stmt = nullptr;
  int rc = sqlite3_prepare_v2(db_, sql.data(), static_cast<int>(sql.size()), &stmt, nullptr);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db_, "preparing " + DescribeStatement(sql));
  *out = Stmt(stmt, db_, /*owned=*/true);
  return Status::Ok();
}

Status Db::QueryInt(std::string_view sql, int64_t* out) {
  Stmt st;
  Status s = PrepareUncached(sql, &st);
  if (!s.ok()) return s;
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  *out = row ? st.ColumnInt(0) : 0;
  return Status::Ok();
}

int64_t Db::LastInsertRowid() const { return sqlite3_last_insert_rowid(db_); }
int64_t Db::Changes() const { return sqlite3_changes64(db_); }
bool Db::InTransaction() const { return sqlite3_get_autocommit(db_) == 0; }

// ---- Transaction ------------------------------------------------------------------------------

Transaction::~Transaction() { Rollback(); }

Status Transaction::Begin(Mode mode) {
  Status s = db_->Exec(mode == Mode::kImmediate ? "BEGIN IMMEDIATE" : "BEGIN DEFERRED");
  if (s.ok()) open_ = true;
  return s;
}

Status Transaction::Commit() {
  if (!open_) return Status::Internal("storage: commit without an open transaction");
  Status s = db_->Exec("COMMIT");
  if (s.ok()) {
    open_ = false;
    return s;
  }
  Rollback();
  return s;
}

void Transaction::Rollback() {
  if (!open_) return;
  open_ = false;
  // After some errors (SQLITE_FULL, IOERR) SQLite has already rolled back on its own.
  if (db_->InTransaction()) (void)db_->Exec("ROLLBACK");
}

}  // namespace calibd::storage
