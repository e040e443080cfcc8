// Tests of the `imu` method (core/imu.h): exact recovery, error laws, honest uncertainty,
// Jacobians of the rotation integrator, failures.
#include "core/imu.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "core/imu_simulation.h"
#include "tests/lib/monte_carlo.h"

namespace calibd::core {
namespace {

using Eigen::Matrix3d;
using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;

ImuOptions OptionsFor(const ImuSimulationOptions& s) {
  ImuOptions o;
  o.accel_unit = s.accel_unit;
  o.gyro_unit = s.gyro_unit;
  o.gravity = s.gravity;
  return o;
}

TEST(ImuCalibration, RecoversParametersExactlyWithoutNoise) {
  ImuSimulationOptions so;
  so.statics = 14;
  so.accel_noise = 0;
  so.gyro_noise = 0;
  so.scale_error = 0.02;
  so.misalignment = 0.01;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuResult r;
  Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, OptionsFor(so), &r);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_TRUE(r.usable);
  EXPECT_EQ(r.statics.size(), 14u);
  EXPECT_LT((r.accelerometer.matrix - sim.accel_truth.matrix).norm(), 1e-9);
  EXPECT_LT((r.accelerometer.bias - sim.accel_truth.bias).norm(), 1e-9);
  EXPECT_LT((r.gyroscope.matrix - sim.gyro_truth.matrix).norm(), 1e-6);
  EXPECT_LT((r.gyroscope.bias - sim.gyro_truth.bias).norm(), 1e-9);
}

// The 21 reported parameters in the order of ImuResult::covariance.
VectorXd Reported(const TriadCalibration& a, const TriadCalibration& g) {
  VectorXd v(21);
  v << a.bias, a.scale, a.misalignment(0, 1), a.misalignment(0, 2), a.misalignment(1, 2), g.bias,
      g.scale, g.misalignment(0, 1), g.misalignment(0, 2), g.misalignment(1, 0),
      g.misalignment(1, 2), g.misalignment(2, 0), g.misalignment(2, 1);
  return v;
}
VectorXd ReportedStd(const TriadCalibration& a, const TriadCalibration& g) {
  VectorXd v(21);
  v << a.bias_std, a.scale_std, a.misalignment_std(0, 1), a.misalignment_std(0, 2),
      a.misalignment_std(1, 2), g.bias_std, g.scale_std, g.misalignment_std(0, 1),
      g.misalignment_std(0, 2), g.misalignment_std(1, 0), g.misalignment_std(1, 2),
      g.misalignment_std(2, 0), g.misalignment_std(2, 1);
  return v;
}
VectorXd Truth(const ImuSimulation& sim) {
  TriadCalibration a, g;
  a.bias = sim.accel_truth.bias;
  a.scale = sim.accel_truth.scale;
  a.misalignment = sim.accel_truth.misalignment;
  g.bias = sim.gyro_truth.bias;
  g.scale = sim.gyro_truth.scale;
  g.misalignment = sim.gyro_truth.misalignment;
  return Reported(a, g);
}

// A short log (about 50 s at 50 Hz): one board and one motion, the noise varies with noise_seed.
ImuSimulationOptions ShortLog(double noise_factor, uint64_t noise_seed) {
  ImuSimulationOptions so;
  so.statics = 12;
  so.static_duration = 3;
  so.rotation_duration = 1.5;
  so.rate = 50;
  so.accel_noise = 0.01 * noise_factor;
  so.gyro_noise = 0.002 * noise_factor;
  so.seed = 7;
  so.noise_seed = noise_seed;
  return so;
}

struct MonteCarlo {
  MatrixXd errors;    // trials × 21
  VectorXd mean_std;  // 21, mean reported σ
};
MonteCarlo RunMonteCarlo(double noise_factor, int trials, GyroBiasModel bias_model) {
  MonteCarlo mc;
  mc.errors.resize(trials, 21);
  mc.mean_std.setZero(21);
  for (int k = 0; k < trials; ++k) {
    const ImuSimulationOptions so = ShortLog(noise_factor, 1000 + k);
    ImuSimulation sim;
    EXPECT_TRUE(SimulateImu(so, &sim).ok());
    ImuOptions o = OptionsFor(so);
    o.threshold_multipliers.clear();  // one detection per trial: the statics are clear here
    o.gyro_bias = bias_model;
    o.recommended_statics = 9;
    ImuResult r;
    const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
    EXPECT_TRUE(s.ok()) << s.message();
    EXPECT_EQ(r.statics.size(), 12u);
    mc.errors.row(k) = (Reported(r.accelerometer, r.gyroscope) - Truth(sim)).transpose();
    mc.mean_std += ReportedStd(r.accelerometer, r.gyroscope) / trials;
  }
  return mc;
}

const char* kNames[21] = {"b_ax",  "b_ay",  "b_az",  "K_ax",  "K_ay",  "K_az",  "T_a01",
                          "T_a02", "T_a12", "b_gx",  "b_gy",  "b_gz",  "K_gx",  "K_gy",
                          "K_gz",  "T_g01", "T_g02", "T_g10", "T_g12", "T_g20", "T_g21"};

// 400 trials: the Monte-Carlo σ (a sample std) has the relative standard error
// √(1 / (2 (T − 1))) = 3.5 % (tests/lib/monte_carlo.h); 21 parameters in each of two tests, so
// ±4 standard errors, 14 % (was a fixed ±15 %). The mean error must be within 4.5 standard errors
// (σ / √T) of zero.
void ExpectHonestUncertainty(GyroBiasModel model) {
  const int trials = 400;
  const MonteCarlo mc = RunMonteCarlo(1.0, trials, model);
  for (int p = 0; p < 21; ++p) {
    const VectorXd e = mc.errors.col(p);
    const double mean = e.mean();
    const double sd = std::sqrt((e.array() - mean).square().sum() / (trials - 1));
    EXPECT_NEAR(mc.mean_std(p) / sd, 1.0, 4 * monte_carlo::StdRatioStandardError(trials - 1))
        << kNames[p] << ": reported " << mc.mean_std(p) << ", Monte Carlo " << sd;
    EXPECT_LT(std::abs(mean), 4.5 * sd / std::sqrt(trials)) << kNames[p] << " biased";
  }
}

TEST(ImuCalibration, ReportedSigmaMatchesMonteCarloSpread) {
  ExpectHonestUncertainty(GyroBiasModel::kStatics);
}

TEST(ImuCalibration, ReportedSigmaMatchesMonteCarloSpreadWithGyroBiasEstimated) {
  ExpectHonestUncertainty(GyroBiasModel::kEstimate);
}

// Error ∝ σ: 4 × the noise gives 4 × the error. RMS over 60 trials and the 21 parameters, each
// normalised by its Monte-Carlo-free scale (the reported σ at the low level). The 21 normalised
// errors of a trial are correlated: from their second-moment matrix C over the trials a trial is
// worth d_eff = (tr C)² / tr(C²) independent errors (tests/lib/monte_carlo.h; the sample C makes
// d_eff, and so the bound, a little conservative), so each RMS has the relative standard error
// √(1 / (2 T d_eff)) and the ratio the root sum of squares of the two. ±3 standard errors (were
// fixed: ±0.6 on the ratio, ±0.2 on the RMS of the low level).
TEST(ImuCalibration, ErrorIsProportionalToNoise) {
  const int trials = 60;
  const MonteCarlo lo = RunMonteCarlo(1.0, trials, GyroBiasModel::kStatics);
  const MonteCarlo hi = RunMonteCarlo(4.0, trials, GyroBiasModel::kStatics);
  const VectorXd scale = lo.mean_std.cwiseInverse();
  const Eigen::MatrixXd z_lo = lo.errors * scale.asDiagonal();
  const Eigen::MatrixXd z_hi = hi.errors * scale.asDiagonal();
  const double rms_lo = std::sqrt(z_lo.array().square().mean());
  const double rms_hi = std::sqrt(z_hi.array().square().mean());
  const double d_lo = monte_carlo::EffectiveDimension(z_lo.transpose() * z_lo / trials);
  const double d_hi = monte_carlo::EffectiveDimension(z_hi.transpose() * z_hi / trials);
  const double se_lo = monte_carlo::StdRatioStandardError(trials * d_lo);
  const double se_hi = monte_carlo::StdRatioStandardError(trials * d_hi);
  const double ratio = rms_hi / rms_lo;
  std::printf(
      "RMS of normalised errors: sigma x1 %.3f (d_eff %.1f, SE %.3f), x4 %.3f (d_eff %.1f),"
      " ratio %.3f (SE %.3f)\n",
      rms_lo, d_lo, se_lo, rms_hi, d_hi, ratio, ratio * std::hypot(se_lo, se_hi));
  EXPECT_NEAR(ratio, 4.0, 3 * 4.0 * std::hypot(se_lo, se_hi)) << rms_lo << " " << rms_hi;
  EXPECT_NEAR(rms_lo, 1.0, 3 * se_lo);  // and the reported σ is the error's scale
  EXPECT_NEAR(hi.mean_std.cwiseQuotient(lo.mean_std).mean(), 4.0, 0.2);
}

TEST(ImuCalibration, HandlesCountsAMovingStartAndBiasDrift) {
  ImuSimulationOptions so;
  so.statics = 16;
  so.initial_motion = 3;
  so.accel_unit = 8 * 9.80665 / 32768;
  so.gyro_unit = 1.0 / 6258;
  so.accel_offset = so.gyro_offset = 32768;
  so.quantize = true;
  so.gyro_bias_drift = 1e-5;  // rad/s per s
  so.seed = 11;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuOptions o = OptionsFor(so);
  o.nominal_accel_bias = o.nominal_gyro_bias = 32768;
  ImuResult r;
  const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.statics.size(), 16u);
  EXPECT_FALSE(r.threshold_trials.empty());
  EXPECT_NE(r.threshold_choice.find("chosen among 5"), std::string::npos);
  int chosen = 0;
  for (const ImuThresholdTrial& tr : r.threshold_trials) chosen += tr.chosen;
  EXPECT_EQ(chosen, 1);
  const VectorXd err = Reported(r.accelerometer, r.gyroscope) - Truth(sim);
  const VectorXd sd = ReportedStd(r.accelerometer, r.gyroscope);
  for (int p = 0; p < 21; ++p) {
    if (p >= 9 && p < 12) continue;  // the gyroscope bias drifts: checked below
    EXPECT_LT(std::abs(err(p)), 5 * sd(p)) << kNames[p];
  }
  // The mean over the statics is the bias at the log's middle time (drift is linear).
  const Vector3d mid_bias = sim.gyro_truth.bias + sim.gyro_truth.bias_drift * sim.t.mean();
  EXPECT_LT((r.gyroscope.bias - mid_bias).norm(), 1.0);  // counts
  EXPECT_LT(r.accel_norm_rms_after, 0.05 * r.accel_norm_rms_before);
  EXPECT_LT(r.gyro_direction_rms_after, 0.1 * r.gyro_direction_rms_before);
}

