// PgStore's recordings: stored once per SHA-256 across all hosts (INSERT ... ON CONFLICT DO
// NOTHING), as chunk rows of at most 1 MiB written and read one at a time.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <utility>
#include <vector>

#include "storage/pg_store_internal.h"
#include "storage/sha256.h"

namespace calibd::storage {
namespace {

using internal::kChunkBytes;

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

}  // namespace

namespace pg {

Status LoadRecording(PgConn* c, int64_t id, RecordingInfo* out) {
  PgResult r;
  Status s = c->Exec(
      "SELECT id, sha256, bytes, rows, layout, device, file_name, created_at, columns_json, "
      "sensors_json FROM recordings WHERE id = $1",
      {PgInt(id)}, &r);
  if (!s.ok()) return s;
  if (r.rows() == 0) return Status::NotFound("recording " + std::to_string(id) + " not found");
  internal::ReadRecording(PgRow(r, 0), out);
  return Status::Ok();
}

}  // namespace pg

using pg::LoadRecording;
using pg::RememberDevice;

Status PgStore::PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) {
  Status valid = internal::ValidateNewRecording(r);
  if (!valid.ok()) return valid;
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
  int64_t now = 0;
  Status s = DbNow(c, &now);  // the database's clock (store.h, StoreOptions::now_ms)
  if (!s.ok()) return s;
  PgResult res;
  s = c->Exec("SELECT id FROM recordings WHERE sha256 = $1", {PgText(sha)}, &res);
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
      s = WriteChunks(c, r, id, file.fd, size, sha);
      if (!s.ok()) return s;
    }
  }
  if (duplicate) {
    // Identical bytes are stored already, unless the stored copy was damaged since: then this
    // upload repairs it (README "Storage damage").
    s = RepairIfDamaged(c, r, id, sha);
    if (!s.ok()) return s;
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

Status PgStore::RepairIfDamaged(PgConn* c, const NewRecording& r, int64_t id,
                                const std::string& sha) {
  PgResult res;
  Status s = c->Exec("SELECT bytes FROM recordings WHERE id = $1", {PgInt(id)}, &res);
  if (!s.ok()) return s;
  const int64_t bytes = res.rows() > 0 ? res.Int(0, 0) : -1;
  Sha256 hasher;
  int64_t stored = 0;
  for (int seq = 0;; ++seq) {
    s = c->Exec("SELECT data FROM recording_chunks WHERE recording_id = $1 AND seq = $2",
                {PgInt(id), PgInt(seq)}, &res, /*binary_result=*/true);
    if (!s.ok()) return s;
    if (res.rows() == 0) break;
    hasher.Update(res.Bytes(0, 0));
    stored += static_cast<int64_t>(res.Bytes(0, 0).size());
  }
  if (stored == bytes && hasher.HexDigest() == sha) return Status::Ok();
  s = c->Exec("DELETE FROM recording_chunks WHERE recording_id = $1", {PgInt(id)});
  if (!s.ok()) return s;
  Fd file;
  int64_t size = static_cast<int64_t>(r.data.size());
  if (!r.path.empty()) {
    file.fd = ::open(r.path.c_str(), O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (file.fd < 0 || ::fstat(file.fd, &st) != 0) {
      return Status::IoError("storage: cannot open " + r.path + ": " + std::strerror(errno));
    }
    size = static_cast<int64_t>(st.st_size);
  }
  s = WriteChunks(c, r, id, file.fd, size, sha);
  if (!s.ok()) return s;
  std::cerr << "calibd: recording " << id
            << ": the stored copy was damaged; repaired from a new upload of the same bytes\n";
  return Status::Ok();
}

Status PgStore::WriteChunks(PgConn* c, const NewRecording& r, int64_t id, int fd, int64_t size,
                            const std::string& sha) {
  Status s;
  {
    {
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
          s = ReadFull(fd, buffer.data(), buffer.size(), r.path, &got);
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
  RecordingInfo info;  // its stored hash, which the bytes read are checked against
  s = LoadRecording(c, id, &info);
  if (!s.ok()) return s;
  const int64_t bytes = info.bytes;
  Sha256 hasher;
  bool whole = true;
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
    hasher.Update(chunk);
    if (!sink(chunk)) {
      whole = false;
      break;
    }
  }
  s = c->ExecScript("COMMIT");
  if (!s.ok() || !whole) return s;
  return internal::CheckRecordingDigest(info, offset, hasher.HexDigest());
}

}  // namespace calibd::storage
