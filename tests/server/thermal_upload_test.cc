// The thermal method through the real HTTP server (issue 31, SPEC §8): a simulated warm-up CSV
// uploaded and calibrated, its report page and its firmware exports served; a 4 °C warm-up is a
// failed job naming the range; the same warm-up as an ArduPilot DataFlash log (IMU messages with
// their temperature T) through the same route; the windows' σ from a noise job ({"job": ID}).
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "formats/recording.h"
#include "methods/thermal/thermal_method.h"
#include "tests/lib/dataflash_writer.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using json = nlohmann::json;
using testing::TestServer;

// A 30-minute warm-up at 20 Hz (`delta` °C asymptotic rise) as calibd's CSV, with its config.
std::string WarmupCsv(double delta, json* config) {
  core::ThermalSimulationOptions o;
  o.rate = 20;
  o.delta = delta;
  o.seed = 3;
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateThermalFiles(o, &csv, config, &truth).ok());
  (*config)["device"] = "TC-1";
  return csv;
}

std::string Get(const TestServer& server, const std::string& path, int want = 200) {
  auto res = server.Client().Get(path.c_str());
  if (!res) {
    ADD_FAILURE() << path << ": no answer";
    return "";
  }
  EXPECT_EQ(res->status, want) << path << ": " << res->body.substr(0, 500);
  return res->body;
}

