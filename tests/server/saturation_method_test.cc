// Saturation found in the data through the method adapters (issue #20): a clipped imu log, array
// log (model positions) and noise log carry the warning and diagnostics.saturation in their
// result JSON (dropped from the fit; the noise log refused), a clean log neither, and a
// configured limit overrides what the data say. The full model on real clipped recordings:
// tests/server/array_full_mimu4444_test.cc.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "core/array_simulation.h"
#include "core/imu_simulation.h"
#include "core/noise.h"
#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "server/config.h"

namespace calibd::server {
namespace {

using nlohmann::json;

bool Warned(const json& result, const std::string& part) {
  for (const json& w : result.value("warnings", json::array())) {
    if (w.get<std::string>().find(part) != std::string::npos) return true;
  }
  return false;
}

// An imu log as CSV, the gyroscope clipped to [-limit, limit] (limit <= 0: not clipped); the
// clipped samples per channel and side in high[3], low[3].
std::string ImuCsv(const core::ImuSimulation& sim, double limit, int64_t high[3], int64_t low[3]) {
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (int a = 0; a < 3; ++a) high[a] = low[a] = 0;
  for (Eigen::Index i = 0; i < sim.t.size(); ++i) {
    double g[3];
    for (int a = 0; a < 3; ++a) {
      g[a] = sim.gyro(i, a);
      if (limit > 0 && g[a] >= limit) g[a] = limit, ++high[a];
      if (limit > 0 && g[a] <= -limit) g[a] = -limit, ++low[a];
    }
    std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n", sim.t[i],
                  sim.accel(i, 0), sim.accel(i, 1), sim.accel(i, 2), g[0], g[1], g[2]);
    csv += line;
  }
  return csv;
}

core::ImuSimulationOptions ImuLog() {
  core::ImuSimulationOptions o;
  o.statics = 24;
  o.rotation_duration = 1;
  o.seed = 11;
  return o;
}

TEST(SaturationMethod, ImuFindsDropsAndReportsClippedGyroscopeSamples) {
  const core::ImuSimulationOptions o = ImuLog();
  core::ImuSimulation sim;
  ASSERT_TRUE(core::SimulateImu(o, &sim).ok());
  std::string unused;
  json config, truth;
  ASSERT_TRUE(SimulateImuFiles(o, &unused, &config, &truth).ok());
  // Clipped at 0.7 of the largest rate: the fastest rotations' peaks are pinned.
  const double limit = 0.7 * sim.gyro.cwiseAbs().maxCoeff();
  int64_t high[3], low[3];
  const std::string csv = ImuCsv(sim, limit, high, low);
  json result;
  Status s = Calibrate(csv, "imu.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.message();
  const json& d = result.at("diagnostics");
  ASSERT_TRUE(d.contains("saturation")) << result.at("warnings").dump();
  const json& sat = d.at("saturation");
  EXPECT_EQ(sat.at("policy"), "dropped");
  int64_t clipped = 0;
  for (int a = 0; a < 3; ++a) clipped += high[a] + low[a];
  ASSERT_GT(clipped, 20);
  // Every channel clipped in runs is listed with its exact count; the listed ones only.
  int64_t listed = 0;
  for (const json& c : sat.at("channels")) {
    const std::string name = c.at("name");
    ASSERT_EQ(name.rfind("g0_", 0), 0u) << name;
    const int a = name[3] - 'x';
    EXPECT_EQ(c.at("source"), "data");
    EXPECT_EQ(c.at("unit"), "reading units");
    if (c.at("pinned_high").get<int64_t>() > 0) {
      EXPECT_NEAR(c.at("high").get<double>(), limit, 1e-9 * limit);
      EXPECT_EQ(c.at("pinned_high").get<int64_t>(), high[a]) << name;
    }
    if (c.at("pinned_low").get<int64_t>() > 0) {
      EXPECT_NEAR(c.at("low").get<double>(), -limit, 1e-9 * limit);
      EXPECT_EQ(c.at("pinned_low").get<int64_t>(), low[a]) << name;
    }
    listed += c.at("pinned_low").get<int64_t>() + c.at("pinned_high").get<int64_t>();
  }
  EXPECT_GE(listed, 0.95 * clipped);  // sides touched once or twice may go unlisted
  EXPECT_GE(sat.at("samples").get<int64_t>(), listed / 3);
  EXPECT_EQ(d.at("saturated_samples"), sat.at("samples"));
  EXPECT_TRUE(Warned(result, "samples pinned at")) << result.at("warnings").dump();
  // The rotations through a pinned sample are not used.
  int excluded = 0;
  for (const json& r : d.at("imus").at(0).at("rotations")) {
    excluded += r.at("used").get<bool>() ? 0 : 1;
  }
  EXPECT_GT(excluded, 0);

  // A configured limit overrides: above the clip it drops nothing, so the clipped rotations are
  // taken as data and the gyroscope fit fails as before #20.
  json configured = config;
  configured["gyro_saturation"] = 0.9 * sim.gyro.cwiseAbs().maxCoeff();
  s = Calibrate(csv, "imu.csv", configured, &result);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_NE(s.message().find("saturation"), std::string::npos) << s.message();
  EXPECT_FALSE(result.at("diagnostics").contains("saturation"))
      << "nothing reaches 0.9 of the largest rate once clipped at 0.7";
  configured["gyro_saturation"] = 0.5 * sim.gyro.cwiseAbs().maxCoeff();
  ASSERT_TRUE(Calibrate(csv, "imu.csv", configured, &result).ok());
  ASSERT_TRUE(result.at("diagnostics").contains("saturation"));
  for (const json& c : result.at("diagnostics").at("saturation").at("channels")) {
    EXPECT_EQ(c.at("source"), "config");
  }
}

TEST(SaturationMethod, ImuOnACleanLogReportsNothing) {
  for (double noise : {1.0, 0.0}) {
    core::ImuSimulationOptions o = ImuLog();
    o.accel_noise *= noise;
    o.gyro_noise *= noise;
    core::ImuSimulation sim;
    ASSERT_TRUE(core::SimulateImu(o, &sim).ok());
    std::string unused;
    json config, truth, result;
    ASSERT_TRUE(SimulateImuFiles(o, &unused, &config, &truth).ok());
    int64_t high[3], low[3];
    const std::string csv = ImuCsv(sim, 0, high, low);
    if (noise == 0) {  // noise-free readings: the noise figures must be given
      config["accel_noise"] = 0.01;
      config["gyro_noise"] = 0.002;
    }
    Status s = Calibrate(csv, "imu.csv", config, &result);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_FALSE(result.at("diagnostics").contains("saturation")) << "noise " << noise;
    EXPECT_FALSE(Warned(result, "pinned")) << result.at("warnings").dump();
    EXPECT_FALSE(result.at("diagnostics").contains("saturated_samples") &&
                 result.at("diagnostics").at("saturated_samples").get<int64_t>() > 0);
  }
}

json ArrayConfig(const core::ArraySimulation& sim, const core::ArraySimulationOptions& o) {
  json positions = json::array();
  for (Eigen::Index k = 0; k < sim.problem.nominal_positions.cols(); ++k) {
    const Eigen::Vector3d p = sim.problem.nominal_positions.col(k);
    positions.push_back({p(0), p(1), p(2)});
  }
  return {{"method", "array"},
          {"geometry", {{"positions", positions}, {"reference", 0}}},
          {"accel_noise", o.accel_noise},
          {"gyro_noise", o.gyro_noise}};
}

// The board of `sim` turned smoothly (each axis of omega two sines of 0.7-2.3 Hz, up to 20 rad/s;
// a continuous log at 200 Hz, as a real one is) rather than SimulateArray's independent samples.
ArrayRecording Recording(const core::ArraySimulation& sim, const core::ArraySimulationOptions& o) {
  const Eigen::Index n = o.samples;
  Eigen::Matrix3Xd omega(3, n), omega_dot(3, n), s(3, n);
  const double kPi = 3.14159265358979323846;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = i / 200.0;
    for (int a = 0; a < 3; ++a) {
      const double f1 = 0.7 + 0.5 * a, f2 = 2.3 - 0.6 * a;
      omega(a, i) = 12 * std::sin(2 * kPi * f1 * t + a) + 8 * std::sin(2 * kPi * f2 * t);
      omega_dot(a, i) = 12 * 2 * kPi * f1 * std::cos(2 * kPi * f1 * t + a) +
                        8 * 2 * kPi * f2 * std::cos(2 * kPi * f2 * t);
      s(a, i) = (a == 2 ? 9.81 : 0) + 2 * std::sin(2 * kPi * 0.9 * t + 2 * a);
    }
  }
  core::GaussianRng rng(7);
  ArrayRecording r;
  SimulateArrayReadings(sim.true_positions, omega, omega_dot, s, o.accel_noise, o.gyro_noise,
                        static_cast<int>(sim.gyro_names.size()), &rng, &r.accel, &r.gyro);
  for (Eigen::Index k = 0; k < r.accel.cols() / 3; ++k)
    r.accel_names.push_back("a" + std::to_string(k));
  r.gyro_names = sim.gyro_names;
  return r;
}

TEST(SaturationMethod, ArrayPositionsDropsAPinnedStretch) {
  core::ArraySimulationOptions o;
  o.samples = 4000;
  core::ArraySimulation sim;
  ASSERT_TRUE(core::SimulateArray(o, &sim).ok());
  const json config = ArrayConfig(sim, o);
  // Clean: nothing.
  json result;
  Status s = RunArray(Recording(sim, o), config, &result);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(result.at("diagnostics").contains("saturation"));
  EXPECT_EQ(result.at("diagnostics").at("samples_dropped"), 0);
  // g0_x held at its maximum for 4 more samples (the motion goes on in the other axes), entered
  // by a jump from wherever the signal is.
  ArrayRecording rec = Recording(sim, o);
  Eigen::Index at_max = 0;
  const double level = rec.gyro.col(0).maxCoeff(&at_max);
  const Eigen::Index start = at_max > 2000 ? 1000 : 3000;
  for (Eigen::Index i = start; i < start + 4; ++i) rec.gyro(i, 0) = level;
  int64_t expected_dropped = 0;  // the symmetric limit: any |gyroscope| >= 99.8 % of level
  for (Eigen::Index i = 0; i < rec.gyro.rows(); ++i) {
    expected_dropped += rec.gyro.row(i).cwiseAbs().maxCoeff() >= level * (1 - 0.002) ? 1 : 0;
  }
  s = RunArray(std::move(rec), config, &result);
  ASSERT_TRUE(s.ok()) << s.message();
  const json& d = result.at("diagnostics");
  ASSERT_TRUE(d.contains("saturation")) << result.at("warnings").dump();
  const json& c = d.at("saturation").at("channels").at(0);
  EXPECT_EQ(c.at("name"), "g0_x");
  EXPECT_EQ(c.at("source"), "data");
  EXPECT_EQ(c.at("unit"), "rad/s");
  EXPECT_EQ(c.at("pinned_high"), 5);
  EXPECT_EQ(c.at("high").get<double>(), level);
  EXPECT_TRUE(c.at("low").is_null());
  EXPECT_EQ(d.at("saturation").at("channels").size(), 1u);
  EXPECT_EQ(d.at("samples_dropped").get<int64_t>(), expected_dropped);
  EXPECT_EQ(d.at("saturation").at("samples").get<int64_t>(), expected_dropped);
  EXPECT_TRUE(Warned(result, "g0_x: 5 samples pinned at")) << result.at("warnings").dump();
  // accel_saturation is a config key of the array method (m/s^2), refused when not > 0.
  json bad = config;
  bad["accel_saturation"] = -1;
  s = RunArray(Recording(sim, o), bad, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "accel_saturation");
}

// A noise log at rest with one knock that clips the gyroscope.
std::string NoiseCsv(bool knock) {
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (int i = 0; i < 12000; ++i) {
    double a[3], g[3];
    for (int k = 0; k < 3; ++k) {
      a[k] = (k == 2 ? 9.81 : 0) + 0.01 * normal(rng);
      g[k] = 0.001 * normal(rng);
    }
    if (knock && i >= 6000 && i < 6100) {
      const double x = (i - 6000) / 100.0;
      for (int k = 0; k < 3; ++k) {
        g[k] += (40 + 10 * k) * std::sin(2 * 3.14159265358979 * 5 * x + k);
        g[k] = std::max(-34.9, std::min(34.9, g[k]));
      }
    }
    std::snprintf(line, sizeof line, "%.6f,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n", i / 100.0, a[0],
                  a[1], a[2], g[0], g[1], g[2]);
    csv += line;
  }
  return csv;
}

TEST(SaturationMethod, NoiseRefusesAClippedLogAndSaysWhy) {
  json result;
  Status s = Calibrate(NoiseCsv(true), "noise.csv", json{{"method", "noise"}}, &result);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.message();
  EXPECT_EQ(s.reason(), core::noise_reason::kNotStationary);
  EXPECT_NE(s.message().find("samples pinned at"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("knocked"), std::string::npos) << s.message();
  ASSERT_TRUE(result.contains("diagnostics")) << result.dump().substr(0, 300);
  const json& sat = result.at("diagnostics").at("saturation");
  EXPECT_EQ(sat.at("policy"), "refused");
  EXPECT_EQ(sat.at("channels").size(), 3u);  // g0_x, g0_y, g0_z each clipped at ±34.9
  for (const json& c : sat.at("channels")) {
    EXPECT_EQ(c.at("name").get<std::string>().rfind("g0_", 0), 0u);
    EXPECT_NEAR(c.at("high").get<double>(), 34.9, 1e-5);  // the noise method reads floats
    EXPECT_NEAR(c.at("low").get<double>(), -34.9, 1e-5);
  }
  EXPECT_GT(sat.at("samples").get<int64_t>(), 10);
  // Without the knock: analysed, nothing reported.
  s = Calibrate(NoiseCsv(false), "noise.csv", json{{"method", "noise"}}, &result);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(result.at("diagnostics").contains("saturation"));
}

}  // namespace
}  // namespace calibd::server
