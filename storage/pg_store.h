// PgStore: the Store (store.h) in a PostgreSQL database, through libpq, so that several calibd
// processes on several hosts share one set of recordings, one job queue, results and devices.
//
// Target: a libpq connection URI ("postgresql://user:password@host:5432/dbname?sslmode=require",
// "postgresql:///calibd?host=/run/postgresql") or keyword string ("host=db dbname=calibd"); any
// libpq parameter and the PG* environment variables apply. Default connect_timeout 5 s.
//
// Schema: its own forward-only migrations, versioned in the table calibd_schema (pg_schema.cc;
// PostgreSQL schema version 1 holds what SQLite schema version 3 holds). Every opener migrates
// inside one transaction holding pg_advisory_xact_lock, so processes starting at once migrate
// once; a database at a version newer than this build fails to open with kConflict.
//
// Durability and atomicity: every write call is one transaction (READ COMMITTED, row locks), so
// when it returns OK it is committed (durable as the server's fsync/synchronous_commit settings
// make it), and after an error nothing of it is. Recordings are stored as chunk rows of at most
// 1 MiB (recording_chunks), written and read one chunk at a time: memory use does not depend on
// a recording's size. Identical uploads are stored once across all hosts (sha256 UNIQUE,
// INSERT ... ON CONFLICT DO NOTHING: a concurrent identical upload waits for the first and then
// finds it).
//
// Queue: ClaimJob takes the oldest claimable job with SELECT ... FOR UPDATE SKIP LOCKED (no two
// callers anywhere get the same job, and claimers never wait on each other); leases, their
// expiry, back-off and the exactly-once CompleteJob are those of the Store contract, with the
// job row locked (SELECT ... FOR UPDATE) for every state transition, so two hosts racing on an
// expired lease are serialised and only the holder's result is stored (results has job_id as
// its primary key: a result is never written twice). Enqueues (and jobs given back) send NOTIFY
// calibd_jobs right after their commit (not inside the transaction, where PostgreSQL's global
// notify lock would serialise the commits); SetJobListener LISTENs on a dedicated connection.
//
// Connections: a pool (one connection per concurrently calling thread, idle ones kept up to
// StoreOptions::max_idle_connections). A call whose connection fails (server stopped or
// restarted, network) returns kBusy naming the cause, the broken connection and every idle one
// are dropped, and the next call connects afresh: the store reconnects by itself. A call that
// finds its pooled connection died while idle (the server restarted in between) runs again at
// once on a fresh one when nothing of it had taken effect (reads; a write whose BEGIN failed). A
// write whose COMMIT was cut off may or may not have committed (the caller was not told OK, so
// nothing acknowledged is lost; retrying is safe: uploads are deduplicated, job transitions check
// state).
//
// Options: busy_timeout_ms becomes lock_timeout; read_only sets
// default_transaction_read_only (writes fail with kIoError); max_page_count is not supported
// (kInvalidInput when set); max_write_batch does not apply (the server does group commit).
#ifndef CALIBD_STORAGE_PG_STORE_H_
#define CALIBD_STORAGE_PG_STORE_H_

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "storage/conn_pool.h"
#include "storage/pg_conn.h"
#include "storage/sql_store.h"

namespace calibd::storage {

// The newest schema version of the PostgreSQL backend (pg_schema.cc).
inline constexpr int kPgSchemaVersion = 6;

// `target` with the password of a URI or keyword string replaced by "***" (for logs, /healthz).
std::string RedactConnectionTarget(const std::string& target);

class PgStore final : public SqlStore {
 public:
  // Connects, then creates or migrates the schema (see above). Fails with kBusy (server not
  // reachable, with libpq's reason), kConflict (schema newer than this build), kInvalidInput
  // (bad options), kIoError (read-only and a migration is needed).
  static Status Connect(const std::string& target, StoreOptions options,
                        std::unique_ptr<Store>* out);
  ~PgStore() override;

  const char* backend() const override { return "postgresql"; }
  bool SetJobListener(std::function<void()> on_job) override;

  Status ReadRecordingData(int64_t id,
                           const std::function<bool(std::string_view chunk)>& sink) override;
  // Checks that every recording's chunks add up to its size: "ok", or the ids that do not.
  Status IntegrityCheck(std::string* result) override;
  // Nothing to do (the server checkpoints its own write-ahead log): OK.
  Status Checkpoint() override;

 private:
  class Lease;  // a pooled connection, returned on destruction (pg_store_internal.h)
  PgStore(std::string target, StoreOptions options);
  Status NewConnection(std::unique_ptr<PgConn>* out);
  // Runs `op` in one transaction (BEGIN ... COMMIT, ROLLBACK on error). A deadlock or
  // serialization failure runs it again (up to 3 times), so `op` must set its outputs afresh.
  // Listeners are woken after the commit when `op` asked for it (NotifyJobsAfterCommit).
  Status Write(const SqlOp& op) override;
  // Runs `op` on a pooled connection outside any explicit transaction (reads).
  Status Read(const SqlOp& op) override;
  // A staged file without its hash is hashed first: the hash is the key of the recording row.
  Status HashUpload(const NewRecording& r, std::string* sha) override;
  // The bytes as chunk rows (recording_chunks), deduplicated across hosts.
  Status StoreRecordingBytes(SqlConn* c, const NewRecording& r, const std::string& sha, int64_t now,
                             int64_t* id, bool* duplicate) override;
  // Writes the upload's bytes as recording `id`'s chunk rows, checking they hash to `sha`. `fd`:
  // the staged file (r.path, at its start) or -1 for r.data.
  Status WriteChunks(PgConn* c, const NewRecording& r, int64_t id, int fd, int64_t size,
                     const std::string& sha);
  // A re-upload of recording `id`'s bytes: when the stored chunks do not hash to `sha` (damaged),
  // replaces them with the upload's.
  Status RepairIfDamaged(PgConn* c, const NewRecording& r, int64_t id, const std::string& sha);
  void ListenLoop();

  std::string target_;  // with the password: never logged
  ConnectionPool<PgConn> pool_;

  std::mutex listen_mu_;  // serialises SetJobListener
  std::function<void()> on_job_;
  std::atomic<bool> listen_stop_{false};
  std::thread listener_;
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_PG_STORE_H_
