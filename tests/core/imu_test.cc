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
  std::cout << (r.accelerometer.matrix - sim.accel_truth.matrix).norm() << " "
            << (r.gyroscope.matrix - sim.gyro_truth.matrix).norm() << " it " << r.accel_iterations
            << " " << r.gyro_iterations << " " << r.joint_iterations << "\n";
}

}  // namespace
}  // namespace calibd::core
