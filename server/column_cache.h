// The parsed-columns cache of stored inertial logs: a stored recording parsed once (at upload, in
// the background, or by the first job, check or /segments that reads it) is kept as a binary
// columnar file (formats/column_file.h), and later reads of the same bytes with the same reading
// rules restore the parser from it instead of reading, hashing and parsing the stored CSV or log
// again (bench/README.md "Recording check": an hour of 400 Hz, 128 MB of CSV).
//
// Entries are keyed by the recording's SHA-256 and the reading rules in force (time unit, CSV
// dialect, log streams and time base, the file format's version): a parser with other rules, or
// other bytes under the same id, never meets an entry made for them. Every read verifies the
// entry (size, key, CRC-32 of header and data); a damaged, cut or stale entry is removed, said
// on stderr, and rebuilt from the stored bytes by that very read. An entry is written only from
// a complete read whose bytes matched their stored SHA-256, atomically (temporary file, fsync,
// rename), so a crash leaves no torn entry under an entry's name; temporaries left by a crash
// are removed after an hour.
//
// Disk use is bounded: entries total at most max_bytes (least recently used removed first, on
// every write); an entry alone larger is not written. Recordings are never deleted by calibd;
// an entry whose recording is gone is unreachable and ages out by the same rule.
//
// Only parsers collecting doubles are served (a float-collecting parser, the noise method's, is
// read from the stored bytes as before: restoring doubles and converting would exceed its memory
// budget). Thread-safe; one build per entry at a time (a second reader waits for it and reads
// the entry).
#ifndef CALIBD_SERVER_COLUMN_CACHE_H_
#define CALIBD_SERVER_COLUMN_CACHE_H_

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <thread>

#include "base/status.h"
#include "formats/recording.h"
#include "storage/store.h"

namespace calibd::server {

struct ColumnCacheOptions {
  std::filesystem::path dir;             // created when missing; "" disables the cache
  int64_t max_bytes = int64_t{2} << 30;  // the entries' total size (> 0)
  // The background build (Prefetch) parses a recording only when its doubles (rows × columns ×
  // 8 bytes, twice: parsed and written) fit in this; <= 0: no limit.
  int64_t prefetch_memory_bytes = 0;
};

class ColumnCache {
 public:
  explicit ColumnCache(ColumnCacheOptions options);
  ~ColumnCache();  // waits for a background build in progress
  ColumnCache(const ColumnCache&) = delete;
  ColumnCache& operator=(const ColumnCache&) = delete;

  // What Fill did: `read` the storage's status (kNotFound, kIoError, kCorruption of the stored
  // bytes...), `parse` the parser's (Feed/Finish), `hit` whether a cache entry served it.
  struct Outcome {
    Status read, parse;
    bool hit = false;
  };
  // Fills `parser` (a collecting parser with its reading rules set, not yet fed) with recording
  // `info`: restored from a verified entry, or else the stored bytes streamed through it and
  // Finish called (then, an array recording parsed without error, an entry written). `keep_going`
  // (may be empty) is asked after every chunk; false stops the read (no Finish, no entry).
  Outcome Fill(storage::Store* store, const storage::RecordingInfo& info, RecordingParser* parser,
               const std::function<bool()>& keep_going = {});

  // Builds, in one background thread, the entry recording `id` needs under `config`'s reading
  // rules (PrepareParser; doubles); nothing for a recording that is not an inertial log or is
  // over prefetch_memory_bytes. At most kMaxQueued wait; more are dropped (their first reader
  // builds them).
  void Prefetch(storage::Store* store, int64_t id, const nlohmann::json& config);
  static constexpr size_t kMaxQueued = 4;

  // The reading rules of `parser` as the entries' key text (formats/column_file.h
  // ColumnFileKey::rules).
  static std::string RulesText(const RecordingParser& parser);
  // Where the entry of these bytes and rules lives.
  std::filesystem::path EntryPath(const std::string& sha256, const std::string& rules) const;

  bool enabled() const { return !options_.dir.empty(); }
  // Counters since start (tests, metrics).
  int64_t hits() const { return hits_; }
  int64_t writes() const { return writes_; }
  int64_t rebuilt() const { return rebuilt_; }
  // Waits until no background build is queued or running (tests).
  void WaitIdle();

 private:
  // Removes entries, least recently used first, until they total at most max_bytes (and
  // temporaries older than an hour).
  void Evict();
  void BuildLoop();

  ColumnCacheOptions options_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::set<std::string> building_;  // entries being read or built
  struct Job {
    storage::Store* store;
    int64_t id;
    nlohmann::json config;
  };
  std::deque<Job> queue_;
  bool busy_ = false, stopping_ = false;
  std::thread builder_;
  std::atomic<int64_t> hits_{0}, writes_{0}, rebuilt_{0};
};

// cache->Fill, or with no cache (null) the stored bytes streamed through `parser` and Finish
// called, as Fill does on a miss.
ColumnCache::Outcome FillParser(ColumnCache* cache, storage::Store* store,
                                const storage::RecordingInfo& info, RecordingParser* parser,
                                const std::function<bool()>& keep_going = {});

}  // namespace calibd::server

#endif  // CALIBD_SERVER_COLUMN_CACHE_H_
