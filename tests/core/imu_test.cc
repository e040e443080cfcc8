// Tests of the `imu` method (core/imu.h): exact recovery, error laws, honest uncertainty,
// Jacobians of the rotation integrator, failures.
#include "core/imu.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "core/imu_simulation.h"

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
MonteCarlo Run(double noise_factor, int trials, GyroBiasModel bias_model) {
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

// 400 trials: the Monte-Carlo σ has a relative standard error of 1/√800 = 3.5 %, so 15 % is
// more than 4 standard errors; the mean error must be within 4.5 standard errors of zero.
void ExpectHonestUncertainty(GyroBiasModel model) {
  const int trials = 400;
  const MonteCarlo mc = Run(1.0, trials, model);
  for (int p = 0; p < 21; ++p) {
    const VectorXd e = mc.errors.col(p);
    const double mean = e.mean();
    const double sd = std::sqrt((e.array() - mean).square().sum() / (trials - 1));
    EXPECT_NEAR(mc.mean_std(p) / sd, 1.0, 0.15)
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

}  // namespace
}  // namespace calibd::core
