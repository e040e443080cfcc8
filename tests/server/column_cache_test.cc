// The parsed-columns cache (server/column_cache.h) on a real SQLite store: a cached read gives
// bit for bit the parse of the stored bytes (summary and every column); an entry damaged
// anywhere (a flipped byte at any of many offsets, a cut file, another version) is detected,
// removed and rebuilt, never served; other reading rules (time unit, CSV dialect) never meet an
// entry made for others; the entries stay within their byte bound (least recently used removed
// first); the upload's background build serves the first reader; and over HTTP the check and
// /segments answer the same with the cache as without it. Hardening: a reader waiting for
// another's build ends with its own stop (a check's stop token too) or the cache's Stop() within
// a second; an entry that cannot be read (kIoError) is kept, not removed; the entry's name holds
// the file version and its key the parser's; a header over the reader's limit is not written;
// the bound is enforced at start; the folder is 0700; no entry below the free-space floor.
#include "server/column_cache.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <future>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/imu_simulation.h"
#include "formats/column_file.h"
#include "formats/csv_dialect.h"
#include "formats/recording_version.h"
#include "methods/imu/imu_method.h"
#include "server/config.h"
#include "server/metrics.h"
#include "server/recording_check.h"
#include "server/worker_pool.h"
#include "storage/store.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using storage::JobStatus;
using testing::TempDir;
using testing::TestServer;

std::string SimulatedCsv(int statics, uint64_t seed) {
  core::ImuSimulationOptions o;
  o.statics = statics;
  o.seed = seed;
  std::string csv;
  json config, truth;
  EXPECT_TRUE(SimulateImuFiles(o, &csv, &config, &truth).ok());
  return csv;
}

// The rules of a parser left at its defaults (seconds, calibd's CSV, every stream).
std::string DefaultRules() {
  RecordingParser parser("default", /*collect=*/true);
  return ColumnCache::RulesText(parser);
}

// `csv` with its header replaced by `header`.
std::string WithHeader(const std::string& csv, const std::string& header) {
  return header + csv.substr(csv.find('\n'));
}

class ColumnCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(storage::Store::Open((dir_.path() / "calibd.db").string(), {}, &store_).ok());
  }

  // Stores `csv` (read with `dialect` for its summary, as an upload does); its metadata.
  storage::RecordingInfo Put(const std::string& csv, const CsvDialect& dialect = {}) {
    RecordingParser parser("upload", /*collect=*/false);
    parser.SetCsvDialect(dialect);
    EXPECT_TRUE(ParseRecording(csv, &parser).ok());
    const RecordingSummary& s = parser.summary();
    storage::NewRecording r;
    r.data = csv;
    r.layout = LayoutName(s.layout);
    r.rows = s.rows;
    r.columns_json = json(s.columns).dump();
    r.sensors_json = json(s.sensors).dump();
    r.log_json = s.log_description;
    storage::RecordingInfo info;
    EXPECT_TRUE(store_->PutRecording(r, &info, nullptr).ok());
    EXPECT_TRUE(store_->GetRecording(info.id, &info).ok());
    return info;
  }

  // The recording read through `cache` (null: the stored bytes parsed) with these rules.
  RecordingSummary Read(ColumnCache* cache, const storage::RecordingInfo& info, ArrayRecording* log,
                        TimeUnit unit = TimeUnit::kSeconds, const CsvDialect& dialect = {},
                        bool* hit = nullptr) {
    RecordingParser parser("recording", /*collect=*/true);
    parser.ExpectRows(info.rows);
    parser.SetTimeUnit(unit);
    parser.SetCsvDialect(dialect);
    const ColumnCache::Outcome o = FillParser(cache, store_.get(), info, &parser);
    EXPECT_TRUE(o.read.ok()) << o.read.ToString();
    EXPECT_TRUE(o.parse.ok()) << o.parse.ToString();
    if (hit != nullptr) *hit = o.hit;
    EXPECT_TRUE(parser.TakeArray(log).ok());
    return parser.summary();
  }

  ColumnCacheOptions Options(int64_t max_bytes = int64_t{1} << 30) {
    ColumnCacheOptions o;
    o.dir = dir_.path() / "columns";
    o.max_bytes = max_bytes;
    o.min_free_bytes = 0;  // the floor has its own test; these must not depend on the disk
    return o;
  }

  std::vector<fs::path> Entries() {
    std::vector<fs::path> out;
    for (const auto& e : fs::directory_iterator(dir_.path() / "columns")) out.push_back(e.path());
    return out;
  }

  TempDir dir_;
  std::unique_ptr<storage::Store> store_;
};

