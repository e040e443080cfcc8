// mag: CalibrateMag (core/mag.h) on the target log, a 10-minute hand-held log at 100 Hz
// (60 000 samples, 12 still holds), clean, with two disturbed spans, and with a wandering hard
// iron (no plateau: the predictive σ's step 3c runs); the robust passes as configured by
// default. Run: build/bench/mag_bench
#include <benchmark/benchmark.h>

#include "core/mag.h"
#include "core/mag_simulation.h"

namespace {

using namespace calibd::core;  // NOLINT

MagSimulation TargetLog(bool disturbed, double walk = 0) {
  MagSimulationOptions o;
  o.turns = 384;  // 384 × 1.5 s + 12 × 2 s = 600 s
  o.hard_iron_walk = walk;
  if (disturbed) {
    o.disturbances = {{100, 110, Eigen::Vector3d(25, -15, 10)},
                      {400, 405, Eigen::Vector3d(-20, 10, -25)}};
  }
  MagSimulation sim;
  if (!SimulateMag(o, &sim).ok()) std::abort();
  return sim;
}

void Run(benchmark::State& state, const MagSimulation& sim, bool offset_wander = true) {
  MagOptions o;
  o.field = sim.field;
  o.offset_wander = offset_wander;
  for (auto _ : state) {
    MagResult r;
    if (!CalibrateMag(sim.problem, o, &r).ok()) state.SkipWithError("fit failed");
    benchmark::DoNotOptimize(r);
    state.counters["iterations"] = r.iterations;
    state.counters["wander"] = r.wander_included;
  }
  state.counters["samples"] = static_cast<double>(sim.problem.y.cols());
}

void BM_MagTenMinutes100Hz(benchmark::State& state) {
  static const MagSimulation sim = TargetLog(false);
  Run(state, sim);
}
BENCHMARK(BM_MagTenMinutes100Hz)->Unit(benchmark::kMillisecond);

void BM_MagTenMinutes100HzDisturbed(benchmark::State& state) {
  static const MagSimulation sim = TargetLog(true);
  Run(state, sim);
}
BENCHMARK(BM_MagTenMinutes100HzDisturbed)->Unit(benchmark::kMillisecond);

void BM_MagTenMinutes100HzWandering(benchmark::State& state) {
  static const MagSimulation sim = TargetLog(false, 0.02);
  Run(state, sim);
}
BENCHMARK(BM_MagTenMinutes100HzWandering)->Unit(benchmark::kMillisecond);

// The same log without step 3c (the sandwich alone): the difference is the wander's cost.
void BM_MagTenMinutes100HzWanderingNoStep3c(benchmark::State& state) {
  static const MagSimulation sim = TargetLog(false, 0.02);
  Run(state, sim, /*offset_wander=*/false);
}
BENCHMARK(BM_MagTenMinutes100HzWanderingNoStep3c)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
