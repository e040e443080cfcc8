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

using sql::FindRecording;
using sql::InsertRecording;
using sql::LoadRecording;

namespace {

using internal::kChunkBytes;

// A blob handle closed on scope exit.
struct Blob {
  sqlite3_blob* blob = nullptr;
  ~Blob() {
    if (blob != nullptr) sqlite3_blob_close(blob);
  }
  // Opens recording `id`'s bytes (recording_data.data).
  int Open(Db* db, int64_t id, bool write) {
    return sqlite3_blob_open(db->handle(), "main", "recording_data", "data", id, write ? 1 : 0,
                             &blob);
  }
  int Close() {
    int rc = blob != nullptr ? sqlite3_blob_close(blob) : SQLITE_OK;
    blob = nullptr;
    return rc;
  }
};

// Writes the staged file, from where `fd` stands, into recording `id`'s blob of `size` zeros
// (inside the caller's transaction). On return *sha is the bytes' hash.
Status WriteFileIntoBlob(Db* db, int64_t id, const NewRecording& r, int fd, int64_t size,
                         std::string* sha) {
  Blob blob;
  int rc = blob.Open(db, id, /*write=*/true);
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

// Streams the staged file into recording `id`'s new blob (inside the caller's transaction). On
// return *sha is the bytes' hash.
Status StreamFileIntoNewRow(Db* db, int64_t id, const NewRecording& r, int fd, int64_t size,
                            std::string* sha) {
  Stmt st;
  Status s = db->Prepare("INSERT INTO recording_data (recording_id, data) VALUES (?1, ?2)", &st);
  if (!s.ok()) return s;
  st.BindInt(1, id).BindZeroBlob(2, size);  // zeros are not materialised in memory
  s = st.Run();
  if (!s.ok()) return s;
  return WriteFileIntoBlob(db, id, r, fd, size, sha);
}

// The SHA-256 of recording `id`'s stored bytes (inside the caller's transaction).
Status HashStoredBlob(Db* db, int64_t id, std::string* sha) {
  Blob blob;
  int rc = blob.Open(db, id, /*write=*/false);
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
  std::string written;
  s = WriteFileIntoBlob(db, id, r, fd, size, &written);
  if (!s.ok()) return s;
  if (written != sha) return Status::IoError("storage: " + r.path + " changed while being stored");
  return Status::Ok();
}

// A staged file's bytes stored in a single pass (write and hash), in a savepoint: the row is
// kept, or, when the bytes turn out to be stored already, rolled back (*id = the stored one's,
// *duplicate = true).
Status StreamNewRecording(SqlConn* c, Db* db, const NewRecording& r, int fd, int64_t size,
                          int64_t now, int64_t* id, bool* duplicate) {
  Status s = db->Exec("SAVEPOINT put_recording");
  if (!s.ok()) return s;
  // The row's sha256 is the placeholder '' until the bytes' hash is known.
  s = InsertRecording(c, r, /*sha=*/"", size, now, id);
  if (!s.ok()) return s;  // the caller's savepoint rolls everything back
  if (*id == 0) return Status::Conflict("storage: the recording row was not stored");
  std::string streamed_sha;
  s = StreamFileIntoNewRow(db, *id, r, fd, size, &streamed_sha);
  if (!s.ok()) return s;
  if (!r.sha256.empty() && r.sha256 != streamed_sha) {
    return Status::IoError("storage: " + r.path + " does not match its announced sha256 (" +
                           r.sha256 + " != " + streamed_sha + "): it changed while staged");
  }
  int64_t existing = 0;
  s = FindRecording(c, streamed_sha, &existing);
  if (!s.ok()) return s;
  if (existing != 0) {
    *id = existing;
    *duplicate = true;
    return db->Exec("ROLLBACK TO put_recording; RELEASE put_recording");
  }
  s = c->Run("UPDATE recordings SET sha256 = $1 WHERE id = $2",
             {SqlText(streamed_sha), SqlInt(*id)});
  if (!s.ok()) return s;
  return db->Exec("RELEASE put_recording");
}

// Identical bytes are stored already as recording `id`, unless the stored copy was damaged since
// (a copied database file, a bad sector): then this upload repairs it (README "Storage damage").
Status RepairIfDamaged(SqlConn* c, Db* db, int64_t id, const NewRecording& r, int fd,
                       int64_t size) {
  RecordingInfo stored;
  Status s = LoadRecording(c, id, &stored);
  if (!s.ok()) return s;
  std::string stored_sha;
  s = HashStoredBlob(db, id, &stored_sha);
  if (!s.ok() && s.code() != StatusCode::kCorruption) return s;
  if (s.ok() && stored_sha == stored.sha256 && stored.bytes == size) return Status::Ok();
  s = RewriteStoredBlob(db, id, r, fd, size, stored.sha256);
  if (!s.ok()) return s;
  std::cerr << "calibd: recording " << id
            << ": the stored copy was damaged; repaired from a new upload of the same bytes\n";
  return Status::Ok();
}

}  // namespace

Status SqliteStore::StoreRecordingBytes(SqlConn* c, const NewRecording& r,
                                        const std::string& known_sha, int64_t now, int64_t* out_id,
                                        bool* duplicate) {
  Db* db = static_cast<sqlite::SqliteConn*>(c)->db();
  internal::StagedFile file;
  Status s = file.OpenUpload(r);
  if (!s.ok()) return s;
  const int64_t size = file.size();
  const int64_t limit = sqlite3_limit(db->handle(), SQLITE_LIMIT_LENGTH, -1);
  if (size > limit) {
    return Status(StatusCode::kTooLarge, "storage: recording of " + std::to_string(size) +
                                             " bytes exceeds the limit of " +
                                             std::to_string(limit));
  }
  int64_t id = 0;
  if (!known_sha.empty()) {
    s = FindRecording(c, known_sha, &id);
    if (!s.ok()) return s;
  }
  *duplicate = id != 0;
  if (!*duplicate && r.path.empty()) {
    s = InsertRecording(c, r, known_sha, size, now, &id);
    if (!s.ok()) return s;
    if (id == 0) return Status::Conflict("storage: the recording row was not stored");
    Stmt st;
    s = db->Prepare("INSERT INTO recording_data (recording_id, data) VALUES (?1, ?2)", &st);
    if (!s.ok()) return s;
    st.BindInt(1, id).BindBlobNoCopy(2, r.data);
    s = st.Run();
  } else if (!*duplicate) {
    s = StreamNewRecording(c, db, r, file.fd(), size, now, &id, duplicate);
  }
  if (!s.ok()) return s;
  if (*duplicate) {
    s = RepairIfDamaged(c, db, id, r, file.fd(), size);
    if (!s.ok()) return s;
  }
  *out_id = id;
  return Status::Ok();
}

Status SqliteStore::ReadRecordingData(int64_t id,
                                      const std::function<bool(std::string_view chunk)>& sink) {
  Conn conn(this);
  Status s = conn.Open();
  if (!s.ok()) return s;
  Db* db = conn.db();
  sqlite::SqliteConn sql(db);
  // The open blob handle keeps one read transaction (snapshot) for the whole stream.
  Blob blob;
  int rc = blob.Open(db, id, /*write=*/false);
  if (rc != SQLITE_OK) {
    Status open_error = StatusFromSqlite(rc, db->handle(), "open recording blob");
    RecordingInfo unused;
    s = LoadRecording(&sql, id, &unused);
    if (s.code() == StatusCode::kNotFound) return s;
    return open_error;
  }
  // The metadata in the blob's snapshot: the stored hash the bytes are checked against.
  RecordingInfo info;
  s = LoadRecording(&sql, id, &info);
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
