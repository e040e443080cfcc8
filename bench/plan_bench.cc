// The cost of an imu plan's suggested protocol (issue #27 item 1, methods/imu/imu_plan.h): the
// greedy D-optimal sequence alone (24 positions, 26 candidates each, closed-form information), and
// SuggestImu end to end (the sequence plus the bisection's runs of the imu method on simulated
// logs) for a protocol of 3 s statics and 2 s rotations at 100 Hz and one of 10 s statics and 3 s
// rotations at 400 Hz, with a limit met part-way (bisection: 5 runs) and one met by no protocol of
// the cap (1 run of 24 positions). The plan request is this plus one run on the user's protocol.
// Run: build/bench/plan_bench --benchmark_min_time=1
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "methods/imu/imu_plan.h"

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

}  // namespace

BENCHMARK_MAIN();
