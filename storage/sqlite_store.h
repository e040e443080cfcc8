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

#include "storage/db.h"
#include "storage/store.h"

namespace calibd::storage {

class SqliteStore final : public Store {
 public:
  // See Store::Open (the file is created with its folder when missing, then migrated).
  static Status OpenFile(const std::string& path, StoreOptions options,
                         std::unique_ptr<Store>* out);
  ~SqliteStore() override;

  const char* backend() const override { return "sqlite"; }
  Status Ping() override;
  Status PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) override;
  Status GetRecording(int64_t id, RecordingInfo* out) override;
  Status ReadRecordingData(int64_t id,
                           const std::function<bool(std::string_view chunk)>& sink) override;
  Status EnqueueJob(int64_t recording_id, const std::string& method, const std::string& device,
                    const std::string& config_json, JobInfo* out) override;
  Status ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                  bool* claimed) override;
  Status RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) override;
  Status CompleteJob(int64_t job_id, const std::string& worker_id,
                     const std::string& result_json) override;
  Status FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                 bool transient) override;
  Status ReleaseJob(int64_t job_id, const std::string& worker_id, ReleaseKind kind) override;
  Status CancelRequests(const std::vector<int64_t>& job_ids,
                        std::vector<int64_t>* requested) override;
  Status RecoverExpiredLeases(int64_t* recovered) override;
  Status ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) override;
  Status GetJob(int64_t id, JobInfo* out) override;
  Status ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) override;
  Status CountJobs(const JobFilter& filter, int64_t* count) override;
  using Store::ListDevices;
  Status ListDevices(const DeviceFilter& filter, std::vector<DeviceInfo>* out) override;
  Status LatestResult(const std::string& device, const std::string& method, JobInfo* out) override;
  Status QueueDepth(QueueCounts* out) override;
  Status ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) override;
  Status IntegrityCheck(std::string* result) override;
  Status QuickCheck(std::string* result) override;
  Status Checkpoint() override;

 private:
  class Conn;     // a pooled connection, returned to the pool (sqlite_store_internal.h)
  struct Writer;  // a write call waiting in the group-commit queue
  // Runs `op` inside a write transaction shared with other queued calls (group commit); `op`
  // must not begin or commit transactions (savepoints are fine) and may be run again in a fresh
  // transaction if another call's failure aborted the shared one.
  Status Write(const std::function<Status(Db*)>& op);
  SqliteStore(std::string path, StoreOptions options);
  friend class Store;
  Status Acquire(std::unique_ptr<Db>* db);
  void Return(std::unique_ptr<Db> db);

  Status PutRecordingLocked(Db* db, const NewRecording& r, const std::string& sha,
                            RecordingInfo* out, bool* existed);
  Status EnqueueJobLocked(Db* db, int64_t recording_id, const std::string& method,
                          const std::string& device, const std::string& config_json, int64_t now,
                          JobInfo* out, bool inherit_device = true);
  Status RecoverLocked(Db* db, int64_t now, int64_t* recovered);
  Status LoadJob(Db* db, int64_t id, bool with_result, JobInfo* out);
  Status Cancel(int64_t job_id, const std::string& reason, const std::string& actor, JobInfo* out,
                JobEvent* event) override;
  Status Decide(int64_t job_id, bool revoke, const std::string& reason, const std::string& actor,
                JobEvent* out) override;
  // Fails a running job whose cancel was requested as cancelled, with `message` (in the
  // caller's transaction).
  Status FailCancelledLocked(Db* db, int64_t job_id, const std::string& message);
  Status RequireHolder(Db* db, int64_t job_id, const std::string& worker_id, const char* action,
                       JobInfo* job);

  Db::Options db_options_;
  std::mutex mu_;
  std::vector<std::unique_ptr<Db>> idle_;  // guarded by mu_
  std::mutex write_mu_;
  std::deque<Writer*> writers_;  // guarded by write_mu_; the front one is the leader
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQLITE_STORE_H_
