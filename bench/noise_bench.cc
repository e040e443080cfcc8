// noise: the analysis of the target log (2 h at 400 Hz, 6 channels, 2.88 M samples per
// channel, float samples + double timestamps), and the Allan variance alone against
// straightforward references (non-overlapping direct summation; overlapping direct summation,
// O(n·m) per cluster time, on shorter logs). Parsing is not included. Run: build/bench/noise_bench
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include "core/allan.h"
#include "core/noise.h"
#include "core/noise_simulation.h"

namespace {

using namespace calibd::core;  // NOLINT

const NoiseSimulation& TargetLog() {
  static const NoiseSimulation sim = [] {
    NoiseSimulationOptions o;
    o.rate = 400;
    o.duration = 2 * 3600;
    const char* names[] = {"a0_x", "a0_y", "a0_z", "g0_x", "g0_y", "g0_z"};
    for (int c = 0; c < 6; ++c) {
      NoiseSimulationChannel ch;
      ch.name = names[c];
      ch.unit = c < 3 ? "m/s^2" : "rad/s";
      ch.white_noise = c < 3 ? 2e-3 : 1.7e-4;  // typical MEMS IMU
      ch.random_walk = c < 3 ? 3e-5 : 2e-6;
      ch.offset = c == 2 ? 9.81 : 0;
      o.channels.push_back(ch);
    }
    o.timestamp_jitter = 0.01;
    return SimulateNoise(o);
  }();
  return sim;
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void BM_NoiseAnalysisTargetLog(benchmark::State& state) {
  const NoiseSimulation& sim = TargetLog();
  NoiseProblem problem;
  problem.samples = sim.samples.rows();
  for (int c = 0; c < sim.samples.cols(); ++c) {
    problem.channels.push_back({sim.names[c], sim.units[c], sim.samples.col(c).data()});
  }
  problem.times = sim.times.data();
  NoiseOptions options;
  options.threads = static_cast<int>(state.range(0));
  options.taus_per_decade = static_cast<int>(state.range(1));
  NoiseResult result;
  for (auto _ : state) {
    if (!EstimateNoise(problem, options, &result).ok()) state.SkipWithError(result.reason.c_str());
    benchmark::DoNotOptimize(result.channels.data());
  }
  state.SetItemsProcessed(state.iterations() * problem.samples * sim.samples.cols());
  state.counters["samples_per_channel"] = static_cast<double>(problem.samples);
  state.counters["points"] = static_cast<double>(result.channels[0].allan.size());
  state.counters["peak_rss_MB"] = PeakRssMb();
}
BENCHMARK(BM_NoiseAnalysisTargetLog)
    ->Args({1, 0})
    ->Args({2, 0})
    ->Args({2, 10})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Allan variance of one channel of the target log.
void BM_AllanOverlappingCumulativeSum(benchmark::State& state) {
  const NoiseSimulation& sim = TargetLog();
  const int64_t n = sim.samples.rows();
  const std::vector<int64_t> m = AllanClusterSizes(n, static_cast<int>(state.range(0)));
  for (auto _ : state) {
    benchmark::DoNotOptimize(OverlappingAllanVariance(sim.samples.col(3).data(), n, m).data());
  }
  state.SetItemsProcessed(state.iterations() * n);
  state.counters["points"] = static_cast<double>(m.size());
}
BENCHMARK(BM_AllanOverlappingCumulativeSum)->Arg(0)->Arg(10)->Unit(benchmark::kMillisecond);

void BM_AllanNonOverlappingDirect(benchmark::State& state) {
  const NoiseSimulation& sim = TargetLog();
  const int64_t n = sim.samples.rows();
  const std::vector<int64_t> m = AllanClusterSizes(n, static_cast<int>(state.range(0)));
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        NonOverlappingAllanVarianceDirect(sim.samples.col(3).data(), n, m).data());
  }
  state.SetItemsProcessed(state.iterations() * n);
}
BENCHMARK(BM_AllanNonOverlappingDirect)->Arg(0)->Arg(10)->Unit(benchmark::kMillisecond);

// The direct overlapping estimator costs 2·n·Σm additions: O(n²) over octaves up to n/4. Run on
// the first n samples only and extrapolate: time × (target/n)², printed as a counter.
void BM_AllanOverlappingDirect(benchmark::State& state) {
  const NoiseSimulation& sim = TargetLog();
  const int64_t n = state.range(0);
  const std::vector<int64_t> m = AllanClusterSizes(n, 0);
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        OverlappingAllanVarianceDirect(sim.samples.col(3).data(), n, m).data());
  }
  state.SetItemsProcessed(state.iterations() * n);
  // Time at the target length = this time × (2.88e6 / n)².
  const double scale = static_cast<double>(sim.samples.rows()) / static_cast<double>(n);
  state.counters["target_over_n_squared"] = scale * scale;
}
BENCHMARK(BM_AllanOverlappingDirect)->Arg(1 << 14)->Arg(1 << 16)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
