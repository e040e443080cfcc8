// Tests of the simulated thermal logs (core/thermal_simulation.h): the accelerometers' scale drift
// multiplies the reading's gravity part by 1 + Σ d_k (T − t_ref)^k and leaves the bias alone; no
// drift by default.
#include "core/thermal_simulation.h"

#include <gtest/gtest.h>

#include "core/thermal.h"

namespace calibd::core {
namespace {

ThermalSimulationOptions NoiseFree(int orientations) {
  ThermalSimulationOptions o;
  o.rate = 5;
  o.warmup = 1200;
  o.orientations = orientations;
  o.accel_noise = o.gyro_noise = o.temp_noise = 0;
  o.b0.head<3>() << 0.05, -0.03, 0.08;
  return o;
}

// The reading of accelerometer axis a at sample i as the truth defines it.
double Expected(const ThermalSimulation& sim, int a, Eigen::Index i, double gravity_component) {
  const double x = sim.temp(i) - sim.truth.t_ref;
  const double gain =
      sim.truth.scale_coefficients.empty()
          ? 1.0
          : 1 + ThermalCurve(sim.truth.scale_coefficients[static_cast<size_t>(a)], x);
  return sim.truth.b0(a) + ThermalCurve(sim.truth.coefficients[static_cast<size_t>(a)], x) +
         gravity_component * gain;
}

TEST(ThermalSimulationTest, ScaleDriftMultipliesTheGravityPart) {
  ThermalSimulationOptions o = NoiseFree(2);  // +z for the first half, then −z
  o.scale_coefficients = DefaultThermalScaleTruth(2);
  const ThermalSimulation sim = SimulateThermal(o);
  const Eigen::Index n = sim.t.size();
  for (Eigen::Index i = 0; i < n; i += 97) {
    const double gz = i * 2 < n ? o.gravity : -o.gravity;
    EXPECT_NEAR(sim.accel(i, 2), Expected(sim, 2, i, gz), 1e-12) << "sample " << i;
    EXPECT_NEAR(sim.accel(i, 0), Expected(sim, 0, i, 0.0), 1e-12) << "sample " << i;
  }
  // The drift is visible: at the log's warmest the z gain differs from 1 by more than 1e-4.
  const double x = sim.temp(n - 1) - o.t_ref;
  EXPECT_GT(std::abs(ThermalCurve(sim.truth.scale_coefficients[2], x)), 1e-4);
}

TEST(ThermalSimulationTest, NoScaleDriftByDefault) {
  const ThermalSimulation sim = SimulateThermal(NoiseFree(1));
  EXPECT_TRUE(sim.truth.scale_coefficients.empty());
  for (Eigen::Index i = 0; i < sim.t.size(); i += 101)
    EXPECT_NEAR(sim.accel(i, 2), Expected(sim, 2, i, sim.truth.gravity), 1e-12);
}

TEST(ThermalSimulationTest, DefaultScaleTruthHasTheOrderAsked) {
  for (int order = 1; order <= 5; ++order) {
    const std::vector<Eigen::VectorXd> d = DefaultThermalScaleTruth(order);
    ASSERT_EQ(d.size(), 3u);
    for (const Eigen::VectorXd& v : d) {
      EXPECT_EQ(v.size(), order);
      EXPECT_GE(std::abs(v(0)), 1e-4);
    }
  }
}

}  // namespace
}  // namespace calibd::core
