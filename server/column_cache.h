// The parsed-columns cache of stored inertial logs: a stored recording parsed once (at upload, in
// the background, or by the first job, check or /segments that reads it) is kept as a binary
// columnar file (formats/column_file.h), and later reads of the same bytes with the same reading
// rules restore the parser from it instead of reading, hashing and parsing the stored CSV or log
// again (bench/README.md "Recording check": an hour of 400 Hz, 128 MB of CSV).
//
// Entries are keyed by the recording's SHA-256 and the reading rules in force (time unit, CSV
// dialect, log streams and time base, the parser's kRecordingParserVersion), and named with the
// column file's kColumnFileVersion as well: a parser with other rules or another version, or
// other bytes under the same id, never meets an entry made for them. Every read verifies the
// entry (size, key, CRC-32 of header and data); a damaged, cut or stale entry (kCorruption) is
// removed, said on stderr, and rebuilt from the stored bytes by that very read; an entry that
// cannot be read (kIoError: EMFILE, EIO...) is left in place and that read parses the stored
// bytes (no entry written). An entry is written only from a complete read whose bytes matched
// their stored SHA-256, atomically (temporary file, fsync, rename), so a crash leaves no torn
// entry under an entry's name; temporaries left by a crash are removed after an hour.
//
// Disk use is bounded: entries total at most max_bytes (least recently used removed first, at
// start and on every write); an entry alone larger is not written, nor one that would leave
// less than min_free_bytes free on the cache's file system. The folder is created 0700 (it
// holds users' data). Two servers given one folder share its entries (keyed by content, so
// correctly) and its bound: each evicts by the total of both. Recordings are never deleted by
// calibd; an entry whose recording is gone is unreachable and ages out by the same rule.
//
// Only parsers collecting doubles are served (a float-collecting parser, the noise method's, is
// read from the stored bytes as before: restoring doubles and converting would exceed its memory
// budget). Thread-safe; one build per entry at a time (a second reader waits for it and reads
// the entry; its keep_going is polled while it waits). Stop() ends the background build and
// every wait at once (shutdown).
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

struct ColumnFileKey;  // formats/column_file.h

// A background build's request (ColumnCache::Prefetch).
struct BuildJob {
  storage::Store* store = nullptr;
  int64_t id = 0;
  nlohmann::json config;
};

struct ColumnCacheOptions {
  std::filesystem::path dir;             // created when missing; "" disables the cache
  int64_t max_bytes = int64_t{2} << 30;  // the entries' total size (> 0)
  // The background build (Prefetch) parses a recording only when its doubles (rows × columns ×
  // 8 bytes, twice: parsed and written) fit in this; <= 0: no limit.
  int64_t prefetch_memory_bytes = 0;
  // An entry is not written (one line on stderr) when it would leave less than this free on
  // the cache's file system (statvfs, space available to unprivileged users); 0: no floor.
  int64_t min_free_bytes = int64_t{1} << 30;
  // How often a reader waiting for another's build of the same entry asks its keep_going (> 0).
  int wait_poll_ms = 50;
};

class ColumnCache {
 public:
  // Creates the folder (0700) and removes entries over max_bytes (the bound may have been
  // lowered since the last run). Options that violate their constraints disable the cache,
  // said on stderr naming the constraint.
  explicit ColumnCache(ColumnCacheOptions options);
  ~ColumnCache();  // Stop()
  // Ends the background build (the queue cleared, the build in progress told to stop, joined)
  // and wakes every reader waiting for a build (their Fill returns kStopped). Later Fill calls
  // read the stored bytes without the cache; later Prefetch calls do nothing. Idempotent.
  void Stop();
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
  // (may be empty) is asked after every chunk and every wait_poll_ms while waiting for another
  // reader's build of the same entry; false stops the read (no Finish, no entry) with `read`
  // kStopped, as does Stop() during such a wait.
  Outcome Fill(storage::Store* store, const storage::RecordingInfo& info, RecordingParser* parser,
               const std::function<bool()>& keep_going = {});

  // Builds, in one background thread, the entry recording `id` needs under `config`'s reading
  // rules (PrepareParser; doubles); nothing for a recording that is not an inertial log or is
  // over prefetch_memory_bytes. At most kMaxQueued wait; more are dropped (their first reader
  // builds them). A build that throws is said on stderr and dropped (the process goes on).
  void Prefetch(storage::Store* store, int64_t id, const nlohmann::json& config);
  static constexpr size_t kMaxQueued = 4;

  // The reading rules of `parser` and kRecordingParserVersion as the entries' key text
  // (formats/column_file.h ColumnFileKey::rules).
  static std::string RulesText(const RecordingParser& parser);
  // Where the entry of these bytes and rules lives (kColumnFileVersion in its name).
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
  void Build(const BuildJob& job);
  // Claims `path` for this reader: waits while another builds it. False: keep_going said stop
  // or the cache was stopped.
  bool Claim(const std::string& path, const std::function<bool()>& keep_going);
  // Writes the entry unless over max_bytes or the free-space floor.
  void WriteEntry(const std::string& path, const ColumnFileKey& key,
                  const RecordingSummary& summary, const ArrayRecording& log, int64_t id);

  ColumnCacheOptions options_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::set<std::string> building_;  // entries being read or built
  std::deque<BuildJob> queue_;
  bool busy_ = false;
  std::atomic<bool> stopping_{false};
  std::thread builder_;
  std::mutex join_mu_;  // Stop() joins builder_ on one thread at a time
  std::atomic<int64_t> hits_{0}, writes_{0}, rebuilt_{0};
};

// cache->Fill, or with no cache (null) the stored bytes streamed through `parser` and Finish
// called, as Fill does on a miss.
ColumnCache::Outcome FillParser(ColumnCache* cache, storage::Store* store,
                                const storage::RecordingInfo& info, RecordingParser* parser,
                                const std::function<bool()>& keep_going = {});

}  // namespace calibd::server

#endif  // CALIBD_SERVER_COLUMN_CACHE_H_
