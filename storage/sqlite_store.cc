// SqliteStore (sqlite_store.h): the connection pool, opening and migrating the file, the
// group-commit write queue. The other parts are in sqlite_store_recordings.cc,
// sqlite_store_jobs.cc and sqlite_store_catalog.cc (see sqlite_store_internal.h).
#include "storage/sqlite_store.h"

#include <exception>
#include <filesystem>
#include <utility>

#include "storage/schema.h"
#include "storage/sqlite_store_internal.h"

namespace calibd::storage {

// ---- connection pool ----------------------------------------------------------------------------

SqliteStore::SqliteStore(std::string path, StoreOptions options)
    : Store(std::move(path), std::move(options)) {
  db_options_.busy_timeout_ms = options_.busy_timeout_ms;
  db_options_.read_only = options_.read_only;
  db_options_.max_page_count = options_.max_page_count;
}

SqliteStore::~SqliteStore() = default;

Status SqliteStore::Acquire(std::unique_ptr<Db>* db) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!idle_.empty()) {
      *db = std::move(idle_.back());
      idle_.pop_back();
      return Status::Ok();
    }
  }
  return Db::Open(path_, db_options_, db);
}

void SqliteStore::Return(std::unique_ptr<Db> db) {
  if (db->InTransaction()) (void)db->Exec("ROLLBACK");  // never hand out a connection mid-txn
  std::lock_guard<std::mutex> lock(mu_);
  if (static_cast<int>(idle_.size()) < options_.max_idle_connections) {
    idle_.push_back(std::move(db));
  }
}

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
  const std::function<Status(Db*)>* op = nullptr;
  Status status;
  bool done = false;
  std::condition_variable cv;
};

Status SqliteStore::Write(const std::function<Status(Db*)>& op) {
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
            s = (*w->op)(db);
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

Status SqliteStore::Ping() {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  int64_t version = 0;
  return SchemaVersion(conn.db(), &version);
}

}  // namespace calibd::storage
