#include "storage/sqlite_store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <exception>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <utility>

#include "storage/schema.h"
#include "storage/sha256.h"
#include "storage/store_internal.h"

namespace calibd::storage {
namespace {

using internal::Backoff;
using internal::IsJsonArray;
using internal::kChunkBytes;

// A file descriptor closed on scope exit.
struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// A blob handle closed on scope exit.
struct Blob {
  sqlite3_blob* blob = nullptr;
  ~Blob() {
    if (blob != nullptr) sqlite3_blob_close(blob);
  }
  int Close() {
    int rc = blob != nullptr ? sqlite3_blob_close(blob) : SQLITE_OK;
    blob = nullptr;
    return rc;
  }
};

// Columns of a job row, in the order ReadJobRow expects. `%RESULT%` is replaced by the
// result column or NULL (constant fragments only: never user text).
constexpr const char* kJobSelect =
    "SELECT j.id, j.recording_id, j.method, j.device, j.config_json, j.status, j.attempts, "
    "j.lease_owner, j.lease_expires_at, j.created_at, j.started_at, j.finished_at, "
    "j.error_code, j.error_message, j.not_before, r.sha256, r.verdict, r.decision, ";
constexpr const char* kJobFrom = " FROM jobs j LEFT JOIN results r ON r.job_id = j.id ";

std::string JobSelect(bool with_result) {
  return std::string(kJobSelect) + (with_result ? "r.result_json" : "NULL") + ", j.error_reason, " +
         (with_result ? "j.error_detail_json" : "NULL") + kJobFrom;
}

void ReadJobRow(const Stmt& st, JobInfo* job) {
  *job = JobInfo();
  job->id = st.ColumnInt(0);
  job->recording_id = st.ColumnInt(1);
  job->method = st.ColumnText(2);
  job->device = st.ColumnText(3);
  job->config_json = st.ColumnText(4);
  job->status = st.ColumnText(5);
  job->attempts = st.ColumnInt(6);
  job->lease_owner = st.ColumnText(7);
  auto ms = [&](int col, int64_t* raw, std::string* text) {
    *raw = st.ColumnIsNull(col) ? 0 : st.ColumnInt(col);
    *text = st.ColumnIsNull(col) ? std::string() : FormatTimestamp(*raw);
  };
  ms(8, &job->lease_expires_at_ms, &job->lease_expires_at);
  ms(9, &job->created_at_ms, &job->created_at);
  ms(10, &job->started_at_ms, &job->started_at);
  ms(11, &job->finished_at_ms, &job->finished_at);
  job->error_code = st.ColumnText(12);
  job->error_message = st.ColumnText(13);
  job->not_before_ms = st.ColumnInt(14);
  if (job->status == "succeeded") {
    job->result_sha256 = st.ColumnText(15);
    job->verdict = st.ColumnText(16);
    job->decision = st.ColumnText(17);
    job->state = job->decision.empty() ? job->verdict : job->decision;
    job->result_json = st.ColumnText(18);
  }
  job->error_reason = st.ColumnText(19);
  job->error_detail_json = st.ColumnText(20);
}

constexpr const char* kRecordingSelect =
    "SELECT id, sha256, bytes, rows, layout, device, file_name, created_at, columns_json, "
    "sensors_json FROM recordings WHERE id = ?1";

Status LoadRecording(Db* db, int64_t id, RecordingInfo* out) {
  Stmt st;
  Status s = db->Prepare(kRecordingSelect, &st);
  if (!s.ok()) return s;
  st.BindInt(1, id);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) return Status::NotFound("recording " + std::to_string(id) + " not found");
  RecordingInfo info;
  info.id = st.ColumnInt(0);
  info.sha256 = st.ColumnText(1);
  info.bytes = st.ColumnInt(2);
  info.rows = st.ColumnInt(3);
  info.layout = st.ColumnText(4);
  info.device = st.ColumnText(5);
  info.file_name = st.ColumnText(6);
  info.created_at_ms = st.ColumnInt(7);
  info.created_at = FormatTimestamp(info.created_at_ms);
  info.columns_json = st.ColumnText(8);
  info.sensors_json = st.ColumnText(9);
  nlohmann::json summary;
  summary["layout"] = info.layout;
  summary["rows"] = info.rows;
  auto columns = nlohmann::json::parse(info.columns_json, nullptr, false);
  auto sensors = nlohmann::json::parse(info.sensors_json, nullptr, false);
  summary["columns"] = columns.is_discarded() ? nlohmann::json::array() : columns;
  summary["sensors"] = sensors.is_discarded() ? nlohmann::json::array() : sensors;
  info.summary_json = summary.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  *out = std::move(info);
  return Status::Ok();
}

// Id of the recording with this hash, or 0.
Status FindBySha(Db* db, const std::string& sha, int64_t* id) {
  *id = 0;
  Stmt st;
  Status s = db->Prepare("SELECT id FROM recordings WHERE sha256 = ?1", &st);
  if (!s.ok()) return s;
  st.BindText(1, sha);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (row) *id = st.ColumnInt(0);
  return Status::Ok();
}

Status RememberDevice(Db* db, const std::string& serial, int64_t now) {
  if (serial.empty()) return Status::Ok();
  Stmt st;
  Status s = db->Prepare("INSERT OR IGNORE INTO devices (serial, first_seen) VALUES (?1, ?2)", &st);
  if (!s.ok()) return s;
  st.BindText(1, serial).BindInt(2, now);
  return st.Run();
}

Status InsertRecordingRow(Db* db, const NewRecording& r, const std::string& sha, int64_t bytes,
                          int64_t now, int64_t* id) {
  Stmt st;
  Status s = db->Prepare(
      "INSERT INTO recordings (sha256, bytes, device, layout, rows, columns_json, sensors_json, "
      "file_name, created_at) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9)",
      &st);
  if (!s.ok()) return s;
  st.BindText(1, sha)
      .BindInt(2, bytes)
      .BindText(3, r.device)
      .BindText(4, r.layout)
      .BindInt(5, r.rows)
      .BindText(6, r.columns_json.empty() ? "[]" : r.columns_json)
      .BindText(7, r.sensors_json.empty() ? "[]" : r.sensors_json)
      .BindText(8, r.file_name)
      .BindInt(9, now);
  s = st.Run();
  if (!s.ok()) return s;
  *id = db->LastInsertRowid();
  return Status::Ok();
}

// Streams the staged file into a new row (inside the caller's transaction). On return *sha is
// the bytes' hash and *id the new row; the row's sha256 column is still the placeholder ''.
Status StreamFileIntoNewRow(Db* db, const NewRecording& r, int fd, int64_t size, int64_t now,
                            int64_t* id, std::string* sha) {
  Status s = InsertRecordingRow(db, r, /*sha=*/"", size, now, id);
  if (!s.ok()) return s;
  Stmt st;
  s = db->Prepare("INSERT INTO recording_data (recording_id, data) VALUES (?1, ?2)", &st);
  if (!s.ok()) return s;
  st.BindInt(1, *id).BindZeroBlob(2, size);  // zeros are not materialised in memory
  s = st.Run();
  if (!s.ok()) return s;

  Blob blob;
  int rc = sqlite3_blob_open(db->handle(), "main", "recording_data", "data", *id, /*write=*/1,
                             &blob.blob);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "open recording blob");
  std::vector<char> buffer(kChunkBytes);
  Sha256 hasher;
  int64_t offset = 0;
  for (;;) {
    ssize_t n = ::read(fd, buffer.data(), buffer.size());
    if (n < 0) {
      if (errno == EINTR) continue;
      return Status::IoError("storage: reading " + r.path + ": " + std::strerror(errno));
    }
    if (n == 0) break;
    if (offset + n > size) {
      return Status::IoError("storage: " + r.path + " grew while being stored");
    }
    hasher.Update(std::string_view(buffer.data(), static_cast<size_t>(n)));
    rc =
        sqlite3_blob_write(blob.blob, buffer.data(), static_cast<int>(n), static_cast<int>(offset));
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "write recording blob");
    offset += n;
  }
  if (offset != size) {
    return Status::IoError("storage: " + r.path + " shrank while being stored (" +
                           std::to_string(offset) + " of " + std::to_string(size) + " bytes)");
  }
  rc = blob.Close();
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "close recording blob");
  *sha = hasher.HexDigest();
  return Status::Ok();
}

}  // namespace

