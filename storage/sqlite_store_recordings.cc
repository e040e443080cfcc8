// SqliteStore's recordings: stored once per SHA-256 (in-memory bytes or a staged file streamed
// through a blob handle in 1 MiB chunks), read back as a stream from one snapshot.
#include <fcntl.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <iostream>
#include <utility>
#include <vector>

#include "storage/sha256.h"
#include "storage/sqlite_store_internal.h"

namespace calibd::storage {

using sqlite::LoadRecording;
using sqlite::RememberDevice;

namespace {

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
constexpr const char* kRecordingSelect =
    "SELECT id, sha256, bytes, rows, layout, device, file_name, created_at, columns_json, "
    "sensors_json FROM recordings WHERE id = ?1";

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

// The SHA-256 of recording `id`'s stored bytes (inside the caller's transaction).
Status HashStoredBlob(Db* db, int64_t id, std::string* sha) {
  Blob blob;
  int rc = sqlite3_blob_open(db->handle(), "main", "recording_data", "data", id, /*write=*/0,
                             &blob.blob);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "open recording blob");
  const int64_t size = sqlite3_blob_bytes(blob.blob);
  std::vector<char> buffer(static_cast<size_t>(std::min<int64_t>(size, kChunkBytes)));
  Sha256 hasher;
  for (int64_t offset = 0; offset < size;) {
    const int n = static_cast<int>(std::min<int64_t>(size - offset, kChunkBytes));
    rc = sqlite3_blob_read(blob.blob, buffer.data(), n, static_cast<int>(offset));
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "read recording blob");
    hasher.Update(std::string_view(buffer.data(), static_cast<size_t>(n)));
    offset += n;
  }
  *sha = hasher.HexDigest();
  return Status::Ok();
}

// Replaces recording `id`'s stored bytes with the upload's (a repair of a damaged copy; inside
// the caller's transaction). The bytes are hashed again on the way and must give `sha`.
Status RewriteStoredBlob(Db* db, int64_t id, const NewRecording& r, int fd, int64_t size,
                         const std::string& sha) {
  Stmt st;
  Status s = db->Prepare("UPDATE recording_data SET data = ?1 WHERE recording_id = ?2", &st);
  if (!s.ok()) return s;
  if (fd < 0) {
    st.BindBlobNoCopy(1, r.data).BindInt(2, id);
    return st.Run();
  }
  st.BindZeroBlob(1, size).BindInt(2, id);
  s = st.Run();
  if (!s.ok()) return s;
  if (::lseek(fd, 0, SEEK_SET) != 0) {
    return Status::IoError("storage: cannot rewind " + r.path + ": " + std::strerror(errno));
  }
  Blob blob;
  int rc = sqlite3_blob_open(db->handle(), "main", "recording_data", "data", id, /*write=*/1,
                             &blob.blob);
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "open recording blob");
  std::vector<char> buffer(kChunkBytes);
  Sha256 hasher;
  int64_t offset = 0;
  while (offset < size) {
    ssize_t n = ::read(fd, buffer.data(),
                       static_cast<size_t>(std::min<int64_t>(size - offset, kChunkBytes)));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      return Status::IoError("storage: reading " + r.path + ": " +
                             (n < 0 ? std::strerror(errno) : "it shrank while being stored"));
    }
    hasher.Update(std::string_view(buffer.data(), static_cast<size_t>(n)));
    rc =
        sqlite3_blob_write(blob.blob, buffer.data(), static_cast<int>(n), static_cast<int>(offset));
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "write recording blob");
    offset += n;
  }
  rc = blob.Close();
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "close recording blob");
  if (hasher.HexDigest() != sha) {
    return Status::IoError("storage: " + r.path + " changed while being stored");
  }
  return Status::Ok();
}

}  // namespace

namespace sqlite {

Status LoadRecording(Db* db, int64_t id, RecordingInfo* out) {
  Stmt st;
  Status s = db->Prepare(kRecordingSelect, &st);
  if (!s.ok()) return s;
  st.BindInt(1, id);
  bool row = false;
  s = st.Step(&row);
  if (!s.ok()) return s;
  if (!row) return Status::NotFound("recording " + std::to_string(id) + " not found");
  internal::ReadRecording(StmtRow(st), out);
  return Status::Ok();
}

}  // namespace sqlite

Status SqliteStore::PutRecording(const NewRecording& r, RecordingInfo* out, bool* existed) {
  Status valid = internal::ValidateNewRecording(r);
  if (!valid.ok()) return valid;
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
  if (duplicate) {
    // Identical bytes are stored already, unless the stored copy was damaged since (a copied
    // database file, a bad sector): then this upload repairs it (README "Storage damage").
    RecordingInfo stored;
    s = LoadRecording(db, id, &stored);
    if (!s.ok()) return s;
    std::string stored_sha;
    s = HashStoredBlob(db, id, &stored_sha);
    if (!s.ok() && s.code() != StatusCode::kCorruption) return s;
    if (!s.ok() || stored_sha != stored.sha256 || stored.bytes != size) {
      s = RewriteStoredBlob(db, id, r, file.fd, size, stored.sha256);
      if (!s.ok()) return s;
      std::cerr << "calibd: recording " << id
                << ": the stored copy was damaged; repaired from a new upload of the same bytes\n";
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
  // The metadata in the blob's snapshot: the stored hash the bytes are checked against.
  RecordingInfo info;
  s = LoadRecording(db, id, &info);
  if (!s.ok()) return s;
  const int64_t size = sqlite3_blob_bytes(blob.blob);
  std::vector<char> buffer(static_cast<size_t>(std::min<int64_t>(size, kChunkBytes)));
  Sha256 hasher;
  bool whole = true;
  for (int64_t offset = 0; offset < size;) {
    int n = static_cast<int>(std::min<int64_t>(size - offset, kChunkBytes));
    rc = sqlite3_blob_read(blob.blob, buffer.data(), n, static_cast<int>(offset));
    if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "read recording blob");
    offset += n;
    const std::string_view chunk(buffer.data(), static_cast<size_t>(n));
    hasher.Update(chunk);
    if (!sink(chunk)) {
      whole = false;
      break;
    }
  }
  rc = blob.Close();
  if (rc != SQLITE_OK) return StatusFromSqlite(rc, db->handle(), "close recording blob");
  if (whole) return internal::CheckRecordingDigest(info, size, hasher.HexDigest());
  return Status::Ok();
}

}  // namespace calibd::storage
