// Monte-Carlo consistency of the primary σ each method reports (issue 28, #22): for pca, array
// (positions-only and `model: full`), imu and noise, z = (estimate − truth) / reported primary σ,
// RMS over the parameters and trials, under the right noise model and misspecified ones. The
// issue's rule: every row within 0.7–1.4, or the result carries a warning in that case (the
// "warned" column: trials whose result says its σ are not the white-noise bound, i.e. basis
// chi2_scaled / sandwich, which comes with a warning in every method).
//
// Rows (the noise is added to noise-free simulations by this program, so each row changes only
// the noise):
//   right       white Gaussian noise, the configured σ the true one
//   3x under    the same data, the configured σ a third of the true one
//   coloured    AR(1) noise, φ = 0.9 sample to sample, the same marginal σ (pca: along the
//               positions; imu: white noise plus a bias random walk instead)
//   jitter      imu: timestamps off by N(0, 0.26 ms) per sample (MIMU4444's timing jitter);
//               noise: the same on its timestamps; array (both models): every triad's sample
//               read that much late, to first order through ω and ω̇ (AddTimingJitter: their
//               simulations draw samples independently, so ω̈ and ṡ are taken as zero).
// Columns: trials, parameters per trial, z RMS with the primary σ, z RMS with the white-noise
// bound (crb), warned trials. The z RMS from P·T values has a relative standard error of about
// 1/√(2·P·T) if they were independent; parameters of one trial share the trial's noise, so the
// trial counts are chosen for ≥ 100 independent-ish values per row (±0.1 at z ≈ 1).
//
//   build/bench/sigma_consistency [trial multiplier, default 1] [pca|array|array_full|imu|noise]
#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "core/array.h"
#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "core/array_simulation.h"
#include "core/imu.h"
#include "core/imu_simulation.h"
#include "core/noise.h"
#include "core/noise_simulation.h"
#include "core/pca.h"
#include "core/pca_simulation.h"

