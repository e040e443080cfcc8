// Tests of the full array model (core/array_full.h) on simulated boards with per-triad
// accelerometer and gyroscope errors (core/array_full_simulation.h). Statistical tests use fixed
// seeds and margins of 3 standard errors of the number of runs.
#include "core/array_full.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/array_full_simulation.h"
#include "tests/lib/sanitizer.h"

namespace calibd::core {
namespace {

ArrayFullSimulationOptions Board8(uint64_t seed) {
  ArrayFullSimulationOptions o;
  o.nominal_positions = Mimu4444NominalPositions();
  o.seed = seed;
  return o;
}

ArrayFullOptions FitOptions(const ArrayFullSimulationOptions& so) {
  ArrayFullOptions o;
  o.accel_noise = so.accel_noise > 0 ? so.accel_noise : 0.04;
  o.gyro_noise = so.gyro_noise > 0 ? so.gyro_noise : 0.2 * kDegree;
  o.statics.static_window = 0.2;
  o.statics.min_static = 0.3;
  o.threads = 1;
  return o;
}

TEST(ArrayFull, RecoversEveryParameterExactlyWithoutNoise) {
  ArrayFullSimulationOptions so = Board8(3);
  so.accel_noise = 0;
  so.gyro_noise = 0;
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  const Status s = CalibrateArrayFull(sim.problem, FitOptions(so), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  std::printf("%s\n", r.BriefReport().c_str());
  EXPECT_EQ(r.statics, so.statics);
  const Eigen::VectorXd err = r.theta - sim.truth_theta;
  EXPECT_LT(err.cwiseAbs().maxCoeff(), 1e-9) << err.transpose();
  EXPECT_EQ(r.gauge, "sum_trace_gyroscope");
}

// The simulation's per-sample motion is the one its noise-free readings were made from.
TEST(ArrayFullSimulationMotion, ReproducesTheNoiseFreeReadings) {
  ArrayFullSimulationOptions so = Board8(9);
  so.accel_noise = so.gyro_noise = 0;
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ASSERT_EQ(sim.motion.cols(), sim.problem.t.size());
  const auto skew = [](const Eigen::Vector3d& v) {
    Eigen::Matrix3d m;
    m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
    return m;
  };
  double worst = 0;
  for (Eigen::Index n = 0; n < sim.motion.cols(); ++n) {
    const Eigen::Vector3d w = sim.motion.col(n).head<3>(), wd = sim.motion.col(n).segment<3>(3),
                          s = sim.motion.col(n).tail<3>();
    for (size_t k = 0; k < sim.truth.size(); ++k) {
      const ArrayFullTriad& t = sim.truth[k];
      const Eigen::Index c = 3 * static_cast<Eigen::Index>(k);
      const Eigen::Vector3d ya =
          t.accel_T * ((skew(w) * skew(w) + skew(wd)) * t.position + s) + t.accel_bias;
      const Eigen::Vector3d yg = t.gyro_T * w + t.gyro_bias;
      worst = std::max({worst, (ya - sim.problem.accel.row(n).segment<3>(c).transpose()).norm(),
                        (yg - sim.problem.gyro.row(n).segment<3>(c).transpose()).norm()});
    }
  }
  EXPECT_LT(worst, 1e-12);
}

// Given static directions are held in order (each static reads gravity along its direction) and
// `statics` is then ignored; a rotation axis makes every dynamic sample's ω and ω̇ parallel to
// it; invalid ones are refused naming the option.
TEST(ArrayFullSimulationMotion, HoldsGivenStaticDirectionsAndRotatesAboutAGivenAxis) {
  ArrayFullSimulationOptions so = Board8(9);
  so.statics = 3;
  so.static_directions = {{0, 0, 2}, {1, 0, 0}, {0, -1, -1}, {1, 1, 1}};
  so.rotation_axis = Eigen::Vector3d(0, 0, 3);
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  const int64_t per = sim.static_samples_per_orientation;
  ASSERT_EQ(sim.problem.t.size(), 4 * per + so.dynamic_samples);
  for (int j = 0; j < 4; ++j) {
    const Eigen::Vector3d s = sim.motion.col(j * per + per / 2).tail<3>();
    EXPECT_LT((s - so.gravity * so.static_directions[j].normalized()).norm(), 1e-12) << j;
  }
  for (int64_t n = 4 * per; n < sim.motion.cols(); ++n) {
    const Eigen::Vector3d w = sim.motion.col(n).head<3>(), wd = sim.motion.col(n).segment<3>(3);
    EXPECT_NEAR(std::abs(w.z()), so.omega_norm, 1e-12);
    EXPECT_NEAR(std::abs(wd.z()), so.omega_dot_norm, 1e-12);
    EXPECT_EQ(w.head<2>().norm() + wd.head<2>().norm(), 0);
  }
  so.static_directions[2].setZero();
  Status s = SimulateArrayFull(so, &sim);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("static_directions[2]"), std::string::npos) << s.message();
  so.static_directions.clear();
  so.rotation_axis = Eigen::Vector3d(0, NAN, 1);
  s = SimulateArrayFull(so, &sim);
  EXPECT_NE(s.message().find("rotation_axis"), std::string::npos) << s.message();
}

// residual_aware_sigma false (the plans' noise-free replays): the same estimate and CRB, no
// sandwich (sigma_ratio NaN, no batches, no such stage), the CRB primary.
TEST(ArrayFull, WithoutTheResidualAwareSigmaTheBoundIsUnchangedAndPrimary) {
  const ArrayFullSimulationOptions so = Board8(11);
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullOptions o = FitOptions(so);
  ArrayFullResult with, without;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, o, &with).ok());
  o.residual_aware_sigma = false;
  std::vector<std::string> stages;
  o.on_stage = [&](const char* stage) { stages.emplace_back(stage); };
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, o, &without).ok());
  EXPECT_EQ((with.theta - without.theta).cwiseAbs().maxCoeff(), 0);
  EXPECT_EQ((with.theta_covariance_crb - without.theta_covariance_crb).cwiseAbs().maxCoeff(), 0);
  EXPECT_EQ((without.theta_covariance - without.theta_covariance_crb).cwiseAbs().maxCoeff(), 0);
  EXPECT_EQ(without.sigma_basis, "crb");
  EXPECT_TRUE(std::isnan(without.sigma_ratio));
  EXPECT_EQ(without.robust_batches, 0);
  EXPECT_GT(with.robust_batches, 0);
  EXPECT_EQ(std::find(stages.begin(), stages.end(), "residual-aware sigma"), stages.end());
  EXPECT_EQ(stages.back(), "done");
}