// ---- connection pool ----------------------------------------------------------------------------

class SqliteStore::Conn {
 public:
  explicit Conn(SqliteStore* store) : store_(store) {}
  ~Conn() {
    if (db_) store_->Return(std::move(db_));
  }
  Status Open() { return store_->Acquire(&db_); }
  Db* db() { return db_.get(); }

 private:
  SqliteStore* store_;
  std::unique_ptr<Db> db_;
};

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

// ---- recordings -------------------------------------------------------------------------------

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

// ---- recordings -------------------------------------------------------------------------------

Status SqliteStore::PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) {
  if (!r.columns_json.empty() && !IsJsonArray(r.columns_json)) {
    return Status::InvalidInput("storage: columns_json is not a JSON array");
  }
  if (!r.sensors_json.empty() && !IsJsonArray(r.sensors_json)) {
    return Status::InvalidInput("storage: sensors_json is not a JSON array");
  }
  if (r.job && r.job->method.empty()) {
    return Status::InvalidInput("storage: a job needs a method");
  }
  // Hash in-memory data on the calling thread, before queueing for the write lock.
  const std::string sha = r.path.empty() ? Sha256Hex(r.data) : r.sha256;
  RecordingInfo info;
  bool duplicate = false;
  Status s = Write([&](Db* db) { return PutRecordingLocked(db, r, sha, &info, &duplicate); });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(info);
  if (existed != nullptr) *existed = duplicate;
  return Status::Ok();
}

