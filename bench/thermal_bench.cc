// thermal: the issue's speed target, "an hour at 200 Hz with two IMUs calibrates in about a
// second". One hour (30 min warm-up, 30 min cool-down) at 200 Hz, two IMUs (720 000 samples
// each): core::CalibrateThermal with lag none and lag "estimate", and the whole of
// `calibd calibrate` (server::Calibrate on the CSV text: parsing included). Run:
// build/bench/thermal_bench
#include <benchmark/benchmark.h>

#include <cstdio>
#include <string>

#include "core/thermal.h"
#include "core/thermal_simulation.h"
#include "server/config.h"

namespace {

using namespace calibd;  // NOLINT

struct HourLog {
  core::ThermalSimulation imu[2];
  std::string csv;  // t, a0_*, g0_*, a1_*, g1_*, temp0, temp1
};

const HourLog& Hour() {
  static const HourLog& log = *[] {
    auto* out = new HourLog;
    for (int k = 0; k < 2; ++k) {
      core::ThermalSimulationOptions o;
      o.rate = 200;
      o.warmup = o.cooldown = 1800;
      o.lag = 60;
      o.seed = 1 + static_cast<uint64_t>(k);
      out->imu[k] = core::SimulateThermal(o);
    }
    out->csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z,a1_x,a1_y,a1_z,g1_x,g1_y,g1_z,temp0,temp1\n";
    char line[512];
    const core::ThermalSimulation& a = out->imu[0];
    const core::ThermalSimulation& b = out->imu[1];
    for (Eigen::Index i = 0; i < a.t.size(); ++i) {
      const int n =
          std::snprintf(line, sizeof line,
                        "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%."
                        "10g,%.4f,%.4f\n",
                        a.t(i), a.accel(i, 0), a.accel(i, 1), a.accel(i, 2), a.gyro(i, 0),
                        a.gyro(i, 1), a.gyro(i, 2), b.accel(i, 0), b.accel(i, 1), b.accel(i, 2),
                        b.gyro(i, 0), b.gyro(i, 1), b.gyro(i, 2), a.temp(i), b.temp(i));
      out->csv.append(line, static_cast<size_t>(n));
    }
    return out;
  }();
  return log;
}

void Core(benchmark::State& state, core::ThermalLagMode lag) {
  const HourLog& log = Hour();
  const std::vector<core::ThermalImuInput> imus = {
      {"0", &log.imu[0].accel, &log.imu[0].gyro, &log.imu[0].temp},
      {"1", &log.imu[1].accel, &log.imu[1].gyro, &log.imu[1].temp}};
  core::ThermalOptions options;
  options.lag = lag;
  for (auto _ : state) {
    core::ThermalResult r;
    if (!core::CalibrateThermal(log.imu[0].t, imus, options, &r).ok())
      state.SkipWithError("calibration failed");
    benchmark::DoNotOptimize(r);
  }
  state.counters["samples_per_imu"] = static_cast<double>(log.imu[0].t.size());
}

void BM_ThermalHour200HzTwoImus(benchmark::State& state) {
  Core(state, core::ThermalLagMode::kNone);
}
BENCHMARK(BM_ThermalHour200HzTwoImus)->Unit(benchmark::kMillisecond);

void BM_ThermalHour200HzTwoImusLagEstimate(benchmark::State& state) {
  Core(state, core::ThermalLagMode::kEstimate);
}
BENCHMARK(BM_ThermalHour200HzTwoImusLagEstimate)->Unit(benchmark::kMillisecond);

// `calibd calibrate` of the same hour as CSV (145 MB): reading, parsing, the fit and the JSON.
void BM_ThermalCalibrateCsvHour200HzTwoImus(benchmark::State& state) {
  const HourLog& log = Hour();
  const nlohmann::json config = {{"method", "thermal"}};
  for (auto _ : state) {
    nlohmann::json result;
    const calibd::Status s = calibd::server::Calibrate(log.csv, "hour.csv", config, &result);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
    benchmark::DoNotOptimize(result);
  }
  state.counters["csv_bytes"] = static_cast<double>(log.csv.size());
}
BENCHMARK(BM_ThermalCalibrateCsvHour200HzTwoImus)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
