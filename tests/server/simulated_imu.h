// A simulated hand-held imu log (core/imu_simulation.h) as the tests of sensor-log and bag uploads
// write it into their formats: its samples (parsed from the simulator's CSV), the imu config
// without the CSV unit keys (a log is SI: the keys are refused for logs), and the truth.
#ifndef CALIBD_TESTS_SERVER_SIMULATED_IMU_H_
#define CALIBD_TESTS_SERVER_SIMULATED_IMU_H_

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>
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

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_SERVER_SIMULATED_IMU_H_