// Bit for bit: == on doubles would take -0 for 0 and refuse NaN == NaN.
template <typename M>
bool SameBits(const M& a, const M& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0);
}

void ExpectSame(const RecordingSummary& sa, const ArrayRecording& a, const RecordingSummary& sb,
                const ArrayRecording& b) {
  EXPECT_TRUE(SameBits(a.t, b.t));
  EXPECT_TRUE(SameBits(a.accel, b.accel));
  EXPECT_TRUE(SameBits(a.gyro, b.gyro));
  EXPECT_TRUE(SameBits(a.temperature, b.temperature));
  EXPECT_TRUE(SameBits(a.mag, b.mag));
  EXPECT_EQ(a.accel_names, b.accel_names);
  EXPECT_EQ(a.gyro_names, b.gyro_names);
  EXPECT_EQ(a.temp_names, b.temp_names);
  EXPECT_EQ(a.mag_names, b.mag_names);
  EXPECT_EQ(sa.rows, sb.rows);
  EXPECT_EQ(sa.columns, sb.columns);
  EXPECT_EQ(sa.sensors, sb.sensors);
  EXPECT_EQ(sa.t_column, sb.t_column);
  EXPECT_EQ(sa.t_first_line, sb.t_first_line);
  EXPECT_EQ(std::memcmp(&sa.t_first, &sb.t_first, 8), 0);
  EXPECT_EQ(std::memcmp(&sa.t_median_step, &sb.t_median_step, 8), 0);
  EXPECT_EQ(sa.t_disorder_line, sb.t_disorder_line);
  EXPECT_EQ(sa.time_origin, sb.time_origin);
  EXPECT_EQ(sa.time_unit, sb.time_unit);
  EXPECT_EQ(sa.format, sb.format);
  EXPECT_EQ(sa.log_description, sb.log_description);
}

TEST_F(ColumnCacheTest, CachedReadIsTheParseBitForBit) {
  // With temperatures and epoch stamps (time_origin), so that every part of the file is used.
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z,temp\n";
  const std::string sim = SimulatedCsv(12, 5);
  std::istringstream lines(sim.substr(sim.find('\n') + 1));
  std::string line;
  for (int i = 0; std::getline(lines, line); ++i) {
    const size_t comma = line.find(',');
    char t[64];
    std::snprintf(t, sizeof t, "%.6f", 1.7e9 + std::stod(line.substr(0, comma)));
    csv += t + line.substr(comma) + "," + std::to_string(20 + (i % 100) * 0.01) + "\n";
  }
  const storage::RecordingInfo info = Put(csv);
  ArrayRecording parsed, first, second;
  const RecordingSummary s0 = Read(nullptr, info, &parsed);
  ASSERT_GT(s0.time_origin, 0);
  ASSERT_EQ(parsed.temperature.cols(), 1);
  ColumnCache cache(Options());
  bool hit = true;
  const RecordingSummary s1 = Read(&cache, info, &first, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit);
  EXPECT_EQ(cache.writes(), 1);
  const RecordingSummary s2 = Read(&cache, info, &second, TimeUnit::kSeconds, {}, &hit);
  EXPECT_TRUE(hit);
  EXPECT_EQ(cache.hits(), 1);
  ExpectSame(s0, parsed, s1, first);
  ExpectSame(s0, parsed, s2, second);
}