TEST(ImuCalibration, TooFewStaticsSaysHowManyAndWhichOrientations) {
  ImuSimulationOptions so;
  so.statics = 6;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuResult r;
  const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, OptionsFor(so), &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_FALSE(r.usable);
  EXPECT_EQ(r.termination, ImuTermination::kTooFewStatics);
  EXPECT_NE(s.message().find("found 6 static intervals, at least 9 are needed"), std::string::npos)
      << s.message();
  EXPECT_TRUE(s.message().find("axis up") != std::string::npos ||
              s.message().find("more orientations") != std::string::npos)
      << s.message();
  EXPECT_NE(r.BriefReport().find("not usable: " + r.reason + "; termination too_few_statics"),
            std::string::npos)
      << r.BriefReport();
}

// Rotations so fast that the gyroscope saturates (here: a range limit below the rotation rates)
// leave the accelerometer determined by the statics but the gyroscope by nothing: the run fails
// with too_few_rotations, names the count and keeps the statics found and the rotations it
// excluded, with why.
TEST(ImuCalibration, SaturatedRotationsFailWithTooFewRotationsAndSayWhy) {
  ImuSimulationOptions so;
  so.statics = 12;
  so.seed = 21;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuOptions o = OptionsFor(so);
  // rad/s: above every static reading (bias and noise), below the peak rate of the rotations
  // (about 90 degrees in 2 s each); the 12 statics found below show the first half.
  o.gyro_saturation_high = 0.2;
  o.gyro_saturation_low = -0.2;
  ImuResult r;
  const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_EQ(s.reason(), core::imu_reason::kTooFewRotations);
  EXPECT_EQ(r.termination, ImuTermination::kTooFewRotations);
  EXPECT_FALSE(r.usable);
  EXPECT_NE(s.message().find("at least 5 rotations"), std::string::npos) << s.message();
  EXPECT_EQ(r.detection.intervals.size(), 12u);  // what the timeline of the failed job shows
  ASSERT_EQ(r.rotations.size(), 11u);
  int excluded = 0;
  for (const ImuRotationDiagnostics& rd : r.rotations) {
    if (!rd.used) {
      ++excluded;
      EXPECT_EQ(rd.excluded, "saturated gyroscope samples");
    }
  }
  EXPECT_GE(excluded, 7);
}

