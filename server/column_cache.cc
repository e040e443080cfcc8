// The parsed-columns cache (server/column_cache.h).
#include "server/column_cache.h"

#include <sys/stat.h>
#include <sys/statvfs.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <utility>
#include <vector>

#include "base/sha256.h"
#include "formats/column_file.h"
#include "formats/csv_dialect.h"
#include "formats/log_assembly.h"
#include "formats/recording_version.h"
#include "server/config.h"

namespace calibd::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kEntrySuffix = ".columns";
constexpr auto kTemporaryAge = std::chrono::hours(1);

Status Stopped(int64_t id) {
  return Status(StatusCode::kStopped, "the read of recording " + std::to_string(id) + " stopped");
}

// Streams recording `id`'s stored bytes through `parser` and finishes it (unless stopped: then
// `read` is kStopped).
ColumnCache::Outcome ReadStored(storage::Store* store, int64_t id, RecordingParser* parser,
                                const std::function<bool()>& keep_going) {
  ColumnCache::Outcome o;
  bool stopped = false;
  o.read = store->ReadRecordingData(id, [&](std::string_view chunk) {
    o.parse = parser->Feed(chunk);
    stopped = keep_going && !keep_going();
    return o.parse.ok() && !stopped;
  });
  if (o.read.ok() && stopped) o.read = Stopped(id);
  if (o.read.ok() && o.parse.ok()) o.parse = parser->Finish();
  return o;
}

// Bytes available to unprivileged users on the file system of `dir`; -1: unknown.
int64_t FreeBytes(const fs::path& dir) {
  struct statvfs v;
  if (::statvfs(dir.c_str(), &v) != 0) return -1;
  return static_cast<int64_t>(v.f_bavail) * static_cast<int64_t>(v.f_frsize);
}

// The first violated constraint of `o`, or "".
std::string Invalid(const ColumnCacheOptions& o) {
  if (o.max_bytes <= 0) return "max_bytes must be > 0";
  if (o.min_free_bytes < 0) return "min_free_bytes must be >= 0";
  if (o.wait_poll_ms <= 0) return "wait_poll_ms must be > 0";
  return "";
}

}  // namespace

ColumnCache::ColumnCache(ColumnCacheOptions options) : options_(std::move(options)) {
  if (!enabled()) return;
  const std::string invalid = Invalid(options_);
  std::error_code ec;
  if (invalid.empty() && !fs::exists(options_.dir, ec)) {
    // Users' data: the owner's alone (the parents, if made, get the usual mode).
    if (fs::create_directories(options_.dir, ec)) {
      fs::permissions(options_.dir, fs::perms::owner_all, fs::perm_options::replace, ec);
    }
  }
  if (!invalid.empty() || ec) {
    std::cerr << "calibd: column cache disabled: "
              << (invalid.empty() ? "cannot create " + options_.dir.string() + ": " + ec.message()
                                  : invalid)
              << "\n";
    options_.dir.clear();
    return;
  }
  Evict();  // the bound may have been lowered since the entries were written
  builder_ = std::thread([this] { BuildLoop(); });
}

ColumnCache::~ColumnCache() { Stop(); }

void ColumnCache::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
    queue_.clear();
  }
  cv_.notify_all();
  // The build in progress polls stopping_ after every chunk. Stop() may run on several threads
  // (Shutdown, the destructor): one joins.
  std::lock_guard<std::mutex> join(join_mu_);
  if (builder_.joinable()) builder_.join();
}

std::string ColumnCache::RulesText(const RecordingParser& parser) {
  const LogStreamSelection& streams = parser.log_streams();
  json imus = json::array();
  for (const auto& imu : streams.imus) imus.push_back({imu.accel, imu.gyro, imu.temp});
  return json{{"parser_version", kRecordingParserVersion},
              {"time_unit", TimeUnitName(parser.time_unit())},
              {"csv", parser.csv_dialect().ToJson()},
              {"imus", imus},
              // `streams` given at all (even {}): a log with IMUs on their own time bases is
              // then refused rather than read without them, so it is a reading rule too.
              {"streams_given", streams.given},
              {"mags", streams.mags},
              {"mag_time_base", streams.mag_time_base}}
      .dump(-1, ' ', false, json::error_handler_t::replace);
}

