// ROS 2 recording reading throughput (formats/mcap.h, formats/rosbag2_sqlite.h), MB/s of file
// bytes: 20000 sensor_msgs/msg/Imu messages (CDR, 324 bytes each, ~6.9 MB) written by the tests'
// writers (tests/formats/mcap_writer.h: chunks of 1000 messages, uncompressed, lz4 and zstd;
// a .db3 by SQLite itself, one transaction), read as an upload is read (the .db3 from a file:
// SQLite reads files; an upload's bytes are first written to a private temporary one, which the
// figure leaves out).
#include <benchmark/benchmark.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "formats/mcap.h"
#include "formats/rosbag2_sqlite.h"
#include "tests/formats/mcap_writer.h"
#include "tests/formats/ros2_cdr_writer.h"

namespace {

namespace t = calibd::server::testing;
constexpr int kMessages = 20000;

std::string ImuMessage(int i) {
  const double a[3] = {0.1 * std::sin(0.01 * i), -9.81, 0.5};
  const double g[3] = {1e-3 * i, 0.02, 0.003};
  const int64_t stamp = 100'000'000'000 + 5'000'000LL * i;
  return t::ImuCdr(false, static_cast<int32_t>(stamp / 1'000'000'000),
                   static_cast<uint32_t>(stamp % 1'000'000'000), a, g);
}

std::string Mcap(const std::string& compression) {
  std::string file = t::McapBegin();
  std::string records = t::Schema(1, "sensor_msgs/msg/Imu") + t::Channel(1, 1, "/imu");
  for (int i = 0; i < kMessages; ++i) {
    records += t::Message(1, 1'000'000'000'000ull + 5'000'000ull * i, ImuMessage(i));
    if (i % 1000 == 999) {
      file += t::Chunk(records, compression);
      records.clear();
    }
  }
  return file + t::McapEnd();
}

// The .db3's path (written once) and its size in bytes.
const std::string& Db3(int64_t* bytes) {
  static const std::string path = [] {
    const std::string p = "/tmp/calibd_ros2_bag_bench_" + std::to_string(::getpid()) + ".db3";
    std::remove(p.c_str());
    sqlite3* db = nullptr;
    sqlite3_open(p.c_str(), &db);
    sqlite3_exec(db,
                 "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT "
                 "NULL, serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
                 "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
                 "timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
                 "INSERT INTO topics VALUES(1, '/imu', 'sensor_msgs/msg/Imu', 'cdr', '');"
                 "PRAGMA synchronous=OFF; BEGIN;",
                 nullptr, nullptr, nullptr);
    sqlite3_stmt* insert = nullptr;
    sqlite3_prepare_v2(db, "INSERT INTO messages(topic_id, timestamp, data) VALUES(1, ?, ?)", -1,
                       &insert, nullptr);
    for (int i = 0; i < kMessages; ++i) {
      const std::string m = ImuMessage(i);
      sqlite3_bind_int64(insert, 1, 1'000'000'000'000 + 5'000'000LL * i);
      sqlite3_bind_blob(insert, 2, m.data(), static_cast<int>(m.size()), SQLITE_TRANSIENT);
      sqlite3_step(insert);
      sqlite3_reset(insert);
    }
    sqlite3_finalize(insert);
    sqlite3_exec(db, "COMMIT;", nullptr, nullptr, nullptr);
    sqlite3_close(db);
    return p;
  }();
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  *bytes = static_cast<int64_t>(in.tellg());
  return path;
}

void BM_ReadMcap(benchmark::State& state, const char* compression) {
  const std::string file = Mcap(compression);
  for (auto _ : state) {
    calibd::server::SensorLog log;
    const calibd::Status s =
        calibd::server::ReadMcap(file, "bench.mcap", calibd::server::SensorLogLimits(), &log);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
    benchmark::DoNotOptimize(log);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(file.size()));
}

void BM_ReadDb3(benchmark::State& state) {
  int64_t bytes = 0;
  const std::string& path = Db3(&bytes);
  for (auto _ : state) {
    calibd::server::SensorLog log;
    const calibd::Status s = calibd::server::ReadRosBag2Sqlite(
        path, "bench.db3", calibd::server::SensorLogLimits(), &log);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
    benchmark::DoNotOptimize(log);
  }
  state.SetBytesProcessed(state.iterations() * bytes);
}

BENCHMARK_CAPTURE(BM_ReadMcap, none, "")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadMcap, lz4, "lz4")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadMcap, zstd, "zstd")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ReadDb3)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