TEST(ThermalUpload, AWarmupCalibratesWithItsReportAndFirmwareFiles) {
  json config;
  const std::string csv = WarmupCsv(40, &config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(csv, config, "warmup.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const json& imu = job["result"]["parameters"]["imus"][0];
  EXPECT_GT(imu["t_max"].get<double>() - imu["t_min"].get<double>(), 30);
  const std::string id = std::to_string(job["id"].get<int64_t>());
  const std::string page = Get(server, "/jobs/" + id);
  EXPECT_NE(page.find("thermal"), std::string::npos);
  EXPECT_NE(page.find("Lag: none"), std::string::npos);
  const std::string base = "/api/v1/devices/TC-1/calibration?method=thermal&job=" + id;
  const std::string ardupilot = Get(server, base + "&format=ardupilot");
  EXPECT_NE(ardupilot.find("INS_TCAL1_ENABLE"), std::string::npos) << ardupilot;
  EXPECT_NE(ardupilot.find("INS_TCAL1_GYR1_X"), std::string::npos) << ardupilot;
  const std::string px4 = Get(server, base + "&format=px4");
  EXPECT_NE(px4.find("TC_A0_X1_0"), std::string::npos) << px4;
  EXPECT_NE(px4.find("TC_G0_TREF"), std::string::npos) << px4;
  for (const char* format : {"json", "csv", "h"}) Get(server, base + "&format=" + format);
}

// +z through a warm-up, −z through the cool-down, with a scale drift: the report plots z's scale
// curve with its band and says why x and y have none; every export is still served.
TEST(ThermalUpload, OppositeFacesReportTheScaleCurve) {
  core::ThermalSimulationOptions o;
  o.rate = 20;
  o.warmup = o.cooldown = 3600;
  o.cool_delta = 40;
  o.tau = 1200;
  o.orientations = 2;
  o.seed = 5;
  o.scale_coefficients = core::DefaultThermalScaleTruth(2);
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  config["device"] = "TC-2";
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(csv, config, "faces.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const std::string id = std::to_string(job["id"].get<int64_t>());
  const std::string page = Get(server, "/jobs/" + id);
  EXPECT_NE(page.find("accelerometer.z scale"), std::string::npos);
  EXPECT_NE(page.find("Scale curve of accelerometer x not estimated"), std::string::npos);
  const std::string base = "/api/v1/devices/TC-2/calibration?method=thermal&job=" + id;
  const std::string px4 = Get(server, base + "&format=px4");
  EXPECT_NE(px4.find("Scale curves are not held by PX4: left out"), std::string::npos) << px4;
  const std::string ardupilot = Get(server, base + "&format=ardupilot");
  EXPECT_NE(ardupilot.find("left out"), std::string::npos) << ardupilot;
  for (const char* format : {"json", "csv", "h"}) Get(server, base + "&format=" + format);
}

TEST(ThermalUpload, AFourDegreeWarmupIsAFailedJobNamingTheRange) {
  json config;
  const std::string csv = WarmupCsv(4, &config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(csv, config, "warmup.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "failed") << job.dump().substr(0, 2000);
  const std::string error = job.dump();
  EXPECT_NE(error.find("min_range 10"), std::string::npos) << error;
  EXPECT_NE(error.find("the statics span 3."), std::string::npos) << error;
}

// The same warm-up as a DataFlash log: IMU instance 0 with its temperature (T, °C).
TEST(ThermalUpload, ADataFlashWarmupCalibratesThroughTheSameRoute) {
  json config;
  const std::string csv = WarmupCsv(40, &config);
  RecordingParser parser("sim.csv", /*collect=*/true);
  ASSERT_TRUE(ParseRecording(csv, &parser).ok());
  ArrayRecording rec;
  ASSERT_TRUE(parser.TakeArray(&rec).ok());
  calibd::testing::DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  for (Eigen::Index i = 0; i < rec.t.size(); ++i) {
    const double gyro[3] = {rec.gyro(i, 0), rec.gyro(i, 1), rec.gyro(i, 2)};
    const double accel[3] = {rec.accel(i, 0), rec.accel(i, 1), rec.accel(i, 2)};
    calibd::testing::WriteImu(&w, static_cast<uint64_t>(std::llround(1e6 + rec.t(i) * 1e6)), 0,
                              gyro, accel, rec.temperature(i, 0));
  }
  config.erase("time_unit");  // the simulated CSV's; a DataFlash log has its own clock
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(w.bytes(), config, "log.bin");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  EXPECT_EQ(job["result"]["diagnostics"]["log"]["format"], "dataflash");
  const json& imu = job["result"]["parameters"]["imus"][0];
  EXPECT_GT(imu["t_max"].get<double>() - imu["t_min"].get<double>(), 30);
}

// A noise job on 20 minutes of white noise at the warm-up's rate (σ 0.02 m/s², 0.002 rad/s, as
// the simulation's); the thermal job given {"job": ID} takes its windows' σ from it: σ/√n.
TEST(ThermalUpload, WindowNoiseFromANoiseJob) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  std::string noise_csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (int i = 0; i < 20 * 1200; ++i) {
    std::snprintf(line, sizeof line, "%.3f,%.6f,%.6f,%.6f,%.7f,%.7f,%.7f\n", i / 20.0,
                  0.02 * normal(rng), 0.02 * normal(rng), 9.80665 + 0.02 * normal(rng),
                  0.002 * normal(rng), 0.002 * normal(rng), 0.002 * normal(rng));
    noise_csv += line;
  }
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json noise = server.UploadAndWait(noise_csv, {{"method", "noise"}}, "still.csv");
  ASSERT_FALSE(noise.is_null());
  ASSERT_EQ(noise["status"], "succeeded") << noise.dump().substr(0, 2000);
  const int64_t id = noise["id"].get<int64_t>();
  json config;
  const std::string csv = WarmupCsv(40, &config);
  config["accel_noise"] = {{"job", id}};
  config["gyro_noise"] = {{"job", id}};
  const json job = server.UploadAndWait(csv, config, "warmup.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const json& d = job["result"]["diagnostics"];
  EXPECT_EQ(d["noise_jobs"]["accelerometer"], id);
  EXPECT_EQ(d["noise_jobs"]["gyroscope"], id);
  // One σ for every full window (200 samples): the noise job's σ (the largest axis, within the
  // ~5 % its white-noise density is determined to) over √200.
  const json& imu = d["imus"][0];
  const double n = imu["windows"][0]["samples"].get<double>();
  const double accel = imu["channels"][0]["points"]["std"][0].get<double>() * std::sqrt(n);
  const double gyro = imu["channels"][3]["points"]["std"][0].get<double>() * std::sqrt(n);
  EXPECT_NEAR(accel, 0.02, 0.002);
  EXPECT_NEAR(gyro, 0.002, 0.0002);
  EXPECT_EQ(imu["channels"][0]["points"]["std"][0], imu["channels"][1]["points"]["std"][0]);
}

}  // namespace
}  // namespace calibd::server