TEST_F(ColumnCacheTest, DamagedOrCutEntryIsRebuiltNeverServed) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 7));
  ArrayRecording parsed;
  const RecordingSummary s0 = Read(nullptr, info, &parsed);
  ColumnCache cache(Options());
  ArrayRecording log;
  Read(&cache, info, &log);
  ASSERT_EQ(Entries().size(), 1u);
  const fs::path entry = Entries()[0];
  std::string good;
  {
    std::ifstream in(entry, std::ios::binary);
    good.assign(std::istreambuf_iterator<char>(in), {});
  }
  // Damage at 40 offsets spread over the whole file (magic, version, header length, header, its
  // checksum, the columns, the last byte), then cuts: every one is detected and rebuilt.
  std::vector<std::string> damaged;
  for (int k = 0; k < 40; ++k) {
    std::string d = good;
    const size_t at = k < 39 ? good.size() * static_cast<size_t>(k) / 39 : good.size() - 1;
    d[at] = static_cast<char>(d[at] ^ (1 << (k % 8)));
    damaged.push_back(d);
  }
  for (size_t cut : {size_t{0}, size_t{20}, good.size() / 2, good.size() - 1}) {
    damaged.push_back(good.substr(0, cut));
  }
  damaged.push_back(good + "x");
  int64_t rebuilt = 0;
  for (size_t i = 0; i < damaged.size(); ++i) {
    {
      std::ofstream out(entry, std::ios::binary | std::ios::trunc);
      out << damaged[i];
    }
    bool hit = true;
    ArrayRecording again;
    const RecordingSummary s = Read(&cache, info, &again, TimeUnit::kSeconds, {}, &hit);
    EXPECT_FALSE(hit) << "damage " << i << " was served";
    EXPECT_EQ(cache.rebuilt(), ++rebuilt) << "damage " << i;
    ExpectSame(s0, parsed, s, again);
    // Rebuilt whole: the next read is a hit with the same numbers.
    ArrayRecording third;
    const RecordingSummary s3 = Read(&cache, info, &third, TimeUnit::kSeconds, {}, &hit);
    EXPECT_TRUE(hit) << "damage " << i;
    ExpectSame(s0, parsed, s3, third);
  }
  // The reader's own verdict names what is wrong.
  {
    std::ofstream out(entry, std::ios::binary | std::ios::trunc);
    out << good.substr(0, good.size() / 2);
  }
  RecordingSummary s;
  ArrayRecording a;
  const Status st = ReadColumnFile(entry.string(), {info.sha256, DefaultRules()}, &s, &a);
  EXPECT_EQ(st.code(), StatusCode::kCorruption) << st.ToString();
}

TEST_F(ColumnCacheTest, OtherReadingRulesNeverMeetAnotherRulesEntry) {
  // A file with its own header names: two dialects map them the other way round, so the same
  // bytes give two different recordings.
  const std::string csv = WithHeader(SimulatedCsv(6, 9), "time,ax,ay,az,gx,gy,gz");
  CsvDialect straight, swapped;
  const char* axes[] = {"x", "y", "z"};
  straight.columns.push_back({"t", "time"});
  swapped.columns.push_back({"t", "time"});
  for (int a = 0; a < 3; ++a) {
    straight.columns.push_back({std::string("a0_") + axes[a], std::string("a") + axes[a]});
    straight.columns.push_back({std::string("g0_") + axes[a], std::string("g") + axes[a]});
    swapped.columns.push_back({std::string("a0_") + axes[a], std::string("g") + axes[a]});
    swapped.columns.push_back({std::string("g0_") + axes[a], std::string("a") + axes[a]});
  }
  const storage::RecordingInfo info = Put(csv, straight);
  ColumnCache cache(Options());
  ArrayRecording cached_straight, cached_swapped, parsed_swapped, cached_ms, parsed_ms;
  bool hit = true;
  Read(&cache, info, &cached_straight, TimeUnit::kSeconds, straight, &hit);
  EXPECT_FALSE(hit);
  // The other dialect: not the first entry (its accelerometer is the first's gyroscope).
  const RecordingSummary sw =
      Read(&cache, info, &cached_swapped, TimeUnit::kSeconds, swapped, &hit);
  EXPECT_FALSE(hit);
  const RecordingSummary sw0 = Read(nullptr, info, &parsed_swapped, TimeUnit::kSeconds, swapped);
  ExpectSame(sw0, parsed_swapped, sw, cached_swapped);
  EXPECT_TRUE(SameBits(cached_swapped.accel, cached_straight.gyro));
  EXPECT_FALSE(SameBits(cached_swapped.accel, cached_straight.accel));
  // Another time unit: t a thousand times smaller, its own entry.
  const RecordingSummary ms =
      Read(&cache, info, &cached_ms, TimeUnit::kMilliseconds, straight, &hit);
  EXPECT_FALSE(hit);
  const RecordingSummary ms0 = Read(nullptr, info, &parsed_ms, TimeUnit::kMilliseconds, straight);
  ExpectSame(ms0, parsed_ms, ms, cached_ms);
  EXPECT_NEAR(cached_ms.t[10] * 1000, cached_straight.t[10], 1e-9);
  EXPECT_EQ(cache.writes(), 3);
  EXPECT_EQ(cache.hits(), 0);
  EXPECT_EQ(Entries().size(), 3u);
  // And each is served to its own rules.
  ArrayRecording again;
  Read(&cache, info, &again, TimeUnit::kSeconds, swapped, &hit);
  EXPECT_TRUE(hit);
  EXPECT_TRUE(SameBits(again.accel, cached_swapped.accel));
}

