// Tests of the accelerometer's scale curves and bias at t_ref (core/thermal.h stage 2b) on
// simulated logs in several orientations with a known truth: exact recovery without noise,
// Monte-Carlo honesty of the scale bands, the bias curves' bands and the bias at t_ref (with and
// without a scale drift), and the null scale with its reason where the orientations do not
// determine it.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/thermal.h"
#include "core/thermal_simulation.h"

namespace calibd::core {
namespace {

// The orientations held in equal consecutive parts of a warm-up and, with `cool`, an equal
// cool-down back to about the start: with 2 orientations +z warms and −z cools over the same
// temperatures.
ThermalSimulationOptions Faces(uint64_t seed, int orientations, bool scale_drift, bool cool = true,
                               int cycles = 1) {
  ThermalSimulationOptions o;
  o.cycles = cycles;
  o.rate = 10;
  o.warmup = 3600;
  o.cooldown = cool ? 3600 : 0;
  o.cool_delta = 40;
  o.tau = 1200;
  o.orientations = orientations;
  o.seed = seed;
  o.b0.head<3>() << 0.05, -0.03, 0.08;
  if (scale_drift) o.scale_coefficients = DefaultThermalScaleTruth(2);
  return o;
}

Status Calibrate(const ThermalSimulation& sim, const ThermalOptions& options, ThermalResult* out) {
  const std::vector<ThermalImuInput> imus = {{"0", &sim.accel, &sim.gyro, &sim.temp}};
  return CalibrateThermal(sim.t, imus, options, out);
}

// The true bias curve of axis a relative to t_ref, and the gain's relative change
// (1 + d(T)) / (1 + d(t_ref)) − 1 that the fit's d curve estimates.
double TrueBias(const ThermalSimulation& sim, int a, double temp, double t_ref) {
  const Eigen::VectorXd& c = sim.truth.coefficients[static_cast<size_t>(a)];
  return ThermalCurve(c, temp - sim.truth.t_ref) - ThermalCurve(c, t_ref - sim.truth.t_ref);
}
double TrueScale(const ThermalSimulation& sim, int a, double temp, double t_ref) {
  if (sim.truth.scale_coefficients.empty()) return 0;
  const Eigen::VectorXd& d = sim.truth.scale_coefficients[static_cast<size_t>(a)];
  return (1 + ThermalCurve(d, temp - sim.truth.t_ref)) /
             (1 + ThermalCurve(d, t_ref - sim.truth.t_ref)) -
         1;
}
double TrueBiasAtRef(const ThermalSimulation& sim, int a, double t_ref) {
  return sim.truth.b0(a) +
         ThermalCurve(sim.truth.coefficients[static_cast<size_t>(a)], t_ref - sim.truth.t_ref);
}

// The method's options for a log without noise: 1 s windows, statics found by fixed thresholds,
// orders from 0.
ThermalOptions NoiseFreeOptions() {
  ThermalOptions options;
  options.window = 1;
  options.statics.accel_threshold = options.statics.gyro_threshold = 1.0;
  options.min_order = 0;
  return options;
}

TEST(ThermalScaleTest, RecoversBiasAndScaleWithoutNoise) {
  ThermalSimulationOptions o = Faces(1, 2, true);
  o.accel_noise = o.gyro_noise = o.temp_noise = 0;
  const ThermalSimulation sim = SimulateThermal(o);
  const ThermalOptions options = NoiseFreeOptions();
  ThermalResult r;
  const Status st = Calibrate(sim, options, &r);
  ASSERT_TRUE(st.ok()) << st.message();
  const ThermalImuResult& imu = r.imus.at(0);
  ASSERT_EQ(imu.orientations, 2);
  for (int a = 2; a < 3; ++a) {
    const ThermalChannel& ch = imu.channels[static_cast<size_t>(a)];
    ASSERT_TRUE(ch.scale_estimated) << ch.name << ": " << ch.scale_reason;
    ASSERT_TRUE(imu.accel_at_t_ref[static_cast<size_t>(a)]);
    EXPECT_NEAR(*imu.accel_at_t_ref[static_cast<size_t>(a)], TrueBiasAtRef(sim, a, imu.t_ref),
                1e-6);
    const double gain_at_ref =
        1 + ThermalCurve(sim.truth.scale_coefficients[static_cast<size_t>(a)],
                         imu.t_ref - sim.truth.t_ref);
    // x and y undetermined: their biases tilt the faces' directions, S by |b_xy|² / (2 |g|).
    const double bx = TrueBiasAtRef(sim, 0, imu.t_ref), by = TrueBiasAtRef(sim, 1, imu.t_ref);
    const double tilt = (bx * bx + by * by) / (2 * o.gravity);
    EXPECT_NEAR(*imu.accel_gravity[static_cast<size_t>(a)], o.gravity * gain_at_ref + tilt, 1e-6);
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      // Window means of curved truths: ~1e-8 with 1 s windows (as in thermal_test).
      EXPECT_NEAR(ch.grid_value(i), TrueBias(sim, a, imu.grid(i), imu.t_ref), 1e-6)
          << ch.name << " at " << imu.grid(i);
      EXPECT_NEAR(ch.grid_scale_value(i), TrueScale(sim, a, imu.grid(i), imu.t_ref), 1e-7)
          << ch.name << " at " << imu.grid(i);
    }
  }
}

// The same without noise for a six-face tumble (+z −z +x −x +y −y, 4 times through the warm-up
// and cool-down): every axis's bias at t_ref, bias curve and scale curve exactly.
TEST(ThermalScaleTest, ASixFaceTumbleRecoversEveryAxisWithoutNoise) {
  ThermalSimulationOptions o = Faces(2, 6, true, true, 4);
  o.accel_noise = o.gyro_noise = o.temp_noise = 0;
  const ThermalSimulation sim = SimulateThermal(o);
  const ThermalOptions options = NoiseFreeOptions();
  ThermalResult r;
  const Status st = Calibrate(sim, options, &r);
  ASSERT_TRUE(st.ok()) << st.message();
  const ThermalImuResult& imu = r.imus.at(0);
  ASSERT_EQ(imu.orientations, 6);
  for (int a = 0; a < 3; ++a) {
    const ThermalChannel& ch = imu.channels[static_cast<size_t>(a)];
    ASSERT_TRUE(ch.scale_estimated) << ch.name << ": " << ch.scale_reason;
    ASSERT_TRUE(imu.accel_at_t_ref[static_cast<size_t>(a)]) << ch.name;
    EXPECT_NEAR(*imu.accel_at_t_ref[static_cast<size_t>(a)], TrueBiasAtRef(sim, a, imu.t_ref), 1e-6)
        << ch.name;
    for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
      EXPECT_NEAR(ch.grid_value(i), TrueBias(sim, a, imu.grid(i), imu.t_ref), 1e-6)
          << ch.name << " at " << imu.grid(i);
      EXPECT_NEAR(ch.grid_scale_value(i), TrueScale(sim, a, imu.grid(i), imu.t_ref), 1e-7)
          << ch.name << " at " << imu.grid(i);
    }
  }
}

