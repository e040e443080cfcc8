// SqlStore: the Store (store.h) written once over an SQL connection (sql_conn.h), the base of
// SqliteStore and PgStore (not a public interface). It holds every rule of the store that SQL can
// say in both dialects: the job queue (enqueue, claim, lease renewal and expiry, complete with
// the gate's verdict, fail with retry and back-off, release, cancel), the device's latest
// calibration, the job/result/device catalog, decisions, and the device a recording's job is
// for. A backend supplies its connections and transactions (Read, Write), how a recording's
// bytes are stored and read (blobs / chunk rows), and maintenance.
//
//   sql_store_jobs.cc     the job queue
//   sql_store_catalog.cc  recordings' metadata, listings, devices, decisions
//
// Thread-safety: as Store; the backend's Read and Write give each call a connection of its own.
#ifndef CALIBD_STORAGE_SQL_STORE_H_
#define CALIBD_STORAGE_SQL_STORE_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "storage/sql_conn.h"
#include "storage/store.h"

namespace calibd::storage {

namespace sql {

// The recording's metadata (internal::ReadRecording); kNotFound.
Status LoadRecording(SqlConn* c, int64_t id, RecordingInfo* out);
// *id = the recording with this SHA-256, or 0.
Status FindRecording(SqlConn* c, const std::string& sha, int64_t* id);
// Inserts the recording row for an upload of `bytes` bytes hashing to `sha`: *id = its id, or 0
// when a row with this hash exists (a concurrent identical upload committed first).
Status InsertRecording(SqlConn* c, const NewRecording& r, const std::string& sha, int64_t bytes,
                       int64_t now, int64_t* id);

}  // namespace sql

class SqlStore : public Store {
 public:
  Status Ping() override;
  Status PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) override;
  Status GetRecording(int64_t id, RecordingInfo* out) override;
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

 protected:
  using SqlOp = std::function<Status(SqlConn*)>;
  // `dialect` must outlive the store (the backends pass a static constant).
  SqlStore(std::string path, StoreOptions options, const SqlDialect& dialect);

  // Runs `op` in one write transaction: committed when it returns OK, nothing of it otherwise.
  // `op` must not begin or commit transactions and may be run more than once (a retried
  // transaction), so it must set its outputs afresh each time.
  virtual Status Write(const SqlOp& op) = 0;
  // Runs `op` on a connection outside an explicit transaction (reads); it may run twice.
  virtual Status Read(const SqlOp& op) = 0;
  // Before PutRecording's transaction, on the calling thread: *sha = the upload's SHA-256 where
  // the backend needs it first ("" = learnt while storing). Default: hashes in-memory data.
  virtual Status HashUpload(const NewRecording& r, std::string* sha);
  // Stores the upload's bytes in `c`'s transaction (a new recording row, or a duplicate's
  // repair); *id = the recording, *duplicate = identical bytes were stored already.
  virtual Status StoreRecordingBytes(SqlConn* c, const NewRecording& r, const std::string& sha,
                                     int64_t now, int64_t* id, bool* duplicate) = 0;

  // The time for the statements of `c`'s transaction: the store's clock (SQLite, or an injected
  // one), else the database server's (SqlDialect::db_now_ms).
  Status TxnNow(SqlConn* c, int64_t* now);

  const SqlDialect& dialect_;

 private:
  // The job (internal::ReadJob); kNotFound. lock: hold its row until the transaction ends.
  Status LoadJob(SqlConn* c, int64_t id, bool with_result, JobInfo* out, bool lock = false);
  // Adds the serial to devices unless empty or known.
  Status RememberDevice(SqlConn* c, const std::string& serial, int64_t now);
  // Makes device_calibrations hold the device's latest served result for the method (succeeded,
  // accepted by the gate or a person, not revoked; the one stored last), or nothing.
  Status RefreshLatest(SqlConn* c, const std::string& device, const std::string& method);
  // Queues a job. inherit_device: device "" = the recording's device (EnqueueJob); else none.
  Status EnqueueJobLocked(SqlConn* c, int64_t recording_id, const std::string& method,
                          const std::string& device, const std::string& config_json, int64_t now,
                          JobInfo* out, bool inherit_device);
  // PutRecording in the transaction: the bytes (StoreRecordingBytes), the upload's device, and
  // its job for the device the upload names.
  Status PutRecordingLocked(SqlConn* c, const NewRecording& r, const std::string& sha,
                            RecordingInfo* out, bool* existed);
  // Takes back running jobs whose lease expired by `now` (RecoverExpiredLeases).
  Status RecoverLocked(SqlConn* c, int64_t now, int64_t* recovered);
  // Whether any job is claimable now (a cheap read, so that idle workers polling do not write).
  Status AnyClaimable(bool* any);
  // The job loaded and locked, checked to be held by `worker_id` (internal::CheckHolder).
  Status RequireHolder(SqlConn* c, int64_t job_id, const std::string& worker_id, const char* action,
                       JobInfo* job);
  // Stores a result: its row (with the gate's verdict), the job succeeded, the device's latest.
  Status StoreResult(SqlConn* c, const JobInfo& job, const std::string& result_json,
                     const std::string& sha);
  // Fails a running job whose cancel was requested as cancelled, with `message`.
  Status FailCancelledLocked(SqlConn* c, int64_t job_id, const std::string& message);
  // Records a job event ("cancel", "revoke", "accept"); *id = its id.
  Status InsertJobEvent(SqlConn* c, int64_t job_id, const char* action, const std::string& reason,
                        const std::string& actor, int64_t now, int64_t* id);
  Status Cancel(int64_t job_id, const std::string& reason, const std::string& actor, JobInfo* out,
                JobEvent* event) override;
  Status Decide(int64_t job_id, bool revoke, const std::string& reason, const std::string& actor,
                JobEvent* out) override;
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SQL_STORE_H_