TEST_F(ColumnCacheTest, EntriesStayWithinTheirBoundLeastRecentlyUsedFirst) {
  std::vector<storage::RecordingInfo> infos;
  for (uint64_t seed = 1; seed <= 3; ++seed) infos.push_back(Put(SimulatedCsv(6, seed)));
  ArrayRecording log;
  int64_t entry_bytes = 0;
  {
    ColumnCache probe(Options());
    Read(&probe, infos[0], &log);
    entry_bytes = static_cast<int64_t>(fs::file_size(Entries()[0]));
    fs::remove_all(dir_.path() / "columns");
  }
  // Room for two entries (the three are within a few bytes of each other).
  ColumnCache cache(Options(2 * entry_bytes + entry_bytes / 2));
  Read(&cache, infos[0], &log);
  Read(&cache, infos[1], &log);
  // Entry 0 used again after 1 (mtime resolution: set it explicitly).
  fs::last_write_time(cache.EntryPath(infos[1].sha256, DefaultRules()),
                      fs::file_time_type::clock::now() - std::chrono::hours(1));
  bool hit = false;
  Read(&cache, infos[0], &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_TRUE(hit);
  Read(&cache, infos[2], &log);
  int64_t total = 0;
  for (const fs::path& p : Entries()) total += static_cast<int64_t>(fs::file_size(p));
  EXPECT_EQ(Entries().size(), 2u);
  EXPECT_LE(total, 2 * entry_bytes + entry_bytes / 2);
  // Entry 0 used before 2 was written (set explicitly: a write's mtime comes from the kernel's
  // coarse clock, which can lag a touch made a millisecond earlier).
  fs::last_write_time(cache.EntryPath(infos[0].sha256, DefaultRules()),
                      fs::file_time_type::clock::now() - std::chrono::minutes(30));
  Read(&cache, infos[1], &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit) << "the least recently used entry should have gone";
  Read(&cache, infos[0], &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit) << "entry 0 was older than 2's: gone when 1 came back";
  // A bound below one entry: nothing is written, every read parses.
  ColumnCache tiny(Options(entry_bytes / 2));
  fs::remove_all(dir_.path() / "columns");
  fs::create_directories(dir_.path() / "columns");
  Read(&tiny, infos[0], &log, TimeUnit::kSeconds, {}, &hit);
  Read(&tiny, infos[0], &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit);
  EXPECT_EQ(tiny.writes(), 0);
}

TEST_F(ColumnCacheTest, BackgroundBuildServesTheFirstReader) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 13));
  ColumnCache cache(Options());
  cache.Prefetch(store_.get(), info.id, json{{"method", "imu"}});
  cache.WaitIdle();
  EXPECT_EQ(cache.writes(), 1);
  bool hit = false;
  ArrayRecording log, parsed;
  const RecordingSummary s = Read(&cache, info, &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_TRUE(hit);
  ExpectSame(Read(nullptr, info, &parsed), parsed, s, log);
}