// dynamic_noise_scale must be a finite number > 0; the error names it.
TEST(ArrayFull, ANonPositiveDynamicNoiseScaleIsRefusedNamingIt) {
  for (double scale : {0.0, -1.0, double{NAN}, double{INFINITY}}) {
    ArrayFullOptions o;
    o.dynamic_noise_scale = scale;
    std::string error;
    EXPECT_FALSE(o.IsValid(&error)) << scale;
    EXPECT_NE(error.find("dynamic_noise_scale"), std::string::npos) << error;
  }
}

// ArrayFullOptions::on_stage names each stage as it begins, in order, and "done" only after a
// successful run; a refused log ends at the stage that refused it.
TEST(ArrayFull, OnStageNamesTheStagesInOrder) {
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(Board8(5), &sim).ok());
  ArrayFullOptions o = FitOptions(Board8(5));
  std::vector<std::string> stages;
  o.on_stage = [&stages](const char* name) { stages.emplace_back(name); };
  ArrayFullResult r;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, o, &r).ok());
  EXPECT_EQ(stages, (std::vector<std::string>{"statics", "start", "joint solver", "crb",
                                              "residual-aware sigma", "done"}));
  stages.clear();
  o.min_statics = 1000;  // more statics than the log has: refused before the start
  EXPECT_FALSE(CalibrateArrayFull(sim.problem, o, &r).ok());
  EXPECT_EQ(stages, (std::vector<std::string>{"statics"}));
}