Status SqliteStore::PutRecordingLocked(Db* db, const NewRecording& r, const std::string& known_sha,
                                       RecordingInfo* out, bool* existed) {
  const int64_t now = Now();
  Fd file;
  int64_t size = static_cast<int64_t>(r.data.size());
  if (!r.path.empty()) {
    file.fd = ::open(r.path.c_str(), O_RDONLY | O_CLOEXEC);
    if (file.fd < 0) {
      return Status::IoError("storage: cannot open " + r.path + ": " + std::strerror(errno));
    }
    struct stat st;
    if (::fstat(file.fd, &st) != 0) {
      return Status::IoError("storage: cannot stat " + r.path + ": " + std::strerror(errno));
    }
    size = static_cast<int64_t>(st.st_size);
  }
  const int64_t limit = sqlite3_limit(db->handle(), SQLITE_LIMIT_LENGTH, -1);
  if (size > limit) {
    return Status(StatusCode::kTooLarge, "storage: recording of " + std::to_string(size) +
                                             " bytes exceeds the limit of " +
                                             std::to_string(limit));
  }
  Status s;
  int64_t id = 0;
  if (!known_sha.empty()) {
    s = FindBySha(db, known_sha, &id);
    if (!s.ok()) return s;
  }
  bool duplicate = id != 0;
  if (!duplicate && r.path.empty()) {
    s = InsertRecordingRow(db, r, known_sha, size, now, &id);
    if (!s.ok()) return s;
    Stmt st;
    s = db->Prepare("INSERT INTO recording_data (recording_id, data) VALUES (?1, ?2)", &st);
    if (!s.ok()) return s;
    st.BindInt(1, id).BindBlobNoCopy(2, r.data);
    s = st.Run();
    if (!s.ok()) return s;
  } else if (!duplicate) {
    // Single pass over the file: write and hash, then either keep the row or, if the bytes turn
    // out to be stored already, roll back to the savepoint.
    s = db->Exec("SAVEPOINT put_recording");
    if (!s.ok()) return s;
    std::string streamed_sha;
    s = StreamFileIntoNewRow(db, r, file.fd, size, now, &id, &streamed_sha);
    if (!s.ok()) return s;  // the caller's savepoint rolls everything back
    if (!r.sha256.empty() && r.sha256 != streamed_sha) {
      return Status::IoError("storage: " + r.path + " does not match its announced sha256 (" +
                             r.sha256 + " != " + streamed_sha + "): it changed while staged");
    }
    int64_t existing = 0;
    s = FindBySha(db, streamed_sha, &existing);
    if (!s.ok()) return s;
    if (existing != 0) {
      s = db->Exec("ROLLBACK TO put_recording; RELEASE put_recording");
      if (!s.ok()) return s;
      id = existing;
      duplicate = true;
    } else {
      Stmt st;
      s = db->Prepare("UPDATE recordings SET sha256 = ?1 WHERE id = ?2", &st);
      if (!s.ok()) return s;
      st.BindText(1, streamed_sha).BindInt(2, id);
      s = st.Run();
      if (!s.ok()) return s;
      s = db->Exec("RELEASE put_recording");
      if (!s.ok()) return s;
    }
  }
  s = RememberDevice(db, r.device, now);
  if (!s.ok()) return s;

  RecordingInfo info;
  s = LoadRecording(db, id, &info);
  if (!s.ok()) return s;
  if (r.job) {
    JobInfo job;
    // The job is for the device this upload names, or none: never the device of identical bytes
    // uploaded before (a re-upload must not move a recording's calibrations to its old device).
    const std::string& device = !r.job->device.empty() ? r.job->device : r.device;
    s = EnqueueJobLocked(db, id, r.job->method, device, r.job->config_json, now, &job,
                         /*inherit_device=*/false);
    if (!s.ok()) return s;
    info.job = std::move(job);
  }
  *out = std::move(info);
  *existed = duplicate;
  return Status::Ok();
}

