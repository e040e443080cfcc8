// Store: everything calibd keeps — recordings (original bytes, deduplicated by SHA-256), the job
// queue with leases and retries, results, devices, the acceptance decisions. An abstract
// interface with two backends, chosen by Store::Open from its target:
//   SqliteStore (sqlite_store.h): one SQLite file, embedded, the default; one host.
//   PgStore (pg_store.h): a PostgreSQL database ("postgresql://..."), shared by any number of
//     calibd processes on any hosts.
// One test suite (tests/storage/store_test.cc) holds both to this contract.
//
// Durability and atomicity: when a write call returns OK its effect is committed and survives
// kill -9 of the process (and power loss, given storage that honours fsync); when it returns an
// error nothing of it was committed (every write call is atomic: never a half-written recording,
// job or result).
//
// Thread-safety: a Store is thread-safe; calls from many threads run concurrently on pooled
// connections. Several processes may open the same database at once (PostgreSQL: on several
// hosts). Do not use a Store across fork(): open a new one in the child. Output arguments are
// written only when a call returns OK.
//
// Errors (calibd::Status): kNotFound (no such id), kConflict (illegal state transition, e.g.
// completing a job one does not lease), kInvalidInput (bad argument), kBusy and kIoError
// (transient / environmental: locked past the timeout, database server unreachable, disk full,
// I/O error, read-only), kCorruption (damaged database), kTooLarge (recording over the backend's
// limit). Messages carry the database's own text.
//
// Times: stored as milliseconds since the Unix epoch from Options::now_ms; reported as ISO-8601
// UTC strings with milliseconds ("2026-11-22T04:03:46.123Z"), or "" when unset, plus the raw *_ms.
//
// Job states: queued -> running (ClaimJob) -> succeeded (CompleteJob) | failed (FailJob
// non-transient, or transient/lease expiry past max_attempts) | queued (FailJob transient,
// ReleaseJob (shutdown, or after a store failure), lease expiry). succeeded and failed are final.
// CancelJob fails a queued job at once and marks a running one (a cancel request): its holder stops
// and fails it; if the holder releases it instead, or its lease lapses, it is failed as cancelled,
// never queued again.
#ifndef CALIBD_STORAGE_STORE_H_
#define CALIBD_STORAGE_STORE_H_

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/job_state.h"
#include "core/status.h"
#include "storage/db.h"

namespace calibd {

// JSON of the job vocabulary: its Name() as a string (so that nlohmann never writes one as its
// number). kNone writes "": where SPEC §5 has null, write NullIfEmpty(Name(...)).
void to_json(nlohmann::json& j, JobStatus v);
void to_json(nlohmann::json& j, GateVerdict v);
void to_json(nlohmann::json& j, Decision v);
void to_json(nlohmann::json& j, ServeState v);

}  // namespace calibd

