#include "storage/pg_store.h"

#include <fcntl.h>
#include <libpq-fe.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <exception>
#include <nlohmann/json.hpp>
#include <utility>

#include "storage/pg_conn.h"
#include "storage/sha256.h"
#include "storage/store_internal.h"

namespace calibd::storage {
namespace {

using internal::kChunkBytes;

constexpr const char* kJobsChannel = "calibd_jobs";

struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

// Reads up to `n` bytes (fewer only at the end of the file).
Status ReadFull(int fd, char* buf, size_t n, const std::string& path, size_t* got) {
  *got = 0;
  while (*got < n) {
    ssize_t k = ::read(fd, buf + *got, n - *got);
    if (k < 0) {
      if (errno == EINTR) continue;
      return Status::IoError("storage: reading " + path + ": " + std::strerror(errno));
    }
    if (k == 0) break;
    *got += static_cast<size_t>(k);
  }
  return Status::Ok();
}

Status HashFile(const std::string& path, std::string* sha) {
  Fd f;
  f.fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (f.fd < 0)
    return Status::IoError("storage: cannot open " + path + ": " + std::strerror(errno));
  std::vector<char> buf(kChunkBytes);
  Sha256 hasher;
  for (;;) {
    size_t got = 0;
    Status s = ReadFull(f.fd, buf.data(), buf.size(), path, &got);
    if (!s.ok()) return s;
    if (got == 0) break;
    hasher.Update(std::string_view(buf.data(), got));
  }
  *sha = hasher.HexDigest();
  return Status::Ok();
}

// Job columns in the order ReadJob expects; `%s` the result column or NULL.
constexpr const char* kJobColumns =
    "SELECT j.id, j.recording_id, j.method, j.device, j.config_json, j.status, j.attempts, "
    "j.lease_owner, j.lease_expires_at, j.created_at, j.started_at, j.finished_at, "
    "j.error_code, j.error_message, j.not_before, r.sha256, r.verdict, r.decision, ";
constexpr const char* kJobFrom = " FROM jobs j LEFT JOIN results r ON r.job_id = j.id ";

std::string JobSelect(bool with_result) {
  return std::string(kJobColumns) + (with_result ? "r.result_json" : "NULL") +
         ", j.error_reason, " + (with_result ? "j.error_detail_json" : "NULL") + kJobFrom;
}

void ReadJob(const PgResult& r, int row, JobInfo* job) {
  *job = JobInfo();
  job->id = r.Int(row, 0);
  job->recording_id = r.Int(row, 1);
  job->method = r.Text(row, 2);
  job->device = r.Text(row, 3);
  job->config_json = r.Text(row, 4);
  job->status = r.Text(row, 5);
  job->attempts = r.Int(row, 6);
  job->lease_owner = r.Text(row, 7);
  auto ms = [&](int col, int64_t* raw, std::string* text) {
    *raw = r.Int(row, col);
    *text = r.IsNull(row, col) ? std::string() : FormatTimestamp(*raw);
  };
  ms(8, &job->lease_expires_at_ms, &job->lease_expires_at);
  ms(9, &job->created_at_ms, &job->created_at);
  ms(10, &job->started_at_ms, &job->started_at);
  ms(11, &job->finished_at_ms, &job->finished_at);
  job->error_code = r.Text(row, 12);
  job->error_message = r.Text(row, 13);
  job->not_before_ms = r.Int(row, 14);
  if (job->status == "succeeded") {
    job->result_sha256 = r.Text(row, 15);
    job->verdict = r.Text(row, 16);
    job->decision = r.Text(row, 17);
    job->state = job->decision.empty() ? job->verdict : job->decision;
    job->result_json = r.Text(row, 18);
  }
  job->error_reason = r.Text(row, 19);
  job->error_detail_json = r.Text(row, 20);
}

// for_update: lock the job row (SELECT ... FOR UPDATE OF j) until the transaction ends.
Status LoadJob(PgConn* c, int64_t id, bool with_result, JobInfo* out, bool for_update = false) {
  const std::string sql =
      JobSelect(with_result) + "WHERE j.id = $1" + (for_update ? " FOR UPDATE OF j" : "");
  PgResult r;
  Status s = c->Exec(sql.c_str(), {PgInt(id)}, &r);
  if (!s.ok()) return s;
  if (r.rows() == 0) return Status::NotFound("job " + std::to_string(id) + " not found");
  ReadJob(r, 0, out);
  return Status::Ok();
}

Status LoadRecording(PgConn* c, int64_t id, RecordingInfo* out) {
  PgResult r;
  Status s = c->Exec(
      "SELECT id, sha256, bytes, rows, layout, device, file_name, created_at, columns_json, "
      "sensors_json FROM recordings WHERE id = $1",
      {PgInt(id)}, &r);
  if (!s.ok()) return s;
  if (r.rows() == 0) return Status::NotFound("recording " + std::to_string(id) + " not found");
  RecordingInfo info;
  info.id = r.Int(0, 0);
  info.sha256 = r.Text(0, 1);
  info.bytes = r.Int(0, 2);
  info.rows = r.Int(0, 3);
  info.layout = r.Text(0, 4);
  info.device = r.Text(0, 5);
  info.file_name = r.Text(0, 6);
  info.created_at_ms = r.Int(0, 7);
  info.created_at = FormatTimestamp(info.created_at_ms);
  info.columns_json = r.Text(0, 8);
  info.sensors_json = r.Text(0, 9);
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

Status RememberDevice(PgConn* c, const std::string& serial, int64_t now) {
  if (serial.empty()) return Status::Ok();
  return c->Exec(
      "INSERT INTO devices (serial, first_seen) VALUES ($1, $2) ON CONFLICT (serial) DO NOTHING",
      {PgText(serial), PgInt(now)});
}

// Makes device_calibrations hold the device's latest served result for the method. Serialised
// per (device, method) by an advisory lock, so that concurrent completions on several hosts
// each see the other's committed result (READ COMMITTED: every statement after the lock takes a
// fresh snapshot) and never insert the same key twice.
Status RefreshLatest(PgConn* c, const std::string& device, const std::string& method) {
  Status s = c->Exec("SELECT pg_advisory_xact_lock(hashtextextended($1 || chr(31) || $2, 0))",
                     {PgText(device), PgText(method)});
  if (!s.ok()) return s;
  s = c->Exec("DELETE FROM device_calibrations WHERE device = $1 AND method = $2",
              {PgText(device), PgText(method)});
  if (!s.ok()) return s;
  return c->Exec(
      "INSERT INTO device_calibrations (device, method, job_id, calibrated_at) "
      "SELECT j.device, j.method, j.id, COALESCE(j.finished_at, j.created_at) "
      "FROM jobs j JOIN results r ON r.job_id = j.id "
      "WHERE j.device = $1 AND j.method = $2 AND j.status = 'succeeded' "
      "AND COALESCE(r.decision, r.verdict) = 'accepted' "
      "ORDER BY COALESCE(j.finished_at, j.created_at) DESC, j.id DESC LIMIT 1",
      {PgText(device), PgText(method)});
}

// Listeners are woken after the transaction commits (PgStore::Txn).
Status NotifyJobs(PgConn* c) {
  c->notify_after_commit = true;
  return Status::Ok();
}

// WHERE clause with $n placeholders; the values in the same order from FilterParams.
std::string FilterSql(const JobFilter& f, bool with_cursor, int* n) {
  std::string where = "WHERE TRUE ";
  if (!f.device.empty()) where += "AND j.device = $" + std::to_string(++*n) + " ";
  if (!f.method.empty()) where += "AND j.method = $" + std::to_string(++*n) + " ";
  if (!f.status.empty()) where += "AND j.status = $" + std::to_string(++*n) + " ";
  if (!f.state.empty()) {
    where += "AND j.status = 'succeeded' AND COALESCE(r.decision, r.verdict) = $" +
             std::to_string(++*n) + " ";
  }
  if (with_cursor && f.before > 0) where += "AND j.id < $" + std::to_string(++*n) + " ";
  return where;
}

std::vector<PgParam> FilterParams(const JobFilter& f, bool with_cursor) {
  std::vector<PgParam> p;
  if (!f.device.empty()) p.push_back(PgText(f.device));
  if (!f.method.empty()) p.push_back(PgText(f.method));
  if (!f.status.empty()) p.push_back(PgText(f.status));
  if (!f.state.empty()) p.push_back(PgText(f.state));
  if (with_cursor && f.before > 0) p.push_back(PgInt(f.before));
  return p;
}

}  // namespace

std::string RedactConnectionTarget(const std::string& target) {
  std::string out = target;
  // URI: scheme://user:password@host...
  size_t scheme = out.find("://");
  if (scheme != std::string::npos) {
    size_t start = scheme + 3;
    size_t at = out.find('@', start);
    size_t slash = out.find('/', start);
    if (at != std::string::npos && (slash == std::string::npos || at < slash)) {
      size_t colon = out.find(':', start);
      if (colon != std::string::npos && colon < at) out.replace(colon + 1, at - colon - 1, "***");
    }
  }
  // password=... in a keyword string or a URI's query.
  for (size_t pos = 0; (pos = out.find("password=", pos)) != std::string::npos;) {
    size_t start = pos + 9;
    size_t end = out.find_first_of(" &", start);
    if (end == std::string::npos) end = out.size();
    out.replace(start, end - start, "***");
    pos = start + 3;
  }
  return out;
}

// ---- connections ----------------------------------------------------------------------------

class PgStore::Lease {
 public:
  explicit Lease(PgStore* store) : store_(store) {}
  ~Lease() {
    if (conn_) store_->Return(std::move(conn_));
  }
  Status Open() { return store_->Acquire(&conn_, &pooled_); }
  PgConn* get() { return conn_.get(); }
  // The connection was idle in the pool (it may have died there: server restarted) and is
  // broken now: the call may run again on a fresh one, once, if nothing of it took effect.
  bool StaleFromPool() const { return pooled_ && conn_ && conn_->broken(); }