Status SqliteStore::GetRecording(int64_t id, RecordingInfo* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  return LoadRecording(conn.db(), id, out);
}

Status SqliteStore::ReadRecordingData(int64_t id,
                                      const std::function<bool(std::string_view chunk)>& sink) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Db* db = conn.db();
  // The open blob handle keeps one read transaction (snapshot) for the whole stream.
  Blob blob;
  int rc = sqlite3_blob_open(db->handle(), "main", "recording_data", "data", id, /*write=*/0,
                             &blob.blob);
  if (rc != SQLITE_OK) {
    Status open_error = StatusFromSqlite(rc, db->handle(), "open recording blob");
    RecordingInfo unused;
    s = LoadRecording(db, id, &unused);
    if (s.code() == StatusCode::kNotFound) return s;
    return open_error;
  }
  const int64_t size = sqlite3_blob_bytes(blob.blob);
  std::vector<char> buffer(static_cast<size_t>(std::min<int64_t>(size, kChunkBytes)));
  for (int64_t offset = 0; offset < size;) {
    int n = static_cast<int>(std::min<int64_t>(size - offset, kChunkBytes));
    rc = sqlite3_blob_read(blob.blob, buffer.data(), n, static_cast<int>(offset));
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "read recording blob");
    offset += n;
    if (!sink(std::string_view(buffer.data(), static_cast<size_t>(n)))) break;
  }
  rc = blob.Close();
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "close recording blob");
  return Status::Ok();
}

// ---- jobs -------------------------------------------------------------------------------------

namespace {

// Makes device_calibrations hold the device's latest served result for the method (succeeded,
// accepted by the gate or a person, not revoked), or nothing.
Status RefreshLatest(Db* db, const std::string& device, const std::string& method) {
  Stmt st;
  Status s = db->Prepare("DELETE FROM device_calibrations WHERE device = ?1 AND method = ?2", &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  s = st.Run();
  if (!s.ok()) return s;
  s = db->Prepare(
      "INSERT INTO device_calibrations (device, method, job_id, calibrated_at) "
      "SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) "
      "FROM jobs j JOIN results r ON r.job_id = j.id "
      "WHERE j.device = ?1 AND j.method = ?2 AND j.status = 'succeeded' "
      "AND COALESCE(r.decision, r.verdict) = 'accepted' "
      "ORDER BY COALESCE(j.finished_at, j.created_at) DESC, j.id DESC LIMIT 1",
      &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  return st.Run();
}

}  // namespace

Status SqliteStore::LoadJob(Db* db, int64_t id, bool with_result, JobInfo* out) {
  Stmt st;
  Status s = db->Prepare(JobSelect(with_result) + "WHERE j.id = ?1", &st);
  if (!s.ok()) return s;
  st.BindInt(1, id);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) return Status::NotFound("job " + std::to_string(id) + " not found");
  ReadJobRow(st, out);
  return Status::Ok();
}

Status SqliteStore::EnqueueJobLocked(Db* db, int64_t recording_id, const std::string& method,
                                     const std::string& device, const std::string& config_json,
                                     int64_t now, JobInfo* out, bool inherit_device) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  RecordingInfo rec;
  Status s = LoadRecording(db, recording_id, &rec);
  if (!s.ok()) return s;
  const std::string& job_device = device.empty() && inherit_device ? rec.device : device;
  Stmt st;
  s = db->Prepare(
      "INSERT INTO jobs (recording_id, method, device, config_json, status, attempts, "
      "created_at, not_before) VALUES (?1, ?2, ?3, ?4, 'queued', 0, ?5, ?5)",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, recording_id)
      .BindText(2, method)
      .BindText(3, job_device)
      .BindText(4, config_json.empty() ? "{}" : config_json)
      .BindInt(5, now);
  s = st.Run();
  if (!s.ok()) return s;
  int64_t id = db->LastInsertRowid();
  s = RememberDevice(db, job_device, now);
  if (!s.ok()) return s;
  return LoadJob(db, id, false, out);
}