// A reader that holds an entry's build: its keep_going (asked after the first chunk) blocks
// until Release() (or 10 s), so the build is as slow as a test needs.
class HeldBuild {
 public:
  // `prepare` sets the parser's reading rules (those of the reader that is to wait for it).
  HeldBuild(ColumnCache* cache, storage::Store* store, const storage::RecordingInfo& info,
            const std::function<void(RecordingParser*)>& prepare) {
    thread_ = std::thread([this, cache, store, info, prepare] {
      RecordingParser parser("held", /*collect=*/true);
      prepare(&parser);
      outcome_ = FillParser(cache, store, info, &parser, [this] {
        std::unique_lock<std::mutex> lock(mu_);
        inside_ = true;
        cv_.notify_all();
        cv_.wait_for(lock, std::chrono::seconds(10), [&] { return released_; });
        return true;
      });
    });
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return inside_; });
  }
  void Release() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      released_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }
  ~HeldBuild() { Release(); }
  const ColumnCache::Outcome& outcome() const { return outcome_; }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool inside_ = false, released_ = false;
  ColumnCache::Outcome outcome_;
  std::thread thread_;
};

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

TEST_F(ColumnCacheTest, AReaderWaitingForAnothersBuildStopsWithItsOwnStop) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 31));
  ColumnCache cache(Options());
  HeldBuild held(&cache, store_.get(), info, [&](RecordingParser* p) { p->ExpectRows(info.rows); });
  std::atomic<bool> stop{false};
  auto waiter = std::async(std::launch::async, [&] {
    RecordingParser parser("waiter", /*collect=*/true);
    ColumnCache::Outcome o = FillParser(&cache, store_.get(), info, &parser, [&] { return !stop; });
    return std::make_pair(o, std::chrono::steady_clock::now());
  });
  // It waits (the build is held)...
  EXPECT_EQ(waiter.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout);
  const auto asked = std::chrono::steady_clock::now();
  stop = true;
  // ...and ends within a second of its stop, with kStopped, though the build still runs.
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(1)), std::future_status::ready);
  const auto [o, when] = waiter.get();
  EXPECT_LT(std::chrono::duration<double>(when - asked).count(), 1.0);
  EXPECT_EQ(o.read.code(), StatusCode::kStopped) << o.read.ToString();
  EXPECT_FALSE(o.hit);
  held.Release();
  EXPECT_TRUE(held.outcome().read.ok()) << held.outcome().read.ToString();
  EXPECT_EQ(cache.writes(), 1);
}

TEST_F(ColumnCacheTest, StopWakesWaitersAndLaterReadsParseTheStoredBytes) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 32));
  ColumnCache cache(Options());
  HeldBuild held(&cache, store_.get(), info, [&](RecordingParser* p) { p->ExpectRows(info.rows); });
  auto waiter = std::async(std::launch::async, [&] {
    RecordingParser parser("waiter", /*collect=*/true);
    return FillParser(&cache, store_.get(), info, &parser);  // no stop of its own
  });
  EXPECT_EQ(waiter.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout);
  const auto start = std::chrono::steady_clock::now();
  cache.Stop();
  ASSERT_EQ(waiter.wait_for(std::chrono::seconds(1)), std::future_status::ready);
  EXPECT_LT(SecondsSince(start), 1.0);
  const ColumnCache::Outcome o = waiter.get();
  EXPECT_EQ(o.read.code(), StatusCode::kStopped) << o.read.ToString();
  // A read after Stop neither waits nor uses the cache: the stored bytes, parsed.
  ArrayRecording log, parsed;
  bool hit = true;
  const RecordingSummary s = Read(&cache, info, &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit);
  ExpectSame(Read(nullptr, info, &parsed), parsed, s, log);
  // Nothing more is queued after Stop.
  cache.Prefetch(store_.get(), info.id, json{{"method", "imu"}});
  cache.WaitIdle();
  EXPECT_EQ(cache.writes(), 0);
  held.Release();
  EXPECT_EQ(cache.hits(), 0);
}