fs::path ColumnCache::EntryPath(const std::string& sha256, const std::string& rules) const {
  // The file's version in the name: a server of another version neither reads nor removes it.
  return options_.dir / (sha256 + "-" + Sha256Hex(rules).substr(0, 16) + ".v" +
                         std::to_string(kColumnFileVersion) + kEntrySuffix);
}

bool ColumnCache::Claim(const std::string& path, const std::function<bool()>& keep_going) {
  // One reader or builder per entry: a second one waits and then reads what the first wrote.
  std::unique_lock<std::mutex> lock(mu_);
  for (;;) {
    if (stopping_) return false;
    if (building_.count(path) == 0) break;
    cv_.wait_for(lock, std::chrono::milliseconds(options_.wait_poll_ms));
    if (stopping_ || building_.count(path) == 0) continue;
    // keep_going may take locks of its own (never call it holding mu_).
    lock.unlock();
    const bool go = !keep_going || keep_going();
    lock.lock();
    if (!go) return false;
  }
  building_.insert(path);
  return true;
}

ColumnCache::Outcome ColumnCache::Fill(storage::Store* store, const storage::RecordingInfo& info,
                                       RecordingParser* parser,
                                       const std::function<bool()>& keep_going) {
  if (!enabled() || stopping_ || !parser->collects() || parser->collects_float() ||
      info.layout != LayoutName(Layout::kArray) || info.sha256.empty()) {
    return ReadStored(store, info.id, parser, keep_going);
  }
  const ColumnFileKey key{info.sha256, RulesText(*parser)};
  const fs::path path = EntryPath(key.recording_sha256, key.rules);
  if (!Claim(path.string(), keep_going)) {
    Outcome o;
    o.read = stopping_ ? Status(StatusCode::kStopped,
                                "the parsed-columns cache stopped "
                                "(shutdown) while recording " +
                                    std::to_string(info.id) + " was built")
                       : Stopped(info.id);
    return o;
  }
  struct Release {
    ColumnCache* cache;
    std::string path;
    ~Release() {
      {
        std::lock_guard<std::mutex> lock(cache->mu_);
        cache->building_.erase(path);
      }
      cache->cv_.notify_all();
    }
  } release{this, path.string()};
  RecordingSummary summary;
  ArrayRecording log;
  Status cached = ReadColumnFile(path.string(), key, &summary, &log);
  if (cached.ok()) {
    // Most recently used: the last to be evicted.
    std::error_code ec;
    fs::last_write_time(path, fs::file_time_type::clock::now(), ec);
    parser->Restore(summary, std::move(log));
    ++hits_;
    Outcome o;
    o.hit = true;
    return o;
  }
  // Damaged, cut or stale: removed and rebuilt. Not readable now (kIoError: out of file
  // descriptors, EIO...): left as it is, this read parses the stored bytes and writes nothing.
  const bool unreadable =
      cached.code() != StatusCode::kNotFound && cached.code() != StatusCode::kCorruption;
  if (unreadable) {
    std::cerr << "calibd: " << cached.message() << "; recording " << info.id
              << " read from its stored bytes, the entry kept\n";
  } else if (cached.code() == StatusCode::kCorruption) {
    std::cerr << "calibd: " << cached.message() << "; removed, rebuilt from recording " << info.id
              << "\n";
    std::error_code ec;
    fs::remove(path, ec);
    ++rebuilt_;
  }
  Outcome o = ReadStored(store, info.id, parser, keep_going);
  if (unreadable || !o.read.ok() || !o.parse.ok() || parser->summary().layout != Layout::kArray ||
      (keep_going && !keep_going())) {
    return o;
  }
  summary = parser->summary();
  if (!parser->TakeArray(&log).ok()) return o;
  WriteEntry(path.string(), key, summary, log, info.id);
  parser->Restore(summary, std::move(log));
  return o;
}