TEST(ArrayFull, RecoversThe32TriadArrayExactlyWithoutNoise) {
  ArrayFullSimulationOptions so;
  so.nominal_positions = PaperArrayNominalPositions();
  so.seed = 5;
  so.rate = 50;
  so.dynamic_samples = 100;
  so.accel_noise = 0;
  so.gyro_noise = 0;
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  const Status s = CalibrateArrayFull(sim.problem, FitOptions(so), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  std::printf("%s\n", r.BriefReport().c_str());
  EXPECT_LT((r.theta - sim.truth_theta).cwiseAbs().maxCoeff(), 1e-9);
}

// Whitened error e^T CRB^+ e of all 27K - 7 free parameters, and the mean of (error / sigma)^2
// over the reported quantities' parameters (theta's coordinates), for one run.
struct Whitened {
  double chi2 = 0;
  double z2 = 0;  // mean over the free coordinates of (error / sigma)^2
  int free = 0;
};

Whitened WhitenedError(const ArrayFullResult& r, const Eigen::VectorXd& truth,
                       const Eigen::MatrixXd& covariance) {
  const Eigen::MatrixXd& E = r.gauge_basis;
  const Eigen::VectorXd err = r.theta - truth;
  const Eigen::VectorXd delta = E.transpose() * err;
  const Eigen::MatrixXd covE = E.transpose() * covariance * E;
  Whitened w;
  w.free = static_cast<int>(E.cols());
  w.chi2 = delta.dot(covE.ldlt().solve(delta));
  int n = 0;
  for (int i = 0; i < err.size(); ++i) {
    const double v = covariance(i, i);
    if (v <= 1e-30) continue;  // a gauge-fixed coordinate
    w.z2 += err(i) * err(i) / v;
    ++n;
  }
  w.z2 /= n;
  return w;
}

struct MeanSe {
  double mean = 0, se = 0;
};
MeanSe Summarise(const std::vector<double>& v) {
  MeanSe m;
  for (double x : v) m.mean += x;
  m.mean /= v.size();
  double ss = 0;
  for (double x : v) ss += (x - m.mean) * (x - m.mean);
  m.se = std::sqrt(ss / (v.size() - 1) / v.size());
  return m;
}

// Efficiency: over Monte-Carlo runs the whitened error chi^2 has the mean of its degrees of
// freedom (the 209 free parameters of an 8-IMU board), and the reported sigma of every
// parameter matches its spread (mean (error / sigma)^2 = 1), within 3 standard errors.
TEST(ArrayFull, IsEfficientAndItsSigmaMatchesTheSpreadOnAnEightImuBoard) {
  // Fewer runs under ASan (10-50x slower): the margins are 3 SE of whatever was run.
  constexpr int kRuns = sanitizer::kAddressSanitizer ? 5 : 16;
  std::vector<double> chi2, z2, cost;
  int free = 0;
  for (int run = 0; run < kRuns; ++run) {
    ArrayFullSimulationOptions so = Board8(100 + run);
    ArrayFullSimulation sim;
    ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
    ArrayFullResult r;
    const Status s = CalibrateArrayFull(sim.problem, FitOptions(so), &r);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_TRUE(r.converged) << r.BriefReport();
    EXPECT_EQ(r.sigma_basis, "crb");
    EXPECT_NEAR(r.static_chi2_per_dof, 1.0, 0.3) << r.BriefReport();
    // No sampling-time errors simulated: the offsets explain (almost) nothing.
    EXPECT_LT(r.time_offset_explained, 0.05);
    const Whitened w = WhitenedError(r, sim.truth_theta, r.theta_covariance);
    free = w.free;
    chi2.push_back(w.chi2 / w.free);
    z2.push_back(w.z2);
    cost.push_back(r.chi2_per_dof);
    if (run == 0) std::printf("%s\n", r.BriefReport().c_str());
  }
  EXPECT_EQ(free, 27 * 8 - 7);
  const MeanSe c = Summarise(chi2), z = Summarise(z2), f = Summarise(cost);
  std::printf("chi2/free %.4f +- %.4f, mean (err/sigma)^2 %.4f +- %.4f, cost/dof %.4f +- %.4f\n",
              c.mean, c.se, z.mean, z.se, f.mean, f.se);
  // The SE of chi2/free from theory: sqrt(2 / (free * runs)); use the larger of the two.
  const double c_se = std::max(c.se, std::sqrt(2.0 / (free * kRuns)));
  EXPECT_NEAR(c.mean, 1.0, 3 * c_se);
  EXPECT_NEAR(z.mean, 1.0, 3 * z.se);
  EXPECT_NEAR(f.mean, 1.0, 3 * std::max(f.se, 1e-3));
}

// With the configured noise three times too small, the residuals exceed it: a warning, and the
// residual-aware sigma matches the spread while the Cramér-Rao sigma (of the understated
// noise) is about three times too small.
TEST(ArrayFull, ResidualAwareSigmaMatchesTheSpreadWhenTheNoiseIsUnderstated) {
  constexpr int kRuns = sanitizer::kAddressSanitizer ? 4 : 12;
  std::vector<double> z2_crb, z2_robust;
  for (int run = 0; run < kRuns; ++run) {
    ArrayFullSimulationOptions so = Board8(200 + run);
    ArrayFullSimulation sim;
    ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
    ArrayFullOptions fo = FitOptions(so);
    fo.accel_noise /= 3;
    fo.gyro_noise /= 3;
    fo.robust_batch = 0.05;
    ArrayFullResult r;
    const Status s = CalibrateArrayFull(sim.problem, fo, &r);
    ASSERT_TRUE(s.ok()) << s.message();
    ASSERT_EQ(r.sigma_basis, "sandwich");
    EXPECT_NEAR(r.chi2_per_dof, 9, 0.5);
    bool warned = false;
    for (const auto& w : r.warnings)
      warned |= w.find("residuals exceed the noise") != std::string::npos;
    EXPECT_TRUE(warned);
    z2_crb.push_back(WhitenedError(r, sim.truth_theta, r.theta_covariance_crb).z2);
    z2_robust.push_back(WhitenedError(r, sim.truth_theta, r.theta_covariance).z2);
  }
  const MeanSe c = Summarise(z2_crb), z = Summarise(z2_robust);
  std::printf("mean (err/sigma)^2: CRB %.3f +- %.3f, robust %.4f +- %.4f\n", c.mean, c.se, z.mean,
              z.se);
  EXPECT_NEAR(c.mean, 9.0, 3 * c.se);
  EXPECT_NEAR(z.mean, 1.0, 3 * z.se);
}

// Noise correlated in time (AR(1), φ = 0.9 from sample to sample, the configured σ its
// marginal σ): the dynamic samples keep χ²/dof near 1, but the static means' χ² is inflated by
// their variance ratio (≈ (1 + φ)/(1 − φ) = 19): the residual-aware sigma becomes the primary,
// with its warning, and is far closer to the spread than the Cramér-Rao sigma (bench/README.md
// "σ consistency": positions and gyroscope biases z RMS 1.1 against 3.3).
TEST(ArrayFull, CorrelatedNoiseInflatesTheStaticsChiSquareAndMakesTheSandwichPrimary) {
  constexpr int kRuns = sanitizer::kAddressSanitizer ? 3 : 10;
  constexpr double kPhi = 0.9;
  std::vector<double> z2_crb, z2_robust;
  for (int run = 0; run < kRuns; ++run) {
    ArrayFullSimulationOptions so = Board8(300 + run);
    const double sa = so.accel_noise, sg = so.gyro_noise;
    so.accel_noise = so.gyro_noise = 0;
    ArrayFullSimulation sim;
    ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
    GaussianRng rng(400 + run);
    for (Eigen::MatrixXd* x : {&sim.problem.accel, &sim.problem.gyro}) {
      const double sigma = x == &sim.problem.accel ? sa : sg;
      for (Eigen::Index c = 0; c < x->cols(); ++c) {
        double e = sigma * rng.Normal();
        for (Eigen::Index n = 0; n < x->rows(); ++n) {
          if (n > 0) e = kPhi * e + sigma * std::sqrt(1 - kPhi * kPhi) * rng.Normal();
          (*x)(n, c) += e;
        }
      }
    }
    ArrayFullOptions fo = FitOptions(so);
    fo.accel_noise = sa;
    fo.gyro_noise = sg;
    ArrayFullResult r;
    const Status s = CalibrateArrayFull(sim.problem, fo, &r);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_LT(r.chi2_per_dof, 1.5);         // the dynamic samples do not see it
    EXPECT_GT(r.static_chi2_per_dof, 5.0);  // the static means do
    ASSERT_EQ(r.sigma_basis, "sandwich");
    bool warned = false;
    for (const auto& w : r.warnings) warned |= w.find("of the static means") != std::string::npos;
    EXPECT_TRUE(warned);
    z2_crb.push_back(WhitenedError(r, sim.truth_theta, r.theta_covariance_crb).z2);
    z2_robust.push_back(WhitenedError(r, sim.truth_theta, r.theta_covariance).z2);
  }
  const MeanSe c = Summarise(z2_crb), z = Summarise(z2_robust);
  std::printf("mean (err/sigma)^2: CRB %.3f +- %.3f, robust %.4f +- %.4f\n", c.mean, c.se, z.mean,
              z.se);
  EXPECT_GT(c.mean, 4.0);  // the CRB is far too small
  EXPECT_LT(z.mean, 2.0);  // z RMS within 1.4
  EXPECT_GT(z.mean, 0.5);  // and not far too large (0.7²)
}

// When the model fits (simulation), weighting the dynamic samples by their own residual level
// changes nothing material: the level found is the noise, and the estimate moves by far less
// than its σ.
TEST(ArrayFull, ResidualWeightingFindsTheNoiseWhenTheModelFits) {
  ArrayFullSimulationOptions so = Board8(13);
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullOptions fo = FitOptions(so);
  ArrayFullResult a, b;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, fo, &a).ok());
  fo.dynamic_weighting = ArrayFullDynamicWeighting::kResidual;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, fo, &b).ok());
  // The residual level is an estimate from ~800 x 48 residuals: within a few % of the truth.
  EXPECT_NEAR(b.dynamic_accel_noise / so.accel_noise, 1, 0.03);
  EXPECT_NEAR(b.dynamic_gyro_noise / so.gyro_noise, 1, 0.03);
  EXPECT_NEAR(b.chi2_per_dof, 1, 0.05);
  double worst = 0;
  for (int i = 0; i < a.theta.size(); ++i)
    if (a.theta_covariance(i, i) > 0)
      worst =
          std::max(worst, std::abs(a.theta(i) - b.theta(i)) / std::sqrt(a.theta_covariance(i, i)));
  EXPECT_LT(worst, 0.2);
}

