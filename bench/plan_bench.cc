// The cost of an imu plan's suggested protocol (issue #27 item 1, methods/imu/imu_plan.h): the
// greedy D-optimal sequence alone (24 positions, 26 candidates each, closed-form information), and
// SuggestImu end to end (the sequence plus the bisection's runs of the imu method on simulated
// logs) for a protocol of 3 s statics and 2 s rotations at 100 Hz and one of 10 s statics and 3 s
// rotations at 400 Hz, with a limit met part-way (bisection: 5 runs) and one met by no protocol of
// the cap (1 run of 24 positions). The plan request is this plus one run on the user's protocol.
// BM_ArrayFullPlan: a whole `POST /plan` of the array's full model (methods/array/
// array_full_plan.cc: the plan's fit on the replay plus the suggestion's bisection), 12 statics of
// 1.5 s then the motion, at 100 Hz, on the 8-IMU board and the paper's 32-IMU board.
// Run: build/bench/plan_bench --benchmark_min_time=1
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "core/array_full_simulation.h"
#include "core/array_simulation.h"
#include "methods/imu/imu_plan.h"
#include "server/plan.h"
#include "tests/lib/array_geometry.h"

namespace {

using calibd::server::AcceptanceLimits;
using calibd::server::EffectiveAcceptance;
using calibd::server::ImuSuggestOptions;
using calibd::server::PlanProtocol;
using nlohmann::json;

void BM_ImuGreedySequence24(benchmark::State& state) {
  for (auto _ : state) {
    benchmark::DoNotOptimize(calibd::server::ImuGreedySequence(24));
  }
}
BENCHMARK(BM_ImuGreedySequence24)->Unit(benchmark::kMillisecond);

// args: rate (Hz), static duration (s), rotation duration (s), max_scale_std × 1e6.
void BM_ImuSuggest(benchmark::State& state) {
  PlanProtocol protocol;
  protocol.orientations = {Eigen::Vector3d::UnitZ()};
  protocol.rate = static_cast<double>(state.range(0));
  protocol.static_duration = static_cast<double>(state.range(1));
  protocol.rotation_duration = static_cast<double>(state.range(2));
  json config = {{"method", "imu"}, {"accel_noise", 0.05}, {"gyro_noise", 0.01}};
  config["acceptance"] = {{"max_scale_std", static_cast<double>(state.range(3)) * 1e-6}};
  const AcceptanceLimits limits = EffectiveAcceptance("imu", json(), config);
  config.erase("acceptance");
  for (auto _ : state) {
    const json s = calibd::server::SuggestImu(config, protocol, limits, ImuSuggestOptions());
    state.counters["positions"] = static_cast<double>(s["orientations"].size());
    state.counters["runs"] = s["predictions"].get<double>();
    state.counters["meets"] = s["meets_limits"].get<bool>() ? 1 : 0;
  }
}
BENCHMARK(BM_ImuSuggest)
    ->Args({100, 3, 2, 500})
    ->Args({100, 3, 2, 1})
    ->Args({400, 10, 3, 300})
    ->Args({400, 10, 3, 1})
    ->Unit(benchmark::kMillisecond);

// args: IMUs (8: MIMU4444, 32: the paper's board), motion duration (s), max_position_std × 1e6
// (0: the default limits).
void BM_ArrayFullPlan(benchmark::State& state) {
  const Eigen::Matrix3Xd p = state.range(0) == 8 ? calibd::core::Mimu4444NominalPositions()
                                                 : calibd::core::PaperArrayNominalPositions();
  const json positions = calibd::testing::GeometryPositions(p);
  json config = {{"method", "array"},
                 {"model", "full"},
                 {"geometry", {{"positions", positions}, {"reference", 0}}},
                 {"accel_noise", 0.04},
                 {"gyro_noise", 0.0035},
                 {"static_window", 0.25},
                 {"min_static", 0.5}};
  if (state.range(2) > 0) {
    config["acceptance"] = {{"max_position_std", static_cast<double>(state.range(2)) * 1e-6}};
  }
  const json protocol = {{"orientations",
                          {"+z", "-z", "+x", "-x", "+y", "-y", "+x+y+z", "-x-y+z", "+x-y-z",
                           "-x+y-z", "+x+z", "-y-z"}},
                         {"static_duration", 1.5},
                         {"angular_rate", 10},
                         {"angular_acceleration", 50},
                         {"duration", static_cast<double>(state.range(1))},
                         {"rate", 100}};
  for (auto _ : state) {
    json out;
    const calibd::Status s = calibd::server::PlanJson(
        {{"method", "array"}, {"config", config}, {"protocol", protocol}}, json(), &out);
    if (!s.ok()) {
      state.SkipWithError(s.message().c_str());
      break;
    }
    state.counters["replay"] = out["replay"]["replay_samples"].get<double>();
    state.counters["runs"] = 1 + out["suggested"]["predictions"].get<double>();
    state.counters["scale"] = out["suggested"]["scale"].get<double>();
  }
}
BENCHMARK(BM_ArrayFullPlan)
    ->Args({8, 4, 0})
    ->Args({8, 4, 20})
    ->Args({8, 60, 0})
    ->Args({32, 4, 0})
    ->Args({32, 30, 0})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