namespace calibd::storage {

// The job vocabulary (base/job_state.h): JobStatus, GateVerdict, Decision, ServeState, with
// Name() and Parse().
using calibd::Decision;
using calibd::GateVerdict;
using calibd::JobStatus;
using calibd::ServeState;

// Formats milliseconds since the epoch as "YYYY-MM-DDTHH:MM:SS.mmmZ".
std::string FormatTimestamp(int64_t ms);

struct StoreOptions {
  // Clock, milliseconds since the Unix epoch. Must be thread-safe. Default: on SQLite the host's
  // system clock (every process on one database file runs on one host); on PostgreSQL the
  // database server's clock (clock_timestamp(), read in each transaction), so that leases,
  // back-offs and times stored by hosts whose clocks disagree are measured on one clock.
  // Tests inject a fake clock to expire leases and back-offs without sleeping; an injected
  // clock is used on both backends.
  std::function<int64_t()> now_ms;
  // Lock wait before kBusy (per statement / BEGIN IMMEDIATE; PostgreSQL: lock_timeout).
  // Default 5000 ms.
  int busy_timeout_ms = 5000;
  // A job is tried at most this many times (claims). A transient failure or an expired lease
  // on the last attempt makes it failed. Default 5.
  int max_attempts = 5;
  // Back-off after the n-th transient failure: min(backoff_base_ms * 2^(n-1), backoff_max_ms).
  int64_t backoff_base_ms = 1000;   // default 1 s
  int64_t backoff_max_ms = 300000;  // default 5 min
  // Open read-only (SQLITE_OPEN_READONLY): reads work, every write fails with kIoError. The file
  // must exist and be at the current schema version. Default false.
  bool read_only = false;
  // > 0: PRAGMA max_page_count on every connection (a size quota; also simulates a full disk).
  // SQLite only: PostgreSQL refuses it (kInvalidInput).
  // Default 0 = unlimited.
  int64_t max_page_count = 0;
  // Connections kept open when idle. Default 16.
  int max_idle_connections = 16;
  // Create the database file's parent directory when missing. Default true.
  bool create_parent_dir = true;
  // Group commit: concurrent write calls in this process are run in one transaction (each in
  // its own savepoint, so one call's failure does not affect the others) and share one fsync.
  // At most this many calls per transaction; 1 disables batching. Default 64.
  // SQLite only (PostgreSQL commits each call in its own transaction; the server batches).
  int max_write_batch = 64;
};

// A job to enqueue (alone or with its recording).
struct NewJob {
  std::string method;       // a registered method's name (validated by the server; non-empty)
  std::string device;       // serial; "" = the upload's device (NewRecording::device), or none
  std::string config_json;  // the config as JSON text, stored verbatim; "" = "{}"
};

// A recording to store. Exactly one of `data` and `path` is used: `path` non-empty means the
// bytes are streamed from that (staged) file in 1 MiB chunks, so memory use does not depend on
// the recording's size; otherwise `data` is stored (the caller keeps it alive during the call).
struct NewRecording {
  std::string_view data;
  std::string path;
  // Optional: the lower-case hex SHA-256 of the bytes if the caller already computed it while
  // staging. A duplicate is then recognised without copying the bytes again; the stored bytes'
  // hash is still computed and must match (else kIoError: the file changed).
  std::string sha256;
  std::string device;               // serial number, "" if unknown
  std::string layout;               // formats/recording.h LayoutName (from the parser)
  int64_t rows = 0;                 // data rows
  std::string columns_json = "[]";  // JSON array of header names
  std::string sensors_json = "[]";  // JSON array of sensor / triad names
  std::string file_name;            // the client's file name, for display only
  // A binary sensor log: what was read (RecordingSummary::log_description); "" for CSV.
  std::string log_json;
  std::optional<NewJob> job;  // enqueued in the same transaction when set
};

// A failed run as the worker records it (Store::FailJob).
struct JobFailure {
  std::string code;         // the StatusCode's name ("not_determinable", ...); "" is "error"
  std::string reason;       // the reason code (server/failure_reasons.h); "" none
  std::string message;      // the method's own words: what it needed and what it found
  std::string detail_json;  // the partial diagnostics, a JSON object's text; "" none
};

// Why a holder gives its job back (Store::ReleaseJob).
enum class ReleaseKind {
  // Shutdown: the run did not count (attempts - 1), claimable at once.
  kShutdown,
  // Neither the job's outcome nor its failure could be stored (full disk): the attempt counts
  // and the job backs off as after a transient failure (now + Backoff(attempts)), so a job
  // whose outcome can never be stored is not claimed again at once, forever. Its last failure
  // (error_*) is left as it was: writing it is what did not fit.
  kStoreFailed,
};

struct JobInfo {
  int64_t id = 0;
  int64_t recording_id = 0;
  std::string method;
  std::string device;
  std::string config_json;
  JobStatus status = JobStatus::kQueued;
  int64_t attempts = 0;          // claims that counted (a shutdown ReleaseJob does not count)
  std::string lease_owner;       // "" unless running
  std::string lease_expires_at;  // "" unless running
  std::string created_at, started_at, finished_at;  // "" when unset
  int64_t lease_expires_at_ms = 0, created_at_ms = 0, started_at_ms = 0, finished_at_ms = 0;
  int64_t not_before_ms = 0;  // a queued job is not claimable before this time (back-off)
  std::string error_code;  // last failure ("" if none), e.g. "lease_expired" or the worker's code
  std::string error_message;
  // The last failure's reason code (server/failure_reasons.h, e.g. "too_few_positions"; "" none
  // recorded: a failure of the store itself such as lease_expired, or one before schema v4).
  std::string error_reason;
  // The partial diagnostics of a failed calibration: a JSON object's text ("" none). Read by
  // GetJob and by ListJobs with include_results only.
  std::string error_detail_json;
  // A cancel request (CancelJob): when, why and by whom ("" / 0: none). A running job with one
  // is being stopped; a failed one with one was cancelled.
  std::string cancel_requested_at, cancel_reason, cancel_actor;
  int64_t cancel_requested_at_ms = 0;
  std::string result_json;    // "" unless succeeded (and, for ListJobs, include_results)
  std::string result_sha256;  // hex SHA-256 of result_json, for an ETag
  // The acceptance gate (succeeded jobs only, else kNone): the gate's verdict of the result
  // (accepted | rejected), a person's later decision (none, revoked, accepted), and the state
  // that follows: accepted (served as the device's calibration when latest), rejected or
  // revoked.
  GateVerdict verdict = GateVerdict::kNone;
  Decision decision = Decision::kNone;
  ServeState state = ServeState::kNone;
  bool served() const { return state == ServeState::kAccepted; }
};

// One revoke/accept decision on a job's result (Store::RevokeJob, AcceptJob).
struct JobEvent {
  int64_t id = 0;
  int64_t job_id = 0;
  std::string action;  // "revoke" | "accept" | "cancel"
  std::string reason;  // the person's words
  std::string actor;   // who: "token" (an authenticated request) or "anonymous"
  std::string created_at;
  int64_t created_at_ms = 0;
};

struct RecordingInfo {
  int64_t id = 0;
  std::string sha256;  // lower-case hex
  int64_t bytes = 0;
  int64_t rows = 0;
  std::string layout;
  std::string device;
  std::string file_name;
  std::string created_at;
  int64_t created_at_ms = 0;
  std::string columns_json, sensors_json;  // JSON arrays as stored
  std::string log_json;                    // as NewRecording::log_json
  // {"layout": ..., "rows": ..., "columns": [...], "sensors": [...]}
  std::string summary_json;
  std::optional<JobInfo> job;  // PutRecording: the job enqueued with it, if any
};

struct JobFilter {
  std::string device;               // "" = any
  std::string method;               // "" = any
  std::optional<JobStatus> status;  // none = any
  int limit = 50;                   // 1..500 (clamped); default 50
  int64_t before = 0;               // cursor: only jobs with id < before; 0 = from the newest
  std::optional<ServeState> state;  // none = any; else JobInfo::state (implies succeeded; kNone
                                    // matches nothing)
  bool include_results = false;     // fill result_json / result_sha256 of succeeded jobs
};

struct DeviceCalibration {
  std::string method;
  int64_t job_id = 0;
  std::string calibrated_at;  // the job's finished_at
  int64_t calibrated_at_ms = 0;
};

struct DeviceInfo {
  std::string serial;
  std::string first_seen;
  int64_t first_seen_ms = 0;
  std::vector<DeviceCalibration> latest;  // one per method with a succeeded job, by method name
};

// A page of ListDevices.
struct DeviceFilter {
  std::string serial;  // "" = any; else only the device with exactly this serial
  std::string after;   // cursor: only serials after this one (byte order); "" = from the first
  bool from = false;   // true: from `after` on, itself included (>=: a prefix's range starts it)
  int limit = 100;     // 1..1000 (clamped); default 100
};

struct QueueCounts {
  int64_t queued = 0, running = 0, succeeded = 0, failed = 0;
};

class Store {
 public:
  // Opens (creating an SQLite file and its folder if needed) the database and migrates its schema
  // to the latest version (schema.h, pg_schema.cc). Safe to call from several processes at once.
  // Fails with kIoError (cannot open/create, read-only when a migration is needed), kCorruption
  // (not a database), kConflict (schema newer than this build), kBusy (locked; PostgreSQL server
  // unreachable).
  // `target` picks the backend: a PostgreSQL connection URI ("postgresql://..." or
  // "postgres://...", libpq's syntax) or a libpq keyword string (starting "KEYWORD=", e.g.
  // "host=/run/postgresql dbname=calibd") opens a PgStore (pg_store.h); anything else is an
  // SQLite file path (SqliteStore, sqlite_store.h).
  static Status Open(const std::string& target, StoreOptions options, std::unique_ptr<Store>* out);
  // True when Open would pick PostgreSQL for `target`.
  static bool IsPostgresTarget(const std::string& target);
  // Closes the pooled connections. Every call must have returned (no call may be in flight).
  virtual ~Store() = default;
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  // The file path (SQLite) or the connection target with any password replaced by "***".
  const std::string& path() const { return path_; }
  const StoreOptions& options() const { return options_; }
  // "sqlite" | "postgresql".
  virtual const char* backend() const = 0;
  // Whether the database answers now (one trivial query on a pooled connection). kBusy /
  // kIoError with the reason when it does not (server down, connection refused).
  virtual Status Ping() = 0;
  // Calls `on_job` (from a thread of the store) soon after a job becomes claimable through any
  // process on the database (PostgreSQL: LISTEN/NOTIFY), so idle workers need not poll hard.
  // Returns false when the backend has no such notification (SQLite: poll; in-process enqueues
  // are signalled by the server itself). At most one listener; nullptr removes it. The store
  // stops calling it before this returns with nullptr and before it is destroyed.
  virtual bool SetJobListener(std::function<void()> on_job) {
    (void)on_job;
    return false;
  }