 private:
  PgStore* store_;
  std::unique_ptr<PgConn> conn_;
  bool pooled_ = false;
};

PgStore::PgStore(std::string target, StoreOptions options)
    : Store(RedactConnectionTarget(target), std::move(options)), target_(std::move(target)) {}

PgStore::~PgStore() { SetJobListener(nullptr); }

Status PgStore::NewConnection(std::unique_ptr<PgConn>* out) {
  std::unique_ptr<PgConn> c;
  Status s = PgConn::Connect(target_, path_, &c);
  if (!s.ok()) return s;
  // Lock waits end with kBusy after busy_timeout_ms, as with SQLite; UTC, plain strings.
  std::string setup =
      "SET lock_timeout = " + std::to_string(std::max(options_.busy_timeout_ms, 1)) +
      "; SET client_encoding = 'UTF8'";
  if (options_.read_only) setup += "; SET default_transaction_read_only = on";
  s = c->ExecScript(setup.c_str());
  if (!s.ok()) return s;
  *out = std::move(c);
  return Status::Ok();
}

Status PgStore::Acquire(std::unique_ptr<PgConn>* out, bool* pooled) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!idle_.empty()) {
      *out = std::move(idle_.back());
      idle_.pop_back();
      *pooled = true;
      return Status::Ok();
    }
  }
  *pooled = false;
  return NewConnection(out);
}

