// SqliteStore (sqlite_store.h): SqlStore's connection over SQLite (SqliteConn, the dialect), the
// connection pool, opening and migrating the file, the group-commit write queue, maintenance.
// Recordings' bytes are in sqlite_store_recordings.cc (see sqlite_store_internal.h).
#include "storage/sqlite_store.h"

#include <sqlite3.h>

#include <cctype>
#include <exception>
#include <filesystem>
#include <utility>

#include "storage/schema.h"
#include "storage/sqlite_store_internal.h"

namespace calibd::storage {

// ---- the connection --------------------------------------------------------------------------

namespace sqlite {

const SqlDialect kDialect = {
    /*ping=*/"PRAGMA user_version",  // reads the file's header
    /*lock_job=*/"",  // a write transaction holds SQLite's write lock (BEGIN IMMEDIATE)
    /*skip_locked=*/"",
    /*db_now_ms=*/nullptr,  // every process on the file runs on one host's clock
    /*result_seq_column=*/", seq",
    /*result_seq_value=*/", (SELECT COALESCE(MAX(seq), 0) + 1 FROM results)",
    /*lock_latest=*/"",
    /*byte_order=*/"",  // BINARY
    // CROSS JOIN fixes the order: SQLite, without statistics, would otherwise scan every
    // succeeded job for a rare verdict such as revoked. With a device, the device's jobs
    // (jobs_by_device) are fewer.
    /*state_from=*/" FROM results r CROSS JOIN jobs j ON j.id = r.job_id ",
    /*state_from_with_device=*/false,
    /*state_id_column=*/"r.job_id",
};

std::string SqliteText(std::string_view sql) {
  std::string out(sql);
  for (size_t i = 0; i + 1 < out.size(); ++i) {
    if (out[i] == '$' && std::isdigit(static_cast<unsigned char>(out[i + 1]))) out[i] = '?';
  }
  return out;
}

Status SqliteConn::Run(std::string_view sql, const SqlParams& params, const SqlRowFn& on_row,
                       int64_t* changed) {
  Stmt st;
  Status s = db_->Prepare(SqliteText(sql), &st);
  if (!s.ok()) return s;
  for (size_t i = 0; i < params.size(); ++i) {
    const int index = static_cast<int>(i) + 1;
    switch (params[i].kind) {
      case SqlValue::Kind::kNull:
        st.BindNull(index);
        break;
      case SqlValue::Kind::kInt:
        st.BindInt(index, params[i].integer);
        break;
      case SqlValue::Kind::kText:
        st.BindText(index, params[i].text);
        break;
    }
  }
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    if (on_row) on_row(StmtRow(st));
  }
  if (changed != nullptr) *changed = db_->Changes();
  return Status::Ok();
}

std::string ListJobsSql(const JobFilter& filter) {
  SqlParams params;
  return SqliteText(internal::ListJobsSql(kDialect, filter, &params));
}

std::string CountJobsSql(const JobFilter& filter) {
  SqlParams params;
  return SqliteText(internal::CountJobsSql(kDialect, filter, &params));
}

}  // namespace sqlite

// ---- connection pool ----------------------------------------------------------------------------

SqliteStore::SqliteStore(std::string path, StoreOptions options)
    : SqlStore(std::move(path), std::move(options), sqlite::kDialect),
      pool_(
          options_.max_idle_connections,
          [this](std::unique_ptr<Db>* db) { return Db::Open(path_, db_options_, db); },
          [](Db* db) {
            if (db->InTransaction()) (void)db->Exec("ROLLBACK");  // never hand one out mid-txn
            return true;
          }) {
  db_options_.busy_timeout_ms = options_.busy_timeout_ms;
  db_options_.read_only = options_.read_only;
  db_options_.max_page_count = options_.max_page_count;
}

SqliteStore::~SqliteStore() = default;

Status SqliteStore::OpenFile(const std::string& path, StoreOptions options,
                             std::unique_ptr<Store>* out) {
  out->reset();
  if (options.max_attempts < 1) return Status::InvalidInput("storage: max_attempts must be >= 1");
  if (options.create_parent_dir && !options.read_only) {
    std::filesystem::path parent = std::filesystem::path(path).parent_path();
    std::error_code ec;
    if (!parent.empty()) std::filesystem::create_directories(parent, ec);
    if (ec) {
      return Status::IoError("storage: cannot create folder " + parent.string() + ": " +
                             ec.message());
    }
  }
  std::unique_ptr<SqliteStore> store(new SqliteStore(path, std::move(options)));
  Conn conn(store.get());
  Status s = conn.Open();
  if (!s.ok()) return s;
  if (store->options_.read_only) {
    int64_t version = 0;
    s = SchemaVersion(conn.db(), &version);
    if (!s.ok()) return s;
    if (version != kSchemaVersion) {
      return Status::IoError("storage: " + path + " is opened read-only but has schema version " +
                             std::to_string(version) + ", not " + std::to_string(kSchemaVersion) +
                             " (it needs a migration)");
    }
  } else {
    s = MigrateSchema(conn.db());
    if (!s.ok()) return s;
  }
  *out = std::move(store);
  return Status::Ok();
}