namespace {

using namespace calibd::core;

enum class Misfit { kRight, kUnderstated, kColoured, kJitter };
const char* NoiseName(Misfit n) {
  switch (n) {
    case Misfit::kRight:
      return "right";
    case Misfit::kUnderstated:
      return "3x under";
    case Misfit::kColoured:
      return "coloured";
    case Misfit::kJitter:
      return "jitter";
  }
  return "?";
}

constexpr double kPhi = 0.9;               // AR(1) coefficient of the coloured rows
constexpr double kTimingJitter = 0.26e-3;  // s rms, MIMU4444's per-sample timing jitter

// Adds noise of marginal σ `sigma` to every column of x (rows are time): white, or AR(1) along
// the rows with coefficient kPhi.
void AddNoise(double sigma, bool coloured, GaussianRng* rng, Eigen::MatrixXd* x) {
  const double innovation = coloured ? std::sqrt(1 - kPhi * kPhi) : 1.0;
  for (Eigen::Index c = 0; c < x->cols(); ++c) {
    double e = sigma * rng->Normal();
    for (Eigen::Index r = 0; r < x->rows(); ++r) {
      if (r > 0)
        e = coloured ? kPhi * e + sigma * innovation * rng->Normal() : sigma * rng->Normal();
      (*x)(r, c) += e;
    }
  }
}

struct Row {
  std::string method, noise;
  int trials = 0, parameters = 0, warned = 0, failed = 0;
  double sum_z2 = 0, sum_z2_crb = 0;
  int64_t count = 0;
  void Add(double error, double primary, double crb) {
    if (!(primary > 0) || !(crb > 0) || !std::isfinite(error)) return;
    sum_z2 += error * error / (primary * primary);
    sum_z2_crb += error * error / (crb * crb);
    ++count;
  }
  void Print() const {
    const double z = std::sqrt(sum_z2 / static_cast<double>(count));
    const double zc = std::sqrt(sum_z2_crb / static_cast<double>(count));
    const bool in = z >= 0.7 && z <= 1.4;
    std::printf("| %-13s | %-9s | %6d | %5d | %6.2f | %6.2f | %4d/%-4d | %s |\n", method.c_str(),
                noise.c_str(), trials, parameters, z, zc, warned, trials,
                in ? "in range" : (warned == trials ? "out, warned" : "OUT, NOT WARNED"));
    if (failed > 0) std::printf("|   (%d trials failed and are left out) |\n", failed);
  }
};

// pca: the paper's set-up (12 gyroscope sensors, 100 positions, σ = 0.01), noise_std given,
// magnitude known; the 12 scale factors against |a_true column|.
Row Pca(Misfit noise, int trials) {
  Row row{"pca", NoiseName(noise)};
  PcaSimulationOptions so;
  so.noise_std = 0;
  so.seed = 77;
  const PcaSimulation sim = SimulatePca(so);
  const double sigma = 0.01;
  for (int t = 0; t < trials; ++t) {
    GaussianRng rng(1000 + t);
    Eigen::MatrixXd readings = sim.m.transpose();  // positions × sensors: AR(1) along positions
    AddNoise(sigma, noise == Misfit::kColoured, &rng, &readings);
    PcaProblem p;
    p.m = readings.transpose();
    PcaOptions o;
    o.magnitude = 1.0;
    o.noise_std = noise == Misfit::kUnderstated ? sigma / 3 : sigma;
    PcaResult r;
    if (!CalibratePca(p, o, &r).ok()) {
      ++row.failed;
      continue;
    }
    ++row.trials;
    row.warned += r.uncertainty_basis != "crb";
    row.parameters = static_cast<int>(r.sensors.size());
    for (size_t i = 0; i < r.sensors.size(); ++i) {
      const PcaSensorEstimate& s = r.sensors[i];
      row.Add(s.scale - sim.a_true.col(static_cast<Eigen::Index>(i)).norm(), s.scale_std,
              s.crb ? s.crb->scale_std : s.scale_std);
    }
  }
  return row;
}

// array positions-only: the paper's 32-triad board, 1 000 samples; 31 × 3 position coordinates.
// Every triad's every sample read kTimingJitter·N(0, 1) late (independently per triad and
// sample), to first order: the reading plus δ times its rate of change, gyroscope G ω̇,
// accelerometer T (ω̇×ω× + ω×ω̇×) r. The array simulations draw their samples independently (no
// trajectory), so ω̈ and ṡ are taken as zero. `accel_T`, `positions`: per accelerometer triad;
// `gyro_T`: per gyroscope triad (the columns of *gyro).
void AddTimingJitter(const Eigen::Matrix3Xd& omega, const Eigen::Matrix3Xd& omega_dot,
                     const std::vector<Eigen::Matrix3d>& accel_T, const Eigen::Matrix3Xd& positions,
                     const std::vector<Eigen::Matrix3d>& gyro_T, GaussianRng* rng,
                     Eigen::MatrixXd* accel, Eigen::MatrixXd* gyro) {
  const auto skew = [](const Eigen::Vector3d& v) {
    Eigen::Matrix3d m;
    m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
    return m;
  };
  for (Eigen::Index n = 0; n < omega.cols(); ++n) {
    const Eigen::Vector3d w = omega.col(n), wd = omega_dot.col(n);
    const Eigen::Matrix3d dA = skew(wd) * skew(w) + skew(w) * skew(wd);
    for (size_t k = 0; k < accel_T.size(); ++k) {
      accel->row(n).segment<3>(3 * static_cast<Eigen::Index>(k)) +=
          kTimingJitter * rng->Normal() *
          (accel_T[k] * dA * positions.col(static_cast<Eigen::Index>(k))).transpose();
    }
    for (size_t j = 0; j < gyro_T.size(); ++j) {
      gyro->row(n).segment<3>(3 * static_cast<Eigen::Index>(j)) +=
          kTimingJitter * rng->Normal() * (gyro_T[j] * wd).transpose();
    }
  }
}

Row Array(Misfit noise, int trials) {
  Row row{"array", NoiseName(noise)};
  for (int t = 0; t < trials; ++t) {
    ArraySimulationOptions so;
    so.accel_noise = 0;
    so.gyro_noise = 0;
    so.seed = 2000 + t;
    ArraySimulation sim;
    if (!SimulateArray(so, &sim).ok()) std::abort();
    const double sa = 0.04, sg = 0.06 * kDegree;
    GaussianRng rng(3000 + t);
    AddNoise(sa, noise == Misfit::kColoured, &rng, &sim.problem.accel);
    AddNoise(sg, noise == Misfit::kColoured, &rng, &sim.problem.gyro);
    if (noise == Misfit::kJitter) {
      std::vector<Eigen::Matrix3d> accel_T(static_cast<size_t>(sim.true_positions.cols()),
                                           Eigen::Matrix3d::Identity());
      for (size_t k = 0; k < sim.accel_models.size() && k < accel_T.size(); ++k)
        accel_T[k] = sim.accel_models[k].sensitivity.transpose();
      const std::vector<Eigen::Matrix3d> gyro_T(static_cast<size_t>(sim.problem.gyro.cols() / 3),
                                                Eigen::Matrix3d::Identity());
      AddTimingJitter(sim.omega, sim.omega_dot, accel_T, sim.true_positions, gyro_T, &rng,
                      &sim.problem.accel, &sim.problem.gyro);
    }
    ArrayOptions o;
    const double f = noise == Misfit::kUnderstated ? 1.0 / 3 : 1.0;
    o.accel_noise = f * sa;
    o.gyro_noise = f * sg;
    o.threads = 1;
    ArrayResult r;
    if (!CalibrateArray(sim.problem, o, &r).ok()) {
      ++row.failed;
      continue;
    }
    ++row.trials;
    row.warned += r.sigma_basis != "crb";
    row.parameters = 0;
    for (Eigen::Index k = 0; k < r.positions.cols(); ++k) {
      if (k == r.reference) continue;
      for (int c = 0; c < 3; ++c) {
        row.Add(r.positions(c, k) - sim.true_positions(c, k), r.position_std(c, k),
                r.position_std_crb(c, k));
        ++row.parameters;
      }
    }
  }
  return row;
}

// array `model: full`: the MIMU4444-like board (8 triads), 20 statics of 1 s at 100 Hz and 400
// dynamic samples; 7 × 3 position coordinates (the σ) and the 8 × 3 gyroscope biases.
Row ArrayFull(Misfit noise, int trials) {
  Row row{"array full", NoiseName(noise)};
  for (int t = 0; t < trials; ++t) {
    ArrayFullSimulationOptions so;
    so.nominal_positions = Mimu4444NominalPositions();
    const double sa = so.accel_noise, sg = so.gyro_noise;
    so.accel_noise = 0;
    so.gyro_noise = 0;
    so.seed = 4000 + t;
    ArrayFullSimulation sim;
    if (!SimulateArrayFull(so, &sim).ok()) std::abort();
    GaussianRng rng(5000 + t);
    AddNoise(sa, noise == Misfit::kColoured, &rng, &sim.problem.accel);
    AddNoise(sg, noise == Misfit::kColoured, &rng, &sim.problem.gyro);
    if (noise == Misfit::kJitter) {
      std::vector<Eigen::Matrix3d> accel_T, gyro_T;
      Eigen::Matrix3Xd positions(3, static_cast<Eigen::Index>(sim.truth.size()));
      for (size_t k = 0; k < sim.truth.size(); ++k) {
        accel_T.push_back(sim.truth[k].accel_T);
        gyro_T.push_back(sim.truth[k].gyro_T);
        positions.col(static_cast<Eigen::Index>(k)) = sim.truth[k].position;
      }
      AddTimingJitter(sim.motion.topRows<3>(), sim.motion.middleRows<3>(3), accel_T, positions,
                      gyro_T, &rng, &sim.problem.accel, &sim.problem.gyro);
    }
    ArrayFullOptions o;
    const double f = noise == Misfit::kUnderstated ? 1.0 / 3 : 1.0;
    o.accel_noise = f * sa;
    o.gyro_noise = f * sg;
    o.statics.static_window = 0.5;
    o.statics.min_static = 0.5;
    o.threads = 1;
    ArrayFullResult r;
    if (!CalibrateArrayFull(sim.problem, o, &r).ok()) {
      ++row.failed;
      continue;
    }
    ++row.trials;
    row.warned += r.sigma_basis != "crb";
    row.parameters = 0;
    for (size_t k = 0; k < r.triads.size(); ++k) {
      const ArrayFullTriadReport truth = ReportArrayFullTriad(sim.truth[k]);
      const ArrayFullTriadStd &u = r.report_std[k], &b = r.report_std_crb[k];
      for (int c = 0; c < 3; ++c) {
        if (static_cast<int>(k) != r.reference) {
          row.Add(r.triads[k].position(c) - sim.truth[k].position(c), u.position_std(c),
                  b.position_std(c));
          ++row.parameters;
        }
        row.Add(r.report[k].gyroscope.bias(c) - truth.gyroscope.bias(c), u.gyroscope.bias_std(c),
                b.gyroscope.bias_std(c));
        ++row.parameters;
      }
    }
  }
  return row;
}

// imu: 20 statics of 3 s and rotations of 2 s at 100 Hz (imu_simulation defaults), the noise
// configured; biases, scale factors and misalignments of both triads (21 parameters).
Row Imu(Misfit noise, int trials) {
  Row row{"imu", NoiseName(noise)};
  for (int t = 0; t < trials; ++t) {
    ImuSimulationOptions so;
    const double sa = so.accel_noise, sg = so.gyro_noise;
    so.accel_noise = 0;
    so.gyro_noise = 0;
    so.seed = 6000 + t;
    ImuSimulation sim;
    if (!SimulateImu(so, &sim).ok()) std::abort();
    GaussianRng rng(7000 + t);
    Eigen::MatrixXd accel = sim.accel, gyro = sim.gyro;
    AddNoise(sa, false, &rng, &accel);
    AddNoise(sg, false, &rng, &gyro);
    if (noise == Misfit::kColoured) {
      // Bias random walks: over the ≈ 100 s log a few times the noise of a static's mean.
      const double qa = 2e-4, qg = 2e-5;  // m/s²/√s, rad/s/√s
      const double root_dt = std::sqrt(1 / so.rate);
      Eigen::Vector3d ba = Eigen::Vector3d::Zero(), bg = Eigen::Vector3d::Zero();
      Eigen::Vector3d mean_a = Eigen::Vector3d::Zero(), mean_g = Eigen::Vector3d::Zero();
      for (Eigen::Index i = 0; i < accel.rows(); ++i) {
        for (int c = 0; c < 3; ++c) {
          ba(c) += qa * root_dt * rng.Normal();
          bg(c) += qg * root_dt * rng.Normal();
        }
        accel.row(i) += ba.transpose();
        gyro.row(i) += bg.transpose();
        mean_a += ba / static_cast<double>(accel.rows());
        mean_g += bg / static_cast<double>(accel.rows());
      }
      // The truth of a wandering bias for a constant-bias model: its mean over the log.
      sim.accel_truth.bias += mean_a;
      sim.gyro_truth.bias += mean_g;
    }
    Eigen::VectorXd time = sim.t;
    if (noise == Misfit::kJitter) {
      for (Eigen::Index i = 0; i < time.size(); ++i) time(i) += kTimingJitter * rng.Normal();
    }
    ImuOptions o;
    const double f = noise == Misfit::kUnderstated ? 1.0 / 3 : 1.0;
    o.accel_noise = f * sa;
    o.gyro_noise = f * sg;
    ImuResult r;
    const Eigen::MatrixX3d a3 = accel, g3 = gyro;
    if (!CalibrateImu(time, a3, g3, o, &r).ok()) {
      ++row.failed;
      continue;
    }
    ++row.trials;
    row.warned += r.uncertainty_basis != "crb";
    row.parameters = 0;
    const std::pair<const TriadCalibration*, const TriadCalibration*> est[] = {
        {&r.accelerometer, &r.accelerometer_crb}, {&r.gyroscope, &r.gyroscope_crb}};
    const ImuTriadTruth* truth[] = {&sim.accel_truth, &sim.gyro_truth};
    for (int s = 0; s < 2; ++s) {
      const TriadCalibration &e = *est[s].first, &b = *est[s].second;
      for (int c = 0; c < 3; ++c) {
        row.Add(e.bias(c) - truth[s]->bias(c), e.bias_std(c), b.bias_std(c));
        row.Add(e.scale(c) - truth[s]->scale(c), e.scale_std(c), b.scale_std(c));
        row.parameters += 2;
        for (int d = 0; d < 3; ++d) {
          if (c == d || !(e.misalignment_std(c, d) > 0)) continue;
          row.Add(e.misalignment(c, d) - truth[s]->misalignment(c, d), e.misalignment_std(c, d),
                  b.misalignment_std(c, d));
          ++row.parameters;
        }
      }
    }
  }
  return row;
}

// noise: 10 min at 50 Hz, N = 1e-3, K = 5e-4 and a flat bias-instability floor 1e-4 (the
// Monte-Carlo set-up of tests/core/noise_test.cc); N and K where visible. Coloured: a strong
// Gauss-Markov bump (correlation times 2–4 s) the N/B/K model does not have.
Row NoiseMethod(Misfit noise, int trials) {
  Row row{"noise", NoiseName(noise)};
  for (int t = 0; t < trials; ++t) {
    NoiseSimulationOptions so;
    so.rate = 50;
    so.duration = 600;
    NoiseSimulationChannel c;
    c.white_noise = 1e-3;
    c.random_walk = 5e-4;
    c.bias_instability = 1e-4;
    so.gauss_markov_per_decade = 1;
    if (noise == Misfit::kColoured) {
      c.bias_instability = 3e-3;
      so.flicker_min_tau = 2;
      so.flicker_max_tau = 4;
    }
    so.channels = {c};
    so.seed = 8000 + t;
    const NoiseSimulation sim = SimulateNoise(so);
    std::vector<double> times = sim.times;
    if (noise == Misfit::kJitter) {
      GaussianRng rng(9000 + t);
      for (size_t i = 0; i < times.size(); ++i) {
        times[i] = static_cast<double>(i) * sim.sample_period + kTimingJitter * rng.Normal();
      }
    }
    NoiseProblem p;
    p.samples = sim.samples.rows();
    p.channels.push_back({sim.names[0], sim.units[0], sim.samples.col(0).data()});
    p.times = times.data();
    NoiseOptions o;
    o.threads = 1;
    NoiseResult r;
    if (!EstimateNoise(p, o, &r).ok()) {
      ++row.failed;
      continue;
    }
    ++row.trials;
    const NoiseChannelResult& ch = r.channels[0];
    row.warned += ch.uncertainty_basis != "crb";
    row.parameters = 2;
    const std::pair<const NoiseTerm*, double> terms[] = {{&ch.white_noise, c.white_noise},
                                                         {&ch.random_walk, c.random_walk}};
    for (const auto& [term, truth] : terms) {
      if (term->value) row.Add(*term->value - truth, *term->std, *term->crb_std);
    }
  }
  return row;
}

}  // namespace