void PgStore::Return(std::unique_ptr<PgConn> conn) {
  if (!conn->broken() && conn->InTransaction()) (void)conn->ExecScript("ROLLBACK");
  std::lock_guard<std::mutex> lock(mu_);
  if (conn->broken()) {
    // The server went away or restarted: the idle connections are most likely dead too. Drop
    // them, so the next calls connect afresh instead of failing one by one.
    idle_.clear();
    return;
  }
  if (static_cast<int>(idle_.size()) < options_.max_idle_connections) {
    idle_.push_back(std::move(conn));
  }
}

Status PgStore::Connect(const std::string& target, StoreOptions options,
                        std::unique_ptr<Store>* out) {
  out->reset();
  if (options.max_attempts < 1) return Status::InvalidInput("storage: max_attempts must be >= 1");
  if (options.max_page_count > 0) {
    return Status::InvalidInput("storage: max_page_count is not supported with PostgreSQL");
  }
  std::unique_ptr<PgStore> store(new PgStore(target, std::move(options)));
  Lease conn(store.get());
  Status s = conn.Open();
  if (!s.ok()) return s;
  s = MigratePgSchema(conn.get(), store->path_, store->options_.read_only);
  if (!s.ok()) return s;
  *out = std::move(store);
  return Status::Ok();
}

Status PgStore::Txn(const std::function<Status(PgConn*)>& op) {
  for (int attempt = 1;; ++attempt) {
    Lease lease(this);
    Status s = lease.Open();
    if (!s.ok()) return s;
    PgConn* c = lease.get();
    c->notify_after_commit = false;
    s = c->ExecScript("BEGIN");
    // A connection that died in the pool (server restarted): nothing was done, run it afresh.
    if (!s.ok() && lease.StaleFromPool() && attempt < 3) continue;
    if (s.ok()) {
      try {
        s = op(c);
      } catch (const std::exception& e) {
        s = Status::Internal(std::string("storage: unexpected exception: ") + e.what());
      }
      if (s.ok()) {
        s = c->ExecScript("COMMIT");
        // Best effort: a lost notification only delays workers until their next poll.
        if (s.ok() && c->notify_after_commit) {
          (void)c->Exec("SELECT pg_notify($1, '')", {PgText(kJobsChannel)});
        }
      } else if (!c->broken()) {
        (void)c->ExecScript("ROLLBACK");
      }
    }
    // A deadlock or serialization failure rolled the transaction back: run it again.
    const bool retry = s.code() == StatusCode::kBusy && !c->broken() && attempt < 3 &&
                       (s.message().find("SQLSTATE 40P01") != std::string::npos ||
                        s.message().find("SQLSTATE 40001") != std::string::npos);
    if (!retry) return s;
  }
}

Status PgStore::Read(const std::function<Status(PgConn*)>& op) {
  for (int attempt = 1;; ++attempt) {
    Lease lease(this);
    Status s = lease.Open();
    if (!s.ok()) return s;
    s = op(lease.get());
    // Reads change nothing: one that met a connection that died in the pool runs again.
    if (s.ok() || !lease.StaleFromPool() || attempt > 1) return s;
  }
}

Status PgStore::Ping() {
  return Read([](PgConn* c) { return c->ExecScript("SELECT 1"); });
}

// ---- LISTEN/NOTIFY ---------------------------------------------------------------------------

bool PgStore::SetJobListener(std::function<void()> on_job) {
  std::lock_guard<std::mutex> lock(listen_mu_);
  if (listener_.joinable()) {
    listen_stop_ = true;
    listener_.join();
  }
  on_job_ = std::move(on_job);
  if (on_job_) {
    listen_stop_ = false;
    listener_ = std::thread([this] { ListenLoop(); });
  }
  return true;
}

