// pca end to end (closed form, diagnostics, coverage and Fisher uncertainty).
//  - BM_PcaClosedForm / Refined / BiasEstimate: the paper's Section IV set-up, m = 12 sensors,
//    n positions (the argument).
//  - BM_PcaManySensors: m sensors (the first argument: 1000 or 10 000) × 12 positions, random unit
//    axes with 5 % gain spread, noise 1 % of the field; second argument 1 = bias estimation;
//    third argument the information solver (0 auto = low rank here, 1 the dense solver that was
//    the only one before issue #14).
// Run: build/bench/pca_bench; peak memory of one case:
//   /usr/bin/time -v build/bench/pca_bench --benchmark_filter='BM_PcaManySensors/1000/1/0'
#include <benchmark/benchmark.h>

#include "core/pca.h"
#include "core/pca_simulation.h"

namespace {

using calibd::core::BiasModel;
using calibd::core::CalibratePca;
using calibd::core::PcaInformationSolver;
using calibd::core::PcaOptions;
using calibd::core::PcaProblem;
using calibd::core::PcaRandom;
using calibd::core::PcaResult;
using calibd::core::PcaSimulationOptions;
using calibd::core::SimulatePca;

void Run(benchmark::State& state, bool refine, BiasModel bias) {
  PcaSimulationOptions so;
  so.positions = static_cast<int>(state.range(0));
  so.noise_std = 0.01;
  if (bias == BiasModel::kEstimate) so.bias_std = 0.1;
  PcaProblem problem;
  problem.m = SimulatePca(so).m;
  PcaOptions options;
  options.magnitude = 1.0;
  options.refine = refine;
  options.bias = bias;
  PcaResult result;
  for (auto _ : state) {
    if (!CalibratePca(problem, options, &result).ok()) state.SkipWithError("calibration failed");
    benchmark::DoNotOptimize(result.sensors.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
  state.counters["refine_iterations"] = result.refine_iterations;
}

void BM_PcaClosedForm(benchmark::State& state) { Run(state, false, BiasModel::kNone); }
void BM_PcaRefined(benchmark::State& state) { Run(state, true, BiasModel::kNone); }
void BM_PcaBiasEstimate(benchmark::State& state) { Run(state, false, BiasModel::kEstimate); }

BENCHMARK(BM_PcaClosedForm)->Arg(100)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PcaRefined)->Arg(100)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PcaBiasEstimate)->Arg(100)->Arg(1000)->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_PcaManySensors(benchmark::State& state) {
  const int m = static_cast<int>(state.range(0));
  const int n = 12;
  const bool bias = state.range(1) != 0;
  const double c = 9.81;
  PcaRandom rng(m + 17);
  Eigen::MatrixXd a(3, m);
  for (int i = 0; i < m; ++i) a.col(i) = (1 + 0.05 * rng.Normal()) * rng.UnitVector(3);
  PcaProblem problem;
  problem.m = a.transpose() * rng.SphereColumns(3, n, c) + 0.01 * c * rng.NormalMatrix(m, n);
  if (bias) problem.m.colwise() += 0.1 * Eigen::VectorXd(rng.NormalMatrix(m, 1));
  PcaOptions options;
  options.magnitude = c;
  options.bias = bias ? BiasModel::kEstimate : BiasModel::kNone;
  options.information_solver =
      state.range(2) == 1 ? PcaInformationSolver::kDense : PcaInformationSolver::kAuto;
  options.max_flops = 0;  // measure, do not refuse
  options.max_memory_bytes = 0;
  PcaResult result;
  for (auto _ : state) {
    if (!CalibratePca(problem, options, &result).ok()) state.SkipWithError(result.reason.c_str());
    benchmark::DoNotOptimize(result.sensors.data());
  }
  state.counters["estimated_MB"] = result.cost_estimate.bytes / 1e6;
  state.counters["estimated_Gflop"] = result.cost_estimate.flops / 1e9;
  state.counters["scale_std_0"] = result.sensors.empty() ? 0 : result.sensors[0].scale_std;
}
BENCHMARK(BM_PcaManySensors)
    ->Args({1000, 0, 0})
    ->Args({1000, 1, 0})
    ->Args({10000, 0, 0})
    ->Args({10000, 1, 0})
    ->Args({1000, 0, 1})
    ->Args({1000, 1, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