// z RMS over `trials` seeds of the bias curves, the scale curves (grid, t_ref excluded) and the
// bias at t_ref, per accelerometer axis (the scale over the temperatures its faces cover).
struct Honesty {
  double bias[3] = {0}, scale[3] = {0}, at_t_ref[3] = {0};
};

// The protocol of a Monte-Carlo: faces (Faces' orientations), how often the sequence is held,
// and the axes it determines. The default: +z through the warm-up, −z through the cool-down, so
// z is determined (x, y not: no such faces).
struct Protocol {
  int faces = 2, cycles = 1;
  int first_axis = 2;
};

Honesty MonteCarlo(int trials, bool scale_drift, Protocol protocol = {}) {
  double sb[3] = {0}, ss[3] = {0}, sa[3] = {0};
  int nb[3] = {0}, na[3] = {0}, ns[3] = {0};
  for (int trial = 0; trial < trials; ++trial) {
    const ThermalSimulation sim = SimulateThermal(Faces(
        500 + static_cast<uint64_t>(trial), protocol.faces, scale_drift, true, protocol.cycles));
    ThermalOptions options;
    options.grid_points = 11;
    ThermalResult r;
    const Status st = Calibrate(sim, options, &r);
    EXPECT_TRUE(st.ok()) << st.message();
    if (!st.ok()) continue;
    const ThermalImuResult& imu = r.imus[0];
    for (int a = protocol.first_axis; a < 3; ++a) {
      const ThermalChannel& ch = imu.channels[static_cast<size_t>(a)];
      EXPECT_TRUE(ch.scale_estimated) << ch.scale_reason;
      if (!imu.accel_at_t_ref[static_cast<size_t>(a)]) continue;
      const double za =
          (*imu.accel_at_t_ref[static_cast<size_t>(a)] - TrueBiasAtRef(sim, a, imu.t_ref)) /
          *imu.accel_at_t_ref_std[static_cast<size_t>(a)];
      sa[a] += za * za;
      ++na[a];
      if (!ch.scale_estimated) continue;
      // The scale curve is seen only where faces near ±a were held (the simulator holds each
      // face over a part of the warm-up); its band outside widens as the polynomials
      // extrapolate (conservative), so its honesty is judged over the faces' temperatures.
      double lo = 1e9, hi = -1e9;
      for (const ThermalWindow& w : imu.windows) {
        if (std::abs(w.mean(a)) > 0.5 * sim.truth.gravity)
          lo = std::min(lo, w.temperature), hi = std::max(hi, w.temperature);
      }
      for (Eigen::Index i = 0; i < imu.grid.size(); ++i) {
        if (std::abs(imu.grid(i) - imu.t_ref) < 1e-6) continue;
        const bool seen = imu.grid(i) >= lo && imu.grid(i) <= hi;
        const double zb =
            (ch.grid_value(i) - TrueBias(sim, a, imu.grid(i), imu.t_ref)) / ch.grid_std(i);
        const double zs = (ch.grid_scale_value(i) - TrueScale(sim, a, imu.grid(i), imu.t_ref)) /
                          ch.grid_scale_std(i);
        sb[a] += zb * zb;
        ++nb[a];
        if (seen) ss[a] += zs * zs, ++ns[a];
      }
    }
  }
  Honesty h;
  for (int a = 0; a < 3; ++a) {
    h.bias[a] = std::sqrt(sb[a] / std::max(1, nb[a]));
    h.scale[a] = std::sqrt(ss[a] / std::max(1, ns[a]));
    h.at_t_ref[a] = std::sqrt(sa[a] / std::max(1, na[a]));
  }
  return h;
}