void PgStore::ListenLoop() {
  std::unique_ptr<PgConn> conn;
  while (!listen_stop_) {
    if (!conn || conn->broken()) {
      conn.reset();
      std::unique_ptr<PgConn> fresh;
      if (PgConn::Connect(target_, path_, &fresh).ok() &&
          fresh->ExecScript("LISTEN calibd_jobs").ok()) {
        conn = std::move(fresh);
        on_job_();  // jobs may have been enqueued while not listening
      } else {
        for (int i = 0; i < 10 && !listen_stop_; ++i) {
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        continue;
      }
    }
    pollfd p{};
    p.fd = PQsocket(conn->handle());
    p.events = POLLIN;
    if (p.fd < 0) {
      conn.reset();
      continue;
    }
    int n = ::poll(&p, 1, 200);  // wakes to check listen_stop_
    if (n <= 0) continue;
    if (PQconsumeInput(conn->handle()) == 0) {
      conn.reset();  // the connection failed: reconnect
      continue;
    }
    bool any = false;
    while (PGnotify* note = PQnotifies(conn->handle())) {
      any = true;
      PQfreemem(note);
    }
    if (any) on_job_();
  }
}

// ---- recordings ------------------------------------------------------------------------------

Status PgStore::PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) {
  if (!r.columns_json.empty() && !internal::IsJsonArray(r.columns_json)) {
    return Status::InvalidInput("storage: columns_json is not a JSON array");
  }
  if (!r.sensors_json.empty() && !internal::IsJsonArray(r.sensors_json)) {
    return Status::InvalidInput("storage: sensors_json is not a JSON array");
  }
  if (r.job && r.job->method.empty()) return Status::InvalidInput("storage: a job needs a method");
  std::string sha = r.path.empty() ? Sha256Hex(r.data) : r.sha256;
  if (sha.empty()) {
    Status s = HashFile(r.path, &sha);  // the hash is the key: know it before the transaction
    if (!s.ok()) return s;
  }
  RecordingInfo info;
  bool duplicate = false;
  Status s = Txn([&](PgConn* c) { return PutRecordingLocked(c, r, sha, &info, &duplicate); });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(info);
  if (existed != nullptr) *existed = duplicate;
  return Status::Ok();
}

Status PgStore::PutRecordingLocked(PgConn* c, const NewRecording& r, const std::string& sha,
                                   RecordingInfo* out, bool* existed) {
  const int64_t now = Now();
  PgResult res;
  Status s = c->Exec("SELECT id FROM recordings WHERE sha256 = $1", {PgText(sha)}, &res);
  if (!s.ok()) return s;
  int64_t id = res.rows() > 0 ? res.Int(0, 0) : 0;
  bool duplicate = id != 0;
  if (!duplicate) {
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
    // A concurrent identical upload (another host) holds the key until it commits; then
    // DO NOTHING returns no row and the SELECT below (a fresh snapshot) finds its row.
    s = c->Exec(
        "INSERT INTO recordings (sha256, bytes, device, layout, rows, columns_json, sensors_json, "
        "file_name, created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) "
        "ON CONFLICT (sha256) DO NOTHING RETURNING id",
        {PgText(sha), PgInt(size), PgText(r.device), PgText(r.layout), PgInt(r.rows),
         PgText(r.columns_json.empty() ? "[]" : r.columns_json),
         PgText(r.sensors_json.empty() ? "[]" : r.sensors_json), PgText(r.file_name), PgInt(now)},
        &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      s = c->Exec("SELECT id FROM recordings WHERE sha256 = $1", {PgText(sha)}, &res);
      if (!s.ok()) return s;
      if (res.rows() == 0) return Status::Busy("storage: a concurrent upload vanished; retry");
      id = res.Int(0, 0);
      duplicate = true;
    } else {
      id = res.Int(0, 0);
      // The bytes, one chunk row (<= 1 MiB) at a time, hashed on the way to check them.
      Sha256 hasher;
      std::vector<char> buffer;
      if (!r.path.empty()) buffer.resize(kChunkBytes);
      int64_t offset = 0;
      for (int seq = 0;; ++seq) {
        std::string_view chunk;
        if (r.path.empty()) {
          if (offset >= size) break;
          chunk = r.data.substr(static_cast<size_t>(offset),
                                std::min<size_t>(kChunkBytes, static_cast<size_t>(size - offset)));
        } else {
          size_t got = 0;
          s = ReadFull(file.fd, buffer.data(), buffer.size(), r.path, &got);
          if (!s.ok()) return s;
          if (got == 0) break;
          chunk = std::string_view(buffer.data(), got);
          if (offset + static_cast<int64_t>(got) > size) {
            return Status::IoError("storage: " + r.path + " grew while being stored");
          }
        }
        hasher.Update(chunk);
        s = c->Exec("INSERT INTO recording_chunks (recording_id, seq, data) VALUES ($1, $2, $3)",
                    {PgInt(id), PgInt(seq), PgBytes(chunk)});
        if (!s.ok()) return s;
        offset += static_cast<int64_t>(chunk.size());
      }
      if (offset != size) {
        return Status::IoError("storage: " + r.path + " shrank while being stored (" +
                               std::to_string(offset) + " of " + std::to_string(size) + " bytes)");
      }
      const std::string streamed = hasher.HexDigest();
      if (streamed != sha) {
        return Status::IoError("storage: " + r.path + " does not match its announced sha256 (" +
                               sha + " != " + streamed + "): it changed while staged");
      }
    }
  }
  s = RememberDevice(c, r.device, now);
  if (!s.ok()) return s;
  RecordingInfo info;
  s = LoadRecording(c, id, &info);
  if (!s.ok()) return s;
  if (r.job) {
    JobInfo job;
    // The job is for the device this upload names, or none (never the stored one's device).
    const std::string& device = !r.job->device.empty() ? r.job->device : r.device;
    s = EnqueueJobLocked(c, id, r.job->method, device, r.job->config_json, now, &job,
                         /*inherit_device=*/false);
    if (!s.ok()) return s;
    info.job = std::move(job);
  }
  *out = std::move(info);
  *existed = duplicate;
  return Status::Ok();
}