int main(int argc, char** argv) {
  const double multiplier = argc > 1 ? std::atof(argv[1]) : 1.0;
  if (!(multiplier > 0)) {
    std::fprintf(stderr, "usage: sigma_consistency [trial multiplier > 0]\n");
    return 2;
  }
  const std::string only = argc > 2 ? argv[2] : "";  // run only the rows of this method
  auto n = [multiplier](int trials) { return std::max(2, static_cast<int>(trials * multiplier)); };
  struct Plan {
    std::string name;
    std::function<Row(Misfit, int)> run;
    std::vector<Misfit> rows;
    int trials;
  };
  const std::vector<Plan> plans = {
      {"pca", Pca, {Misfit::kRight, Misfit::kUnderstated, Misfit::kColoured}, 300},
      {"array",
       Array,
       {Misfit::kRight, Misfit::kUnderstated, Misfit::kColoured, Misfit::kJitter},
       40},
      {"array_full",
       ArrayFull,
       {Misfit::kRight, Misfit::kUnderstated, Misfit::kColoured, Misfit::kJitter},
       30},
      {"imu", Imu, {Misfit::kRight, Misfit::kUnderstated, Misfit::kColoured, Misfit::kJitter}, 150},
      {"noise", NoiseMethod, {Misfit::kRight, Misfit::kColoured, Misfit::kJitter}, 400},
  };
  std::printf(
      "| method        | noise     | trials | par.  | z RMS  | z crb  | warned    | rule |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---|\n");
  for (const Plan& plan : plans) {
    for (Misfit noise : plan.rows) {
      const auto start = std::chrono::steady_clock::now();
      if (!only.empty() && only != plan.name) continue;
      const Row row = plan.run(noise, n(plan.trials));
      row.Print();
      std::fflush(stdout);
      std::fprintf(stderr, "  %s %s: %.1f s\n", row.method.c_str(), row.noise.c_str(),
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    }
  }
  return 0;
}
