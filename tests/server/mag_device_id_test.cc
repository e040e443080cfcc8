// The magnetometer's firmware device id taken from the log (issue 32, #26 item 5): a DataFlash
// log's COMPASS_DEV_ID parameter reaches the mag result (`device_id`, `device_id_source` "log")
// and both firmware files (COMPASS_DEV_ID, CAL_MAG0_ID), also when the recording is read again
// from the parsed-columns cache; a config device_id wins and a mismatch is warned about; a CSV
// log has none and the files say so.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/mag_simulation.h"
#include "formats/recording.h"
#include "methods/mag/mag_method.h"
#include "tests/lib/dataflash_writer.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using json = nlohmann::json;
using testing::TestServer;

constexpr int64_t kLogId = 97539;  // an ArduPilot compass device id (bus, address, type)

// A simulated hand-held turn (calibd simulate mag) as calibd's CSV, with its config.
std::string MagCsv(json* config) {
  core::MagSimulationOptions o;
  o.seed = 11;
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateMagFiles(o, &csv, config, &truth).ok());
  (*config)["device"] = "MAG-ID-1";
  return csv;
}

// The same log as ArduPilot writes it: ACC (m/s²) and MAG (milligauss) instance 0 at the same
// stamps, and the compass's id as the parameter COMPASS_DEV_ID.
std::string AsDataFlash(const std::string& csv) {
  RecordingParser parser("sim.csv", /*collect=*/true);
  EXPECT_TRUE(ParseRecording(csv, &parser).ok());
  ArrayRecording rec;
  EXPECT_TRUE(parser.TakeArray(&rec).ok());
  calibd::testing::DataFlashWriter w;
  calibd::testing::WriteArduPilotFormats(&w);
  w.Message(calibd::testing::kDfParm, {uint64_t{1000}, "COMPASS_DEV_ID", kLogId, 0});
  for (Eigen::Index i = 0; i < rec.t.size(); ++i) {
    const auto us = static_cast<uint64_t>(std::llround(1e6 + rec.t(i) * 1e6));
    w.Message(calibd::testing::kDfAcc,
              {us, 0, us, rec.accel(i, 0), rec.accel(i, 1), rec.accel(i, 2)});
    const int mg[3] = {static_cast<int>(std::lround(rec.mag(i, 0) * 10)),
                       static_cast<int>(std::lround(rec.mag(i, 1) * 10)),
                       static_cast<int>(std::lround(rec.mag(i, 2) * 10))};
    calibd::testing::WriteMag(&w, us, 0, mg);
  }
  return w.bytes();
}

std::string Get(const TestServer& server, const std::string& path) {
  auto res = server.Client().Get(path.c_str());
  if (!res) return "(no response)";
  EXPECT_EQ(res->status, 200) << path << ": " << res->body.substr(0, 500);
  return res->body;
}

std::string Export(const TestServer& server, const json& job, const char* format) {
  return Get(server, "/api/v1/devices/MAG-ID-1/calibration?method=mag&job=" +
                         std::to_string(job["id"].get<int64_t>()) + "&format=" + format);
}

TEST(MagDeviceId, TheLogsCompassIdReachesTheResultAndBothFirmwareFiles) {
  json config;
  const std::string log = AsDataFlash(MagCsv(&config));
  TestServer server;
  ASSERT_EQ(server.error(), "");
  // Twice: the second job reads the recording from the parsed-columns cache.
  for (int run = 0; run < 2; ++run) {
    const json job = server.UploadAndWait(log, config, "log.bin");
    ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 2000);
    EXPECT_EQ(job["result"]["diagnostics"]["log"]["format"], "dataflash");
    const json& m = job["result"]["parameters"]["mags"][0];
    EXPECT_EQ(m["device_id"], kLogId) << "run " << run << ": " << m.dump().substr(0, 300);
    EXPECT_EQ(m["device_id_source"], "log") << "run " << run;
    const std::string ardupilot = Export(server, job, "ardupilot");
    EXPECT_NE(ardupilot.find("COMPASS_DEV_ID," + std::to_string(kLogId) + "\n"), std::string::npos)
        << ardupilot;
    const std::string px4 = Export(server, job, "px4");
    EXPECT_NE(px4.find("CAL_MAG0_ID\t" + std::to_string(kLogId) + "\t6"), std::string::npos) << px4;
  }
}

TEST(MagDeviceId, AConfigIdWinsAndAMismatchIsWarned) {
  json config;
  const std::string log = AsDataFlash(MagCsv(&config));
  config["device_id"] = 12345;
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(log, config, "log.bin");
  ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 2000);
  const json& m = job["result"]["parameters"]["mags"][0];
  EXPECT_EQ(m["device_id"], 12345);
  EXPECT_EQ(m["device_id_source"], "config");
  EXPECT_NE(job["result"].dump().find("differs from the log's " + std::to_string(kLogId)),
            std::string::npos)
      << job["result"]["warnings"].dump();
  EXPECT_NE(Export(server, job, "ardupilot").find("COMPASS_DEV_ID,12345\n"), std::string::npos);
}

TEST(MagDeviceId, ACsvLogHasNoneAndTheFilesSaySo) {
  json config;
  const std::string csv = MagCsv(&config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const json job = server.UploadAndWait(csv, config, "mag.csv");
  ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 2000);
  const json& m = job["result"]["parameters"]["mags"][0];
  EXPECT_TRUE(m["device_id"].is_null()) << m.dump().substr(0, 300);
  EXPECT_TRUE(m["device_id_source"].is_null());
  EXPECT_NE(Export(server, job, "ardupilot").find("# COMPASS_DEV_ID not written"),
            std::string::npos);
  EXPECT_NE(Export(server, job, "px4").find("# CAL_MAG0_ID not written"), std::string::npos);
}

}  // namespace
}  // namespace calibd::server