Status PgStore::GetRecording(int64_t id, RecordingInfo* out) {
  return Read([&](PgConn* c) { return LoadRecording(c, id, out); });
}

Status PgStore::ReadRecordingData(int64_t id,
                                  const std::function<bool(std::string_view chunk)>& sink) {
  std::unique_ptr<Lease> lease;
  Status s;
  for (int attempt = 1;; ++attempt) {
    lease = std::make_unique<Lease>(this);
    s = lease->Open();
    if (!s.ok()) return s;
    // One snapshot for the whole stream (the Lease rolls it back on an early return).
    s = lease->get()->ExecScript("BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY");
    if (s.ok()) break;
    if (!lease->StaleFromPool() || attempt > 1) return s;
  }
  PgConn* c = lease->get();
  PgResult res;
  s = c->Exec("SELECT bytes FROM recordings WHERE id = $1", {PgInt(id)}, &res);
  if (!s.ok()) return s;
  if (res.rows() == 0) return Status::NotFound("recording " + std::to_string(id) + " not found");
  const int64_t bytes = res.Int(0, 0);
  int64_t offset = 0;
  for (int seq = 0; offset < bytes; ++seq) {
    s = c->Exec("SELECT data FROM recording_chunks WHERE recording_id = $1 AND seq = $2",
                {PgInt(id), PgInt(seq)}, &res, /*binary_result=*/true);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      return Status::Corruption("storage: recording " + std::to_string(id) + " lacks chunk " +
                                std::to_string(seq) + " (" + std::to_string(offset) + " of " +
                                std::to_string(bytes) + " bytes present)");
    }
    std::string_view chunk = res.Bytes(0, 0);
    offset += static_cast<int64_t>(chunk.size());
    if (!sink(chunk)) break;
  }
  return c->ExecScript("COMMIT");
}

// ---- jobs ------------------------------------------------------------------------------------

Status PgStore::EnqueueJobLocked(PgConn* c, int64_t recording_id, const std::string& method,
                                 const std::string& device, const std::string& config_json,
                                 int64_t now, JobInfo* out, bool inherit_device) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  RecordingInfo rec;
  Status s = LoadRecording(c, recording_id, &rec);
  if (!s.ok()) return s;
  const std::string& job_device = device.empty() && inherit_device ? rec.device : device;
  PgResult res;
  s = c->Exec(
      "INSERT INTO jobs (recording_id, method, device, config_json, status, attempts, "
      "created_at, not_before) VALUES ($1, $2, $3, $4, 'queued', 0, $5, $5) RETURNING id",
      {PgInt(recording_id), PgText(method), PgText(job_device),
       PgText(config_json.empty() ? "{}" : config_json), PgInt(now)},
      &res);
  if (!s.ok()) return s;
  const int64_t id = res.Int(0, 0);
  s = RememberDevice(c, job_device, now);
  if (!s.ok()) return s;
  s = NotifyJobs(c);  // sent to listeners once the transaction commits
  if (!s.ok()) return s;
  return LoadJob(c, id, false, out);
}

Status PgStore::EnqueueJob(int64_t recording_id, const std::string& method,
                           const std::string& device, const std::string& config_json,
                           JobInfo* out) {
  if (method.empty()) return Status::InvalidInput("storage: a job needs a method");
  JobInfo job;
  Status s = Txn([&](PgConn* c) {
    return EnqueueJobLocked(c, recording_id, method, device, config_json, Now(), &job, true);
  });
  if (!s.ok()) return s;
  if (out != nullptr) *out = std::move(job);
  return Status::Ok();
}

Status PgStore::RecoverLocked(PgConn* c, int64_t now, int64_t* recovered) {
  int64_t total = 0;
  PgResult res;
  // Out of attempts: failed for good. SKIP LOCKED: a row another transaction is changing (its
  // holder completing it, another host recovering it) is left to that transaction.
  Status s = c->Exec(
      "UPDATE jobs SET status = 'failed', finished_at = $1, lease_owner = NULL, "
      "lease_expires_at = NULL, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || "
      "' expired on attempt ' || attempts::text || ' of ' || $2::bigint::text || '; giving up' "
      "WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at <= $1 "
      "AND attempts >= $2::bigint FOR UPDATE SKIP LOCKED)",
      {PgInt(now), PgInt(options_.max_attempts)}, &res);
  if (!s.ok()) return s;
  total += res.Affected();
  s = c->Exec(
      "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
      "started_at = NULL, not_before = $1, error_code = 'lease_expired', error_reason = NULL, "
      "error_detail_json = NULL, "
      "error_message = 'the lease of ' || COALESCE(lease_owner, '?') || ' expired' "
      "WHERE id IN (SELECT id FROM jobs WHERE status = 'running' AND lease_expires_at <= $1 "
      "FOR UPDATE SKIP LOCKED)",
      {PgInt(now)}, &res);
  if (!s.ok()) return s;
  const int64_t requeued = res.Affected();
  total += requeued;
  if (requeued > 0) {
    s = NotifyJobs(c);
    if (!s.ok()) return s;
  }
  if (recovered != nullptr) *recovered = total;
  return Status::Ok();
}

Status PgStore::RecoverExpiredLeases(int64_t* recovered) {
  int64_t n = 0;
  Status s = Txn([&](PgConn* c) { return RecoverLocked(c, Now(), &n); });
  if (!s.ok()) return s;
  if (recovered != nullptr) *recovered = n;
  return Status::Ok();
}