Status SqliteStore::EnqueueJob(int64_t recording_id, const std::string& method,
                               const std::string& device, const std::string& config_json,
                               JobInfo* out) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  JobInfo job;
  Status s = Write([&](Db* db) {
    return EnqueueJobLocked(db, recording_id, method, device, config_json, Now(), &job);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  return Status::Ok();
}

Status SqliteStore::RecoverLocked(Db* db, int64_t now, int64_t* recovered) {
  int64_t total = 0;
  Stmt st;
  // Out of attempts: failed for good.
  Status s = db->Prepare(
      "UPDATE jobs SET status = 'failed', finished_at = ?1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || "
      "' expired on attempt ' || attempts || ' of ' || ?2 || '; giving up' "
      "WHERE status = 'running' AND lease_expires_at <= ?1 AND attempts >= ?2",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, now).BindInt(2, options_.max_attempts);
  s = st.Run();
  if (!s.ok()) return s;
  total += db->Changes();
  // Otherwise: back in the queue, claimable at once.
  s = db->Prepare(
      "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
      "started_at = NULL, not_before = ?1, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || ' expired' "
      "WHERE status = 'running' AND lease_expires_at <= ?1",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, now);
  s = st.Run();
  if (!s.ok()) return s;
  total += db->Changes();
  if (recovered != nullptr) *recovered = total;
  return Status::Ok();
}

Status SqliteStore::RecoverExpiredLeases(int64_t* recovered) {
  int64_t n = 0;
  Status s = Write([&](Db* db) { return RecoverLocked(db, Now(), &n); });
  if (!s.ok()) return s;
  if (recovered != nullptr) *recovered = n;
  return Status::Ok();
}

Status SqliteStore::ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) {
  if (owner_prefix.empty()) return Status::InvalidInput("storage: owner_prefix must not be empty");
  int64_t n = 0;
  Status s = Write([&](Db* db) {
    const int64_t now = Now();
    Stmt st;
    Status s = db->Prepare(
        "UPDATE jobs SET lease_expires_at = ?1 WHERE status = 'running' AND "
        "substr(lease_owner, 1, length(?2)) = ?2 AND lease_expires_at > ?1",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, now).BindText(2, owner_prefix);
    s = st.Run();
    if (!s.ok()) return s;
    n = db->Changes();
    return n > 0 ? RecoverLocked(db, now, nullptr) : Status::Ok();
  });
  if (!s.ok()) return s;
  if (taken_back != nullptr) *taken_back = n;
  return Status::Ok();
}

Status SqliteStore::ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                             bool* claimed) {
  *claimed = false;
  if (worker_id.empty()) return Status::InvalidInput("storage: worker_id must not be empty");
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  {
    // Cheap check without the write lock, so idle workers polling do not serialise on it.
    Conn conn(this);
    Status s = conn.Open();
    if (!s.ok()) return s;
    Stmt st;
    s = conn.db()->Prepare(
        "SELECT EXISTS (SELECT 1 FROM jobs WHERE status = 'queued' AND not_before <= ?1) "
        "OR EXISTS (SELECT 1 FROM jobs WHERE status = 'running' AND lease_expires_at <= ?1)",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, Now());
    bool row = false;
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row || st.ColumnInt(0) == 0) return Status::Ok();
  }
  JobInfo job;
  bool got = false;
  Status s = Write([&](Db* db) {
    got = false;
    const int64_t now = Now();
    Status s = RecoverLocked(db, now, nullptr);
    if (!s.ok()) return s;
    int64_t id = 0;
    {
      Stmt st;
      s = db->Prepare(
          "SELECT id FROM jobs WHERE status = 'queued' AND not_before <= ?1 ORDER BY id LIMIT 1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, now);
      bool row = false;
      s = st.Step(&row);
      if (!s.ok()) return s;
      if (row) id = st.ColumnInt(0);
    }
    if (id == 0) return Status::Ok();
    Stmt st;
    s = db->Prepare(
        "UPDATE jobs SET status = 'running', lease_owner = ?2, lease_expires_at = ?3, "
        "attempts = attempts + 1, started_at = ?4, finished_at = NULL "
        "WHERE id = ?1 AND status = 'queued'",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, id).BindText(2, worker_id).BindInt(3, now + lease_ms).BindInt(4, now);
    s = st.Run();
    if (!s.ok()) return s;
    s = LoadJob(db, id, false, &job);
    if (!s.ok()) return s;
    got = true;
    return Status::Ok();
  });
  if (!s.ok()) return s;
  if (got) {
    *claimed = true;
    if (out != nullptr) *out = std::move(job);
  }
  return Status::Ok();
}

Status SqliteStore::RequireHolder(Db* db, int64_t job_id, const std::string& worker_id,
                                  const char* action, JobInfo* job) {
  Status s = LoadJob(db, job_id, false, job);
  if (!s.ok()) return s;
  if (job->status != "running") {
    return Status::Conflict("cannot " + std::string(action) + " job " + std::to_string(job_id) +
                            ": it is " + job->status + ", not running");
  }
  if (job->lease_owner != worker_id) {
    return Status::Conflict("cannot " + std::string(action) + " job " + std::to_string(job_id) +
                            ": it is leased by " + job->lease_owner + ", not " + worker_id);
  }
  return Status::Ok();
}

