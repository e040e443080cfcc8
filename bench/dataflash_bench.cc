// ArduPilot DataFlash reading throughput (formats/dataflash.h, issue #24): a synthetic ~50 MB log
// of three IMUs at 1 kHz (IMU messages with accelerometer, gyroscope and temperature) and three
// magnetometers at 100 Hz, written by tests/lib/dataflash_writer.h as ArduPilot 4.x lays it out
// (FMT, FMTU, UNIT, MULT, PARM first). Figures in bench/README.md, beside the CSV parser's.
#include <benchmark/benchmark.h>

#include <random>
#include <string>

#include "formats/dataflash.h"
#include "tests/lib/dataflash_writer.h"

namespace {

using calibd::testing::DataFlashWriter;

// ~50 MB, deterministic: 54-byte IMU messages, 3 per ms, plus 35-byte MAG messages.
const std::string& Log() {
  static const std::string log = [] {
    DataFlashWriter w;
    calibd::testing::WriteArduPilotFormats(&w);
    w.Message(calibd::testing::kDfFmtu,
              {0, calibd::testing::kDfMag, "s#GGGGGGGGG-s", "F-CCCCCCCCC-F"});
    std::mt19937_64 rng(1);
    std::normal_distribution<double> noise;
    for (int64_t ms = 0; w.size() < (50u << 20); ++ms) {
      for (int i = 0; i < 3; ++i) {
        const double gyro[3] = {1e-3 * noise(rng), 1e-3 * noise(rng), 1e-3 * noise(rng)};
        const double accel[3] = {0.01 * noise(rng), 0.01 * noise(rng), -9.81 + 0.01 * noise(rng)};
        calibd::testing::WriteImu(&w, 1'000'000 + 1000 * ms + i, i, gyro, accel, 30 + 1e-4 * ms);
      }
      if (ms % 10 == 0)
        for (int i = 0; i < 3; ++i) {
          const int mg[3] = {200 + i, -100, 450};
          calibd::testing::WriteMag(&w, 1'000'500 + 1000 * ms, i, mg);
        }
    }
    return w.bytes();
  }();
  return log;
}

void BM_ReadDataFlash(benchmark::State& state) {
  const std::string& log = Log();
  int64_t samples = 0;
  for (auto _ : state) {
    calibd::server::SensorLog out;
    const calibd::Status s = calibd::server::ReadDataFlash(log, "bench.bin", {}, &out);
    if (!s.ok()) state.SkipWithError(s.ToString().c_str());
    samples = 0;
    for (const auto& stream : out.streams) samples += stream.samples();
    benchmark::DoNotOptimize(out.streams.data());
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * log.size()));
  state.counters["samples"] = static_cast<double>(samples);
}

BENCHMARK(BM_ReadDataFlash)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