TEST(ImuCalibration, BriefReportSaysUsableTerminationAndStaticsInOneLine) {
  ImuSimulationOptions so;
  so.statics = 14;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuResult r;
  ASSERT_TRUE(CalibrateImu(sim.t, sim.accel, sim.gyro, OptionsFor(so), &r).ok());
  const std::string brief = r.BriefReport();
  EXPECT_EQ(brief.find('\n'), std::string::npos) << brief;
  EXPECT_NE(brief.find(": usable; termination converged, 14 statics"), std::string::npos) << brief;
}

TEST(ImuCalibration, CoverageNamesTheMissingOrientations) {
  // Statics only with +z roughly up (a board tilted on a table): the accelerometer cannot be
  // determined and the message asks for the other faces.
  ImuSimulationOptions so;
  so.statics = 12;
  so.accel_noise = so.gyro_noise = 0;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  // Tilt every static reading toward +z up: replace accelerometer readings of each static by
  // those of an orientation within 30° of level.
  ImuOptions o = OptionsFor(so);
  for (size_t j = 0; j < sim.statics.size(); ++j) {
    const Vector3d tilt = Vector3d(std::cos(j), std::sin(j), 0) * 0.5;
    const Vector3d up = (Vector3d::UnitZ() + tilt).normalized() * so.gravity;
    const Vector3d y = sim.accel_truth.matrix.inverse() * up + sim.accel_truth.bias;
    for (int64_t i = sim.statics[j].first; i <= sim.statics[j].second; ++i) {
      sim.accel.row(i) = y.transpose();
    }
  }
  ImuResult r;
  const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_FALSE(r.usable);
  EXPECT_NE(s.message().find("-z"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("+x"), std::string::npos) << s.message();
}

TEST(ImuCalibration, WrongUnitIsImplausible) {
  ImuSimulationOptions so;
  so.statics = 12;
  so.gyro_unit = 3.14159265358979 / 180;  // deg/s readings
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuOptions o = OptionsFor(so);
  o.gyro_unit = 1;  // the user forgot gyro_unit
  ImuResult r;
  const Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_EQ(r.termination, ImuTermination::kImplausible);
  EXPECT_NE(s.message().find("gyro_unit"), std::string::npos) << s.message();
}

TEST(ImuCalibration, RejectsBadInputNamingIt) {
  ImuSimulationOptions so;
  so.statics = 10;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ImuResult r;
  ImuOptions o;
  o.gravity = -1;
  Status s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("gravity"), std::string::npos) << s.message();
  EXPECT_EQ(r.termination, ImuTermination::kInvalidInput);
  o = ImuOptions();
  o.min_statics = 5;
  s = CalibrateImu(sim.t, sim.accel, sim.gyro, o, &r);
  EXPECT_NE(s.message().find("min_statics"), std::string::npos) << s.message();
  const Eigen::MatrixX3d short_gyro = sim.gyro.topRows(5);
  s = CalibrateImu(sim.t, sim.accel, short_gyro, ImuOptions(), &r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("g0 has 5 samples"), std::string::npos) << s.message();
}