// 60 trials: a z RMS from 60 independent trials has a relative σ of ~1/√120 = 9 % (the grid
// points of a trial are correlated, so not less; the bias at t_ref is one value per trial);
// 0.7–1.4 is > 3σ from 1 on both sides, while a band too narrow or wide by 1.5× fails.
void ExpectHonest(const Honesty& h, int first_axis = 2) {
  for (int a = first_axis; a < 3; ++a) {
    EXPECT_GT(h.bias[a], 0.7) << "axis " << a;
    EXPECT_LT(h.bias[a], 1.4) << "axis " << a;
    EXPECT_GT(h.scale[a], 0.7) << "axis " << a;
    EXPECT_LT(h.scale[a], 1.4) << "axis " << a;
    EXPECT_GT(h.at_t_ref[a], 0.7) << "axis " << a;
    EXPECT_LT(h.at_t_ref[a], 1.4) << "axis " << a;
  }
}

TEST(ThermalScaleTest, BandsAreHonestInMonteCarlo) {
  const Honesty h = MonteCarlo(60, true);
  for (int a = 2; a < 3; ++a) {
    std::printf("axis %d: z RMS bias %.3f scale %.3f at_t_ref %.3f\n", a, h.bias[a], h.scale[a],
                h.at_t_ref[a]);
  }
  ExpectHonest(h);
}

// No scale drift: the bias curves stay within their bands (the scale columns cost variance, not
// bias) and the scale curves' bands cover zero.
TEST(ThermalScaleTest, BiasCurvesUnchangedWithoutScaleDrift) {
  const Honesty h = MonteCarlo(60, false);
  for (int a = 2; a < 3; ++a) {
    std::printf("axis %d: z RMS bias %.3f scale %.3f at_t_ref %.3f\n", a, h.bias[a], h.scale[a],
                h.at_t_ref[a]);
  }
  ExpectHonest(h);
}