  // ---- Recordings ----

  // Stores a recording unless identical bytes are already stored; then *existed = true and *out
  // describes the stored one (its id, original device and upload time). r.job, if set, is
  // enqueued against the (new or existing) recording in the same transaction; its device
  // defaults to r.device, else it has none: never the stored recording's device (a re-upload of
  // the same bytes must not silently calibrate the device they were first uploaded for). One
  // transaction: after an error nothing was stored. kInvalidInput for bad arguments
  // (columns/sensors not JSON arrays, job without method, unreadable path gives kIoError).
  // `out`/`existed` may be null.
  virtual Status PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) = 0;
  // Metadata (summary_json filled, job empty). kNotFound.
  virtual Status GetRecording(int64_t id, RecordingInfo* out) = 0;
  // Streams the original bytes to `sink` in chunks of at most 1 MiB, in order, from one
  // consistent snapshot. `sink` returns false to stop early (then the call returns OK).
  // The sink may call other Store methods (it runs on a borrowed connection). kNotFound.
  virtual Status ReadRecordingData(int64_t id,
                                   const std::function<bool(std::string_view chunk)>& sink) = 0;
  // The whole bytes in memory (small recordings, tests, the worker).
  Status ReadRecordingBytes(int64_t id, std::string* out);

  // ---- Jobs ----

