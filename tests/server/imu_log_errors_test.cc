// The inertial-log errors of issue 16 through a real server: a t that repeats or goes back is a
// 400 naming its line at upload (and in a job or offline), gaps are reported with their times in
// the imu result (diagnostics and a warning), saturated samples are dropped and counted, and too
// few statics fail the job as not determinable saying how many were found, how many are needed
// and which orientations to add.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "methods/imu/imu_method.h"
#include "server/config.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

std::vector<std::string> Lines(const std::string& csv) {
  std::vector<std::string> lines;
  std::istringstream in(csv);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::string Join(const std::vector<std::string>& lines) {
  std::string out;
  for (const auto& l : lines) out += l + "\n";
  return out;
}

std::string SimulatedLog(int statics, json* config, uint64_t seed = 2) {
  core::ImuSimulationOptions sim;
  sim.statics = statics;
  sim.seed = seed;
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateImuFiles(sim, &csv, config, &truth).ok());
  return csv;
}

TEST(InertialLogErrors, RepeatedOrBackwardTimeIsA400NamingTheLine) {
  json config;
  std::vector<std::string> lines = Lines(SimulatedLog(12, &config));
  lines.insert(lines.begin() + 1, "# a comment line moves the rows down");
  // Line 501 of the file (index 500) repeats the t of line 500.
  lines[500] = lines[499].substr(0, lines[499].find(',')) + lines[500].substr(lines[500].find(','));
  const std::string csv = Join(lines);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  for (const char* method : {"imu", "noise"}) {
    auto res = server.Client().Post(("/api/v1/recordings?method=" + std::string(method)).c_str(),
                                    csv, "text/csv");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << res->body;
    const json e = json::parse(res->body)["error"];
    EXPECT_EQ(e["line"], 501) << e.dump();
    EXPECT_EQ(e["column"], 1) << e.dump();
    EXPECT_EQ(e["field"], "t");
    EXPECT_NE(e["message"].get<std::string>().find("repeats"), std::string::npos) << e.dump();
  }
  // Offline (and so in a job) the same line is named.
  json result;
  Status s = Calibrate(csv, "imu.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.line(), 501) << s.ToString();
  // Going back.
  lines[500] = "0" + lines[500].substr(lines[500].find(','));
  s = Calibrate(Join(lines), "imu.csv", config, &result);
  EXPECT_EQ(s.line(), 501) << s.ToString();
  EXPECT_NE(s.message().find("comes after"), std::string::npos) << s.message();
  // Without a method the log is stored (the array method accepts any t).
  auto plain = server.Client().Post("/api/v1/recordings", Join(lines), "text/csv");
  ASSERT_TRUE(plain);
  EXPECT_EQ(plain->status, 201);
}

TEST(InertialLogErrors, GapsAreReportedWithTheirTimesInTheImuResult) {
  json config;
  std::vector<std::string> lines = Lines(SimulatedLog(24, &config, 4));
  // Drop half a second of samples (100 Hz) at t = 30 s: a gap from 29.99 s to 30.5 s.
  const size_t first = 1 + 3000;
  const double gap_start = std::stod(lines[first - 1]);
  lines.erase(lines.begin() + first, lines.begin() + first + 50);
  const double gap_end = std::stod(lines[first]);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  json job = server.UploadAndWait(Join(lines), config, "imu.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  const json& gaps = job["result"]["diagnostics"]["gaps"];
  ASSERT_EQ(gaps.size(), 1u) << gaps.dump();
  EXPECT_DOUBLE_EQ(gaps[0]["start"].get<double>(), gap_start);
  EXPECT_DOUBLE_EQ(gaps[0]["end"].get<double>(), gap_end);
  bool warned = false;
  for (const json& w : job["result"]["warnings"]) {
    warned |= w.get<std::string>().find("1 gap(s) in t (") != std::string::npos;
  }
  EXPECT_TRUE(warned) << job["result"]["warnings"].dump();
}

TEST(InertialLogErrors, SaturatedSamplesAreDroppedAndCounted) {
  json config;
  std::vector<std::string> lines = Lines(SimulatedLog(24, &config, 6));
  // 7 gyroscope readings pinned at the rail (an ADC's full scale) in the first static.
  for (size_t i = 100; i < 107; ++i) {
    std::string& l = lines[i];
    const size_t gx = l.find(',', l.find(',', l.find(',', l.find(',') + 1) + 1) + 1);
    const size_t gy = l.find(',', gx + 1);
    l = l.substr(0, gx + 1) + "34.9" + l.substr(gy);
  }
  config["gyro_saturation"] = 34.9;  // rad/s
  json result;
  Status s = Calibrate(Join(lines), "imu.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["saturated_samples"], 7);
  bool warned = false;
  for (const json& w : result["warnings"]) {
    warned |= w.get<std::string>().find("7 saturated sample(s) dropped") != std::string::npos;
  }
  EXPECT_TRUE(warned) << result["warnings"].dump();
  config["gyro_saturation"] = json::array({40000, 0});
  s = Calibrate(Join(lines), "imu.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "gyro_saturation") << s.ToString();
}

TEST(InertialLogErrors, TooFewStaticsFailTheJobSayingFoundNeededAndWhichOrientations) {
  json config;
  const std::string csv = SimulatedLog(5, &config);
  TestServer server;
  ASSERT_EQ(server.error(), "");
  json job = server.UploadAndWait(csv, config, "imu.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "failed") << job.dump();
  EXPECT_EQ(job["error"]["code"], "not_determinable");
  const std::string m = job["error"]["message"];
  EXPECT_NE(m.find("found 5 static intervals, at least 9 are needed"), std::string::npos) << m;
  EXPECT_TRUE(m.find("axis up") != std::string::npos ||
              m.find("more orientations") != std::string::npos)
      << m;
}

}  // namespace
}  // namespace calibd::server