// Issue 28 (#22): the statics are listed (SPEC §7), and their residuals are the static means'
// misfit in reading units: at the noise of a mean, σ/√samples, when the model fits (a little below:
// the fit absorbs some of it; the earlier ×√samples figure would sit √samples ≈ 20–40 × higher).
TEST(ArrayFull, ListsTheStaticsWithTheirMeansResidualsAtTheNoiseOfAMean) {
  ArrayFullSimulationOptions so = Board8(13);
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, FitOptions(so), &r).ok()) << r.reason;
  ASSERT_EQ(static_cast<int64_t>(r.static_intervals.size()), r.statics);
  double ratio_a = 0, ratio_g = 0, last_end = -1;
  int64_t samples = 0;
  for (const ArrayFullStatic& st : r.static_intervals) {
    EXPECT_GT(st.start, last_end);
    EXPECT_GT(st.end, st.start);
    last_end = st.end;
    samples += st.samples;
    const double root_n = std::sqrt(static_cast<double>(st.samples));
    ratio_a += std::pow(st.accel_rms / (so.accel_noise / root_n), 2) / r.statics;
    ratio_g += std::pow(st.gyro_rms / (so.gyro_noise / root_n), 2) / r.statics;
  }
  EXPECT_EQ(samples, r.static_samples);
  std::printf("static means' residual / noise of a mean: accelerometers %.2f, gyroscopes %.2f\n",
              std::sqrt(ratio_a), std::sqrt(ratio_g));
  EXPECT_GT(std::sqrt(ratio_a), 0.5);
  EXPECT_LT(std::sqrt(ratio_a), 1.2);
  EXPECT_GT(std::sqrt(ratio_g), 0.5);
  EXPECT_LT(std::sqrt(ratio_g), 1.2);
}