Status PgStore::ExpireLeasesOf(const std::string& owner_prefix, int64_t* taken_back) {
  if (owner_prefix.empty()) return Status::InvalidInput("storage: owner_prefix must not be empty");
  int64_t n = 0;
  Status s = Txn([&](PgConn* c) {
    const int64_t now = Now();
    PgResult res;
    Status s = c->Exec(
        "UPDATE jobs SET lease_expires_at = $1 WHERE status = 'running' AND "
        "left(lease_owner, length($2)) = $2 AND lease_expires_at > $1",
        {PgInt(now), PgText(owner_prefix)}, &res);
    if (!s.ok()) return s;
    n = res.Affected();
    return n > 0 ? RecoverLocked(c, now, nullptr) : Status::Ok();
  });
  if (!s.ok()) return s;
  if (taken_back != nullptr) *taken_back = n;
  return Status::Ok();
}

Status PgStore::ClaimJob(const std::string& worker_id, int64_t lease_ms, JobInfo* out,
                         bool* claimed) {
  *claimed = false;
  if (worker_id.empty()) return Status::InvalidInput("storage: worker_id must not be empty");
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  {
    // Cheap check without a transaction, so idle workers polling cost one indexed lookup.
    bool any = false;
    Status s = Read([&](PgConn* c) {
      PgResult res;
      Status s = c->Exec(
          "SELECT EXISTS (SELECT 1 FROM jobs WHERE status = 'queued' AND not_before <= $1) "
          "OR EXISTS (SELECT 1 FROM jobs WHERE status = 'running' AND lease_expires_at <= $1)",
          {PgInt(Now())}, &res);
      if (!s.ok()) return s;
      any = res.Text(0, 0) == "t";
      return Status::Ok();
    });
    if (!s.ok()) return s;
    if (!any) return Status::Ok();
  }
  JobInfo job;
  bool got = false;
  Status s = Txn([&](PgConn* c) {
    got = false;
    const int64_t now = Now();
    Status s = RecoverLocked(c, now, nullptr);
    if (!s.ok()) return s;
    PgResult res;
    // The oldest claimable job nobody else is claiming right now (SKIP LOCKED: claimers on
    // every host proceed in parallel, each with a different job).
    s = c->Exec(
        "UPDATE jobs SET status = 'running', lease_owner = $2, lease_expires_at = $3, "
        "attempts = attempts + 1, started_at = $1, finished_at = NULL "
        "WHERE id = (SELECT id FROM jobs WHERE status = 'queued' AND not_before <= $1 "
        "ORDER BY id LIMIT 1 FOR UPDATE SKIP LOCKED) RETURNING id",
        {PgInt(now), PgText(worker_id), PgInt(now + lease_ms)}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) return Status::Ok();
    s = LoadJob(c, res.Int(0, 0), false, &job);
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

Status PgStore::RequireHolder(PgConn* c, int64_t job_id, const std::string& worker_id,
                              const char* action, JobInfo* job) {
  Status s = LoadJob(c, job_id, false, job, /*for_update=*/true);
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

Status PgStore::RenewLease(int64_t job_id, const std::string& worker_id, int64_t lease_ms) {
  if (lease_ms <= 0) return Status::InvalidInput("storage: lease_ms must be positive");
  return Txn([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(
        "UPDATE jobs SET lease_expires_at = $3 "
        "WHERE id = $1 AND status = 'running' AND lease_owner = $2",
        {PgInt(job_id), PgText(worker_id), PgInt(Now() + lease_ms)}, &res);
    if (!s.ok()) return s;
    if (res.Affected() == 1) return Status::Ok();
    JobInfo job;
    s = RequireHolder(c, job_id, worker_id, "renew the lease of", &job);
    if (!s.ok()) return s;
    return Status::Conflict("cannot renew the lease of job " + std::to_string(job_id));
  });
}

Status PgStore::CompleteJob(int64_t job_id, const std::string& worker_id,
                            const std::string& result_json) {
  if (result_json.empty()) return Status::InvalidInput("storage: empty result");
  const std::string sha = Sha256Hex(result_json);
  const std::string verdict = internal::VerdictOf(result_json);
  return Txn([&](PgConn* c) {
    JobInfo job;
    // The row lock serialises every transition of this job across hosts.
    Status s = LoadJob(c, job_id, false, &job, /*for_update=*/true);
    if (!s.ok()) return s;
    if (job.status == "succeeded") {
      if (job.result_sha256 == sha) return Status::Ok();  // the same run again: nothing to do
      return Status::Conflict("job " + std::to_string(job_id) +
                              " already succeeded with a different result");
    }
    s = RequireHolder(c, job_id, worker_id, "complete", &job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    s = c->Exec(
        "INSERT INTO results (job_id, result_json, sha256, created_at, verdict) "
        "VALUES ($1, $2, $3, $4, $5)",
        {PgInt(job_id), PgText(result_json), PgText(sha), PgInt(now), PgText(verdict)});
    if (!s.ok()) return s;
    s = c->Exec(
        "UPDATE jobs SET status = 'succeeded', finished_at = $2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = NULL, error_message = NULL, error_reason = NULL, "
        "error_detail_json = NULL WHERE id = $1",
        {PgInt(job_id), PgInt(now)});
    if (!s.ok()) return s;
    if (!job.device.empty()) {
      s = RememberDevice(c, job.device, now);
      if (!s.ok()) return s;
      s = RefreshLatest(c, job.device, job.method);
      if (!s.ok()) return s;
    }
    return Status::Ok();
  });
}

Status PgStore::FailJob(int64_t job_id, const std::string& worker_id, const JobFailure& failure,
                        bool transient) {
  return Txn([&](PgConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "fail", &job);
    if (!s.ok()) return s;
    const int64_t now = Now();
    const std::string error_code = failure.code.empty() ? std::string("error") : failure.code;
    const PgParam reason = PgTextOrNull(failure.reason);
    const PgParam detail = PgTextOrNull(failure.detail_json);
    if (transient && job.attempts < options_.max_attempts) {
      return c->Exec(
          "UPDATE jobs SET status = 'queued', lease_owner = NULL, lease_expires_at = NULL, "
          "started_at = NULL, not_before = $2, error_code = $3, error_message = $4, "
          "error_reason = $5, error_detail_json = $6 WHERE id = $1",
          {PgInt(job_id), PgInt(now + internal::Backoff(options_, job.attempts)),
           PgText(error_code), PgText(failure.message), reason, detail});
    }
    std::string final_message = failure.message;
    if (transient) {
      final_message =
          "gave up after " + std::to_string(job.attempts) + " attempts: " + failure.message;
    }
    return c->Exec(
        "UPDATE jobs SET status = 'failed', finished_at = $2, lease_owner = NULL, "
        "lease_expires_at = NULL, error_code = $3, error_message = $4, error_reason = $5, "
        "error_detail_json = $6 WHERE id = $1",
        {PgInt(job_id), PgInt(now), PgText(error_code), PgText(final_message), reason, detail});
  });
}

Status PgStore::ReleaseJob(int64_t job_id, const std::string& worker_id) {
  return Txn([&](PgConn* c) {
    JobInfo job;
    Status s = RequireHolder(c, job_id, worker_id, "release", &job);
    if (!s.ok()) return s;
    s = c->Exec(
        "UPDATE jobs SET status = 'queued', attempts = GREATEST(attempts - 1, 0), "
        "lease_owner = NULL, lease_expires_at = NULL, started_at = NULL, not_before = $2 "
        "WHERE id = $1",
        {PgInt(job_id), PgInt(Now())});
    if (!s.ok()) return s;
    return NotifyJobs(c);
  });
}

Status PgStore::GetJob(int64_t id, JobInfo* out) {
  return Read([&](PgConn* c) { return LoadJob(c, id, true, out); });
}

Status PgStore::ListJobs(const JobFilter& filter, std::vector<JobInfo>* out) {
  out->clear();
  Status s = internal::ValidateFilter(filter);
  if (!s.ok()) return s;
  const int limit = std::clamp(filter.limit <= 0 ? 50 : filter.limit, 1, 500);
  int n = 0;
  const std::string where = FilterSql(filter, true, &n);
  const std::string sql = JobSelect(filter.include_results) + where + "ORDER BY j.id DESC LIMIT $" +
                          std::to_string(n + 1);
  std::vector<PgParam> params = FilterParams(filter, true);
  params.push_back(PgInt(limit));
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), params, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) {
      JobInfo job;
      ReadJob(res, i, &job);
      out->push_back(std::move(job));
    }
    return Status::Ok();
  });
}

