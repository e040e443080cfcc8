// Cost of every method against its input size (issue #20): time of one calibration, from a
// small input up to the job budget's largest (bench/README.md, "Cost of every method"), so that
// the bound in each core header (core/<method>.h, "Cost:") is measured, not only stated.
// Inputs are simulated in memory (parsing is the server's and not here); one iteration each.
//   imu:        one IMU, statics of 10 s joined by 5 s rotations at 400 Hz (`rows` samples), and
//               the same log with its time column in ms (the input of issue #20)
//   noise:      6 white-noise channels at 400 Hz, octave cluster times
//   array:      32 triads (the paper's set-up), joint solver, and bcd per sweep
//   array full: 8-IMU MIMU4444-like board, 20 statics then the rotation
//   pca:        m sensors (3 axes each) at 3m positions, biases estimated, dense information
// Run: build/bench/method_cost_bench --benchmark_filter=Imu --benchmark_counters_tabular=true
// The largest sizes take minutes and gigabytes: select them with --benchmark_filter.
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "core/array.h"
#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "core/array_simulation.h"
#include "core/imu.h"
#include "core/imu_simulation.h"
#include "core/noise.h"
#include "core/pca.h"

namespace {

using namespace calibd::core;  // NOLINT(build/namespaces)

ImuSimulation ImuLog(int64_t rows) {
  ImuSimulationOptions so;
  so.static_duration = 10;
  so.rotation_duration = 5;
  so.rate = 400;
  so.statics = static_cast<int>(std::max<int64_t>(12, rows / (15 * 400)));
  so.seed = 42;
  ImuSimulation sim;
  if (!SimulateImu(so, &sim).ok()) std::abort();
  return sim;
}

void RunImu(benchmark::State& state, double time_scale) {
  const ImuSimulation sim = ImuLog(state.range(0));
  const Eigen::VectorXd t = sim.t * time_scale;
  ImuResult r;
  calibd::Status s;
  for (auto _ : state) {
    s = CalibrateImu(t, sim.accel, sim.gyro, ImuOptions(), &r);
    benchmark::DoNotOptimize(r.accelerometer.matrix.data());
  }
  state.counters["rows"] = static_cast<double>(t.size());
  state.counters["statics"] = static_cast<double>(r.statics.size());
  state.counters["found"] = static_cast<double>(r.detection.intervals.size());
  state.counters["ok"] = s.ok() ? 1 : 0;
}
void BM_ImuCost(benchmark::State& state) { RunImu(state, 1); }
void BM_ImuCostTimeInMs(benchmark::State& state) { RunImu(state, 1000); }

void BM_NoiseCost(benchmark::State& state) {
  const int64_t n = state.range(0);
  Eigen::MatrixXf samples(n, 6);
  std::vector<double> times(static_cast<size_t>(n));
  std::mt19937_64 rng(7);
  std::normal_distribution<float> normal(0.f, 1e-2f);
  for (int c = 0; c < 6; ++c) {
    for (int64_t i = 0; i < n; ++i) samples(i, c) = (c < 3 ? 9.8f * (c == 2) : 0.f) + normal(rng);
  }
  for (int64_t i = 0; i < n; ++i) times[static_cast<size_t>(i)] = static_cast<double>(i) / 400;
  NoiseProblem p;
  p.samples = n;
  p.times = times.data();
  for (int c = 0; c < 6; ++c) {
    p.channels.push_back({std::string(c < 3 ? "a0_" : "g0_") + "xyz"[c % 3],
                          c < 3 ? "m/s^2" : "rad/s", samples.col(c).data()});
  }
  NoiseOptions o;
  o.threads = 1;
  NoiseResult r;
  for (auto _ : state) {
    const calibd::Status s = EstimateNoise(p, o, &r);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  state.counters["rows"] = static_cast<double>(n);
}

void RunArray(benchmark::State& state, ArraySolver solver) {
  ArraySimulationOptions so;
  so.samples = state.range(0);
  so.seed = 2;
  ArraySimulation sim;
  if (!SimulateArray(so, &sim).ok()) std::abort();
  ArrayOptions o;
  o.accel_noise = so.accel_noise;
  o.gyro_noise = so.gyro_noise;
  o.solver = solver;
  o.threads = 1;
  if (solver == ArraySolver::kBcd) o.max_iterations = 5;  // per sweep: 500 sweeps by default
  ArrayResult r;
  for (auto _ : state) {
    const calibd::Status s = CalibrateArray(sim.problem, o, &r);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  state.counters["rows"] = static_cast<double>(so.samples);
  state.counters["iterations"] = r.iterations;
}
void BM_ArrayJointCost(benchmark::State& state) { RunArray(state, ArraySolver::kJoint); }
void BM_ArrayBcdFiveSweeps(benchmark::State& state) { RunArray(state, ArraySolver::kBcd); }

void BM_ArrayFullCost(benchmark::State& state) {
  ArrayFullSimulationOptions so;
  so.nominal_positions = Mimu4444NominalPositions();
  so.rate = 62.5;
  so.statics = 20;
  so.static_duration = 2;
  so.dynamic_samples = state.range(0);
  so.seed = 3;
  ArrayFullSimulation sim;
  if (!SimulateArrayFull(so, &sim).ok()) std::abort();
  ArrayFullOptions o;
  o.accel_noise = so.accel_noise;
  o.gyro_noise = so.gyro_noise;
  o.statics.static_window = 0.2;
  o.statics.min_static = 0.3;
  o.threads = 1;
  ArrayFullResult r;
  for (auto _ : state) {
    const calibd::Status s = CalibrateArrayFull(sim.problem, o, &r);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  state.counters["rows"] = static_cast<double>(sim.problem.t.size());
  state.counters["iterations"] = r.iterations;
}

void BM_PcaCost(benchmark::State& state) {
  const int sensors = static_cast<int>(state.range(0)), positions = 3 * sensors;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal(0, 1);
  Eigen::MatrixXd a(3, sensors), v(3, positions);
  for (int i = 0; i < a.size(); ++i) a.data()[i] = normal(rng);
  for (int i = 0; i < v.size(); ++i) v.data()[i] = normal(rng);
  a.colwise().normalize();
  v.colwise().normalize();
  PcaProblem p;
  p.m = a.transpose() * v;
  for (int i = 0; i < p.m.size(); ++i) p.m.data()[i] += 1e-3 * normal(rng);
  PcaOptions o;
  o.bias = BiasModel::kEstimate;
  o.information_solver = PcaInformationSolver::kDense;
  PcaResult r;
  for (auto _ : state) {
    const calibd::Status s = CalibratePca(p, o, &r);
    if (!s.ok()) state.SkipWithError(s.message().c_str());
  }
  state.counters["values"] = static_cast<double>(p.m.size());
}

BENCHMARK(BM_ImuCost)
    ->RangeMultiplier(4)
    ->Range(1 << 16, 1 << 24)
    ->Arg(37000000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ImuCostTimeInMs)
    ->RangeMultiplier(4)
    ->Range(1 << 14, 1 << 24)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_NoiseCost)
    ->RangeMultiplier(4)
    ->Range(1 << 16, 1 << 26)
    ->Arg(128000000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ArrayJointCost)
    ->RangeMultiplier(4)
    ->Range(1 << 12, 1 << 20)
    ->Arg(1350000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ArrayBcdFiveSweeps)
    ->RangeMultiplier(4)
    ->Range(1 << 12, 1 << 20)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ArrayFullCost)
    ->RangeMultiplier(4)
    ->Range(1 << 12, 1 << 18)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PcaCost)
    ->RangeMultiplier(2)
    ->Range(16, 512)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
