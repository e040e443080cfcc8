// The recording page (web/recording_page.h): metadata and links, the two timelines with one
// shaded, numbered band per static interval, the tables of thresholds, gaps and intervals,
// user strings escaped, a long log decimated to a bounded page, and the note when there is no
// timeline.
#include "web/recording_page.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

namespace calibd::web {
namespace {

using json = nlohmann::json;

size_t Count(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// A 2-minute 100 Hz log (or `seconds`) with statics [10k, 10k + 6] s.
RecordingPageView View(double seconds = 120) {
  RecordingPageView v;
  v.id = 7;
  v.sha256 = "ab12";
  v.layout = "array";
  v.device = "<script>alert(1)</script>";
  v.file_name = "\"><img src=x onerror=alert(1)>.csv";
  v.bytes = 123456;
  v.rows = static_cast<int64_t>(seconds * 100);
  v.columns = {"t", "a0_x", "a0_y", "a0_z", "g0_x", "g0_y", "g0_z"};
  json intervals = json::array();
  for (int k = 0; 10.0 * k + 6 < seconds; ++k) {
    intervals.push_back({{"number", k + 1},
                         {"start", 10.0 * k},
                         {"end", 10.0 * k + 6},
                         {"samples", 601},
                         {"mean", {{"a0", {0, 0, 9.81}}, {"g0", {0, 0, 0}}}},
                         {"std", {{"a0", {0.01, 0.01, 0.01}}, {"g0", {1e-3, 1e-3, 1e-3}}}}});
  }
  v.segments = {{"recording_id", 7},
                {"static_window", 1},
                {"min_static", 1},
                {"threshold_multiplier", 3},
                {"triads",
                 {{{"name", "a0"},
                   {"kind", "accelerometer"},
                   {"noise_floor", 0.01},
                   {"threshold", 0.03},
                   {"threshold_si", 0.03},
                   {"overridden", false},
                   {"saturated_samples", 4}}}},
                {"gaps", {{{"index", 500}, {"start", 4.99}, {"end", 5.5}}}},
                {"intervals", intervals}};
  RecordingPageView::Trace a{"a0", {}, {}}, g{"g0", {}, {}};
  for (int i = 0; i < static_cast<int>(seconds * 100); ++i) {
    const double t = i / 100.0;
    const bool still = std::fmod(t, 10.0) < 6;
    a.t.push_back(t);
    a.norm.push_back(9.81 + (still ? 0.01 : 2.0) * std::sin(3.1 * i));
    g.t.push_back(t);
    g.norm.push_back(still ? 0.001 : 1.5 + std::sin(0.01 * i));
  }
  v.accel.push_back(a);
  v.gyro.push_back(g);
  web::JobSummary j;
  j.id = 42;
  j.method = "imu";
  j.status = JobStatus::kSucceeded;
  j.device = "SN 1";
  v.jobs.push_back(j);
  return v;
}

TEST(RecordingPage, TimelinesShadeAndNumberEveryStaticAndLinkItsJobs) {
  const RecordingPageView v = View();
  const std::string html = RenderRecordingPage(v);
  EXPECT_NE(html.find("class=\"page-recording\""), std::string::npos);
  EXPECT_NE(html.find("plot-timeline-accel"), std::string::npos);
  EXPECT_NE(html.find("plot-timeline-gyro"), std::string::npos);
  // 12 statics, shaded in both timelines, labelled 1..12.
  EXPECT_EQ(Count(html, "fill=\"#cfe3f3\""), 2 * v.segments["intervals"].size());
  EXPECT_EQ(v.segments["intervals"].size(), 12u);
  EXPECT_NE(html.find(">12</text>"), std::string::npos);
  EXPECT_NE(html.find("href=\"/jobs/42\""), std::string::npos);
  EXPECT_NE(html.find("href=\"/devices/SN%201\""), std::string::npos);
  EXPECT_NE(html.find("href=\"/api/v1/recordings/7/data\""), std::string::npos);
  EXPECT_NE(html.find("href=\"/api/v1/recordings/7/segments\""), std::string::npos);
  EXPECT_NE(html.find("table-intervals"), std::string::npos);
  EXPECT_NE(html.find("1 gap(s)"), std::string::npos);
  // User strings never reach the page raw.
  EXPECT_EQ(html.find("<script>alert"), std::string::npos);
  EXPECT_EQ(html.find("<img src=x"), std::string::npos);
}

TEST(RecordingPage, AnHourLongLogIsDecimatedToABoundedPage) {
  const std::string html = RenderRecordingPage(View(3600));
  EXPECT_LT(html.size(), 1u << 20) << html.size();
  EXPECT_NE(html.find("decimated"), std::string::npos);
}

// A log of counts (|a| of 54 000 at rest) without accel_unit: the timelines say reading units,
// not m/s², and the page names the accel_unit that would convert them.
TEST(RecordingPage, ACountLogIsNotLabelledSI) {
  RecordingPageView v = View();
  EXPECT_NEAR(RestNorm(v), 9.81, 0.02);
  std::string html = RenderRecordingPage(v);
  EXPECT_NE(html.find("|a| (m/s\xC2\xB2)"), std::string::npos);
  EXPECT_NE(html.find("|\xCF\x89| (rad/s)"), std::string::npos);
  EXPECT_EQ(html.find("units-note"), std::string::npos);
  EXPECT_NE(html.find("threshold (SI)"), std::string::npos);
  for (auto& x : v.accel[0].norm) x *= 5500;  // counts: 1 g = 5500
  for (auto& x : v.gyro[0].norm) x *= 900;
  EXPECT_NEAR(RestNorm(v), 53955, 120);  // the statics only, not the motion between them
  html = RenderRecordingPage(v);
  EXPECT_EQ(html.find("|a| (m/s\xC2\xB2)"), std::string::npos);
  EXPECT_EQ(html.find("|\xCF\x89| (rad/s)"), std::string::npos);
  EXPECT_NE(html.find("|a| (reading units)"), std::string::npos);
  EXPECT_NE(html.find("|\xCF\x89| (reading units)"), std::string::npos);
  EXPECT_NE(html.find("The accelerometer norm at rest is 53955, not about 9.81"), std::string::npos)
      << html;
  EXPECT_NE(html.find("?accel_unit=1.818e-4"), std::string::npos);
  EXPECT_EQ(html.find("threshold (SI)"), std::string::npos);
  // Units given in the query: the norms are SI as given, questioned when not about 1 g at rest.
  v.accel_unit_given = v.gyro_unit_given = true;
  html = RenderRecordingPage(v);
  EXPECT_NE(html.find("|a| (m/s\xC2\xB2)"), std::string::npos);
  EXPECT_NE(html.find("With the accel_unit given, the accelerometer norm at rest is 53955 m/s"),
            std::string::npos);
  for (auto& x : v.accel[0].norm) x /= 5500;
  html = RenderRecordingPage(v);
  EXPECT_NE(html.find("|a| (m/s\xC2\xB2)"), std::string::npos);
  EXPECT_EQ(html.find("units-note"), std::string::npos);
  // No samples: no judgement against SI.
  v.accel.clear();
  EXPECT_TRUE(std::isnan(RestNorm(v)));
}

TEST(RecordingPage, WithoutSegmentsTheNoteSaysWhy) {
  RecordingPageView v = View();
  v.segments = nullptr;
  v.accel.clear();
  v.gyro.clear();
  v.segments_note = "No timeline: recording 7 has the pca_averaged layout";
  const std::string html = RenderRecordingPage(v);
  EXPECT_NE(html.find("No timeline: recording 7 has the pca_averaged layout"), std::string::npos);
  EXPECT_EQ(html.find("plot-timeline-accel"), std::string::npos);
}

TEST(RecordingPage, ASensorLogShowsItsStreamsImusAndWarningsEscaped) {
  RecordingPageView v = View();
  v.log = {{"format", "ulog"},
           {"time_base", "sensor_gyro:0 (timestamp_sample)"},
           {"warnings", {"log cut at byte 1234 <b>"}},
           {"streams",
            {{{"name", "sensor_accel:0"},
              {"kind", "accel"},
              {"device_id", 2490378},
              {"samples", 12000},
              {"rate", 1000.0},
              {"start", 1.5},
              {"end", 13.499},
              {"gaps", 2},
              {"unit", "m/s^2"},
              {"time_source", "timestamp_sample"},
              {"note", "<script>x</script>"}}}},
           {"imus",
            {{{"index", 0},
              {"accel", "sensor_accel:0"},
              {"gyro", "sensor_gyro:0"},
              {"temp", nullptr},
              {"samples", 12000},
              {"dropped", 0},
              {"resampled", json::array()}}}}};
  const std::string html = RenderRecordingPage(v);
  EXPECT_NE(html.find("<section id=\"log\">"), std::string::npos);
  EXPECT_NE(html.find("A ulog log"), std::string::npos);
  EXPECT_NE(html.find("sensor_gyro:0 (timestamp_sample)"), std::string::npos);
  EXPECT_NE(html.find("log cut at byte 1234 &lt;b&gt;"), std::string::npos);
  EXPECT_EQ(html.find("<script>x</script>"), std::string::npos);
  EXPECT_NE(html.find("2490378"), std::string::npos);
  EXPECT_NE(html.find("the log as uploaded"), std::string::npos);
  EXPECT_EQ(Count(html, "<tr><td>sensor_accel:0</td>"), 1u);

  v.log = nullptr;  // CSV: no such section
  EXPECT_EQ(RenderRecordingPage(v).find("id=\"log\""), std::string::npos);
}

// The check's predicted σ: every σ of the uncertainty shape by its largest value, per IMU (a
// band's grid reduced to its largest), covariances, grids and crb copies left out, names escaped;
// without a prediction, the reason.
TEST(RecordingPage, TheChecksPredictedSigmaIsListedOrItsReasonGiven) {
  RecordingPageView v = View();
  v.check_methods = {"thermal"};
  v.check_method = "thermal";
  v.check = json::parse(R"({"predicted": {"how": "white-noise <bound>", "uncertainty": {"imus": [
      {"name": "<0>",
       "accelerometer": {"bias": {"std": [[1e-3, 4e-3, 2e-3], [1e-3, 1e-3, 1e-3], [5e-3, 1e-3, 1e-3]],
                                  "covariance": [[[9.0]]], "temperatures": [20, 35, 50],
                                  "at_t_ref_std": null},
                         "scale": null},
       "crb": {"accelerometer": {"bias": {"std": [[7.0]]}}}}]}}})");
  const std::string page = CheckSection(v);
  EXPECT_NE(page.find("white-noise &lt;bound&gt;"), std::string::npos) << page;
  EXPECT_NE(page.find("IMU &lt;0&gt; accelerometer.bias.std</td><td class=\"num\">0.005"),
            std::string::npos)
      << page;
  EXPECT_EQ(Count(page, "<tr><td>"), 1u) << page;  // no covariance, grid, null σ or crb row
  EXPECT_EQ(page.find(">7<"), std::string::npos) << page;

  v.check = {{"predicted", {{"uncertainty", nullptr}, {"reason", "the windows span 4 °C"}}}};
  EXPECT_NE(CheckSection(v).find("No prediction: the windows span 4 °C"), std::string::npos);
}

}  // namespace
}  // namespace calibd::web