  // Queues a job for a stored recording (kNotFound if it does not exist). Device "" = the
  // recording's device. The device is remembered in ListDevices.
  virtual Status EnqueueJob(int64_t recording_id, const std::string& method,
                            const std::string& device, const std::string& config_json,
                            JobInfo* out) = 0;

  // Atomically takes the oldest claimable job: queued with not_before <= now, after first taking
  // back jobs whose lease has lapsed (as RecoverExpiredLeases). The job becomes running with
  // lease_owner = worker_id, lease expiry now + lease_ms, attempts + 1, started_at = now.
  // *claimed = false (and OK) when nothing is claimable. No two callers, in any threads or
  // processes, get the same job while its lease is valid. worker_id must be unique among all
  // live workers on the file (e.g. "host:pid:n"): the lease checks compare it.
  virtual Status ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                          bool* claimed) = 0;

  // Extends the lease to now + lease_ms. The holder may renew a lapsed lease as long as nobody
  // has taken the job back. kConflict if `worker_id` does not hold the job (taken back, finished,
  // another owner); kNotFound if no such job.
  virtual Status RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) = 0;

  // Stores the result and marks the job succeeded (finished_at = now, lease cleared), stores the
  // result's SHA-256 and its verdict (the result JSON's verdict.status; anything but "rejected",
  // including no verdict, is "accepted") and, when accepted, makes it the device's latest
  // calibration for the method if it finished last. Idempotent: if the job already succeeded with
  // the identical result, OK and nothing changes (whoever calls). kConflict: the caller does not
  // hold the job (and it has not succeeded with this result), or it already succeeded with a
  // different result, or it failed. kInvalidInput: empty result. kNotFound.
  virtual Status CompleteJob(int64_t job_id, const std::string& worker_id,
                             const std::string& result_json) = 0;

  // Records a failure of the holder's run. transient = true (I/O error, busy database): back to
  // queued, not claimable before now + back-off, unless attempts >= max_attempts, then failed.
  // transient = false (the input cannot be calibrated): failed at once. The failure's fields are
  // kept on the job (error_code, error_reason, error_message, error_detail_json), stored as
  // given (the caller caps detail_json). kConflict if `worker_id` does not hold the job;
  // kNotFound.
  virtual Status FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                         bool transient) = 0;

  // Gives the job back to the queue (lease cleared), as `kind` says: kShutdown claimable at once
  // without counting the attempt; kStoreFailed counting it, not claimable before now +
  // back-off. Past max_attempts a kStoreFailed job is still queued (ending it as failed needs
  // the write that did not fit); its next failure that can be stored ends it. A job with a
  // cancel request is failed as cancelled instead. kConflict if not the holder; kNotFound.
  virtual Status ReleaseJob(int64_t job_id, const std::string& worker_id, ReleaseKind kind) = 0;

  // Takes back every running job whose lease expired before now: queued again (claimable at
  // once), or failed with error_code "lease_expired" when it already used max_attempts.
  // Call at server start. *recovered (may be null) = jobs taken back.
  virtual Status RecoverExpiredLeases(int64_t* recovered) = 0;

  // The holder of some leases is known to be dead (same host, its process gone): every running
  // job whose lease_owner starts with `owner_prefix` is taken back at once, exactly as if its
  // lease had expired now (queued again, or failed past max_attempts). Leases of live holders
  // elsewhere still run out their time. *taken_back (may be null) = jobs taken back.
  // kInvalidInput for an empty prefix.
  virtual Status ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) = 0;

  // One job with its result if succeeded. kNotFound.
  virtual Status GetJob(int64_t id, JobInfo* out) = 0;
  // Newest first (by id, which only grows: the cursor `before` is stable under inserts).
  // For the next page pass before = the last returned id.
  virtual Status ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) = 0;
  // Number of jobs matching filter's device/method/status (limit/before ignored).
  virtual Status CountJobs(const JobFilter& filter, int64_t* count) = 0;
  // Devices seen (uploads and jobs) in byte order of their serials, at most filter.limit of them
  // after filter.after, each with its latest calibration per method. For the next page pass
  // after = the last returned serial; a page shorter than the limit is the last. Memory and time
  // are bounded by the page (index range scan), whatever the number of devices.
  virtual Status ListDevices(const DeviceFilter& filter, std::vector<DeviceInfo>* out) = 0;
  // Every device: ListDevices page after page (memory grows with the number of devices; for
  // tools and tests, not for request handlers).
  Status ListDevices(std::vector<DeviceInfo>* out);
  // The device's latest served job for `method` (succeeded, accepted by the gate or a person, not
  // revoked; the one stored last: results are numbered in the order they were stored, so no host's
  // clock decides), with result_json and result_sha256. kNotFound if there is none.
  virtual Status LatestResult(const std::string& device, const std::string& method,
                              JobInfo* out) = 0;
  // Jobs per state.
  virtual Status QueueDepth(QueueCounts* out) = 0;

  // ---- The acceptance gate's decisions ----

  // Withdraws a served result (state "accepted" -> "revoked"): the device's latest calibration
  // falls back to its previous served one. Recorded as a JobEvent with `reason` and `actor`.
  // kConflict (message says why) unless the job succeeded and its result is served (a queued,
  // running or failed job has no result; a rejected one is not served; a revoked one already is);
  // kInvalidInput for an empty reason; kNotFound.
  Status RevokeJob(int64_t job_id, const std::string& reason, const std::string& actor,
                   JobEvent* out = nullptr);
  // Accepts a result the gate rejected, or re-accepts a revoked one (state -> "accepted"): it is
  // then served when it is the device's latest served one. kConflict unless the job succeeded
  // and its state is "rejected" or "revoked"; otherwise as RevokeJob.
  Status AcceptJob(int64_t job_id, const std::string& reason, const std::string& actor,
                   JobEvent* out = nullptr);

  // ---- Stopping jobs ----

  // Cancels a job, recorded as a JobEvent "cancel" with `reason` and `actor`. A queued job is
  // failed at once (error_code "stopped", error_reason "cancelled", error_message "cancelled by
  // ACTOR: REASON"). A running job gets a cancel request (JobInfo::cancel_*; the first request's
  // words are kept) for the process computing it, which sees it through CancelRequests, stops,
  // and fails it the same way; a holder that releases it instead, or whose lease lapses, leaves
  // it failed as cancelled too. `out` (may be null): the job afterwards. kConflict when the job
  // already finished (succeeded or failed: the message names its status); kInvalidInput for an
  // empty reason; kNotFound.
  Status CancelJob(int64_t job_id, const std::string& reason, const std::string& actor,
                   JobInfo* out = nullptr, JobEvent* event = nullptr);
  // Which of `job_ids` are running with a cancel request: one cheap query for all of them (a
  // worker pool asks for its running jobs a few times a second). *requested in ascending order.
  virtual Status CancelRequests(const std::vector<int64_t>& job_ids,
                                std::vector<int64_t>* requested) = 0;

  // The job's decisions and cancel requests, oldest first. kNotFound for no such job.
  virtual Status ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) = 0;

  // ---- Maintenance ----

  // *result = "ok" when the database is sound, else a report (SQLite: PRAGMA integrity_check;
  // PostgreSQL: every recording's stored bytes add up to its size).
  virtual Status IntegrityCheck(std::string* result) = 0;
  // A quicker check for a schedule: *result = "ok" when sound, else the report. SQLite: PRAGMA
  // quick_check on a fresh connection, so the file is read as it is now (every page and record's
  // structure, O(file size), no index cross-check); a check that cannot even run on a damaged
  // file gives its error as the report (and OK).
  // PostgreSQL (which checks its own pages): "ok" when the database answers (Ping).
  virtual Status QuickCheck(std::string* result) {
    Status s = Ping();
    if (s.ok()) *result = "ok";
    return s;
  }
  // SQLite: runs a WAL checkpoint (TRUNCATE), e.g. at shutdown; kBusy if readers prevent it.
  // PostgreSQL: nothing to do (OK).
  virtual Status Checkpoint() = 0;

 protected:
  Store(std::string path, StoreOptions options);
  int64_t Now() const { return options_.now_ms(); }
  // Whether options.now_ms was given (a test's clock) rather than defaulted.
  bool clock_injected() const { return clock_injected_; }
  // RevokeJob (revoke) or AcceptJob, the reason checked: one transaction that loads the job
  // (locked), checks internal::CheckDecision, stores the decision and its event and refreshes the
  // device's latest calibration. `out` may be null.
  virtual Status Decide(int64_t job_id, bool revoke, const std::string& reason,
                        const std::string& actor, JobEvent* out) = 0;
  // CancelJob, the reason checked: one transaction that loads the job (locked), checks
  // internal::CheckCancel, fails it (queued) or stores the request (running), and the event.
  virtual Status Cancel(int64_t job_id, const std::string& reason, const std::string& actor,
                        JobInfo* out, JobEvent* event) = 0;

  std::string path_;
  StoreOptions options_;

 private:
  bool clock_injected_ = false;
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_STORE_H_