// A check (its stop token) waiting for a build of the same entry: stopped within a second.
TEST_F(ColumnCacheTest, ACheckWaitingForABuildStopsWithItsStopToken) {
  const storage::RecordingInfo info = Put(SimulatedCsv(24, 33));
  ColumnCache cache(Options());
  const json config = {{"method", "imu"}};
  // The check's own reading rules (recording_check.cc), so that it waits for this very entry.
  HeldBuild held(&cache, store_.get(), info, [&](RecordingParser* p) {
    json read_config = config;
    InheritCsvDialect(info, &read_config);
    p->ExpectRows(info.rows);
    PrepareParser(read_config, p);
    p->CollectArrayAsDouble();
  });
  core::StopToken stop;
  CheckRequest request;
  request.recording_id = info.id;
  request.config = config;
  request.cache = &cache;
  request.stop = &stop;
  auto check = std::async(std::launch::async, [&] {
    json out;
    return ComputeCheck(store_.get(), request, &out);
  });
  EXPECT_EQ(check.wait_for(std::chrono::milliseconds(300)), std::future_status::timeout);
  const auto start = std::chrono::steady_clock::now();
  stop.RequestStop(core::StopReason::kShutdown);
  ASSERT_EQ(check.wait_for(std::chrono::seconds(1)), std::future_status::ready);
  EXPECT_LT(SecondsSince(start), 1.0);
  const Status s = check.get();
  EXPECT_EQ(s.code(), StatusCode::kStopped) << s.ToString();
  held.Release();
  // Unstopped, the same check is served by the entry the build wrote.
  json out;
  request.stop = nullptr;
  ASSERT_TRUE(ComputeCheck(store_.get(), request, &out).ok());
  EXPECT_EQ(cache.hits(), 1);
}

// A job (WorkerPool) waiting for a build of its entry: a cancel fails it within a second; the
// shutdown (the cache's Stop, then the workers') sends it back to the queue within a second,
// uncounted.
TEST_F(ColumnCacheTest, AJobWaitingForABuildStopsWithItsCancelAndAtShutdown) {
  const storage::RecordingInfo info = Put(SimulatedCsv(24, 38));
  const json config = {{"method", "imu"}};
  ColumnCache cache(Options());
  // The job's own reading rules (worker_pool.cc), so that it waits for this very entry.
  HeldBuild held(&cache, store_.get(), info, [&](RecordingParser* p) {
    p->ExpectRows(info.rows);
    PrepareParser(config, p);
  });
  Metrics metrics;
  WorkerPoolOptions o;
  o.workers = 1;
  o.lease_ms = 300;
  o.poll_ms = 20;
  o.cancel_poll_ms = 20;
  o.id_prefix = "test:1";
  o.column_cache = &cache;
  WorkerPool pool(store_.get(), &metrics, o);
  pool.Start();
  // Polls job `id` (a liveness bound of 30 s, not a speed claim) until done(job).
  auto wait_for = [&](int64_t id, auto done) {
    storage::JobInfo job;
    for (int i = 0; i < 3000; ++i) {
      EXPECT_TRUE(store_->GetJob(id, &job).ok());
      if (done(job)) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return job;
  };
  for (const bool cancel : {true, false}) {
    storage::JobInfo queued;
    ASSERT_TRUE(store_->EnqueueJob(info.id, "imu", "", config.dump(), &queued).ok());
    pool.Notify();
    ASSERT_EQ(wait_for(queued.id,
                       [](const storage::JobInfo& j) { return j.status == JobStatus::kRunning; })
                  .status,
              JobStatus::kRunning);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // waiting for the build
    const auto start = std::chrono::steady_clock::now();
    if (cancel) {
      EXPECT_TRUE(pool.Cancel(queued.id));
      const storage::JobInfo job = wait_for(
          queued.id, [](const storage::JobInfo& j) { return j.status != JobStatus::kRunning; });
      EXPECT_LT(SecondsSince(start), 1.0) << "cancel";
      EXPECT_EQ(job.status, JobStatus::kFailed);
      EXPECT_EQ(job.error_reason, "cancelled");
    } else {
      // As Service::Shutdown does: the cache first (its waiters woken with kStopped), then the
      // workers (here without grace: their jobs' stop requested at once).
      cache.Stop();
      // The woken job returns itself to the queue; whether that happens before the pool's stop
      // (kFinished: nothing left running) or by it (kReleased) is the threads' timing (under
      // ASan on a loaded machine, the former). Never abandoned.
      EXPECT_NE(pool.Stop(std::chrono::milliseconds(0)), StopOutcome::kAbandoned);
      EXPECT_LT(SecondsSince(start), 1.0) << "shutdown";
      storage::JobInfo job;
      ASSERT_TRUE(store_->GetJob(queued.id, &job).ok());
      EXPECT_EQ(job.status, JobStatus::kQueued) << job.error_code << ": " << job.error_message;
      EXPECT_EQ(job.attempts, 0) << "a shutdown's release is not counted";
    }
  }
  held.Release();
}

// An entry that cannot be read now (kIoError: here a directory where the file should be, EISDIR)
// is not removed and not overwritten: the read parses the stored bytes.
TEST_F(ColumnCacheTest, AnUnreadableEntryIsKeptAndTheStoredBytesRead) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 34));
  ColumnCache cache(Options());
  const fs::path entry = cache.EntryPath(info.sha256, DefaultRules());
  fs::create_directories(entry);
  RecordingSummary s;
  ArrayRecording a;
  ASSERT_EQ(ReadColumnFile(entry.string(), {info.sha256, DefaultRules()}, &s, &a).code(),
            StatusCode::kIoError);
  ArrayRecording log, parsed;
  for (int round = 0; round < 2; ++round) {
    bool hit = true;
    const RecordingSummary got = Read(&cache, info, &log, TimeUnit::kSeconds, {}, &hit);
    EXPECT_FALSE(hit);
    ExpectSame(Read(nullptr, info, &parsed), parsed, got, log);
  }
  EXPECT_TRUE(fs::is_directory(entry)) << "an unreadable entry was removed";
  EXPECT_EQ(cache.rebuilt(), 0);
  EXPECT_EQ(cache.writes(), 0);
}