Status PgStore::CountJobs(const JobFilter& filter, int64_t* count) {
  Status s = internal::ValidateFilter(filter);
  if (!s.ok()) return s;
  int n = 0;
  const std::string sql = "SELECT COUNT(*) FROM jobs j LEFT JOIN results r ON r.job_id = j.id " +
                          FilterSql(filter, false, &n);
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), FilterParams(filter, false), &res);
    if (!s.ok()) return s;
    *count = res.rows() > 0 ? res.Int(0, 0) : 0;
    return Status::Ok();
  });
}

Status PgStore::ListDevices(std::vector<DeviceInfo>* out) {
  out->clear();
  return Read([&](PgConn* c) {
    PgResult res;
    // COLLATE "C": byte order, as SQLite sorts, whatever the database's locale.
    Status s = c->Exec(
        "SELECT d.serial, d.first_seen, c.method, c.job_id, c.calibrated_at "
        "FROM devices d LEFT JOIN device_calibrations c ON c.device = d.serial "
        "ORDER BY d.serial COLLATE \"C\", c.method COLLATE \"C\"",
        {}, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) {
      std::string serial = res.Text(i, 0);
      if (out->empty() || out->back().serial != serial) {
        DeviceInfo d;
        d.serial = serial;
        d.first_seen_ms = res.Int(i, 1);
        d.first_seen = FormatTimestamp(d.first_seen_ms);
        out->push_back(std::move(d));
      }
      if (!res.IsNull(i, 2)) {
        DeviceCalibration cal;
        cal.method = res.Text(i, 2);
        cal.job_id = res.Int(i, 3);
        cal.calibrated_at_ms = res.Int(i, 4);
        cal.calibrated_at = FormatTimestamp(cal.calibrated_at_ms);
        out->back().latest.push_back(std::move(cal));
      }
    }
    return Status::Ok();
  });
}

