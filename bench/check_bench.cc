// The check before fitting (issue #27 item 2, server/recording_check.h) of the imu method on a
// one-hour 400 Hz log (1.44 M samples: 200 statics of 12 s joined by 6 s rotations, counts),
// one IMU: Method::Check (saturation search on the six channels, static detection at the five
// threshold candidates with their accelerometer fits, coverage), against the full calibration
// (Method::Run) on the same log. And what reading the recording costs before that: the stored
// CSV (128 MB, %.10g as `calibd simulate` writes) hashed (the store verifies its SHA-256 on every
// whole read) and parsed in 1 MiB chunks into doubles, against the same log restored from its
// parsed-columns cache entry (server/column_cache.h, formats/column_file.h).
// Run: build/bench/check_bench --benchmark_min_time=0.5
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "base/sha256.h"
#include "core/imu_simulation.h"
#include "formats/column_file.h"
#include "formats/recording.h"
#include "methods/imu/imu_method.h"

namespace {

using calibd::server::ArrayRecording;
using nlohmann::json;

const double kAccelUnit = 16 * 9.80665 / 32768;                  // ±16 g counts
const double kGyroUnit = 2000 * 3.14159265358979 / 180 / 32768;  // ±2000 °/s counts

const ArrayRecording& LogOneHour() {
  static const ArrayRecording log = [] {
    calibd::core::ImuSimulationOptions so;
    so.statics = 200;
    so.static_duration = 12;
    so.rotation_duration = 6;
    so.rate = 400;
    so.accel_unit = kAccelUnit;
    so.gyro_unit = kGyroUnit;
    so.quantize = true;
    so.seed = 42;
    calibd::core::ImuSimulation s;
    if (!calibd::core::SimulateImu(so, &s).ok()) std::abort();
    ArrayRecording r;
    r.t = s.t;
    r.accel = s.accel;
    r.gyro = s.gyro;
    r.accel_names = {"a0"};
    r.gyro_names = {"g0"};
    return r;
  }();
  return log;
}

const json& Config() {
  static const json config = {{"accel_unit", kAccelUnit}, {"gyro_unit", kGyroUnit}};
  return config;
}

void BM_ImuCheckOneHour400Hz(benchmark::State& state) {
  const ArrayRecording& log = LogOneHour();
  for (auto _ : state) {
    json check = json::object();
    if (!calibd::server::ImuMethod().Check(log, Config(), {}, &check).ok()) std::abort();
    benchmark::DoNotOptimize(check);
    state.counters["statics"] = static_cast<double>(check["statics"].size());
  }
}
BENCHMARK(BM_ImuCheckOneHour400Hz)->Unit(benchmark::kMillisecond);

// The log as the CSV calibd stores (t %.10g, readings %.10g).
const std::string& CsvOneHour() {
  static const std::string csv = [] {
    const ArrayRecording& log = LogOneHour();
    std::string out = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
    out.reserve(static_cast<size_t>(log.t.size()) * 90);
    char line[256];
    for (Eigen::Index i = 0; i < log.t.size(); ++i) {
      std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n", log.t[i],
                    log.accel(i, 0), log.accel(i, 1), log.accel(i, 2), log.gyro(i, 0),
                    log.gyro(i, 1), log.gyro(i, 2));
      out += line;
    }
    return out;
  }();
  return csv;
}

void BM_HashStoredCsvOneHour(benchmark::State& state) {
  const std::string& csv = CsvOneHour();
  for (auto _ : state) benchmark::DoNotOptimize(calibd::Sha256Hex(csv));
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * csv.size()));
}
BENCHMARK(BM_HashStoredCsvOneHour)->Unit(benchmark::kMillisecond);

void BM_ParseStoredCsvOneHour(benchmark::State& state) {
  const std::string& csv = CsvOneHour();
  for (auto _ : state) {
    calibd::server::RecordingParser parser("bench", /*collect=*/true);
    parser.ExpectRows(LogOneHour().t.size());
    for (size_t at = 0; at < csv.size(); at += size_t{1} << 20) {
      if (!parser.Feed(std::string_view(csv).substr(at, size_t{1} << 20)).ok()) std::abort();
    }
    ArrayRecording log;
    if (!parser.Finish().ok() || !parser.TakeArray(&log).ok()) std::abort();
    benchmark::DoNotOptimize(log);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations() * csv.size()));
}
BENCHMARK(BM_ParseStoredCsvOneHour)->Unit(benchmark::kMillisecond);

void BM_ReadColumnCacheEntryOneHour(benchmark::State& state) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("check_bench-" + std::to_string(::getpid()) + ".columns"))
                               .string();
  const std::string& csv = CsvOneHour();
  calibd::server::RecordingParser parser("bench", /*collect=*/true);
  ArrayRecording parsed;
  if (!calibd::server::ParseRecording(csv, &parser).ok() || !parser.TakeArray(&parsed).ok()) {
    std::abort();
  }
  const calibd::server::ColumnFileKey key{calibd::Sha256Hex(csv), "bench"};
  int64_t bytes = 0;
  if (!calibd::server::WriteColumnFile(path, key, parser.summary(), parsed, &bytes).ok()) {
    std::abort();
  }
  for (auto _ : state) {
    calibd::server::RecordingSummary summary;
    ArrayRecording log;
    if (!calibd::server::ReadColumnFile(path, key, &summary, &log).ok()) std::abort();
    benchmark::DoNotOptimize(log);
  }
  std::filesystem::remove(path);
  state.SetBytesProcessed(state.iterations() * bytes);
}
BENCHMARK(BM_ReadColumnCacheEntryOneHour)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