Status SqliteStore::RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) {
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Write([&](Db* db) {
    Stmt st;
    Status s = db->Prepare(
        "UPDATE jobs SET lease_expires_at = ?3 "
        "WHERE id = ?1 AND status = 'running' AND lease_owner = ?2",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, worker_id).BindInt(3, Now() + lease_ms);
    s = st.Run();
    if (!s.ok()) return s;
    if (db->Changes() == 1) return Status::Ok();
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "renew the lease of", &job);
    if (!s.ok()) return s;
    return Status::Conflict("cannot renew the lease of job " + std::to_string(job_id));
  });
}

Status SqliteStore::CompleteJob(int64_t job_id, const std::string& worker_id,
                                const std::string& result_json) {
  if (result_json.empty()) return Status::InvalidInput("storage: empty result");
  const std::string sha = Sha256Hex(result_json);
  return Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = LoadJob(db, job_id, false, &job);
    if (!s.ok()) return s;
    if (job.status == "succeeded") {
      if (job.result_sha256 == sha) return Status::Ok();  // the same run again: nothing to do
      return Status::Conflict("job " + std::to_string(job_id) +
                              " already succeeded with a different result");
    }
    s = RequireHolder(db, job_id, worker_id, "complete", &job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    Stmt st;
    // The gate's verdict, read from the result (anything but "rejected" counts as accepted).
    s = db->Prepare(
        "INSERT INTO results (job_id, result_json, sha256, created_at, verdict) VALUES (?1, ?2, "
        "?3, ?4, CASE WHEN (CASE WHEN json_valid(?2) THEN json_extract(?2, '$.verdict.status') "
        "END) = 'rejected' THEN 'rejected' ELSE 'accepted' END)",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindText(2, result_json).BindText(3, sha).BindInt(4, now);
    s = st.Run();
    if (!s.ok()) return s;
    s = db->Prepare(
        "UPDATE jobs SET status = 'succeeded', finished_at = ?2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = NULL, error_message = NULL, error_reason = NULL, "
        "error_detail_json = NULL WHERE id = ?1",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindInt(2, now);
    s = st.Run();
    if (!s.ok()) return s;
    if (!job.device.empty()) {
      s = RememberDevice(db, job.device, now);
      if (!s.ok()) return s;
      s = RefreshLatest(db, job.device, job.method);
      if (!s.ok()) return s;
    }
    return Status::Ok();
  });
}

Status SqliteStore::FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                            bool transient) {
  return Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "fail", &job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    const std::string error_code = failure.code.empty() ? std::string("error") : failure.code;
    auto bind_failure = [&](Stmt* st, const std::string& message) {
      st->BindText(3, error_code).BindText(4, message);
      if (failure.reason.empty()) {
        st->BindNull(5);
      } else {
        st->BindText(5, failure.reason);
      }
      if (failure.detail_json.empty()) {
        st->BindNull(6);
      } else {
        st->BindText(6, failure.detail_json);
      }
    };
    Stmt st;
    if (transient && job.attempts < options_.max_attempts) {
      s = db->Prepare(
          "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
          "started_at = NULL, not_before = ?2, error_code = ?3, error_message = ?4, "
          "error_reason = ?5, error_detail_json = ?6 WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id).BindInt(2, now + Backoff(options_, job.attempts));
      bind_failure(&st, failure.message);
    } else {
      std::string final_message = failure.message;
      if (transient) {
        final_message =
            "gave up after " + std::to_string(job.attempts) + " attempts: " + failure.message;
      }
      s = db->Prepare(
          "UPDATE jobs SET status = 'failed', finished_at = ?2, lease_owner = NULL, "
          "lease_expires_at = NULL, error_code = ?3, error_message = ?4, error_reason = ?5, "
          "error_detail_json = ?6 WHERE id = ?1",
          &st);
      if (!s.ok()) return s;
      st.BindInt(1, job_id).BindInt(2, now);
      bind_failure(&st, final_message);
    }
    s = st.Run();
    if (!s.ok()) return s;
    return Status::Ok();
  });
}

Status SqliteStore::ReleaseJob(int64_t job_id, const std::string& worker_id) {
  return Write([&](Db* db) {
    Status s;
    JobInfo job;
    s = RequireHolder(db, job_id, worker_id, "release", &job);
    if (!s.ok()) return s;
    Stmt st;
    s = db->Prepare(
        "UPDATE jobs SET status = 'queued', attempts = MAX(attempts - 1, 0), lease_owner = NULL, "
        "lease_expires_at = NULL, started_at = NULL, not_before = ?2 WHERE id = ?1",
        &st);
    if (!s.ok()) return s;
    st.BindInt(1, job_id).BindInt(2, Now());
    s = st.Run();
    if (!s.ok()) return s;
    return Status::Ok();
  });
}

