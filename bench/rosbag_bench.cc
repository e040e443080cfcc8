// ROS 1 bag reading throughput (formats/rosbag1.h), MB/s of bag bytes, on bags written by
// Debian's python3-rosbag (tests/formats/write_rosbag1.py: Imu, MagneticField, Temperature and a
// skipped String topic; 20000 messages each, ~15 MB uncompressed) with uncompressed, bz2 and lz4
// chunks.
#include <benchmark/benchmark.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "formats/rosbag1.h"

namespace {

const std::string& Bag(const std::string& compression) {
  static std::map<std::string, std::string> bags;
  std::string& bag = bags[compression];
  if (!bag.empty()) return bag;
  std::string path = "/tmp/calibd_rosbag_bench_" + compression + ".bag";
  std::string cmd = "/usr/bin/python3 " CALIBD_SOURCE_DIR "/tests/formats/write_rosbag1.py " +
                    path + " " + compression + " 20000";
  if (std::system(cmd.c_str()) != 0) return bag;  // python3-rosbag absent: the bench skips
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  bag = ss.str();
  std::remove(path.c_str());
  return bag;
}

void BM_ReadRosBag1(benchmark::State& state, const char* compression) {
  const std::string& bag = Bag(compression);
  if (bag.empty()) {
    state.SkipWithError("python3-rosbag absent (scripts/setup.sh)");
    return;
  }
  for (auto _ : state) {
    calibd::server::SensorLog log;
    calibd::Status s =
        calibd::server::ReadRosBag1(bag, "bench.bag", calibd::server::SensorLogLimits(), &log);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
    benchmark::DoNotOptimize(log);
  }
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(bag.size()));
}

BENCHMARK_CAPTURE(BM_ReadRosBag1, none, "none")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadRosBag1, bz2, "bz2")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadRosBag1, lz4, "lz4")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