TEST(ImuCalibration, IntegratorIsExactForAFixedAxisAtLinearRate) {
  // ω(t) = a (c0 + c1 t): the trapezoid rate is exact per step, so R = Exp(a ∫ω).
  const int n = 201;
  Eigen::VectorXd t(n);
  Eigen::MatrixX3d y(n, 3);
  const Vector3d axis = Vector3d(1, -2, 0.5).normalized();
  for (int i = 0; i < n; ++i) {
    t(i) = 0.01 * i + 1e-4 * (i % 3);  // irregular sampling
    y.row(i) = (axis * (0.3 + 2.0 * t(i))).transpose();
  }
  const double angle = 0.3 * (t(n - 1) - t(0)) + (t(n - 1) * t(n - 1) - t(0) * t(0));
  const Matrix3d r = IntegrateRotation(t, y, Matrix3d::Identity(), Vector3d::Zero(), 0, n - 1);
  const Matrix3d expected = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  EXPECT_LT((r - expected).norm(), 1e-12);
}

TEST(Wgs84NormalGravity, MatchesTheFormulaAtKnownPoints) {
  EXPECT_NEAR(Wgs84NormalGravity(0, 0), 9.7803253359, 1e-9);
  EXPECT_NEAR(Wgs84NormalGravity(90, 0), 9.8321849378, 1e-9);
  EXPECT_NEAR(Wgs84NormalGravity(45, 0), 9.80619776937, 1e-10);  // Somigliana at sin²φ = ½
  EXPECT_NEAR(Wgs84NormalGravity(45, 1000) - Wgs84NormalGravity(45, 0), -3.086e-3, 2e-5);
}

}  // namespace
}  // namespace calibd::core