// The key holds the parser's reading-rules version; the name, the column file's version.
TEST_F(ColumnCacheTest, KeyAndNameHoldTheParsersAndTheFilesVersions) {
  const json rules = json::parse(DefaultRules());
  EXPECT_EQ(rules.at("parser_version").get<int>(), kRecordingParserVersion);
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 35));
  ColumnCache cache(Options());
  ArrayRecording log;
  Read(&cache, info, &log);
  ASSERT_EQ(Entries().size(), 1u);
  const std::string name = Entries()[0].filename().string();
  const std::string suffix = ".v" + std::to_string(kColumnFileVersion) + ".columns";
  EXPECT_EQ(name.substr(name.size() - suffix.size()), suffix) << name;
  EXPECT_EQ(Entries()[0], cache.EntryPath(info.sha256, DefaultRules()));
}

// A header the reader would refuse (over 16 MB: here the log's description) is not written.
TEST_F(ColumnCacheTest, AHeaderOverTheReadersLimitIsNotWritten) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 36));
  ArrayRecording log;
  RecordingSummary s = Read(nullptr, info, &log);
  fs::create_directories(dir_.path() / "columns");
  const std::string path = (dir_.path() / "columns" / "big.columns").string();
  const ColumnFileKey key{info.sha256, DefaultRules()};
  s.log_description = std::string(kMaxColumnFileHeaderBytes, 'x');
  const Status w = WriteColumnFile(path, key, s, log);
  EXPECT_EQ(w.code(), StatusCode::kInvalidInput) << w.ToString();
  EXPECT_TRUE(Entries().empty()) << "a file or its temporary was left";
  // Just under the limit: written and read back.
  s.log_description.resize(kMaxColumnFileHeaderBytes - 8192);
  ASSERT_TRUE(WriteColumnFile(path, key, s, log).ok());
  RecordingSummary back;
  ArrayRecording again;
  ASSERT_TRUE(ReadColumnFile(path, key, &back, &again).ok());
  EXPECT_EQ(back.log_description.size(), s.log_description.size());
}

// A bound lowered between runs holds from the start, before any write.
TEST_F(ColumnCacheTest, TheBoundIsEnforcedAtStart) {
  std::vector<storage::RecordingInfo> infos;
  for (uint64_t seed = 41; seed <= 43; ++seed) infos.push_back(Put(SimulatedCsv(6, seed)));
  {
    ColumnCache large(Options());
    ArrayRecording log;
    for (const auto& info : infos) Read(&large, info, &log);
  }
  ASSERT_EQ(Entries().size(), 3u);
  int64_t entry_bytes = 0;
  for (const fs::path& p : Entries())
    entry_bytes = std::max<int64_t>(entry_bytes, fs::file_size(p));
  const int64_t bound = entry_bytes + entry_bytes / 2;
  ColumnCache small(Options(bound));
  ASSERT_EQ(Entries().size(), 1u);
  EXPECT_LE(static_cast<int64_t>(fs::file_size(Entries()[0])), bound);
}

