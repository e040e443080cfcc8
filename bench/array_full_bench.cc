// Benchmarks of the full array model (core/array_full.h, issue #14) on a simulated 8-IMU
// MIMU4444-like board at 62.5 Hz: 20 statics of 2 s (2 500 samples) then the rotation, N samples
// in all (the Ceres Solver 2.1 peer: 0.77 s and 60 MB at N ~ 4 000, 1.4 s and 107 MB at
// 6 000, per-sample blocks, DENSE_SCHUR, 2 threads, analytic Jacobians).
//
//   BM_ArrayFull/N   joint LM to convergence (default tolerance) + CRB + (not needed here)
//                    the residual-aware σ; wall time with 2 threads, CPU of all threads,
//                    iterations, extra peak RSS of the process
// Run each N in its own process so the peak RSS is its own:
//   build/bench/array_full_bench --benchmark_filter=BM_ArrayFull/4000
//   --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <ctime>

#include "core/array_full.h"
#include "core/array_full_simulation.h"

namespace {

using namespace calibd::core;
using calibd::Status;

double ProcessCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void BM_ArrayFull(benchmark::State& state) {
  ArrayFullSimulationOptions so;
  so.nominal_positions = Mimu4444NominalPositions();
  so.rate = 62.5;
  so.static_duration = 2;
  so.dynamic_samples = state.range(0) - 2500;
  so.seed = 2026;
  ArrayFullSimulation sim;
  if (!SimulateArrayFull(so, &sim).ok()) state.SkipWithError("simulation failed");
  ArrayFullOptions o;
  o.accel_noise = so.accel_noise;
  o.gyro_noise = so.gyro_noise;
  o.statics.static_window = 0.5;
  o.statics.min_static = 0.5;
  o.threads = 2;
  const double rss_before = PeakRssMb();
  const double cpu0 = ProcessCpuSeconds();
  ArrayFullResult r;
  for (auto _ : state) {
    const Status s = CalibrateArrayFull(sim.problem, o, &r);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  state.counters["cpu_ms"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations();
  state.counters["iterations"] = r.iterations;
  state.counters["blocks"] = static_cast<double>(r.statics + r.dynamic_samples);
  state.counters["chi2_dof"] = r.chi2_per_dof;
  state.counters["peak_rss_delta_MB"] = PeakRssMb() - rss_before;
}
BENCHMARK(BM_ArrayFull)->Arg(4000)->Arg(6000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