TEST(ArrayFull, EstimateHoldsTheGauges) {
  ArrayFullSimulationOptions so = Board8(7);
  so.reference = 5;
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  ASSERT_TRUE(CalibrateArrayFull(sim.problem, FitOptions(so), &r).ok());
  const ArrayFullTriad& ref = r.triads[5];
  EXPECT_EQ(ref.accel_T(1, 0), 0);
  EXPECT_EQ(ref.accel_T(2, 0), 0);
  EXPECT_EQ(ref.accel_T(2, 1), 0);
  EXPECT_EQ((ref.position - so.nominal_positions.col(5)).norm(), 0);
  double trace = 0;
  for (const auto& t : r.triads) trace += t.gyro_T.trace();
  EXPECT_NEAR(trace, 24, 1e-12);
  EXPECT_EQ(r.report_std[5].position_std.norm(), 0);
  EXPECT_GT(r.report_std[4].position_std.minCoeff(), 0);
  // The other triads' positions moved from the nominal by the simulated perturbation.
  EXPECT_GT((r.triads[0].position - so.nominal_positions.col(0)).norm(), 1e-5);
}

TEST(ArrayFull, RotationAboutTwoAxesOnlyIsNotDeterminableAndNamesTheThird) {
  ArrayFullSimulationOptions so = Board8(9);
  so.omega_axes = Eigen::Vector3d(1, 1, 0);
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  const Status s = CalibrateArrayFull(sim.problem, FitOptions(so), &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("rotation about the body axis (0.00, 0.00, 1.00)"), std::string::npos)
      << s.message();
  EXPECT_EQ(r.rotation_verdict, "insufficient");
  EXPECT_FALSE(r.usable);
}

TEST(ArrayFull, TooFewStaticsIsNotDeterminable) {
  ArrayFullSimulationOptions so = Board8(11);
  so.statics = 6;
  ArrayFullSimulation sim;
  ASSERT_TRUE(SimulateArrayFull(so, &sim).ok());
  ArrayFullResult r;
  const Status s = CalibrateArrayFull(sim.problem, FitOptions(so), &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("at least 9 static orientations"), std::string::npos) << s.message();
  EXPECT_EQ(r.statics, 6);
}

}  // namespace
}  // namespace calibd::core