TEST_F(ColumnCacheTest, TheFolderIsTheOwnersAlone) {
  ColumnCacheOptions o = Options();
  o.dir = dir_.path() / "made" / "columns";
  ColumnCache cache(o);
  ASSERT_TRUE(cache.enabled());
  struct stat st;
  ASSERT_EQ(::stat(o.dir.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0700u);
}

// Below the free-space floor no entry is written (the read is served all the same); a floor
// the disk has room for writes.
TEST_F(ColumnCacheTest, NoEntryBelowTheFreeSpaceFloor) {
  const storage::RecordingInfo info = Put(SimulatedCsv(6, 37));
  ColumnCacheOptions o = Options();
  o.min_free_bytes = int64_t{1} << 62;  // more than any disk has
  ColumnCache full(o);
  ArrayRecording log, parsed;
  bool hit = true;
  const RecordingSummary s = Read(&full, info, &log, TimeUnit::kSeconds, {}, &hit);
  EXPECT_FALSE(hit);
  ExpectSame(Read(nullptr, info, &parsed), parsed, s, log);
  EXPECT_EQ(full.writes(), 0);
  EXPECT_TRUE(Entries().empty());
  o.min_free_bytes = 1;
  ColumnCache roomy(o);
  Read(&roomy, info, &log);
  EXPECT_EQ(roomy.writes(), 1);
  EXPECT_EQ(Entries().size(), 1u);
}

TEST(ColumnCacheOptionsTest, ViolatedConstraintsDisableTheCache) {
  TempDir dir;
  for (int k = 0; k < 3; ++k) {
    ColumnCacheOptions o;
    o.dir = dir.path() / "columns";
    if (k == 0) o.max_bytes = 0;
    if (k == 1) o.min_free_bytes = -1;
    if (k == 2) o.wait_poll_ms = 0;
    ColumnCache cache(o);
    EXPECT_FALSE(cache.enabled()) << k;
  }
}

// Over HTTP: the check and /segments of a server with the cache (served from it the second time)
// answer exactly what a server without a cache does.
TEST(ColumnCacheHttp, CheckAndSegmentsAreTheUncachedOnes) {
  const std::string csv = SimulatedCsv(24, 21);
  ServeOptions no_cache;
  no_cache.column_cache_bytes = 0;
  TestServer cached, uncached(no_cache);
  ASSERT_EQ(cached.error(), "");
  ASSERT_EQ(uncached.error(), "");
  std::vector<std::string> answers;
  for (const TestServer* server : {&cached, &uncached}) {
    auto res = server->Client().Post("/api/v1/recordings", csv, "text/csv");
    ASSERT_TRUE(res && res->status == 201);
    const int64_t id = json::parse(res->body)["recording"]["id"].get<int64_t>();
    const std::string base = "/api/v1/recordings/" + std::to_string(id);
    for (int round = 0; round < 2; ++round) {
      for (const std::string& path : {base + "/check?method=imu", base + "/segments"}) {
        auto r = server->Client().Get(path.c_str());
        ASSERT_TRUE(r);
        ASSERT_EQ(r->status, 200) << r->body;
        answers.push_back(r->body);
      }
    }
  }
  ASSERT_EQ(answers.size(), 8u);
  for (size_t i = 0; i < 4; ++i) EXPECT_EQ(answers[i], answers[i + 4]) << "answer " << i;
  EXPECT_TRUE(fs::exists(cached.dir() / "columns"));
  EXPECT_FALSE(fs::exists(uncached.dir() / "columns"));
}

// A shutdown while the background build reads a just-uploaded log: the build stops and is joined
// before the store is closed (before the fix the store went first and the builder used it freed:
// ThreadSanitizer and AddressSanitizer report it here; in Release the server must simply stop).
TEST(ColumnCacheHttp, AShutdownDuringTheBackgroundBuildStopsItBeforeTheStoreCloses) {
  const std::string csv = SimulatedCsv(200, 22);  // ~1.8 MB: its build is still running
  for (int round = 0; round < 3; ++round) {
    TestServer server;
    ASSERT_EQ(server.error(), "");
    auto res = server.Client().Post("/api/v1/recordings", csv, "text/csv");
    ASSERT_TRUE(res && res->status == 201);
    server.Stop();  // at once: the build has just started
  }
}

}  // namespace
}  // namespace calibd::server
