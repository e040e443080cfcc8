// The parsed-columns cache (server/column_cache.h).
#include "server/column_cache.h"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <iostream>
#include <utility>
#include <vector>

#include "base/sha256.h"
#include "formats/column_file.h"
#include "formats/csv_dialect.h"
#include "formats/log_assembly.h"
#include "server/config.h"

namespace calibd::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kEntrySuffix = ".columns";
constexpr auto kTemporaryAge = std::chrono::hours(1);

// Streams recording `id`'s stored bytes through `parser` and finishes it (unless stopped).
ColumnCache::Outcome ReadStored(storage::Store* store, int64_t id, RecordingParser* parser,
                                const std::function<bool()>& keep_going) {
  ColumnCache::Outcome o;
  bool stopped = false;
  o.read = store->ReadRecordingData(id, [&](std::string_view chunk) {
    o.parse = parser->Feed(chunk);
    stopped = keep_going && !keep_going();
    return o.parse.ok() && !stopped;
  });
  if (o.read.ok() && o.parse.ok() && !stopped) o.parse = parser->Finish();
  return o;
}

}  // namespace

ColumnCache::ColumnCache(ColumnCacheOptions options) : options_(std::move(options)) {
  if (!enabled()) return;
  std::error_code ec;
  fs::create_directories(options_.dir, ec);
  if (ec) {
    std::cerr << "calibd: column cache disabled: cannot create " << options_.dir << ": "
              << ec.message() << "\n";
    options_.dir.clear();
    return;
  }
  builder_ = std::thread([this] { BuildLoop(); });
}

ColumnCache::~ColumnCache() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
    queue_.clear();
  }
  cv_.notify_all();
  if (builder_.joinable()) builder_.join();
}

std::string ColumnCache::RulesText(const RecordingParser& parser) {
  const LogStreamSelection& streams = parser.log_streams();
  json imus = json::array();
  for (const auto& imu : streams.imus) imus.push_back({imu.accel, imu.gyro, imu.temp});
  return json{{"time_unit", TimeUnitName(parser.time_unit())},
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
  return options_.dir / (sha256 + "-" + Sha256Hex(rules).substr(0, 16) + kEntrySuffix);
}

ColumnCache::Outcome ColumnCache::Fill(storage::Store* store, const storage::RecordingInfo& info,
                                       RecordingParser* parser,
                                       const std::function<bool()>& keep_going) {
  if (!enabled() || !parser->collects() || parser->collects_float() ||
      info.layout != LayoutName(Layout::kArray) || info.sha256.empty()) {
    return ReadStored(store, info.id, parser, keep_going);
  }
  const ColumnFileKey key{info.sha256, RulesText(*parser)};
  const fs::path path = EntryPath(key.recording_sha256, key.rules);
  {
    // One reader or builder per entry: a second one waits and then reads what the first wrote.
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return building_.count(path.string()) == 0; });
    building_.insert(path.string());
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
  if (cached.code() != StatusCode::kNotFound) {
    std::cerr << "calibd: " << cached.message() << "; removed, rebuilt from recording " << info.id
              << "\n";
    std::error_code ec;
    fs::remove(path, ec);
    ++rebuilt_;
  }
  Outcome o = ReadStored(store, info.id, parser, keep_going);
  if (!o.read.ok() || !o.parse.ok() || parser->summary().layout != Layout::kArray ||
      (keep_going && !keep_going())) {
    return o;
  }
  summary = parser->summary();
  if (!parser->TakeArray(&log).ok()) return o;
  const int64_t estimate = 8 * (log.t.size() + log.accel.size() + log.gyro.size() +
                                log.temperature.size() + log.mag.size());
  if (estimate < options_.max_bytes) {
    int64_t bytes = 0;
    Status w = WriteColumnFile(path.string(), key, summary, log, &bytes);
    if (w.ok()) {
      ++writes_;
      Evict();
    } else {
      std::cerr << "calibd: " << w.message() << " (recording " << info.id
                << " is read from its stored bytes until an entry can be written)\n";
    }
  }
  parser->Restore(summary, std::move(log));
  return o;
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
    Job job;
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      job = std::move(queue_.front());
      queue_.pop_front();
      busy_ = true;
    }
    storage::RecordingInfo info;
    if (job.store->GetRecording(job.id, &info).ok() && info.layout == LayoutName(Layout::kArray)) {
      const json columns = json::parse(info.columns_json, nullptr, /*allow_exceptions=*/false);
      const int64_t doubles =
          info.rows * (columns.is_array() ? static_cast<int64_t>(columns.size()) : 0);
      if (options_.prefetch_memory_bytes <= 0 || 16 * doubles <= options_.prefetch_memory_bytes) {
        json config = job.config.is_object() ? job.config : json::object();
        InheritCsvDialect(info, &config);
        RecordingParser parser("recording " + std::to_string(job.id), /*collect=*/true);
        parser.ExpectRows(info.rows);
        PrepareParser(config, &parser);
        parser.CollectArrayAsDouble();
        // Stops at shutdown; errors are the reader's to report (the job's or the check's).
        (void)Fill(job.store, info, &parser, [this] {
          std::lock_guard<std::mutex> lock(mu_);
          return !stopping_;
        });
      }
    }
    {
      std::lock_guard<std::mutex> lock(mu_);
      busy_ = false;
    }
    cv_.notify_all();
  }
}

ColumnCache::Outcome FillParser(ColumnCache* cache, storage::Store* store,
                                const storage::RecordingInfo& info, RecordingParser* parser,
                                const std::function<bool()>& keep_going) {
  if (cache != nullptr) return cache->Fill(store, info, parser, keep_going);
  return ReadStored(store, info.id, parser, keep_going);
}

}  // namespace calibd::server