Status SqliteStore::GetJob(int64_t id, JobInfo* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  return LoadJob(conn.db(), id, true, out);
}

namespace {

// WHERE clause from constant fragments; the values are bound by BindFilter in the same order.
Status FilterSql(const JobFilter& f, bool with_cursor, std::string* where) {
  Status valid = internal::ValidateFilter(f);
  if (!valid.ok()) return valid;
  *where = "WHERE 1 ";
  int n = 0;
  if (!f.device.empty()) *where += "AND j.device = ?" + std::to_string(++n) + " ";
  if (!f.method.empty()) *where += "AND j.method = ?" + std::to_string(++n) + " ";
  if (!f.status.empty()) *where += "AND j.status = ?" + std::to_string(++n) + " ";
  if (!f.state.empty()) {
    *where += "AND j.status = 'succeeded' AND COALESCE(r.decision, r.verdict) = ?" +
              std::to_string(++n) + " ";
  }
  if (with_cursor && f.before > 0) *where += "AND j.id < ?" + std::to_string(++n) + " ";
  return Status::Ok();
}

int BindFilter(Stmt* st, const JobFilter& f, bool with_cursor) {
  int n = 0;
  if (!f.device.empty()) st->BindText(++n, f.device);
  if (!f.method.empty()) st->BindText(++n, f.method);
  if (!f.status.empty()) st->BindText(++n, f.status);
  if (!f.state.empty()) st->BindText(++n, f.state);
  if (with_cursor && f.before > 0) st->BindInt(++n, f.before);
  return n;
}

}  // namespace

Status SqliteStore::ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) {
  out->clear();
  std::string where;
  Status s = FilterSql(filter, true, &where);
  if (!s.ok()) return s;
  const int limit = std::clamp(filter.limit <= 0 ? 50 : filter.limit, 1, 500);
  Conn conn(this);
  s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  const int limit_param = 1 + (!filter.device.empty()) + (!filter.method.empty()) +
                          (!filter.status.empty()) + (!filter.state.empty()) + (filter.before > 0);
  s = conn.db()->Prepare(JobSelect(filter.include_results) + where + "ORDER BY j.id DESC LIMIT ?" +
                             std::to_string(limit_param),
                         &st);
  if (!s.ok()) return s;
  int n = BindFilter(&st, filter, true);
  st.BindInt(n + 1, limit);
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    JobInfo job;
    ReadJobRow(st, &job);
    out->push_back(std::move(job));
  }
  return Status::Ok();
}

Status SqliteStore::CountJobs(const JobFilter& filter, int64_t* count) {
  std::string where;
  Status s = FilterSql(filter, false, &where);
  if (!s.ok()) return s;
  Conn conn(this);
  s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      "SELECT COUNT(*) FROM jobs j LEFT JOIN results r ON r.job_id = j.id " + where, &st);
  if (!s.ok()) return s;
  BindFilter(&st, filter, false);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  *count = row ? st.ColumnInt(0) : 0;
  return Status::Ok();
}

Status SqliteStore::ListDevices(std::vector<DeviceInfo>* out) {
  out->clear();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
      "FROM devices d LEFT JOIN device_calibrations c ON c.device = d.serial "
      "ORDER BY d.serial, c.method",
      &st);
  if (!s.ok()) return s;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    std::string serial = st.ColumnText(0);
    if (out->empty() || out->back().serial != serial) {
      DeviceInfo d;
      d.serial = serial;
      d.first_seen_ms = st.ColumnInt(1);
      d.first_seen = FormatTimestamp(d.first_seen_ms);
      out->push_back(std::move(d));
    }
    if (!st.ColumnIsNull(2)) {
      DeviceCalibration c;
      c.method = st.ColumnText(2);
      c.job_id = st.ColumnInt(3);
      c.calibrated_at_ms = st.ColumnInt(4);
      c.calibrated_at = FormatTimestamp(c.calibrated_at_ms);
      out->back().latest.push_back(std::move(c));
    }
  }
  return Status::Ok();
}

Status SqliteStore::LatestResult(const std::string& device, const std::string& method,
                                 JobInfo* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      JobSelect(true) +
          "WHERE j.id = (SELECT job_id FROM device_calibrations WHERE device = ?1 AND method = ?2)",
      &st);
  if (!s.ok()) return s;
  st.BindText(1, device).BindText(2, method);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) {
    return Status::NotFound("no succeeded " + method + " calibration for device " + device);
  }
  ReadJobRow(st, out);
  return Status::Ok();
}

