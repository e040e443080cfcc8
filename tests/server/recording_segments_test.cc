// GET /api/v1/recordings/{id}/segments and the recording page /recordings/{id} through a real
// server: the static intervals of a stored inertial log (numbered from 1, per-triad mean and std,
// the thresholds used), the query options that override the detection, and the errors (bad
// option 400 naming it, not an inertial log 422, unknown recording 404).
#include "server/recording_segments.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "methods/imu/imu_method.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

class Segments : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(server_.error(), "");
    core::ImuSimulationOptions sim;
    sim.statics = 12;
    sim.seed = 3;
    std::string csv;
    json config, truth;
    ASSERT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
    auto res = server_.Client().Post("/api/v1/recordings?device=SEG-1", csv, "text/csv");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 201) << res->body;
    id_ = json::parse(res->body)["recording"]["id"];
  }

  json Get(const std::string& path, int* status) {
    auto res = server_.Client().Get(path.c_str());
    EXPECT_TRUE(res);
    if (!res) return json();
    *status = res->status;
    return json::parse(res->body);
  }
  std::string Url(const std::string& query = "") {
    return "/api/v1/recordings/" + std::to_string(id_) + "/segments" + query;
  }

  TestServer server_;
  int64_t id_ = 0;
};

TEST_F(Segments, FindsEveryStaticOfASimulatedLogNumberedWithItsMeansAndThresholds) {
  int status = 0;
  json seg = Get(Url(), &status);
  ASSERT_EQ(status, 200) << seg.dump();
  EXPECT_EQ(seg["recording_id"], id_);
  ASSERT_EQ(seg["intervals"].size(), 12u) << seg.dump();
  double previous_end = -1;
  for (size_t n = 0; n < 12; ++n) {
    const json& iv = seg["intervals"][n];
    EXPECT_EQ(iv["number"], n + 1);
    EXPECT_GT(iv["start"].get<double>(), previous_end);
    EXPECT_GE(iv["end"].get<double>() - iv["start"].get<double>(), 1.0);  // min_static
    previous_end = iv["end"];
    EXPECT_GT(iv["samples"].get<int64_t>(), 100);
    // At rest the accelerometer reads gravity (SI readings, scale errors of ~1 %).
    const json& m = iv["mean"]["a0"];
    const double norm = std::hypot(m[0].get<double>(), m[1].get<double>(), m[2].get<double>());
    EXPECT_NEAR(norm, 9.80665, 0.5) << iv.dump();
    ASSERT_EQ(iv["std"]["g0"].size(), 3u);
  }
  ASSERT_EQ(seg["triads"].size(), 2u);
  for (const json& t : seg["triads"]) {
    EXPECT_GT(t["threshold"].get<double>(), 0) << t.dump();
    EXPECT_FALSE(t["overridden"].get<bool>());
  }
  EXPECT_DOUBLE_EQ(seg["static_window"].get<double>(), 1.0);
  EXPECT_TRUE(seg["gaps"].empty());
}

TEST_F(Segments, QueryOptionsOverrideTheDetection) {
  int status = 0;
  json seg = Get(Url("?min_static=1000"), &status);
  ASSERT_EQ(status, 200) << seg.dump();
  EXPECT_TRUE(seg["intervals"].empty());
  seg = Get(Url("?static_threshold=%7B%22accelerometer%22%3A1e-9%2C%22gyroscope%22%3A1e-9%7D"),
            &status);
  ASSERT_EQ(status, 200) << seg.dump();
  EXPECT_TRUE(seg["intervals"].empty());
  for (const json& t : seg["triads"]) EXPECT_TRUE(t["overridden"].get<bool>());
  seg = Get(Url("?static_window=0.5"), &status);
  ASSERT_EQ(status, 200);
  EXPECT_DOUBLE_EQ(seg["static_window"].get<double>(), 0.5);
  EXPECT_EQ(seg["intervals"].size(), 12u);
}

TEST_F(Segments, BadOptionsNotAnInertialLogAndUnknownRecordingsAreNamed) {
  int status = 0;
  json e = Get(Url("?static_window=-1"), &status);
  EXPECT_EQ(status, 400);
  EXPECT_EQ(e["error"]["field"], "static_window") << e.dump();
  e = Get(Url("?gravity=9.8"), &status);
  EXPECT_EQ(status, 400);
  EXPECT_EQ(e["error"]["field"], "gravity") << e.dump();
  e = Get("/api/v1/recordings/999/segments", &status);
  EXPECT_EQ(status, 404) << e.dump();
  auto pca =
      server_.Client().Post("/api/v1/recordings", "position,s1,s2\np,1,2\nq,2,1\n", "text/csv");
  ASSERT_TRUE(pca);
  ASSERT_EQ(pca->status, 201);
  e = Get("/api/v1/recordings/" + json::parse(pca->body)["recording"]["id"].dump() + "/segments",
          &status);
  EXPECT_EQ(status, 422) << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find("inertial logs"), std::string::npos);
}

TEST_F(Segments, TheRecordingPageShowsTheTimelineWithNumberedStaticsAndItsJobs) {
  auto job = server_.Client().Post(
      "/api/v1/jobs",
      json{{"recording_id", id_}, {"config", {{"method", "imu"}, {"device", "SEG-1"}}}}.dump(),
      "application/json");
  ASSERT_TRUE(job);
  ASSERT_EQ(job->status, 202) << job->body;
  const int64_t job_id = json::parse(job->body)["job"]["id"];
  auto page = server_.Client().Get(("/recordings/" + std::to_string(id_)).c_str());
  ASSERT_TRUE(page);
  ASSERT_EQ(page->status, 200);
  const std::string& html = page->body;
  EXPECT_NE(html.find("plot-timeline-accel"), std::string::npos);
  EXPECT_NE(html.find("plot-timeline-gyro"), std::string::npos);
  // One shaded band per static in each of the two timelines, labelled 1..12.
  size_t bands = 0;
  for (size_t at = html.find("fill=\"#cfe3f3\""); at != std::string::npos;
       at = html.find("fill=\"#cfe3f3\"", at + 1)) {
    ++bands;
  }
  EXPECT_EQ(bands, 24u);
  EXPECT_NE(html.find(">12</text>"), std::string::npos);
  EXPECT_NE(html.find("href=\"/jobs/" + std::to_string(job_id) + "\""), std::string::npos);
  EXPECT_NE(html.find("href=\"/devices/SEG-1\""), std::string::npos);
  auto missing = server_.Client().Get("/recordings/999");
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404);
  // A bad option is said on the page, not a failure of it.
  auto bad =
      server_.Client().Get(("/recordings/" + std::to_string(id_) + "?static_window=x").c_str());
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 200);
  EXPECT_NE(bad->body.find("No timeline: config key &#39;static_window&#39;"), std::string::npos)
      << bad->body.substr(0, 3000);
}

}  // namespace
}  // namespace calibd::server
