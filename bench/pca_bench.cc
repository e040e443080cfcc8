// pca end to end (closed form, diagnostics and Fisher uncertainty) on the paper's Section IV
// set-up: m = 12 sensors, n positions. Run: build/pca_bench
#include <benchmark/benchmark.h>

#include "core/pca.h"
#include "core/pca_simulation.h"

namespace {

using calibd::core::BiasModel;
using calibd::core::CalibratePca;
using calibd::core::PcaOptions;
using calibd::core::PcaProblem;
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

}  // namespace

BENCHMARK_MAIN();