Status SqliteStore::QueueDepth(QueueCounts* out) {
  *out = QueueCounts();
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare("SELECT status, COUNT(*) FROM jobs GROUP BY status", &st);
  if (!s.ok()) return s;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    std::string status = st.ColumnText(0);
    int64_t n = st.ColumnInt(1);
    if (status == "queued") out->queued = n;
    if (status == "running") out->running = n;
    if (status == "succeeded") out->succeeded = n;
    if (status == "failed") out->failed = n;
  }
  return Status::Ok();
}

// ---- the acceptance gate's decisions ------------------------------------------------------------

Status SqliteStore::DecideLocked(Db* db, int64_t job_id, const std::string& action,
                                 const std::string& reason, const std::string& actor,
                                 JobEvent* out) {
  JobInfo job;
  Status s = LoadJob(db, job_id, false, &job);
  if (!s.ok()) return s;
  const std::string id = "job " + std::to_string(job_id);
  const bool revoke = action == "revoke";
  if (job.status != "succeeded") {
    return Status::Conflict(id + " is " + job.status + ": it has no result to " + action);
  }
  if (revoke && job.state == "revoked") return Status::Conflict(id + " is already revoked");
  if (revoke && job.state == "rejected") {
    return Status::Conflict(id +
                            " was rejected by the acceptance gate and is not served: "
                            "there is nothing to revoke");
  }
  if (!revoke && job.state == "accepted") {
    return Status::Conflict(
        id + " is already accepted" +
        (job.decision.empty() ? std::string(" by the acceptance gate") : std::string()));
  }
  const int64_t now = Now();
  Stmt st;
  s = db->Prepare("UPDATE results SET decision = ?2 WHERE job_id = ?1", &st);
  if (!s.ok()) return s;
  st.BindInt(1, job_id).BindText(2, revoke ? "revoked" : "accepted");
  s = st.Run();
  if (!s.ok()) return s;
  s = db->Prepare(
      "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
      "VALUES (?1, ?2, ?3, ?4, ?5)",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, job_id).BindText(2, action).BindText(3, reason).BindText(4, actor).BindInt(5, now);
  s = st.Run();
  if (!s.ok()) return s;
  JobEvent event;
  event.id = db->LastInsertRowid();
  event.job_id = job_id;
  event.action = action;
  event.reason = reason;
  event.actor = actor;
  event.created_at_ms = now;
  event.created_at = FormatTimestamp(now);
  if (!job.device.empty()) {
    s = RefreshLatest(db, job.device, job.method);
    if (!s.ok()) return s;
  }
  if (out != nullptr) *out = std::move(event);
  return Status::Ok();
}

Status SqliteStore::RevokeJob(int64_t job_id, const std::string& reason, const std::string& actor,
                              JobEvent* out) {
  if (reason.empty())
    return Status::InvalidInput("a revocation needs a reason").WithField("reason");
  JobEvent event;
  Status s =
      Write([&](Db* db) { return DecideLocked(db, job_id, "revoke", reason, actor, &event); });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status SqliteStore::AcceptJob(int64_t job_id, const std::string& reason, const std::string& actor,
                              JobEvent* out) {
  if (reason.empty())
    return Status::InvalidInput("an acceptance needs a reason").WithField("reason");
  JobEvent event;
  Status s =
      Write([&](Db* db) { return DecideLocked(db, job_id, "accept", reason, actor, &event); });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status SqliteStore::ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  JobInfo job;
  s = LoadJob(conn.db(), job_id, false, &job);
  if (!s.ok()) return s;
  Stmt st;
  s = conn.db()->Prepare(
      "SELECT id, job_id, action, reason, actor, created_at FROM job_events WHERE job_id = ?1 "
      "ORDER BY id",
      &st);
  if (!s.ok()) return s;
  st.BindInt(1, job_id);
  std::vector<JobEvent> events;
  for (bool row = true;;) {
    s = st.Step(&row);
    if (!s.ok()) return s;
    if (!row) break;
    JobEvent e;
    e.id = st.ColumnInt(0);
    e.job_id = st.ColumnInt(1);
    e.action = st.ColumnText(2);
    e.reason = st.ColumnText(3);
    e.actor = st.ColumnText(4);
    e.created_at_ms = st.ColumnInt(5);
    e.created_at = FormatTimestamp(e.created_at_ms);
    events.push_back(std::move(e));
  }
  *out = std::move(events);
  return Status::Ok();
}

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

namespace calibd::storage {

Status SqliteStore::Ping() {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  int64_t version = 0;
  return SchemaVersion(conn.db(), &version);
}

}  // namespace calibd::storage
