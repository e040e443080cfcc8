// Sensor logs through the real server (issue 30, SPEC §9): a DataFlash log uploaded under a
// neutral file name is recognised by its bytes, says what was read, and runs `imu` and `noise`
// jobs end to end; the CSV unit keys are refused for it; a cut log is stored with a warning naming
// the byte, and a damaged one is a 400 with nothing stored.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "formats/recording.h"
#include "methods/imu/imu_method.h"
#include "tests/lib/dataflash_writer.h"
#include "tests/lib/ulog_writer.h"
#include "tests/server/http_test_util.h"
#include "tests/server/simulated_imu.h"

namespace calibd::server {
namespace {

using json = nlohmann::json;
using calibd::testing::DataFlashWriter;
using testing::TestServer;

// The array recording `rec` (IMU 0 only) as an ArduPilot 4.x DataFlash log: IMU messages at the
// recording's times plus 1 s (TimeUS), SI as IMU messages hold them.
std::string AsDataFlash(const ArrayRecording& rec) {
  DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  for (Eigen::Index i = 0; i < rec.t.size(); ++i) {
    const double gyro[3] = {rec.gyro(i, 0), rec.gyro(i, 1), rec.gyro(i, 2)};
    const double accel[3] = {rec.accel(i, 0), rec.accel(i, 1), rec.accel(i, 2)};
    const auto time_us = static_cast<uint64_t>(std::llround(1e6 + rec.t(i) * 1e6));
    calibd::testing::WriteImu(&w, time_us, 0, gyro, accel, 35.0);
  }
  return w.bytes();
}

// The same as a PX4 ULog: sensor_accel and sensor_gyro (multi_id 0, one device id) at the
// recording's times plus 1 s (timestamp_sample; timestamp 200 µs later, as the driver publishes).
std::string AsULog(const ArrayRecording& rec) {
  calibd::testing::ULogWriter w;
  w.Format(calibd::testing::kSensorAccelFormat).Format(calibd::testing::kSensorGyroFormat);
  w.Subscribe(0, 0, "sensor_accel").Subscribe(0, 1, "sensor_gyro");
  for (Eigen::Index i = 0; i < rec.t.size(); ++i) {
    const auto t = static_cast<uint64_t>(std::llround(1e6 + rec.t(i) * 1e6));
    w.Data(0, calibd::testing::TriadData(t + 200, t, 2490378, rec.accel(i, 0), rec.accel(i, 1),
                                         rec.accel(i, 2), 41.5f));
    w.Data(1, calibd::testing::TriadData(t + 200, t, 2490378, rec.gyro(i, 0), rec.gyro(i, 1),
                                         rec.gyro(i, 2), 41.5f));
  }
  return w.bytes();
}

// A simulated hand-held imu log with `statics` holds (tests/server/simulated_imu.h).
using testing::SimulatedImu;
SimulatedImu Simulate(int statics, uint64_t seed) { return testing::SimulateImuLog(statics, seed); }

json GetJson(const TestServer& server, const std::string& path) {
  auto res = server.Client().Get(path.c_str());
  if (!res || res->status != 200) return nullptr;
  return json::parse(res->body, nullptr, false);
}

TEST(SensorLogUpload, AnImuJobOnADataFlashLogRecoversTheTruthAndSaysWhatWasRead) {
  SimulatedImu sim = Simulate(24, 11);
  json& config = sim.config;
  const json& truth = sim.truth;
  const ArrayRecording& rec = sim.rec;
  const std::string log = AsDataFlash(rec);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(log, config, "upload.dat");  // a neutral name
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const json& r = job["result"];
  // 5σ per entry: float32 storage is far below σ.
  testing::ExpectImuRecoversTheTruth(r, truth);
  EXPECT_EQ(r["diagnostics"]["log"]["format"], "dataflash");
  EXPECT_EQ(r["diagnostics"]["log"]["time_base"], "IMU:0 (TimeUS)");

  const json recording =
      GetJson(server, "/api/v1/recordings/" + std::to_string(job["recording_id"].get<int64_t>()));
  ASSERT_TRUE(recording.is_object());
  EXPECT_EQ(recording["format"], "dataflash");
  EXPECT_EQ(recording["rows"], rec.t.size());
  ASSERT_TRUE(recording["streams"].is_array());
  bool found = false;
  for (const json& s : recording["streams"]) {
    if (s["name"] != "IMU:0" || s["kind"] != "accelerometer") continue;
    found = true;
    EXPECT_EQ(s["samples"], rec.t.size());
    EXPECT_NEAR(s["start"].get<double>(), 1.0 + rec.t(0), 1e-6);
    EXPECT_NEAR(s["end"].get<double>(), 1.0 + rec.t(rec.t.size() - 1), 1e-6);
    const double rate = (rec.t.size() - 1) / (rec.t(rec.t.size() - 1) - rec.t(0));
    EXPECT_NEAR(s["rate"].get<double>(), rate, 0.01 * rate);
  }
  EXPECT_TRUE(found) << recording["streams"].dump();
  // The bytes come back as uploaded.
  auto data = server.Client().Get(
      ("/api/v1/recordings/" + std::to_string(job["recording_id"].get<int64_t>()) + "/data")
          .c_str());
  ASSERT_TRUE(data);
  EXPECT_EQ(data->body, log);
  // The recording page lists the streams.
  auto page = server.Client().Get(
      ("/recordings/" + std::to_string(job["recording_id"].get<int64_t>())).c_str());
  ASSERT_TRUE(page);
  EXPECT_NE(page->body.find("<section id=\"log\">"), std::string::npos);
}

TEST(SensorLogUpload, AnImuJobOnAULogPairsAccelAndGyroByDeviceAndRecoversTheTruth) {
  SimulatedImu sim = Simulate(24, 12);
  json& config = sim.config;
  const json& truth = sim.truth;
  const ArrayRecording& rec = sim.rec;
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(AsULog(rec), config, "flight");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
  const json& r = job["result"];
  testing::ExpectImuRecoversTheTruth(r, truth);  // biases and scales, 5σ (ULog holds float32)
  const json& imu = r["diagnostics"]["log"]["imus"][0];
  EXPECT_EQ(imu["accel"], "sensor_accel:0");
  EXPECT_EQ(imu["gyro"], "sensor_gyro:0");
  EXPECT_EQ(imu["temp"], "sensor_accel:0");
  EXPECT_EQ(imu["time_source"], "timestamp_sample");
  EXPECT_TRUE(imu["resampled"].empty());
}

TEST(SensorLogUpload, ANoiseJobOnADataFlashOrULogLogFindsTheWhiteNoiseDensity) {
  // White noise (tests/server/simulated_imu.h); ULog holds float32, far below σ.
  const ArrayRecording rec = testing::SimulateWhiteNoise(7).rec;
  TestServer server;
  ASSERT_EQ(server.error(), "");
  for (const bool ulog : {false, true}) {
    SCOPED_TRACE(ulog ? "ULog" : "DataFlash");
    const json job =
        server.UploadAndWait(ulog ? AsULog(rec) : AsDataFlash(rec), {{"method", "noise"}}, "log");
    ASSERT_FALSE(job.is_null());
    ASSERT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);
    EXPECT_EQ(job["result"]["diagnostics"]["log"]["format"], ulog ? "ulog" : "dataflash");
    testing::ExpectWhiteNoiseDensity(job["result"]);
  }
}

TEST(SensorLogUpload, CsvUnitKeysAreRefusedForALog) {
  SimulatedImu sim = Simulate(12, 1);
  json& config = sim.config;
  const std::string log = AsDataFlash(sim.rec);
  config["time_unit"] = "ms";
  TestServer server;
  ASSERT_EQ(server.error(), "");
  auto res = server.Client().Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", log, "x", "application/octet-stream"},
                                      {"config", config.dump(), "", "application/json"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  EXPECT_NE(res->body.find("time_unit"), std::string::npos) << res->body;
  EXPECT_NE(res->body.find("dataflash"), std::string::npos) << res->body;
}

TEST(SensorLogUpload, ACutLogIsStoredWithAWarningAndADamagedOneIsRefused) {
  SimulatedImu sim = Simulate(12, 1);
  const std::string log = AsDataFlash(sim.rec);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  auto client = server.Client();
  // Cut 7 bytes into the last message: read to the message before, with a warning.
  const std::string cut = log.substr(0, log.size() - 20);
  auto res = client.Post("/api/v1/recordings", cut, "application/octet-stream");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  const json stored = json::parse(res->body);
  const json recording = GetJson(
      server, "/api/v1/recordings/" + std::to_string(stored["recording"]["id"].get<int64_t>()));
  ASSERT_TRUE(recording.is_object());
  EXPECT_NE(recording["warnings"].dump().find("cut"), std::string::npos) << recording.dump();
  // A FMT message of an impossible length inside the log: a 400 naming the byte offset.
  std::string damaged = log;
  const size_t fmt = damaged.find(std::string("\xA3\x95\x80", 3), 3);
  ASSERT_NE(fmt, std::string::npos);
  damaged[fmt + 4] = 2;  // Length 2: shorter than its own header
  res = client.Post("/api/v1/recordings", damaged, "application/octet-stream");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  EXPECT_NE(res->body.find("byte"), std::string::npos) << res->body;
  // Nothing stored: the next id is still free.
  auto next = client.Get(
      ("/api/v1/recordings/" + std::to_string(stored["recording"]["id"].get<int64_t>() + 1))
          .c_str());
  ASSERT_TRUE(next);
  EXPECT_EQ(next->status, 404) << next->body;
}

}  // namespace
}  // namespace calibd::server
