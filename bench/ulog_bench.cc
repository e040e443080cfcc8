// PX4 ULog reading throughput (formats/ulog.h) on a synthetic ~50 MB log of two IMUs at 1 kHz:
// sensor_accel and sensor_gyro, two instances each, each message with its temperature (what a
// raised logging profile writes), or the same IMUs as sensor_accel_fifo / sensor_gyro_fifo
// bursts of 8 readings at 125 Hz (PX4's high-rate logging of 8 kHz sensors, thinned to 1 kHz).
// Figures in bench/README.md ("Log readers").
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "formats/ulog.h"
#include "tests/lib/ulog_writer.h"

namespace {

using calibd::testing::FifoData;
using calibd::testing::TriadData;
using calibd::testing::ULogWriter;

constexpr size_t kTargetBytes = size_t{50} << 20;

// A log with the two formats subscribed as instances 0 and 1 each: msg_ids 1, 2 (accelerometers)
// and 3, 4 (gyroscopes).
ULogWriter TwoImus(const char* accel_format, const char* gyro_format) {
  ULogWriter w;
  w.FlagBits(0).Format(accel_format).Format(gyro_format);
  for (const char* format : {accel_format, gyro_format}) {
    const std::string topic(format, std::strchr(format, ':'));
    const uint16_t id = format == accel_format ? 1 : 3;
    w.Subscribe(0, id, topic).Subscribe(1, id + 1, topic);
  }
  return w;
}

const std::string& TriadLog() {
  static const std::string bytes = [] {
    ULogWriter w = TwoImus(calibd::testing::kSensorAccelFormat, calibd::testing::kSensorGyroFormat);
    std::mt19937 rng(1);
    std::normal_distribution<float> noise(0, 0.01f);
    for (uint64_t t = 1'000'000; w.bytes().size() < kTargetBytes; t += 1000) {
      for (uint16_t imu = 0; imu < 2; ++imu) {
        w.Data(1 + imu,
               TriadData(t + 40, t, 0x100 + imu, noise(rng), noise(rng), 9.81f + noise(rng), 40));
        w.Data(3 + imu, TriadData(t + 40, t, 0x100 + imu, noise(rng), noise(rng), noise(rng), 40));
      }
    }
    return w.bytes();
  }();
  return bytes;
}

const std::string& FifoLog() {
  static const std::string bytes = [] {
    ULogWriter w =
        TwoImus(calibd::testing::kSensorAccelFifoFormat, calibd::testing::kSensorGyroFifoFormat);
    std::mt19937 rng(1);
    std::uniform_int_distribution<int> counts(-40, 40);
    std::vector<std::vector<int16_t>> burst(8, std::vector<int16_t>(3));
    for (uint64_t t = 1'000'000; w.bytes().size() < kTargetBytes; t += 8000) {
      for (uint16_t id = 1; id <= 4; ++id) {
        for (auto& reading : burst)
          for (int16_t& c : reading) c = static_cast<int16_t>(counts(rng));
        w.Data(id, FifoData(t + 40, t, 0x100 + id, 1000, 0.0048f, burst));
      }
    }
    return w.bytes();
  }();
  return bytes;
}

void Read(benchmark::State& state, const std::string& bytes) {
  for (auto _ : state) {
    calibd::server::SensorLog log;
    auto s = calibd::server::ReadULog(bytes, "bench.ulg", calibd::server::SensorLogLimits(), &log);
    if (!s.ok()) state.SkipWithError(s.ToString().c_str());
    benchmark::DoNotOptimize(log.streams.data());
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * bytes.size()));
}

void BM_ReadULogTriads(benchmark::State& state) { Read(state, TriadLog()); }
void BM_ReadULogFifo(benchmark::State& state) { Read(state, FifoLog()); }

BENCHMARK(BM_ReadULogTriads)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ReadULogFifo)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
