// A simulated hand-held imu log (core/imu_simulation.h) as the tests of sensor-log and bag uploads
// write it into their formats: its samples (parsed from the simulator's CSV), the imu config
// without the CSV unit keys (a log is SI: the keys are refused for logs), and the truth.
#ifndef CALIBD_TESTS_SERVER_SIMULATED_IMU_H_
#define CALIBD_TESTS_SERVER_SIMULATED_IMU_H_

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "formats/recording.h"
#include "methods/imu/imu_method.h"

namespace calibd::server::testing {

struct SimulatedImu {
  ArrayRecording rec;
  nlohmann::json config, truth;
};

// `statics` holds, simulator seed `seed`.
inline SimulatedImu SimulateImuLog(int statics, uint64_t seed) {
  core::ImuSimulationOptions sim;
  sim.statics = statics;
  sim.seed = seed;
  std::string csv;
  SimulatedImu out;
  EXPECT_TRUE(SimulateImuFiles(sim, &csv, &out.config, &out.truth).ok());
  RecordingParser parser("sim.csv", /*collect=*/true);
  EXPECT_TRUE(ParseRecording(csv, &parser).ok());
  EXPECT_TRUE(parser.TakeArray(&out.rec).ok());
  for (const char* key : {"accel_unit", "gyro_unit", "time_unit"}) out.config.erase(key);
  return out;
}

// Every accelerometer and gyroscope bias and scale of IMU 0 of an imu job's `result` within 5σ (its
// own σ) of `truth` (SimulateImuLog's): as for the same log as CSV (imu_method_test).
inline void ExpectImuRecoversTheTruth(const nlohmann::json& result, const nlohmann::json& truth) {
  const nlohmann::json& p = result["parameters"]["imus"][0];
  const nlohmann::json& u = result["uncertainty"]["imus"][0];
  for (const char* sensor : {"accelerometer", "gyroscope"}) {
    for (const char* key : {"bias", "scale"}) {
      for (int k = 0; k < 3; ++k) {
        const double est = p[sensor][key][k], want = truth[sensor][key][k];
        const double s = u[sensor][std::string(key) + "_std"][k];
        EXPECT_LE(std::abs(est - want), 5 * s) << sensor << "." << key << "[" << k << "]";
      }
    }
  }
}

// A still IMU for noise jobs: 120 s at 200 Hz (t from 4 s) of white noise of σ 0.02 m/s² and
// 0.002 rad/s about gravity on -z and a 0.01 rad/s gyroscope bias; the white-noise density a job
// should find is σ·√Δt per channel.
struct WhiteNoiseLog {
  static constexpr double kRate = 200, kSigmaAccel = 0.02, kSigmaGyro = 0.002;
  ArrayRecording rec;
};
inline WhiteNoiseLog SimulateWhiteNoise(uint64_t seed) {
  const int n = static_cast<int>(120 * WhiteNoiseLog::kRate);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  WhiteNoiseLog out;
  ArrayRecording& rec = out.rec;
  rec.t.resize(n);
  rec.accel.resize(n, 3);
  rec.gyro.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    rec.t(i) = 4.0 + i / WhiteNoiseLog::kRate;
    for (int k = 0; k < 3; ++k) {
      rec.gyro(i, k) = 0.01 + WhiteNoiseLog::kSigmaGyro * normal(rng);
      rec.accel(i, k) = (k == 2 ? -9.81 : 0.0) + WhiteNoiseLog::kSigmaAccel * normal(rng);
    }
  }
  return out;
}

// A noise job's `result` on SimulateWhiteNoise's log: each of the six channels' white-noise
// density within 5σ (its own σ) and 10 % of σ·√Δt.
inline void ExpectWhiteNoiseDensity(const nlohmann::json& result) {
  const nlohmann::json& channels = result["parameters"]["channels"];
  const nlohmann::json& stds = result["uncertainty"]["channels"];
  ASSERT_EQ(channels.size(), 6u);
  for (size_t c = 0; c < channels.size(); ++c) {
    const bool accel = channels[c]["name"].get<std::string>()[0] == 'a';
    const double want = (accel ? WhiteNoiseLog::kSigmaAccel : WhiteNoiseLog::kSigmaGyro) /
                        std::sqrt(WhiteNoiseLog::kRate);
    const double got = channels[c]["white_noise"], s = stds[c]["white_noise_std"];
    EXPECT_LE(std::abs(got - want), 5 * s) << channels[c].dump();
    EXPECT_LE(std::abs(got - want), 0.1 * want) << channels[c].dump();
  }
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_SERVER_SIMULATED_IMU_H_