void ColumnCache::WriteEntry(const std::string& path, const ColumnFileKey& key,
                             const RecordingSummary& summary, const ArrayRecording& log,
                             int64_t id) {
  const int64_t estimate = 8 * (log.t.size() + log.accel.size() + log.gyro.size() +
                                log.temperature.size() + log.mag.size());
  if (estimate >= options_.max_bytes) return;
  if (options_.min_free_bytes > 0) {
    const int64_t free = FreeBytes(options_.dir);
    if (free >= 0 && free - estimate < options_.min_free_bytes) {
      std::cerr << "calibd: column cache: no entry for recording " << id << ": "
                << options_.dir.string() << " has " << free << " bytes free, under "
                << options_.min_free_bytes << " after a " << estimate << "-byte entry\n";
      return;
    }
  }
  Status w = WriteColumnFile(path, key, summary, log);
  if (w.ok()) {
    ++writes_;
    Evict();
  } else {
    std::cerr << "calibd: " << w.message() << " (recording " << id
              << " is read from its stored bytes until an entry can be written)\n";
  }
}

void ColumnCache::Evict() {
  struct Entry {
    fs::path path;
    fs::file_time_type used;
    int64_t bytes;
  };
  std::vector<Entry> entries;
  int64_t total = 0;
  const auto now = fs::file_time_type::clock::now();
  std::error_code ec;
  for (fs::directory_iterator it(options_.dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code e2;
    if (!it->is_regular_file(e2)) continue;
    const std::string name = it->path().filename().string();
    const auto used = it->last_write_time(e2);
    if (e2) continue;
    if (name.find(".tmp.") != std::string::npos) {
      // A temporary of a write that crashed (live writes finish within seconds).
      if (now - used > kTemporaryAge) fs::remove(it->path(), e2);
      continue;
    }
    if (name.size() < 8 || name.compare(name.size() - 8, 8, kEntrySuffix) != 0) continue;
    const auto bytes = static_cast<int64_t>(it->file_size(e2));
    if (e2) continue;
    entries.push_back({it->path(), used, bytes});
    total += bytes;
  }
  std::sort(entries.begin(), entries.end(),
            [](const Entry& a, const Entry& b) { return a.used < b.used; });
  for (const Entry& e : entries) {
    if (total <= options_.max_bytes) break;
    std::error_code e3;
    if (fs::remove(e.path, e3)) total -= e.bytes;
  }
}

void ColumnCache::Prefetch(storage::Store* store, int64_t id, const json& config) {
  if (!enabled()) return;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ || queue_.size() >= kMaxQueued) return;
    queue_.push_back({store, id, config});
  }
  cv_.notify_all();
}

void ColumnCache::WaitIdle() {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait(lock, [&] { return stopping_ || (queue_.empty() && !busy_); });
}

void ColumnCache::BuildLoop() {
  for (;;) {
    BuildJob job;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
    }
    // One failed build (out of memory, a store or library that throws) is that build's alone:
    // an exception escaping this thread would end the process.
    try {
      Build(job);
    } catch (const std::exception& e) {
      std::cerr << "calibd: column cache: the background build of recording " << job.id
                << " failed: " << e.what() << "\n";
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      busy_ = false;
    }
    cv_.notify_all();
  }
}

void ColumnCache::Build(const BuildJob& job) {
  storage::RecordingInfo info;
  if (!job.store->GetRecording(job.id, &info).ok() || info.layout != LayoutName(Layout::kArray)) {
    return;
  }
  const json columns = json::parse(info.columns_json, nullptr, /*allow_exceptions=*/false);
  const int64_t doubles =
      info.rows * (columns.is_array() ? static_cast<int64_t>(columns.size()) : 0);
  if (options_.prefetch_memory_bytes > 0 && 16 * doubles > options_.prefetch_memory_bytes) return;
  json config = job.config.is_object() ? job.config : json::object();
  InheritCsvDialect(info, &config);
  RecordingParser parser("recording " + std::to_string(job.id), /*collect=*/true);
  parser.ExpectRows(info.rows);
  PrepareParser(config, &parser);
  parser.CollectArrayAsDouble();
  // Stops at Stop(); errors are the reader's to report (the job's or the check's).
  (void)Fill(job.store, info, &parser, [this] { return !stopping_.load(); });
}

ColumnCache::Outcome FillParser(ColumnCache* cache, storage::Store* store,
                                const storage::RecordingInfo& info, RecordingParser* parser,
                                const std::function<bool()>& keep_going) {
  if (cache != nullptr) return cache->Fill(store, info, parser, keep_going);
  return ReadStored(store, info.id, parser, keep_going);
}

}  // namespace calibd::server
