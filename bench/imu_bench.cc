// imu (issue #16): static detection and the full calibration (detection with 5 threshold
// candidates, accelerometer closed form + ML, gyroscope fit, joint ML, Fisher σ, diagnostics)
// of a 30-minute 400 Hz log (718 k samples: 100 statics of 12 s joined by 6 s rotations), one
// IMU, and 8 IMUs (the same readings 8 times: same work). Parsing is the server's and not here.
// Run: build/bench/imu_bench --benchmark_min_time=0.5
#include <benchmark/benchmark.h>

#include "core/imu.h"
#include "core/imu_simulation.h"
#include "core/static_detection.h"

namespace {

using namespace calibd::core;  // NOLINT(build/namespaces)

const ImuSimulation& Log30Min() {
  static const ImuSimulation sim = [] {
    ImuSimulationOptions so;
    so.statics = 100;
    so.static_duration = 12;
    so.rotation_duration = 6;
    so.rate = 400;
    so.accel_unit = 16 * 9.80665 / 32768;                  // ±16 g counts
    so.gyro_unit = 2000 * 3.14159265358979 / 180 / 32768;  // ±2000 °/s counts
    so.quantize = true;
    so.seed = 42;
    ImuSimulation s;
    if (!SimulateImu(so, &s).ok()) std::abort();
    return s;
  }();
  return sim;
}

ImuOptions Options() {
  ImuOptions o;
  o.accel_unit = 16 * 9.80665 / 32768;
  o.gyro_unit = 2000 * 3.14159265358979 / 180 / 32768;
  return o;
}

void BM_DetectStatics(benchmark::State& state) {
  const ImuSimulation& sim = Log30Min();
  std::vector<TriadSeries> triads = {{"a0", TriadKind::kAccelerometer, &sim.accel},
                                     {"g0", TriadKind::kGyroscope, &sim.gyro}};
  StaticDetection d;
  for (auto _ : state) {
    if (!DetectStatics(sim.t, triads, StaticDetectionOptions(), &d).ok()) {
      state.SkipWithError("detection failed");
    }
    benchmark::DoNotOptimize(d.intervals.data());
  }
  state.counters["samples"] = static_cast<double>(sim.t.size());
  state.counters["statics"] = static_cast<double>(d.intervals.size());
}

void BM_CalibrateImus(benchmark::State& state) {
  const ImuSimulation& sim = Log30Min();
  std::vector<ImuReadings> imus;
  for (int k = 0; k < state.range(0); ++k) {
    imus.push_back(ImuReadings{std::to_string(k), &sim.accel, &sim.gyro});
  }
  std::vector<ImuResult> results;
  for (auto _ : state) {
    const calibd::Status s = CalibrateImus(sim.t, imus, Options(), &results);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
    benchmark::DoNotOptimize(results.data());
  }
  const ImuResult& r = results[0];
  state.counters["samples"] = static_cast<double>(sim.t.size());
  state.counters["statics"] = static_cast<double>(r.statics.size());
  state.counters["gyro_it"] = r.gyro_iterations;
  state.counters["joint_it"] = r.joint_iterations;
  state.counters["Kg_err_ppm"] =
      1e6 * (r.gyroscope.scale.cwiseQuotient(sim.gyro_truth.scale).array() - 1).abs().maxCoeff();
}

BENCHMARK(BM_DetectStatics)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_CalibrateImus)->Arg(1)->Arg(8)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
