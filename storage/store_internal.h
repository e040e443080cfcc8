// Helpers shared by the Store backends (sqlite_store*.cc, pg_store*.cc). Not a public interface.
//
// The backends keep only their SQL; every rule about jobs that does not depend on the database
// lives here once: who may change a running job, which revoke/accept decisions are legal and
// what their errors say, and how a row of a job, recording, device or event becomes the struct
// of store.h.
#ifndef CALIBD_STORAGE_STORE_INTERNAL_H_
#define CALIBD_STORAGE_STORE_INTERNAL_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "storage/store.h"

namespace calibd::storage::internal {

// Recording bytes move in chunks of at most this size (streaming unit, 1 MiB).
inline constexpr size_t kChunkBytes = 1 << 20;

int64_t SystemNowMs();
// Whether `text` parses as a JSON array.
bool IsJsonArray(const std::string& text);
// Back-off after the n-th transient failure: min(base * 2^(n-1), max) (StoreOptions).
int64_t Backoff(const StoreOptions& o, int64_t failures);
// The acceptance gate's verdict of a result: kRejected when the JSON's verdict.status is
// "rejected", else kAccepted (no verdict, or not JSON, included).
GateVerdict VerdictOf(const std::string& result_json);
// ListJobs' page size: filter.limit clamped to 1..500, 50 when unset.
int PageLimit(const JobFilter& f);
// DeviceFilter::limit clamped to 1..1000 (100 when <= 0).
int PageLimit(const DeviceFilter& f);

// ---- arguments ----------------------------------------------------------------------------------

// PutRecording's argument checks (kInvalidInput): columns/sensors JSON arrays, a job's method.
Status ValidateNewRecording(const NewRecording& r);
// After a whole recording was read: kCorruption naming the recording and both hashes when the
// bytes read (`bytes`, their SHA-256 `sha`) are not the ones stored (`info`), with how to repair
// it.
Status CheckRecordingDigest(const RecordingInfo& info, int64_t bytes, const std::string& sha);
// An upload's staged file (NewRecording::path) open for reading, closed on destruction.
class StagedFile {
 public:
  StagedFile() = default;
  ~StagedFile();
  StagedFile(const StagedFile&) = delete;
  StagedFile& operator=(const StagedFile&) = delete;
  // Opens `path` and reads its size: kIoError naming the path when it cannot.
  Status Open(const std::string& path);
  // The upload's bytes: r.path opened as Open does, else r.data's size (fd() stays -1).
  Status OpenUpload(const NewRecording& r);
  int fd() const { return fd_; }          // -1 until opened
  int64_t size() const { return size_; }  // bytes when opened

 private:
  int fd_ = -1;
  int64_t size_ = 0;
};
// ClaimJob's argument checks (kInvalidInput): a worker id, a positive lease.
Status ValidateClaim(const std::string& worker_id, int64_t lease_ms);

// ---- rows ---------------------------------------------------------------------------------------

// One row of a query result, as a backend reads it: NULL reads as 0 and "".
class Row {
 public:
  virtual ~Row() = default;
  virtual bool IsNull(int col) const = 0;
  virtual int64_t Int(int col) const = 0;
  virtual std::string Text(int col) const = 0;
};

// The columns of a job row joined with its result (jobs j LEFT JOIN results r), in the order
// ReadJob reads them; JobSelect appends r.result_json, j.error_reason and j.error_detail_json
// (the two large ones NULL without results). Plain column names, the same in both dialects.
inline constexpr const char* kJobColumns =
    "SELECT j.id, j.recording_id, j.method, j.device, j.config_json, j.status, j.attempts, "
    "j.lease_owner, j.lease_expires_at, j.created_at, j.started_at, j.finished_at, "
    "j.error_code, j.error_message, j.not_before, r.sha256, r.verdict, r.decision, ";
inline constexpr const char* kJobFrom = " FROM jobs j LEFT JOIN results r ON r.job_id = j.id ";
// kJobColumns + result_json|NULL, error_reason, error_detail_json|NULL, cancel_requested_at,
// cancel_reason, cancel_actor + kJobFrom.
std::string JobSelect(bool with_result);
// A job from a row of JobSelect: timestamps formatted ("" when NULL); result, verdict, decision
// and state only for a succeeded job (state = the decision, else the verdict).
void ReadJob(const Row& row, JobInfo* job);

// A recording from a row of (id, sha256, bytes, rows, layout, device, file_name, created_at,
// columns_json, sensors_json), with its summary_json.
void ReadRecording(const Row& row, RecordingInfo* out);
// A job event from a row of (id, job_id, action, reason, actor, created_at).
void ReadJobEvent(const Row& row, JobEvent* out);
// Adds a row of (serial, first_seen, method, job_id, calibrated_at) to `devices`, the rows
// ordered by serial: a new device when the serial changes, a calibration when method is not
// NULL.
void AddDeviceRow(const Row& row, std::vector<DeviceInfo>* devices);
// Adds a row of (status, count) to the counts.
void AddQueueCount(const Row& row, QueueCounts* out);

// ---- job state rules ----------------------------------------------------------------------------

// Whether `worker_id` holds `job` (loaded, and locked where the backend locks, in the caller's
// transaction): OK when it is running under that worker (a lapsed lease still counts until
// somebody takes the job back); kConflict "cannot <action> job N: ..." saying why not.
Status CheckHolder(const JobInfo& job, const std::string& worker_id, const char* action);
// CompleteJob's decision on the loaded job: OK with *done = true when it already succeeded with
// the result of SHA-256 `sha` (nothing to do); kConflict when it succeeded with another result;
// otherwise CheckHolder (*done = false).
Status CheckCompletion(const JobInfo& job, const std::string& worker_id, const std::string& sha,
                       bool* done);
// RevokeJob / AcceptJob: kInvalidInput for an empty reason.
Status ValidateDecision(bool revoke, const std::string& reason);
// Whether the decision is legal on the loaded job: kConflict saying why not (no result, already
// revoked, rejected and so not served, already accepted).
Status CheckDecision(const JobInfo& job, bool revoke);
// The event recorded for a decision ("revoke" | "accept"), created now.
JobEvent MakeDecisionEvent(int64_t id, int64_t job_id, bool revoke, const std::string& reason,
                           const std::string& actor, int64_t now);
// A cancelled job's failure: error_code "stopped", error_reason "cancelled", and its message.
inline constexpr const char* kCancelledCode = "stopped";
inline constexpr const char* kCancelledReason = "cancelled";
std::string CancelledMessage(const std::string& actor, const std::string& reason);
// CancelJob: kInvalidInput for an empty reason.
Status ValidateCancel(const std::string& reason);
// Whether the loaded job may be cancelled: kConflict "job N is succeeded: ..." for a finished one.
Status CheckCancel(const JobInfo& job);
// The event recorded for a cancel request, created now.
JobEvent MakeCancelEvent(int64_t id, int64_t job_id, const std::string& reason,
                         const std::string& actor, int64_t now);
// "1,2,3": job ids for an SQL IN list (integers only, so no quoting is needed).
std::string IdList(const std::vector<int64_t>& ids);
// The results.decision a decision stores: "revoked" | "accepted".
const char* DecisionValue(bool revoke);
// The event's action: "revoke" | "accept".
const char* DecisionAction(bool revoke);

}  // namespace calibd::storage::internal

#endif  // CALIBD_STORAGE_STORE_INTERNAL_H_
