// SqliteStore: the Store (store.h) in one SQLite file — the embedded default backend.
//
// Durability: WAL with synchronous=FULL. When a write call returns OK its effect is on disk and
// survives kill -9 and power loss (given a disk that honours fdatasync).
//
// Connections: each read borrows a connection from an internal pool (one per concurrently
// calling thread, opened on demand; idle ones are kept up to Options::max_idle_connections), so
// readers never wait for writers (WAL) and a long upload does not block reads. Writes from the
// threads of one process go through a group-commit queue (LevelDB-style: the first waiting
// writer runs the queued calls in one BEGIN IMMEDIATE transaction, one savepoint per call, and one
// fsync acknowledges them all), so durable writes per second can exceed the disk's fsync rate when
// calls are concurrent. Between processes, SQLite's write lock serialises transactions (waiting up
// to Options::busy_timeout_ms, then kBusy). Several processes on one host may open the same file
// at once; it cannot be shared between hosts (use PgStore). Messages carry SQLite's own text;
// kCorruption for a damaged file, kTooLarge for a recording over SQLite's blob limit.
#ifndef CALIBD_STORAGE_SQLITE_STORE_H_
#define CALIBD_STORAGE_SQLITE_STORE_H_

#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "storage/conn_pool.h"
#include "storage/db.h"
#include "storage/sql_store.h"

namespace calibd::storage {

class SqliteStore final : public SqlStore {
 public:
  // See Store::Open (the file is created with its folder when missing, then migrated).
  static Status OpenFile(const std::string& path, StoreOptions options,
                         std::unique_ptr<Store>* out);
  ~SqliteStore() override;

  const char* backend() const override { return "sqlite"; }
  Status ReadRecordingData(int64_t id,
                           const std::function<bool(std::string_view chunk)>& sink) override;
  Status IntegrityCheck(std::string* result) override;
  Status QuickCheck(std::string* result) override;
  Status Checkpoint() override;

 private:
  class Conn;     // a pooled connection, returned to the pool (sqlite_store_internal.h)
  struct Writer;  // a write call waiting in the group-commit queue
  SqliteStore(std::string path, StoreOptions options);
  friend class Store;
  // Runs `op` inside a write transaction shared with other queued calls (group commit), in a
  // savepoint of its own; it may be run again in a fresh transaction if another call's failure
  // aborted the shared one.
  Status Write(const SqlOp& op) override;
  // Runs `op` on a pooled connection (WAL: reads never wait for writers).
  Status Read(const SqlOp& op) override;
  // The bytes as one blob (recording_data), streamed from a staged file through a blob handle.
  Status StoreRecordingBytes(SqlConn* c, const NewRecording& r, const std::string& sha, int64_t now,
                             int64_t* id, bool* duplicate) override;

  Db::Options db_options_;
  ConnectionPool<Db> pool_;
  std::mutex write_mu_;
  std::deque<Writer*> writers_;  // guarded by write_mu_; the front one is the leader
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQLITE_STORE_H_
