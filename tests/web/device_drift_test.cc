// The device page's drift of the raw-log methods (methods/noise/noise_drift.h,
// methods/imu/imu_drift.h): the noise terms and the IMU intrinsics per calibration, their changes
// against the previous calibration in standard deviations, and the device page that shows them for
// accepted results only.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "methods/imu/imu_drift.h"
#include "methods/imu/imu_result.h"
#include "methods/noise/noise_drift.h"
#include "methods/noise/noise_result.h"
#include "web/drift_table.h"

namespace calibd::web {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

using json = nlohmann::json;

bool Has(const std::string& page, const std::string& needle) {
  return page.find(needle) != std::string::npos;
}

size_t Count(const std::string& page, const std::string& needle) {
  size_t n = 0;
  for (size_t p = page.find(needle); p != std::string::npos; p = page.find(needle, p + 1)) ++n;
  return n;
}

// A noise result (SPEC §7, methods/noise/noise_result.h) of one IMU: white noise `n_gyro` on the
// gyroscopes (1σ 1 %), K visible on the gyroscopes only when `gyro_k` > 0, B visible everywhere.
json NoiseResult(double n_gyro, double gyro_k, const std::string& extra_channel = "") {
  results::NoiseResult r;
  r.envelope.method = "noise";
  r.envelope.model = "the Allan variance";
  r.envelope.verdict = results::StoredVerdict{GateVerdict::kAccepted, {}, {}};
  std::vector<std::string> names = {"a0_x", "a0_y", "a0_z", "g0_x", "g0_y", "g0_z"};
  if (!extra_channel.empty()) names.push_back(extra_channel);
  const double kNaN = std::numeric_limits<double>::quiet_NaN();
  for (const std::string& name : names) {
    const bool gyro = name[0] == 'g';
    const double n = gyro ? n_gyro : 2e-3;
    const double k = gyro && gyro_k > 0 ? gyro_k : kNaN;
    r.channels.push_back({name, gyro ? "rad/s" : "m/s^2", n, 0.5 * n, 120.0, k});
    r.channel_stds.push_back({name, 0.01 * n, 0.1 * n, 0.2 * k, "crb", 1.0, std::nullopt});
  }
  return results::ToJson(r);
}

// An imu result (SPEC §7, methods/imu/imu_result.h) of IMU `name`: accelerometer x scale `ax_scale`
// (1σ 1e-6), bias x `bias_x` (1σ 0.5), misalignment T_a(0,1) = `t01`.
json ImuResult(const std::string& name, double ax_scale, double bias_x, double t01) {
  results::ImuResult r;
  r.envelope.method = "imu";
  r.envelope.model = "a = T_a K_a (y_a - b_a)";
  r.envelope.verdict = results::StoredVerdict{GateVerdict::kAccepted, {}, {}};
  results::SensorTriad accel, gyro;
  accel.scale = Eigen::Vector3d(ax_scale, 1.0, 1.0);
  accel.bias = Eigen::Vector3d(bias_x, 0.0, 0.0);
  accel.misalignment(0, 1) = t01;
  gyro.bias = Eigen::Vector3d(0.01, 0.02, 0.03);
  results::SensorTriadStd sd;
  sd.scale_std = Eigen::Vector3d::Constant(1e-6);
  sd.bias_std = Eigen::Vector3d::Constant(0.5);
  sd.misalignment_std << 0, 1e-4, 1e-4, 0, 0, 1e-4, 0, 0, 0;
  r.parameters = results::ImuParameters{9.80665, "statics", 1.0, 1.0, {{name, accel, gyro}}};
  r.uncertainty = results::ImuUncertainty{"crb", kNan, {{name, sd, sd}}, {}};
  return results::ToJson(r);
}

JobSummary Job(int64_t id, const std::string& method, const std::string& created, json result) {
  JobSummary j;
  j.id = id;
  j.device = "IMU-9";
  j.method = method;
  j.status = JobStatus::kSucceeded;
  j.created_at = j.started_at = j.finished_at = created;
  j.attempts = 1;
  j.result = std::move(result);
  return j;
}

TEST(NoiseDrift, ListsTheTermsPerCalibrationAndMarksAChangeBeyondThreeSigma) {
  const JobSummary a = Job(4, "noise", "2026-01-01T00:00:00Z", NoiseResult(1e-4, 0));
  // Gyroscope white noise up 10 % (6.7 σ of the difference), K now visible.
  const JobSummary b = Job(9, "noise", "2026-02-01T00:00:00Z", NoiseResult(1.1e-4, 3e-6));
  const std::string html = NoiseDriftHtml({&a, &b});
  EXPECT_EQ(Count(html, "<table class=\"table-drift-noise\""), 2u);
  EXPECT_TRUE(Has(html, "data-sensor=\"accelerometer\""));
  EXPECT_TRUE(Has(html, "data-sensor=\"gyroscope\""));
  // Units of each term, per sensor type.
  EXPECT_TRUE(Has(html, "white noise N (m/s\xC2\xB2/\xE2\x88\x9AHz)"));
  EXPECT_TRUE(Has(html, "random walk K (rad/s/s/\xE2\x88\x9AHz)"));
  // Both calibrations, the values with 1σ.
  EXPECT_TRUE(Has(html, "href=\"/jobs/4\""));
  EXPECT_TRUE(Has(html, "href=\"/jobs/9\""));
  EXPECT_TRUE(Has(html, "1.100e-4 \xC2\xB1 1.1e-6"));
  // The change: +10 % at 6.7 σ, marked on the three gyroscope axes only; the accelerometer's
  // terms did not move (0 %, 0 σ).
  EXPECT_TRUE(Has(html, "+10.0 %"));
  EXPECT_TRUE(Has(html, "(6.7 \xCF\x83)"));
  EXPECT_EQ(Count(html, "drift-significant"), 3u);
  EXPECT_TRUE(Has(html, "now visible"));
  EXPECT_TRUE(Has(html, "not visible"));
  EXPECT_TRUE(Has(html, "class=\"plot plot-drift-noise-accel\""));
  EXPECT_TRUE(Has(html, "class=\"plot plot-drift-noise-gyro\""));
  // The older calibration's rows come first (over time), each row's channel named.
  EXPECT_LT(html.find("/jobs/4\""), html.find("/jobs/9\""));
  EXPECT_EQ(Count(html, "<td class=\"name\">g0_y</td>"), 2u);
}

TEST(NoiseDrift, ComparesEachChannelWithTheLastCalibrationThatHadItAndEscapesNames) {
  const JobSummary a =
      Job(1, "noise", "2026-01-01T00:00:00Z", NoiseResult(1e-4, 0, "g1_<script>x"));
  const JobSummary b = Job(2, "noise", "2026-01-02T00:00:00Z", NoiseResult(1e-4, 0));
  const JobSummary c =
      Job(3, "noise", "2026-01-03T00:00:00Z", NoiseResult(1e-4, 0, "g1_<script>x"));
  const std::string html = NoiseDriftHtml({&a, &b, &c});
  EXPECT_FALSE(Has(html, "<script"));
  EXPECT_TRUE(Has(html, "g1_&lt;script&gt;x"));
  // Job 3's g1 channel is compared with job 1 (job 2 does not have it): a change, not "first".
  EXPECT_EQ(Count(html, ">first</td>"), 7u * 3);  // job 1 only: 7 channels × 3 terms
}

TEST(ImuDrift, ShowsScalesMisalignmentsAndBiasesWithTheirChangesInSigma) {
  const JobSummary a = Job(5, "imu", "2026-01-01T00:00:00Z", ImuResult("0", 1.0, 10.0, 0.0));
  // Scale x +100 ppm (70 σ), bias x +0.4 (0.57 σ), T(0,1) +0.2 mrad (1.4 σ).
  const JobSummary b = Job(6, "imu", "2026-01-05T00:00:00Z", ImuResult("0", 1.0001, 10.4, 2e-4));
  const std::string html = ImuDriftHtml({&a, &b});
  EXPECT_EQ(Count(html, "<table class=\"table-drift-imu\""), 1u);
  EXPECT_TRUE(Has(html, "+100.0 ppm"));
  EXPECT_TRUE(Has(html, "(71 \xCF\x83)"));
  EXPECT_TRUE(Has(html, "+0.200 mrad (xy)"));
  EXPECT_TRUE(Has(html, "(1.4 \xCF\x83)"));
  EXPECT_TRUE(Has(html, "+0.400 <span"));
  EXPECT_TRUE(Has(html, "(0.57 \xCF\x83)"));
  // Only the accelerometer's scale cell of the second calibration is marked.
  EXPECT_EQ(Count(html, "drift-significant"), 1u);
  EXPECT_TRUE(Has(html, "1.000100 \xC2\xB1 1.0e-6"));
  EXPECT_TRUE(Has(html, "0.20 0.00"));  // T − I in mrad, first row of the second calibration
  // The rows of T − I are collapsed under its largest entry (the table fits 1280 px).
  EXPECT_TRUE(Has(html, "<details><summary>max 0.20</summary>0.00 0.20 0.00<br>"));
  // Both sensors of the first calibration and the gyroscope of the second are the identity.
  EXPECT_EQ(Count(html, "<details><summary>max 0.00</summary>"), 3u);
  EXPECT_TRUE(Has(html, "class=\"plot plot-drift-imu-scale\""));
  EXPECT_EQ(Count(html, "<td>accelerometer</td>"), 2u);
  EXPECT_EQ(Count(html, "<td>gyroscope</td>"), 2u);
}

TEST(ImuDrift, MalformedResultsRenderWithoutThrowing) {
  const JobSummary a = Job(1, "imu", "x", json{{"parameters", {{"imus", "nope"}}}});
  const JobSummary b = Job(2, "imu", "", json{{"parameters", {{"imus", {{{"name", 3}}}}}}});
  const JobSummary c = Job(3, "noise", "", json::array());
  EXPECT_NO_THROW(ImuDriftHtml({&a, &b}));
  EXPECT_NO_THROW(NoiseDriftHtml({&a, &c}));
  EXPECT_TRUE(Has(NoiseDriftHtml({&a, &c}), "No noise terms"));
  EXPECT_EQ(NoiseDriftHtml({}), "");
}

TEST(ImuDrift, AResultThatDoesNotReadIsListedWithThePathOfItsProblem) {
  const JobSummary a = Job(5, "imu", "2026-01-01T00:00:00Z", ImuResult("0", 1.0, 10.0, 0.0));
  json damaged = ImuResult("0", 1.0001, 10.4, 2e-4);
  damaged["parameters"]["imus"][0]["accelerometer"]["scale"] = "1.0001";
  const JobSummary b = Job(6, "imu", "2026-01-05T00:00:00Z", damaged);
  const std::string html = ImuDriftHtml({&a, &b});
  // Job 5 is shown; job 6 is listed as not available, naming the path.
  EXPECT_EQ(Count(html, "<td>accelerometer</td>"), 1u);
  EXPECT_TRUE(Has(html, "drift-unreadable")) << html;
  EXPECT_TRUE(Has(html, "parameters.imus[0].accelerometer.scale")) << html;
}

TEST(NoiseDrift, AResultThatDoesNotReadIsListedWithThePathOfItsProblem) {
  const JobSummary n = Job(7, "noise", "2026-01-01T00:00:00Z", NoiseResult(1e-4, 0));
  json newer = NoiseResult(1e-4, 0);
  newer["schema_version"] = 99;
  const JobSummary m = Job(8, "noise", "2026-01-02T00:00:00Z", newer);
  const std::string noise = NoiseDriftHtml({&n, &m});
  EXPECT_TRUE(Has(noise, "table-drift-noise"));
  EXPECT_TRUE(Has(noise, "href=\"/jobs/8\">#8</a>: not available")) << noise;
  EXPECT_TRUE(Has(noise, "schema_version")) << noise;
}

TEST(DevicePage, ShowsNoiseAndImuDriftOfAcceptedCalibrationsOnly) {
  DeviceView d;
  d.serial = "IMU-9";
  d.jobs = {Job(1, "noise", "2026-01-01T00:00:00Z", NoiseResult(1e-4, 0)),
            Job(2, "imu", "2026-01-02T00:00:00Z", ImuResult("0", 1.0, 10.0, 0.0)),
            Job(3, "noise", "2026-02-01T00:00:00Z", NoiseResult(1.1e-4, 0)),
            Job(4, "imu", "2026-02-02T00:00:00Z", ImuResult("0", 1.0001, 10.4, 2e-4)),
            Job(5, "noise", "2026-03-01T00:00:00Z", NoiseResult(9e-4, 0))};
  d.jobs.back().state = ServeState::kRevoked;
  const std::string page = RenderDevicePage(d);
  EXPECT_TRUE(Has(page, "class=\"page-device"));
  EXPECT_TRUE(Has(page, "table-drift-noise"));
  EXPECT_TRUE(Has(page, "table-drift-imu"));
  EXPECT_TRUE(Has(page, "noise (2 accepted calibrations"));
  EXPECT_TRUE(Has(page, "imu (2 accepted calibrations"));
  // The revoked job is not in the drift (it is still in the calibrations table).
  const size_t drift = page.find("id=\"drift\"");
  ASSERT_NE(drift, std::string::npos);
  EXPECT_EQ(page.find("href=\"/jobs/5\"", drift), std::string::npos);
}

}  // namespace
}  // namespace calibd::web
