// Benchmarks of the array method (core/array.h) on the paper's Section IV set-up, K = 32 triads.
//
//   BM_ArrayJoint/N             joint LM + Schur complement (core/block_lm.h), time to
//                               convergence (default tolerance), RMSE vs truth, iterations,
//                               extra peak memory
//   BM_ArrayJointOneThread/N    the same on one thread: CPU time of the calling thread, the
//                               figure least disturbed by other load (before/after comparisons)
//   BM_ArrayBcdToJointAccuracy/N  the paper's BCD, stopped (callback) when every coordinate is
//                               within 0.1 sqrt(CRB) of the joint estimate: the same accuracy
//   BM_ArrayBcdSweep/N          time of one BCD sweep (for N where running BCD to the joint's
//                               accuracy takes minutes)
// Run: build-array/bench/array_bench --benchmark_counters_tabular=true
// Wall time (UseRealTime): both cores are used. cpu_ms counts all threads of the process.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <cmath>
#include <ctime>
#include <limits>
#include <map>

#include "core/array.h"
#include "core/array_simulation.h"

namespace {

using calibd::core::ArrayOptions;
using calibd::core::ArrayResult;
using calibd::core::ArraySimulation;
using calibd::core::ArraySimulationOptions;
using calibd::core::ArraySolver;
using calibd::core::kDegree;

const ArraySimulation& Simulation(int64_t n) {
  static std::map<int64_t, ArraySimulation> cache;
  auto it = cache.find(n);
  if (it == cache.end()) {
    ArraySimulationOptions so;
    so.samples = n;
    so.seed = 2024;
    it = cache.emplace(n, ArraySimulation()).first;
    calibd::core::SimulateArray(so, &it->second);
  }
  return it->second;
}

ArrayOptions Options() {
  ArrayOptions o;
  o.accel_noise = 0.04;
  o.gyro_noise = 0.06 * kDegree;
  return o;
}

double Rmse(const Eigen::Matrix3Xd& estimate, const Eigen::Matrix3Xd& truth) {
  return std::sqrt((estimate - truth).squaredNorm() / (3.0 * (truth.cols() - 1)));
}

double PeakRssMb() {
  rusage u;
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

double ProcessCpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void BM_ArrayJoint(benchmark::State& state) {
  const ArraySimulation& sim = Simulation(state.range(0));
  const double rss_before = PeakRssMb();
  ArrayResult r;
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) calibd::core::CalibrateArray(sim.problem, Options(), &r);
  state.counters["cpu_ms"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations();
  state.counters["iterations"] = r.iterations;
  state.counters["rmse_um"] = 1e6 * Rmse(r.positions, sim.true_positions);
  state.counters["sqrt_crb_um"] =
      1e6 * std::sqrt(r.position_std.squaredNorm() / (3.0 * (r.positions.cols() - 1)));
  state.counters["peak_rss_delta_MB"] = PeakRssMb() - rss_before;
}

double ThreadCpuSeconds() {
  timespec t;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

void BM_ArrayJointOneThread(benchmark::State& state) {
  const ArraySimulation& sim = Simulation(state.range(0));
  ArrayOptions o = Options();
  o.threads = 1;
  ArrayResult r;
  double min_cpu = std::numeric_limits<double>::infinity();
  for (auto _ : state) {
    const double cpu0 = ThreadCpuSeconds();
    calibd::core::CalibrateArray(sim.problem, o, &r);
    min_cpu = std::min(min_cpu, ThreadCpuSeconds() - cpu0);
  }
  state.counters["min_cpu_ms"] = 1e3 * min_cpu;
  state.counters["iterations"] = r.iterations;
  state.counters["rmse_um"] = 1e6 * Rmse(r.positions, sim.true_positions);
}

void BM_ArrayBcdToJointAccuracy(benchmark::State& state) {
  const ArraySimulation& sim = Simulation(state.range(0));
  ArrayResult joint, r;
  calibd::core::CalibrateArray(sim.problem, Options(), &joint);
  const double target =
      0.1 * std::sqrt(joint.position_std.squaredNorm() / (3.0 * (joint.positions.cols() - 1)));
  ArrayOptions o = Options();
  o.solver = ArraySolver::kBcd;
  o.max_iterations = 100000;
  o.tolerance = 0;
  o.callback = [&](int, const Eigen::Matrix3Xd& p) {
    return (p - joint.positions).cwiseAbs().maxCoeff() > target;
  };
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) calibd::core::CalibrateArray(sim.problem, o, &r);
  state.counters["cpu_ms"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations();
  state.counters["iterations"] = r.iterations;
  state.counters["rmse_um"] = 1e6 * Rmse(r.positions, sim.true_positions);
  state.counters["joint_rmse_um"] = 1e6 * Rmse(joint.positions, sim.true_positions);
}

void BM_ArrayBcdSweep(benchmark::State& state) {
  const ArraySimulation& sim = Simulation(state.range(0));
  ArrayOptions o = Options();
  o.solver = ArraySolver::kBcd;
  o.max_iterations = 10;
  o.tolerance = 0;
  ArrayResult r;
  const double cpu0 = ProcessCpuSeconds();
  for (auto _ : state) calibd::core::CalibrateArray(sim.problem, o, &r);
  state.counters["cpu_ms_per_sweep"] = 1e3 * (ProcessCpuSeconds() - cpu0) / state.iterations() / 10;
  state.counters["sweeps"] = r.iterations;
}

BENCHMARK(BM_ArrayJoint)
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ArrayJointOneThread)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ArrayBcdToJointAccuracy)
    ->Arg(1000)
    ->Arg(10000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ArrayBcdSweep)
    ->Arg(1000)
    ->Arg(100000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