// ---- group commit --------------------------------------------------------------------------

struct SqliteStore::Writer {
  const SqlOp* op = nullptr;
  Status status;
  bool done = false;
  std::condition_variable cv;
};

Status SqliteStore::Write(const SqlOp& op) {
  Writer self;
  self.op = &op;
  std::unique_lock<std::mutex> lock(write_mu_);
  writers_.push_back(&self);
  while (!self.done && writers_.front() != &self) self.cv.wait(lock);
  if (self.done) return self.status;  // a leader ran it for us

  // Leader: take the queued calls (self first) and run them in one transaction.
  const size_t max_batch = static_cast<size_t>(std::max(options_.max_write_batch, 1));
  std::vector<Writer*> batch(writers_.begin(),
                             writers_.begin() + std::min(writers_.size(), max_batch));
  lock.unlock();

  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) {
    for (Writer* w : batch) w->status = s;
  } else {
    Db* db = conn.db();
    sqlite::SqliteConn sql(db);
    std::vector<Writer*> pending = batch;
    while (!pending.empty()) {
      Transaction txn(db);
      s = txn.Begin(Transaction::Mode::kImmediate);
      if (!s.ok()) {
        for (Writer* w : pending) w->status = s;
        break;
      }
      bool aborted = false;  // an error made SQLite roll the whole transaction back
      std::vector<Writer*> ran;
      for (size_t i = 0; i < pending.size(); ++i) {
        Writer* w = pending[i];
        s = db->Exec("SAVEPOINT batch_op");
        if (s.ok()) {
          try {
            s = (*w->op)(&sql);
          } catch (const std::exception& e) {  // never leave the queue without a leader
            s = Status::Internal(std::string("storage: unexpected exception: ") + e.what());
          }
          if (!db->InTransaction()) {
            // SQLite already rolled everything back (e.g. SQLITE_FULL, IOERR): this call fails,
            // the others run again in a fresh transaction.
            w->status = s.ok() ? Status::IoError("storage: transaction lost") : s;
            pending.erase(pending.begin() + static_cast<std::ptrdiff_t>(i));
            aborted = true;
            break;
          }
          Status undo = s.ok() ? db->Exec("RELEASE batch_op")
                               : db->Exec("ROLLBACK TO batch_op; RELEASE batch_op");
          if (s.ok()) s = undo;
          if (!undo.ok() && !db->InTransaction()) {
            w->status = undo;
            pending.erase(pending.begin() + static_cast<std::ptrdiff_t>(i));
            aborted = true;
            break;
          }
        }
        w->status = s;
        ran.push_back(w);
      }
      if (aborted) continue;  // retry the rest (one fewer each round: terminates)
      s = txn.Commit();
      if (!s.ok()) {
        for (Writer* w : ran) {
          if (w->status.ok()) w->status = s;  // nothing of the transaction is on disk
        }
      }
      break;
    }
  }

  lock.lock();
  for (Writer* w : batch) {
    writers_.pop_front();  // the batch is the front of the queue, in order
    if (w != &self) {
      w->done = true;
      w->cv.notify_one();
    }
  }
  if (!writers_.empty()) writers_.front()->cv.notify_one();  // the next leader
  return self.status;
}

Status SqliteStore::Read(const SqlOp& op) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  sqlite::SqliteConn sql(conn.db());
  return op(&sql);
}

// ---- maintenance -------------------------------------------------------------------------------

Status SqliteStore::IntegrityCheck(std::string* result) {
  result->clear();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->PrepareUncached("PRAGMA integrity_check", &st);
  if (!s.ok()) return s;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    if (!result->empty()) *result += "\n";
    *result += st.ColumnText(0);
  }
  return Status::Ok();
}

Status SqliteStore::QuickCheck(std::string* result) {
  // A connection of its own, not a pooled one: a pooled connection's page cache may still hold
  // pages as they were before the file was damaged (nothing written since tells it otherwise).
  std::unique_ptr<Db> db;
  Status s = Db::Open(path_, db_options_, &db);
  if (s.code() == StatusCode::kCorruption) {
    *result = s.message();
    return Status::Ok();
  }
  if (!s.ok()) return s;
  Stmt st;
  s = db->PrepareUncached("PRAGMA quick_check(20)", &st);
  std::string report;
  for (bool row = s.ok(); row;) {
    s = st.Step(&row);
    if (!s.ok() || !row) break;
    if (!report.empty()) report += "\n";
    report += st.ColumnText(0);
  }
  if (s.code() == StatusCode::kCorruption) {
    report = s.message();  // too damaged to check
  } else if (!s.ok()) {
    return s;
  }
  *result = report.empty() ? "ok" : report;
  return Status::Ok();
}

Status SqliteStore::Checkpoint() {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  int busy = 0, log = 0, done = 0;
  int rc = sqlite3_wal_checkpoint_v2(conn.db()->handle(), nullptr, SQLITE_CHECKPOINT_TRUNCATE, &log,
                                     &done);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, conn.db()->handle(), "checkpoint");
  (void)busy;
  return Status::Ok();
}

}  // namespace calibd::storage
