// The check before fitting (issue #27 item 2, server/recording_check.h) of the imu method on a
// one-hour 400 Hz log (1.44 M samples: 200 statics of 12 s joined by 6 s rotations, counts),
// one IMU: Method::Check (saturation search on the six channels, static detection at the five
// threshold candidates with their accelerometer fits, coverage), against the full calibration
// (Method::Run) on the same log. Reading the stored CSV is the server's and not here.
// Run: build/bench/check_bench --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "core/imu_simulation.h"
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

}  // namespace

BENCHMARK_MAIN();
