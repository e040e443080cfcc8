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
  internal::StagedFile f;
  Status s = f.Open(path);
  if (!s.ok()) return s;
  std::vector<char> buf(kChunkBytes);
  Sha256 hasher;
  for (;;) {
    size_t got = 0;
    s = ReadFull(f.fd(), buf.data(), buf.size(), path, &got);
    if (!s.ok()) return s;
    if (got == 0) break;
    hasher.Update(std::string_view(buf.data(), got));
  }
  *sha = hasher.HexDigest();
  return Status::Ok();
}

}  // namespace

using sql::FindRecording;
using sql::InsertRecording;
using sql::LoadRecording;

Status PgStore::HashUpload(const NewRecording& r, std::string* sha) {
  Status s = SqlStore::HashUpload(r, sha);
  if (s.ok() && sha->empty()) s = HashFile(r.path, sha);  // the hash is the key: know it first
  return s;
}

Status PgStore::StoreRecordingBytes(SqlConn* c, const NewRecording& r, const std::string& sha,
                                    int64_t now, int64_t* id, bool* duplicate) {
  PgConn* conn = static_cast<pg::PgSqlConn*>(c)->conn();
  Status s = FindRecording(c, sha, id);
  if (!s.ok()) return s;
  *duplicate = *id != 0;
  if (!*duplicate) {
    internal::StagedFile file;
    s = file.OpenUpload(r);
    if (!s.ok()) return s;
    // A concurrent identical upload (another host) holds the key until it commits; then no row
    // is inserted and the SELECT below (a fresh snapshot) finds its row.
    s = InsertRecording(c, r, sha, file.size(), now, id);
    if (!s.ok()) return s;
    if (*id != 0) return WriteChunks(conn, r, *id, file.fd(), file.size(), sha);
    s = FindRecording(c, sha, id);
    if (!s.ok()) return s;
    if (*id == 0) return Status::Busy("storage: a concurrent upload vanished; retry");
    *duplicate = true;
  }
  // Identical bytes are stored already, unless the stored copy was damaged since: then this
  // upload repairs it (README "Storage damage").
  return RepairIfDamaged(conn, r, *id, sha);
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
  internal::StagedFile file;
  s = file.OpenUpload(r);
  if (!s.ok()) return s;
  s = WriteChunks(c, r, id, file.fd(), file.size(), sha);
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
  pg::PgSqlConn sql(c);
  PgResult res;
  RecordingInfo info;  // its stored hash, which the bytes read are checked against
  s = LoadRecording(&sql, id, &info);
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
    const std::string_view chunk = res.Bytes(0, 0);
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