// A six-face tumble repeated through the warm-up and the cool-down (+z −z +x −x +y −y, 4 times:
// 24 holds of 300 s): every face is seen across the range, so all three axes' scale curves and
// biases at t_ref are determined, and honest (same margins as above, 40 trials: relative σ of a
// z RMS ~1/√80 = 11 %, 0.7–1.4 still > 2.7σ from 1).
TEST(ThermalScaleTest, ASixFaceTumbleDeterminesEveryAxisHonestly) {
  const Honesty h = MonteCarlo(40, true, {6, 4, 0});
  for (int a = 0; a < 3; ++a) {
    std::printf("axis %d: z RMS bias %.3f scale %.3f at_t_ref %.3f\n", a, h.bias[a], h.scale[a],
                h.at_t_ref[a]);
  }
  ExpectHonest(h, 0);
}

TEST(ThermalScaleTest, OneOrientationLeavesTheScaleNullWithItsReason) {
  const ThermalSimulation sim = SimulateThermal(Faces(3, 1, true));
  ThermalResult r;
  ASSERT_TRUE(Calibrate(sim, ThermalOptions(), &r).ok());
  for (int a = 0; a < 3; ++a) {
    const ThermalChannel& ch = r.imus[0].channels[static_cast<size_t>(a)];
    EXPECT_FALSE(ch.scale_estimated);
    EXPECT_EQ(ch.fit.scale_coefficients.size(), 0);
    EXPECT_NE(ch.scale_reason.find("one orientation"), std::string::npos) << ch.scale_reason;
    EXPECT_FALSE(r.imus[0].accel_at_t_ref[static_cast<size_t>(a)]);
  }
}

// +z and −z: only z is determined; x and y say by how little their directions differ.
TEST(ThermalScaleTest, OppositeFacesDetermineOnlyTheirAxis) {
  const ThermalSimulation sim = SimulateThermal(Faces(4, 2, true));
  ThermalResult r;
  ASSERT_TRUE(Calibrate(sim, ThermalOptions(), &r).ok());
  const ThermalImuResult& imu = r.imus[0];
  for (int a = 0; a < 2; ++a) {
    const ThermalChannel& ch = imu.channels[static_cast<size_t>(a)];
    EXPECT_FALSE(ch.scale_estimated);
    EXPECT_NE(ch.scale_reason.find("below scale_min_spread"), std::string::npos) << ch.scale_reason;
    EXPECT_FALSE(imu.accel_at_t_ref[static_cast<size_t>(a)]);
  }
  EXPECT_TRUE(imu.channels[2].scale_estimated) << imu.channels[2].scale_reason;
  ASSERT_TRUE(imu.accel_at_t_ref[2]);
  EXPECT_NEAR(*imu.accel_at_t_ref[2], TrueBiasAtRef(sim, 2, imu.t_ref),
              5 * *imu.accel_at_t_ref_std[2]);
  bool warned = false;
  for (const std::string& w : r.warnings) warned |= w.find("accelerometer.x") != std::string::npos;
  EXPECT_TRUE(warned);
}

// Opposite faces held at different temperatures (+z the first half of a warm-up, −z the second):
// the curves would rest on extrapolation, so the scale and the bias at t_ref stay null and say so.
TEST(ThermalScaleTest, FacesAtDifferentTemperaturesLeaveTheScaleNull) {
  const ThermalSimulation sim = SimulateThermal(Faces(5, 2, true, false));
  ThermalResult r;
  ASSERT_TRUE(Calibrate(sim, ThermalOptions(), &r).ok());
  const ThermalChannel& ch = r.imus[0].channels[2];
  EXPECT_FALSE(ch.scale_estimated);
  EXPECT_NE(ch.scale_reason.find("share less than min_range"), std::string::npos)
      << ch.scale_reason;
  EXPECT_FALSE(r.imus[0].accel_at_t_ref[2]);
}

TEST(ThermalScaleTest, ValidatesScaleMinSpread) {
  ThermalOptions options;
  options.scale_min_spread = 0;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("scale_min_spread"), std::string::npos);
}

}  // namespace
}  // namespace calibd::core