Status PgStore::LatestResult(const std::string& device, const std::string& method, JobInfo* out) {
  const std::string sql =
      JobSelect(true) +
      "WHERE j.id = (SELECT job_id FROM device_calibrations WHERE device = $1 AND method = $2)";
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(sql.c_str(), {PgText(device), PgText(method)}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      return Status::NotFound("no succeeded " + method + " calibration for device " + device);
    }
    ReadJob(res, 0, out);
    return Status::Ok();
  });
}

Status PgStore::QueueDepth(QueueCounts* out) {
  *out = QueueCounts();
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec("SELECT status, COUNT(*) FROM jobs GROUP BY status", {}, &res);
    if (!s.ok()) return s;
    for (int i = 0; i < res.rows(); ++i) {
      const std::string status = res.Text(i, 0);
      const int64_t n = res.Int(i, 1);
      if (status == "queued") out->queued = n;
      if (status == "running") out->running = n;
      if (status == "succeeded") out->succeeded = n;
      if (status == "failed") out->failed = n;
    }
    return Status::Ok();
  });
}

// ---- the acceptance gate's decisions -----------------------------------------------------------

Status PgStore::DecideLocked(PgConn* c, int64_t job_id, const std::string& action,
                             const std::string& reason, const std::string& actor, JobEvent* out) {
  JobInfo job;
  Status s = LoadJob(c, job_id, false, &job, /*for_update=*/true);
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
  s = c->Exec("UPDATE results SET decision = $2 WHERE job_id = $1",
              {PgInt(job_id), PgText(revoke ? "revoked" : "accepted")});
  if (!s.ok()) return s;
  PgResult res;
  s = c->Exec(
      "INSERT INTO job_events (job_id, action, reason, actor, created_at) "
      "VALUES ($1, $2, $3, $4, $5) RETURNING id",
      {PgInt(job_id), PgText(action), PgText(reason), PgText(actor), PgInt(now)}, &res);
  if (!s.ok()) return s;
  JobEvent event;
  event.id = res.Int(0, 0);
  event.job_id = job_id;
  event.action = action;
  event.reason = reason;
  event.actor = actor;
  event.created_at_ms = now;
  event.created_at = FormatTimestamp(now);
  if (!job.device.empty()) {
    s = RefreshLatest(c, job.device, job.method);
    if (!s.ok()) return s;
  }
  *out = std::move(event);
  return Status::Ok();
}

Status PgStore::RevokeJob(int64_t job_id, const std::string& reason, const std::string& actor,
                          JobEvent* out) {
  if (reason.empty()) {
    return Status::InvalidInput("a revocation needs a reason").WithField("reason");
  }
  JobEvent event;
  Status s =
      Txn([&](PgConn* c) { return DecideLocked(c, job_id, "revoke", reason, actor, &event); });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status PgStore::AcceptJob(int64_t job_id, const std::string& reason, const std::string& actor,
                          JobEvent* out) {
  if (reason.empty()) {
    return Status::InvalidInput("an acceptance needs a reason").WithField("reason");
  }
  JobEvent event;
  Status s =
      Txn([&](PgConn* c) { return DecideLocked(c, job_id, "accept", reason, actor, &event); });
  if (s.ok() && out != nullptr) *out = std::move(event);
  return s;
}

Status PgStore::ListJobEvents(int64_t job_id, std::vector<JobEvent>* out) {
  return Read([&](PgConn* c) {
    JobInfo job;
    Status s = LoadJob(c, job_id, false, &job);
    if (!s.ok()) return s;
    PgResult res;
    s = c->Exec(
        "SELECT id, job_id, action, reason, actor, created_at FROM job_events WHERE job_id = $1 "
        "ORDER BY id",
        {PgInt(job_id)}, &res);
    if (!s.ok()) return s;
    std::vector<JobEvent> events;
    for (int i = 0; i < res.rows(); ++i) {
      JobEvent e;
      e.id = res.Int(i, 0);
      e.job_id = res.Int(i, 1);
      e.action = res.Text(i, 2);
      e.reason = res.Text(i, 3);
      e.actor = res.Text(i, 4);
      e.created_at_ms = res.Int(i, 5);
      e.created_at = FormatTimestamp(e.created_at_ms);
      events.push_back(std::move(e));
    }
    *out = std::move(events);
    return Status::Ok();
  });
}

// ---- maintenance -------------------------------------------------------------------------------

Status PgStore::IntegrityCheck(std::string* result) {
  result->clear();
  return Read([&](PgConn* c) {
    PgResult res;
    Status s = c->Exec(
        "SELECT r.id FROM recordings r LEFT JOIN (SELECT recording_id, SUM(length(data)) AS n, "
        "COUNT(*) AS k, MAX(seq) AS last FROM recording_chunks GROUP BY recording_id) c "
        "ON c.recording_id = r.id WHERE r.bytes <> COALESCE(c.n, 0) "
        "OR COALESCE(c.k, 0) <> COALESCE(c.last + 1, 0) ORDER BY r.id LIMIT 100",
        {}, &res);
    if (!s.ok()) return s;
    if (res.rows() == 0) {
      *result = "ok";
      return Status::Ok();
    }
    *result = "recordings whose stored bytes do not add up to their size:";
    for (int i = 0; i < res.rows(); ++i) *result += " " + res.Text(i, 0);
    return Status::Ok();
  });
}

Status PgStore::Checkpoint() { return Status::Ok(); }

}  // namespace calibd::storage
