#include "web/pages.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "methods/array/array_result.h"
#include "methods/imu/imu_result.h"
#include "methods/noise/noise_result.h"

namespace calibd::web {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

using json = nlohmann::json;

const char kScript[] = "<script>alert(1)</script>";
const char kImg[] = "\"><img src=x onerror=alert(1)>";

// Deterministic small "noise" for fixtures.
double Wiggle(int i, double scale) { return scale * std::sin(1.7 * i + 0.3 * i * i); }

// diagnostics.coverage of a pca result.
json PcaCoverage(const std::string& verdict, const std::string& advice) {
  return {{"verdict", verdict},
          {"scatter_eigenvalues", {0.3, 0.33, 0.37}},
          {"scatter_min", 0.9},
          {"design_min", 0.8},
          {"positions_per_direction", {{"+x", 2}, {"-x", 2}}},
          {"advice", advice}};
}

// A pca result as calibd would store it: 4 gyroscope triads (12 sensors), d = 3, n = 24,
// nominal frame, known magnitude.
json PcaResult(const std::string& sensor_prefix = "g", double scale_shift = 0) {
  json sensors = json::array(), unc = json::array(), rms = json::array();
  for (int i = 0; i < 12; ++i) {
    const int axis = i % 3;
    std::vector<double> a{0, 0, 0};
    a[axis] = 1;
    a[(axis + 1) % 3] = Wiggle(i, 0.01);
    a[(axis + 2) % 3] = Wiggle(i + 5, 0.01);
    const double n = std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
    for (double& v : a) v /= n;
    const double scale = 1 + Wiggle(i + 11, 0.02) + scale_shift;
    const std::string name = sensor_prefix + std::to_string(i / 3) + "_" + "xyz"[axis];
    sensors.push_back({{"name", name},
                       {"sensitivity", {a[0] * scale, a[1] * scale, a[2] * scale}},
                       {"scale", scale},
                       {"axis", a},
                       {"bias", 0}});
    unc.push_back({{"name", name},
                   {"scale_std", 0.0014 + Wiggle(i, 0.0002)},
                   {"axis_std_rad", 0.0011},
                   {"bias_std", 0}});
    rms.push_back(0.0098 + Wiggle(i + 3, 0.001));
  }
  json sv = json::array({8.91, 8.52, 8.07});
  for (int i = 0; i < 9; ++i) sv.push_back(0.052 - 0.003 * i);
  json mag = json::array();
  for (int j = 0; j < 24; ++j) mag.push_back(Wiggle(j, 0.012));
  // Every key of the typed result (methods/pca/pca_result.h): the report reads it through FromJson.
  return {{"method", "pca"},
          {"schema_version", 1},
          {"model", "r_i = a_i^T v + b_i"},
          {"parameters",
           {{"dimension", 3},
            {"magnitude", 1.0},
            {"magnitude_known", true},
            {"frame", "nominal"},
            {"bias", "none"},
            {"sensors", sensors}}},
          {"uncertainty", {{"sensors", unc}, {"noise_std", 0.01}}},
          {"diagnostics",
           {{"singular_values", sv},
            {"rank_gap", 8.07 / 0.052},
            {"positions", 24},
            {"min_positions", 6},
            {"g_eigenvalues", {0.0151, 0.0137, 0.0126}},
            {"residual_rms", rms},
            {"magnitude_error", mag},
            {"degrees_of_freedom", 222},
            {"coverage", PcaCoverage("good", "")},
            {"usable", true},
            {"noise_std", 0.01},
            {"noise_std_given", false},
            {"noise_std_estimated", 0.01},
            {"cost_closed_form", 0.0112},
            {"cost", 0.0111},
            {"refined", false},
            {"refine_iterations", 0},
            {"reflection", false}}},
          {"warnings", json::array()}};
}

json PcaConfig() {
  json nominal = json::array();
  for (int i = 0; i < 12; ++i) {
    std::vector<double> a{0, 0, 0};
    a[i % 3] = 1;
    nominal.push_back(a);
  }
  return {{"method", "pca"}, {"device", "IMU-0042"}, {"magnitude", 1.0}, {"nominal", nominal}};
}

// An array result (methods/array/array_result.h, every key the server writes): 32 triads on a 4x4
// grid, top and underside, 6.3 mm pitch, 2 mm apart; |omega| and |omega_dot| of
// `excitation_samples` samples, kept as the server does (at most 2000 points, every stride-th
// sample).
json ArrayResult(size_t excitation_samples = 1000, double shift = 0) {
  results::ArrayResult r;
  r.envelope.method = "array";
  r.envelope.model = "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k";
  r.envelope.warnings = {"3 samples dropped at gyroscope saturation"};
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  for (int k = 0; k < 32; ++k) {
    const double x = 6.3e-3 * (k % 4), y = 6.3e-3 * ((k / 4) % 4), z = k < 16 ? 0 : -2e-3;
    const double o[3] = {k == 0 ? 0 : Wiggle(k, 1e-3) + shift, k == 0 ? 0 : Wiggle(k + 7, 1e-3),
                         k == 0 ? 0 : Wiggle(k + 13, 1e-3)};
    const std::string name = "a" + std::to_string(k);
    params.positions.push_back({name, {x + o[0], y + o[1], z + o[2]}, {o[0], o[1], o[2]}});
    const double s = k == 0 ? 0 : 2.0e-6 + Wiggle(k, 0.3e-6);
    unc.positions.push_back({name, {s, s * 1.1, s * 0.9}, std::nullopt});
  }
  unc.std_rms = 2e-6;
  r.parameters = params;
  r.uncertainty = unc;
  results::ArrayPositionsDiagnostics& d = r.diagnostics;
  d.solver = "joint";
  d.termination = "converged";
  d.iterations = 5;
  d.samples = static_cast<int64_t>(excitation_samples);
  d.samples_dropped = 3;
  d.gyro_triads = 32;
  d.gyro_unit = "deg/s";
  d.excitation.min_eigenvalue = 1.7e5;
  d.excitation.max_eigenvalue = 3e5;
  d.excitation.noise_floor = 10;
  d.excitation.weakest_direction = {0, 0, 1};
  d.excitation.verdict = "good";
  d.converged = true;
  d.cost = {5.2e7, 3.1e4, 2.9e3, 2.87e3, 2.869e3};
  d.residual_rms = {0.0401, 0.0597};
  d.noise_estimate = {0.0399, 0.0602};
  d.noise_configured = {0.04, 0.06};
  d.parallel_fraction = 0.9;
  d.motion.stride = std::max<int64_t>(1, (static_cast<int64_t>(excitation_samples) + 1999) / 2000);
  for (size_t n = 0; n < excitation_samples; n += static_cast<size_t>(d.motion.stride)) {
    d.motion.omega_norm.push_back(30 + 5 * std::sin(n * 0.01) +
                                  Wiggle(static_cast<int>(n % 1000), 1));
    d.motion.omega_dot_norm.push_back(35 + 8 * std::cos(n * 0.013));
  }
  return results::ToJson(r);
}

json ArrayConfig() {
  json pos = json::array();
  for (int k = 0; k < 32; ++k) {
    pos.push_back({6.3e-3 * (k % 4), 6.3e-3 * ((k / 4) % 4), k < 16 ? 0 : -2e-3});
  }
  return {{"method", "array"},
          {"device", "ARRAY-7"},
          {"geometry", {{"positions", pos}, {"reference", 0}}},
          {"accel_noise", 0.04},
          {"gyro_noise", 0.06},
          {"gyro_unit", "deg/s"}};
}

JobSummary Job(int64_t id, const std::string& device, const std::string& method,
               const std::string& status, const std::string& created, json result) {
  JobSummary j;
  j.id = id;
  j.device = device;
  j.method = method;
  Parse(status, &j.status);
  j.created_at = created;
  if (status != "queued") j.started_at = created;
  if (status == "succeeded" || status == "failed") j.finished_at = created;
  j.attempts = status == "queued" ? 0 : 1;
  j.result = std::move(result);
  return j;
}

size_t Count(const std::string& page, const std::string& needle) {
  size_t n = 0;
  for (size_t p = page.find(needle); p != std::string::npos; p = page.find(needle, p + 1)) ++n;
  return n;
}

bool Has(const std::string& page, const std::string& needle) {
  return page.find(needle) != std::string::npos;
}

// The page is a complete document with our body class.
void ExpectDocument(const std::string& page, const std::string& body_class) {
  EXPECT_EQ(page.rfind("<!doctype html>", 0), 0u);
  EXPECT_TRUE(Has(page, "<body class=\"" + body_class + "\">"));
  EXPECT_TRUE(Has(page, "</html>"));
  EXPECT_FALSE(Has(page, "<script"));
  EXPECT_FALSE(Has(page, "<link "));  // no external resources
  EXPECT_FALSE(Has(page, "http://") && !Has(page, "http://www.w3.org/2000/svg"));
  EXPECT_FALSE(Has(page, "nan\""));
  EXPECT_FALSE(Has(page, "not be rendered completely"));
}

// Hostile strings never appear unescaped: no "<script", no "<img", and every "onerror=" is
// inside an escaped (inert) "&lt;img" text.
void ExpectNoInjection(const std::string& page) {
  EXPECT_EQ(page.find("<script"), std::string::npos);
  EXPECT_EQ(page.find("<img"), std::string::npos);
  for (size_t p = page.find("onerror="); p != std::string::npos; p = page.find("onerror=", p + 1)) {
    ASSERT_GE(p, 14u);
    EXPECT_EQ(page.substr(p - 14, 14), "&lt;img src=x ") << page.substr(p - 14, 40);
  }
}

TEST(JobPage, PcaReportHasParametersPlotsAndDownloads) {
  JobView v;
  v.job = Job(17, "IMU-0042", "pca", "succeeded", "2026-11-20T09:15:02Z", PcaResult());
  v.job.finished_at = "2026-11-20T09:15:04.250Z";
  v.recording_id = 5;
  v.recording_bytes = 18234;
  v.recording_rows = 24;
  v.recording_sha256 = "9f86d081884c7d659a2feaa0c55ad015a3bf4f1b2b0b822cd15d6c15b0f00a08";
  v.config = PcaConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "class=\"table-pca-parameters\""));
  EXPECT_TRUE(Has(page, "angle to<br>nominal<br>(mrad)"));
  EXPECT_TRUE(Has(page, "class=\"table-diagnostics\""));
  for (const char* plot :
       {"singular-values", "magnitude-error", "residual-rms", "axes-xy", "axes-xz"}) {
    EXPECT_TRUE(Has(page, std::string("class=\"plot plot-") + plot + "\"")) << plot;
  }
  EXPECT_TRUE(Has(page, "href=\"/api/v1/recordings/5/data\""));
  EXPECT_TRUE(Has(page, "href=\"/api/v1/jobs/17\""));
  EXPECT_TRUE(Has(page, "/api/v1/devices/IMU-0042/calibration?method=pca&amp;format=csv"));
  EXPECT_TRUE(Has(page, "/api/v1/devices/IMU-0042/calibration?method=pca&amp;format=h"));
  EXPECT_TRUE(Has(page, "href=\"/devices/IMU-0042\""));
  EXPECT_TRUE(Has(page, "class=\"config\""));
  EXPECT_TRUE(Has(page, "ran 2.2 s"));
  EXPECT_TRUE(Has(page, "callout-ok"));
  EXPECT_TRUE(Has(page,
                  "gap \xCF\x83"
                  "3/\xCF\x83"
                  "4 = 155"));
  EXPECT_LT(page.size(), 300u * 1024u);
}

TEST(JobPage, ArrayReportHasPositionsCostResidualsAndExcitation) {
  JobView v;
  v.job = Job(23, "ARRAY-7", "array", "succeeded", "2026-11-21 10:00:00", ArrayResult());
  v.recording_id = 9;
  v.config = ArrayConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "class=\"table-array-parameters\""));
  EXPECT_TRUE(Has(page, "(reference, fixed)"));
  for (const char* plot : {"cost", "positions-xy", "positions-xz", "position-sigma", "residual-rms",
                           "excitation-omega", "excitation-omega-dot"}) {
    EXPECT_TRUE(Has(page, std::string("class=\"plot plot-") + plot + "\"")) << plot;
  }
  EXPECT_TRUE(Has(page, "Offsets from nominal magnified \xC3\x97"));
  EXPECT_TRUE(Has(page, "class=\"ellipses\""));
  EXPECT_TRUE(Has(page, "gyroscope (\xC2\xB0/s)"));
  EXPECT_TRUE(Has(page, "(converged)"));
  EXPECT_TRUE(Has(page, "3 samples dropped at gyroscope saturation"));
  EXPECT_TRUE(Has(page, "callout-warn"));
}

TEST(JobPage, ArrayReportLinksTheAccelerometerCalibrationItUsed) {
  JobView v;
  json result = ArrayResult();
  result["diagnostics"]["accelerometer_calibration"] = {
      {"job", 17},       {"sensors", 96},    {"frame", "nominal"},
      {"bias", nullptr}, {"magnitude", 9.8}, {"max_condition_number", 1.01}};
  v.job = Job(23, "ARRAY-7", "array", "succeeded", "2026-11-21 10:00:00", result);
  const std::string page = RenderJobPage(v);
  EXPECT_TRUE(Has(page, "<a href=\"/jobs/17\">job #17</a>")) << page.substr(0, 3000);
  EXPECT_TRUE(Has(page, "(96 sensors)"));
  result["diagnostics"]["accelerometer_calibration"] = nullptr;  // none used: no line
  v.job.result = result;
  EXPECT_FALSE(Has(RenderJobPage(v), "accelerometer-calibration"));
}

TEST(JobPage, HundredThousandSampleExcitationKeepsPageUnderOneMegabyte) {
  JobView v;
  v.job = Job(24, "ARRAY-7", "array", "succeeded", "2026-11-21 10:00:00", ArrayResult(100000));
  v.config = ArrayConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "plot-excitation-omega\""));
  EXPECT_TRUE(Has(page, "decimated"));
  EXPECT_LT(page.size(), 1024u * 1024u);
  EXPECT_LT(page.size(), 400u * 1024u);
}

// The method's message is the one source of requirements and advice: the page shows it once and
// adds no generic advice that could contradict it (a minimum of 6 positions when the method,
// estimating biases, needs 9) or suggest a setting the config already has.
TEST(JobPage, FailedJobShowsTheMethodsMessageOnceAndNothingThatContradictsIt) {
  JobView v;
  const std::string message =
      "7 positions recorded, but dimension 3 with unknown biases needs at least 9 (d(d+3)/2); "
      "record at least 9 positions with orientations spread over the sphere";
  v.job = Job(31, "IMU-0042", "pca", "failed", "2026-11-20T09:20:00Z", json());
  v.job.error = message;
  v.config = PcaConfig();
  v.config["bias"] = "estimate";
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "callout-error"));
  EXPECT_TRUE(Has(page, "badge-failed"));
  const std::string escaped = "7 positions recorded, but dimension 3 with unknown biases needs";
  const size_t at = page.find(escaped);
  ASSERT_NE(at, std::string::npos);
  EXPECT_EQ(page.find(escaped, at + 1), std::string::npos) << "the message is shown once";
  EXPECT_FALSE(Has(page, "6 for d = 3"));
  EXPECT_FALSE(Has(page, "d(d+1)/2"));
  // "bias": "estimate" appears in the config block only, never as advice.
  EXPECT_FALSE(Has(page, "configure"));
  EXPECT_FALSE(Has(page, "class=\"advice\""));
  EXPECT_FALSE(Has(page, "class=\"plot "));
}

// "reflection" is explained where the diagnostics show it: a mirror image, normal either way.
// Which σ the pca tables show (the σ convention): said under the table for each basis.
TEST(JobPage, PcaReportSaysWhichSigmaItShows) {
  auto page_with = [](const json& basis, const json& chi2) {
    json r = PcaResult();
    if (basis.is_null()) {
      r["uncertainty"].erase("basis");
      r["uncertainty"].erase("chi2_per_dof");
    } else {
      r["uncertainty"]["basis"] = basis;
      r["uncertainty"]["chi2_per_dof"] = chi2;
    }
    JobView v;
    v.job = Job(17, "IMU-0042", "pca", "succeeded", "2026-11-20T09:15:02Z", r);
    v.config = PcaConfig();
    return RenderJobPage(v);
  };
  EXPECT_TRUE(Has(page_with("chi2_scaled", 9.0), "scaled by the residuals"));
  EXPECT_TRUE(Has(page_with("chi2_scaled", nullptr), "at the noise the residuals estimate"));
  EXPECT_TRUE(Has(page_with("crb", 1.02), "at the given noise_std"));
  EXPECT_TRUE(Has(page_with(nullptr, nullptr), "stored by an earlier calibd"));
}

// Which σ the noise table shows (the σ convention, issue 28): said under the table.
TEST(JobPage, NoiseReportSaysWhichSigmaItShows) {
  auto page_with = [](const char* basis) {
    results::NoiseResult noise;
    noise.envelope.method = "noise";
    noise.envelope.model = "the Allan variance";
    noise.channels = {{"a0_x", "m/s^2", 2e-3, NAN, NAN, NAN}};
    noise.channel_stds = {{"a0_x", 4.4e-5, NAN, NAN, basis, 19.36, std::nullopt}};
    if (std::string(basis) != results::kNoiseBasisCrbOnly) {
      noise.basis = basis;
      noise.chi2_per_dof = 19.36;
      noise.channel_stds[0].crb = results::NoiseTermStds{1e-5, NAN, NAN};
    }
    JobView v;
    v.job =
        Job(43, "IMU-0042", "noise", "succeeded", "2026-11-20T09:20:00Z", results::ToJson(noise));
    return RenderJobPage(v);
  };
  EXPECT_TRUE(Has(page_with("chi2_scaled"),
                  "a0_x \xC3\x97"
                  "4.4"));
  EXPECT_TRUE(Has(page_with("crb"), "follows N/B/K within its intervals"));
  EXPECT_TRUE(Has(page_with(results::kNoiseBasisCrbOnly), "stored by an earlier calibd"));
}

TEST(JobPage, PcaReflectionIsExplainedWhereShown) {
  JobView v;
  json r = PcaResult();
  r["diagnostics"]["reflection"] = true;
  v.job = Job(33, "IMU-0042", "pca", "succeeded", "2026-11-20T09:20:00Z", r);
  v.config = PcaConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "mirror image"));
  EXPECT_TRUE(Has(page, "either value is normal"));
}

// A stored pca result the typed reader (methods/pca/pca_result.h) refuses: the report says "not
// available" with the reader's message naming the path; the key figures say so too.
TEST(JobPage, PcaResultThatDoesNotReadShowsNotAvailableNamingThePath) {
  JobView v;
  json r = PcaResult();
  r["parameters"]["sensors"][1]["scale"] = "big";
  v.job = Job(37, "IMU-0042", "pca", "succeeded", "2026-11-20T09:20:00Z", r);
  v.config = PcaConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "The pca report: not available.")) << page;
  EXPECT_TRUE(Has(page,
                  "pca result: parameters.sensors[1].scale: expected a number, found a "
                  "string"));
  EXPECT_FALSE(Has(page, "table-pca-parameters"));
  EXPECT_EQ(KeyFigures("pca", r).rfind("not available: pca result: parameters.sensors[1].scale", 0),
            0u)
      << KeyFigures("pca", r);
  // The drift table names the calibration it could not read and compares the others.
  DeviceView d;
  d.serial = "IMU-0042";
  d.jobs = {Job(1, "IMU-0042", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult()),
            Job(2, "IMU-0042", "pca", "succeeded", "2026-02-01T08:00:00Z", r),
            Job(3, "IMU-0042", "pca", "succeeded", "2026-03-01T08:00:00Z", PcaResult("g", 2e-4))};
  const std::string device = RenderDevicePage(d);
  ExpectDocument(device, "page-device");
  EXPECT_TRUE(Has(device, "Calibration 2: not available.")) << device;
  EXPECT_TRUE(Has(device, "class=\"table-drift-pca\""));
}

// A failed job: the reason's title, the method's message and the catalog's advice, each once,
// then what the method found before failing drawn by its report (pca: the singular values; the
// partial result has diagnostics.usable == false) and the diagnostics table. No parameters.
TEST(JobPage, FailedPcaJobShowsReasonMessageAdviceOnceAndThePartialDiagnostics) {
  JobView v;
  v.job = Job(34, "IMU-0042", "pca", "failed", "2026-11-20T09:20:00Z", json());
  v.job.error = "no clear gap between singular values 3 and 4 (ratio 1.01)";
  v.job.error_reason = "no_rank_gap";
  v.job.error_title = "No clear rank gap";
  v.job.error_advice = "Record positions whose field directions differ more.";
  v.job.error_detail = {{"method", "pca"},
                        {"usable", false},
                        {"diagnostics",
                         {{"usable", false},
                          {"reason", "no clear gap"},
                          {"singular_values", {9.1, 8.7, 0.0102, 0.0101, 0.0099, 0.0098}},
                          {"rank_gap", 1.01},
                          {"positions", 12},
                          {"min_positions", 6},
                          {"g_eigenvalues", json::array()},
                          {"residual_rms", json::array()},
                          {"magnitude_error", json::array()},
                          {"degrees_of_freedom", -1},
                          {"coverage", PcaCoverage("poor", "add positions with z up")},
                          {"noise_std", nullptr},
                          {"noise_std_given", false},
                          {"noise_std_estimated", nullptr},
                          {"cost_closed_form", nullptr},
                          {"cost", nullptr},
                          {"refined", false},
                          {"refine_iterations", 0},
                          {"reflection", false}}},
                        {"warnings", json::array()}};
  v.config = PcaConfig();
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  for (const std::string& once :
       {std::string("No clear rank gap"), std::string("no clear gap between singular values 3"),
        std::string("Record positions whose field directions differ more.")}) {
    const size_t at = page.find(once);
    ASSERT_NE(at, std::string::npos) << once;
    EXPECT_EQ(page.find(once, at + 1), std::string::npos) << once << " is shown once";
  }
  EXPECT_TRUE(Has(page, "failure-code"));
  EXPECT_TRUE(Has(page, "id=\"partial\""));
  EXPECT_TRUE(Has(page, "plot-singular-values"));
  EXPECT_TRUE(Has(page, "12 (minimum 6)"));
  EXPECT_TRUE(Has(page, "add positions with z up"));
  EXPECT_TRUE(Has(page, "table-diagnostics"));
  EXPECT_FALSE(Has(page, "id=\"parameters\""));
}

TEST(JobPage, FailedImuJobShowsTheStaticsFoundOnTheTimelineAndTheCoverage) {
  JobView v;
  v.job = Job(35, "IMU-0042", "imu", "failed", "2026-11-20T09:20:00Z", json());
  v.job.error = "found 3 static intervals, at least 9 are needed";
  v.job.error_reason = "too_few_statics";
  v.job.error_title = "Too few static intervals";
  v.job.error_advice = "Hold the device still in more orientations.";
  // The partial diagnostics as the imu adapter writes them (methods/imu/imu_result.h).
  results::ImuResult partial;
  partial.envelope.method = "imu";
  partial.envelope.usable = false;
  for (int i = 0; i < 3; ++i) partial.diagnostics.statics.push_back({10.0 * i, 10.0 * i + 4, 400});
  partial.diagnostics.rate = 100;
  partial.diagnostics.threshold_choice = "single multiplier given";
  results::ImuFitDiagnostics imu;
  imu.name = "0";
  imu.termination = "too_few_statics";
  imu.coverage.verdict = "missing: z up, z down";
  imu.coverage.missing_up = {"+z", "-z"};
  partial.diagnostics.imus = {imu};
  v.job.error_detail = results::ToJson(partial);
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "plot-imu-statics-found"));
  EXPECT_TRUE(Has(page, "missing: z up, z down"));
  EXPECT_TRUE(Has(page, "+z, -z"));
  EXPECT_TRUE(Has(page, "Hold the device still in more orientations."));
}

TEST(JobPage, FailedNoiseAndArrayJobsShowWhatWasFound) {
  JobView noise;
  noise.job = Job(37, "IMU-0042", "noise", "failed", "2026-11-20T09:20:00Z", json());
  noise.job.error = "the log is not stationary";
  // The partial diagnostics as the noise adapter writes them (methods/noise/noise_result.h).
  results::NoiseResult partial;
  partial.envelope.method = "noise";
  partial.envelope.usable = false;
  partial.diagnostics.samples = 6000;
  partial.diagnostics.rate = 100;
  partial.diagnostics.duration = 60;
  partial.diagnostics.stationary = false;
  partial.diagnostics.channels = {{"a0_x", "not_stationary", "the mean jumps at 30 s", 0, NAN, 0}};
  noise.job.error_detail = results::ToJson(partial);
  std::string page = RenderJobPage(noise);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "table-noise-channels"));
  EXPECT_TRUE(Has(page, "the mean jumps at 30 s"));
  JobView array;
  array.job = Job(38, "ARRAY-1", "array", "failed", "2026-11-20T09:20:00Z", json());
  array.job.error = "the motion does not determine the positions";
  results::ArrayResult array_partial;  // as the server keeps it (methods/array/array_result.h)
  array_partial.envelope.method = "array";
  array_partial.envelope.usable = false;
  array_partial.diagnostics.solver = "joint";
  array_partial.diagnostics.termination = "not_determinable";
  array_partial.diagnostics.samples = 900;
  array_partial.diagnostics.samples_dropped = 100;
  array_partial.diagnostics.gyro_triads = 4;
  array_partial.diagnostics.gyro_unit = "rad/s";
  array_partial.diagnostics.excitation.verdict = "insufficient";
  array_partial.diagnostics.excitation.min_eigenvalue = 1e-3;
  array_partial.diagnostics.excitation.noise_floor = 2e-3;
  array.job.error_detail = results::ToJson(array_partial);
  page = RenderJobPage(array);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "partial-array"));
  EXPECT_TRUE(Has(page, "insufficient (smallest eigenvalue"));
  EXPECT_TRUE(Has(page, "100 dropped for gyroscope saturation"));
}

// An imu or noise result that does not read as its typed result (methods/imu/imu_result.h,
// methods/noise/noise_result.h) shows "not available" with the reader's message naming the path.
TEST(JobPage, AnImuOrNoiseResultThatDoesNotReadSaysWhereItIsDamaged) {
  results::NoiseResult noise;
  noise.envelope.method = "noise";
  noise.envelope.model = "the Allan variance";
  noise.channels = {{"a0_x", "m/s^2", 2e-3, NAN, NAN, NAN}};
  noise.channel_stds = {{"a0_x", 1e-5, NAN, NAN, "crb", 1.0, std::nullopt}};
  json damaged = results::ToJson(noise);
  damaged["diagnostics"]["stationary"] = "yes";
  JobView v;
  v.job = Job(41, "IMU-0042", "noise", "succeeded", "2026-11-20T09:20:00Z", damaged);
  std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "The noise result: not available.")) << page;
  EXPECT_TRUE(Has(page, "noise result: diagnostics.stationary: expected a boolean")) << page;
  EXPECT_FALSE(Has(page, "table-noise-parameters"));
  results::ImuResult imu;
  imu.envelope.method = "imu";
  imu.envelope.model = "a = T_a K_a (y_a - b_a)";
  imu.parameters = results::ImuParameters{9.8, "statics", 1.0, 1.0, {{"0", {}, {}}}};
  imu.uncertainty = results::ImuUncertainty{"crb", kNan, {{"0", {}, {}}}, {}};
  damaged = results::ToJson(imu);
  damaged["schema_version"] = 7;
  v.job = Job(42, "IMU-0042", "imu", "succeeded", "2026-11-20T09:20:00Z", damaged);
  page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "The imu result: not available.")) << page;
  EXPECT_TRUE(Has(page, "imu result: schema_version: version 7 is newer")) << page;
  EXPECT_FALSE(Has(page, "table-imu-parameters"));
}

// Partial diagnostics of an unexpected shape (another version, trimmed) never break the page.
TEST(JobPage, FailedJobWithOddPartialDiagnosticsStillRenders) {
  for (const json& detail :
       {json{{"method", "pca"}, {"diagnostics", "garbage"}},
        json{{"method", "imu"}, {"diagnostics", {{"statics", 3}, {"imus", {1, 2}}}}},
        json{{"method", "noise"}, {"diagnostics", {{"channels", {{{"name", 1}}}}}}},
        json{{"method", "array"}, {"usable", false}, {"trimmed", {{"note", "left out"}}}},
        json{{"method", "nope"}}}) {
    JobView v;
    v.job = Job(36, "", detail.value("method", ""), "failed", "2026-11-20T09:20:00Z", json());
    v.job.error = "failed";
    v.job.error_detail = detail;
    const std::string page = RenderJobPage(v);
    ExpectDocument(page, "page-job");
    EXPECT_TRUE(Has(page, "id=\"partial\"")) << detail.dump();
  }
}

TEST(JobPage, QueuedJobRendersWithoutResult) {
  JobView v;
  v.job = Job(40, "", "array", "queued", "2026-11-20T09:20:00Z", json());
  const std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "badge-queued"));
  EXPECT_TRUE(Has(page, "This job is queued"));
}

TEST(JobPage, RunningAndQueuedJobsOfferACancelFormAndTheRunningOneItsElapsedTime) {
  JobView v;
  v.job = Job(41, "SN<1>", "array", "running", "2026-11-20T09:20:00Z", json());
  v.elapsed_ms = 12345;
  std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "<span class=\"elapsed\">12.3 s</span>")) << page;
  EXPECT_TRUE(Has(page,
                  "<form class=\"cancel-job\" method=\"post\" "
                  "action=\"/api/v1/jobs/41/cancel\">"));
  EXPECT_TRUE(Has(page, "name=\"reason\" required"));
  EXPECT_FALSE(Has(page, "name=\"token\""));  // the server has no token
  v.token_required = true;
  page = RenderJobPage(v);
  EXPECT_TRUE(Has(page, "<input type=\"password\" name=\"token\" required"));
  // Unknown elapsed time still renders.
  v.elapsed_ms = -1;
  EXPECT_TRUE(Has(RenderJobPage(v), "<span class=\"elapsed\">?</span>"));
  // A queued job: the form, no elapsed time.
  v.job = Job(42, "", "pca", "queued", "2026-11-20T09:20:00Z", json());
  page = RenderJobPage(v);
  EXPECT_TRUE(Has(page, "action=\"/api/v1/jobs/42/cancel\""));
  EXPECT_FALSE(Has(page, "class=\"elapsed\""));
  // Finished jobs have nothing to cancel.
  for (const char* status : {"succeeded", "failed"}) {
    v.job = Job(43, "", "pca", status, "2026-11-20T09:20:00Z", json());
    EXPECT_FALSE(Has(RenderJobPage(v), "cancel-job")) << status;
  }
}

TEST(JobPage, ResultWithMissingKeysAndWrongTypesStillRenders) {
  const std::vector<json> broken = {
      json::object(),
      json{{"method", "pca"}},
      json{{"method", "pca"}, {"parameters", "oops"}, {"diagnostics", 42}},
      json{{"method", "pca"},
           {"parameters", {{"sensors", {{{"name", 5}, {"scale", "big"}, {"axis", "x"}}}}}},
           {"uncertainty", {{"sensors", {1, 2, 3}}}},
           {"diagnostics", {{"singular_values", {"a", nullptr, -1, 0}}, {"rank_gap", "wide"}}},
           {"warnings", "not a list"}},
      json{{"method", "array"}},
      json{{"method", "array"},
           {"parameters", {{"reference", "zero"}, {"positions", {{{"position", {1}}}, 7}}}},
           {"diagnostics", {{"cost", {}}, {"residual_rms", 3}, {"excitation", nullptr}}}},
      json{{"method", "array"}, {"parameters", {{"positions", json::array()}}}},
      json{{"method", "unknown-method"}},
      json::array({1, 2, 3}),
  };
  int id = 100;
  for (const auto& result : broken) {
    JobView v;
    v.job = Job(id++, "D1", "pca", "succeeded", "not a timestamp", result);
    v.config = json{{"nominal", "wrong"}, {"geometry", {{"positions", 3}}}};
    const std::string page = RenderJobPage(v);
    ExpectDocument(page, "page-job");
    HistoryView h;
    h.jobs = {v.job};
    ExpectDocument(RenderHistoryPage(h), "page-history");
  }
}

// Replaces one randomly chosen value anywhere in `j` by a value of a random other type.
void Mutate(json* j, std::mt19937* rng) {
  std::vector<json*> nodes;
  std::vector<json*> stack{j};
  while (!stack.empty()) {
    json* n = stack.back();
    stack.pop_back();
    nodes.push_back(n);
    if (n->is_structured()) {
      for (auto& c : *n) stack.push_back(&c);
    }
  }
  json* target = nodes[(*rng)() % nodes.size()];
  switch ((*rng)() % 7) {
    case 0:
      *target = nullptr;
      break;
    case 1:
      *target = "<b>x</b>";
      break;
    case 2:
      *target = -1e300;
      break;
    case 3:
      *target = json::array({1, "a", nullptr});
      break;
    case 4:
      *target = json::object({{"k", 1}});
      break;
    case 5:
      *target = std::numeric_limits<double>::quiet_NaN();
      break;
    default:
      *target = 0;
      break;
  }
}

TEST(JobPage, RandomlyCorruptedResultsAlwaysRender) {
  std::mt19937 rng(12345);
  for (int round = 0; round < 300; ++round) {
    JobView v;
    const bool pca = round % 2 == 0;
    json result = pca ? PcaResult() : ArrayResult(50);
    json config = pca ? PcaConfig() : ArrayConfig();
    for (int m = 0; m < 1 + round % 5; ++m) Mutate(&result, &rng);
    if (round % 3 == 0) Mutate(&config, &rng);
    v.job = Job(round, "D", pca ? "pca" : "array", "succeeded", "2026-01-01T00:00:00Z", result);
    v.config = config;
    const std::string page = RenderJobPage(v);
    ExpectDocument(page, "page-job");
    EXPECT_FALSE(Has(page, "<b>"));
    DeviceView d;
    d.serial = "D";
    d.jobs = {v.job, v.job};
    d.jobs[1].id = round + 1000;
    d.jobs[1].created_at = "2026-02-01T00:00:00Z";
    ExpectDocument(RenderDevicePage(d), "page-device");
  }
}

TEST(HistoryPage, ListsJobsWithFiltersKeyFiguresAndPager) {
  HistoryView h;
  h.jobs = {Job(24, "ARRAY-7", "array", "succeeded", "2026-11-21T10:00:00Z", ArrayResult(10)),
            Job(23, "IMU-0042", "pca", "failed", "2026-11-21T09:00:00Z", json()),
            Job(22, "IMU-0042", "pca", "succeeded", "2026-11-20T09:15:02Z", PcaResult()),
            Job(21, "IMU-0042", "pca", "running", "2026-11-20T09:00:00Z", json())};
  h.jobs[1].error = "rank gap too small";
  h.filter.method = "pca";
  h.devices = {"IMU-0042", "ARRAY-7"};
  h.next_before = "21";
  const std::string page = RenderHistoryPage(h);
  ExpectDocument(page, "page-history");
  EXPECT_TRUE(Has(page, "class=\"table-history\""));
  EXPECT_TRUE(Has(page, "<form class=\"filters\" method=\"get\" action=\"/\">"));
  EXPECT_TRUE(Has(page, "<option value=\"pca\" selected>"));
  EXPECT_TRUE(Has(page, "href=\"/?before=21&amp;method=pca\""));
  EXPECT_TRUE(Has(page, "class=\"older\""));
  EXPECT_TRUE(Has(page, "href=\"/devices/ARRAY-7\""));
  EXPECT_TRUE(Has(page, "href=\"/jobs/22\""));
  for (const char* s : {"succeeded", "failed", "running"}) {
    EXPECT_TRUE(Has(page, std::string("badge badge-") + s)) << s;
  }
  EXPECT_TRUE(Has(page, "gap 155"));
  EXPECT_TRUE(Has(page, "offset RMS "));
  EXPECT_TRUE(Has(page, "\xE2\x9A\xA0 1"));  // the array job's warning flag
  EXPECT_TRUE(Has(page, "rank gap too small"));
  // Newest first, as given.
  EXPECT_LT(page.find("/jobs/24\""), page.find("/jobs/21\""));
}

// The device filter: exact when a device has the serial, else a case-insensitive prefix.
TEST(HistoryPage, DeviceFilterMatchesExactlyThenByPrefixIgnoringCase) {
  const std::vector<std::string> known = {"SN-0001", "SN-0002", "sn-0001-b", "OTHER", "SN-1"};
  DeviceMatch m = MatchDevices("SN-1", known);
  EXPECT_TRUE(m.exact);  // exact wins over the prefix of "SN-1..." serials
  EXPECT_EQ(m.devices, std::vector<std::string>{"SN-1"});
  m = MatchDevices("sn-000", known);
  EXPECT_FALSE(m.exact);
  EXPECT_EQ(m.devices, (std::vector<std::string>{"SN-0001", "SN-0002", "sn-0001-b"}));
  m = MatchDevices("other", known);
  EXPECT_EQ(m.devices, std::vector<std::string>{"OTHER"});
  EXPECT_TRUE(MatchDevices("X", known).devices.empty());
  EXPECT_TRUE(MatchDevices("", known).devices.empty());
  m = MatchDevices("s", known, 2);  // at most `limit`, the rest counted
  EXPECT_EQ(m.devices.size(), 2u);
  EXPECT_EQ(m.more, 2u);
  // Non-ASCII bytes compare exactly.
  EXPECT_TRUE(MatchDevices("caf\xC3\x89", {"caf\xC3\xA9-1"}).devices.empty());
  EXPECT_EQ(MatchDevices("CAF\xC3\xA9", {"caf\xC3\xA9-1"}).devices.size(), 1u);

  // The page names the devices it shows and links each; what was typed stays in the form.
  HistoryView h;
  h.filter.device = "sn-<000";
  h.device_matches = {"SN-<0001", "SN-<0002"};
  h.device_more = 3;
  h.jobs = {Job(2, "SN-<0002", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult()),
            Job(1, "SN-<0001", "pca", "succeeded", "2026-01-01T07:00:00Z", PcaResult())};
  h.next_before = "1";
  std::string page = RenderHistoryPage(h);
  EXPECT_TRUE(Has(page,
                  "No device is called \xE2\x80\x9Csn-&lt;000\xE2\x80\x9D: showing the 2 "
                  "first devices whose serial starts with it (case ignored): "
                  "<a href=\"/?device=SN-%3C0001\">SN-&lt;0001</a>, "
                  "<a href=\"/?device=SN-%3C0002\">SN-&lt;0002</a>. 3 more devices match"))
      << page;
  EXPECT_TRUE(Has(page, "name=\"device\" value=\"sn-&lt;000\""));
  EXPECT_TRUE(Has(page, "href=\"/?before=1&amp;device=sn-%3C000\""));
  // The search stopped before it had counted every match: a lower bound, or only "may".
  h.device_more_at_least = true;
  EXPECT_TRUE(Has(RenderHistoryPage(h), "SN-&lt;0002</a>. At least 3 more devices match"));
  h.device_more = 0;
  page = RenderHistoryPage(h);
  EXPECT_TRUE(Has(page, "showing the 2 first devices"));
  EXPECT_TRUE(Has(page, "SN-&lt;0002</a>. More devices may match: type more of the serial"));
  h.device_more_at_least = false;
  EXPECT_FALSE(Has(RenderHistoryPage(h), "more devices match"));
  EXPECT_FALSE(Has(RenderHistoryPage(h), "may match"));
  // Nothing matched: the server's hint as given.
  h.device_matches.clear();
  h.device_more = 0;
  h.jobs.clear();
  h.device_hint = "no device 'sn-<000'; did you mean 'SN-0001'?";
  page = RenderHistoryPage(h);
  EXPECT_TRUE(Has(page,
                  "<div class=\"callout device-hint\"><p>no device &#39;sn-&lt;000&#39;; "
                  "did you mean &#39;SN-0001&#39;?</p></div>"))
      << page;
  // An exact serial: no hint.
  h.device_hint.clear();
  EXPECT_FALSE(Has(RenderHistoryPage(h), "class=\"callout device-hint\""));
}

TEST(HistoryPage, EmptyHistorySaysSoWithoutPager) {
  const std::string page = RenderHistoryPage(HistoryView{});
  ExpectDocument(page, "page-history");
  EXPECT_TRUE(Has(page, "No calibrations match."));
  EXPECT_FALSE(Has(page, "class=\"older\""));
}

TEST(KeyFiguresTest, PcaAndArraySummaries) {
  EXPECT_EQ(KeyFigures("pca", PcaResult()).find("\xCF\x83(scale) \xE2\x89\xA4 0.1"), 0u)
      << KeyFigures("pca", PcaResult());
  const std::string a = KeyFigures("array", ArrayResult(0));
  EXPECT_NE(a.find("offset RMS"), std::string::npos);
  EXPECT_NE(a.find("\xC2\xB5m"), std::string::npos);
  EXPECT_EQ(KeyFigures("pca", json()), "\xE2\x80\x93");
}

// The imu and noise methods have key figures too (the history showed a dash for them).
TEST(KeyFiguresTest, ImuAndNoiseSummaries) {
  results::ImuResult imu;
  imu.envelope.method = "imu";
  imu.envelope.model = "a = T_a K_a (y_a - b_a)";
  imu.parameters = results::ImuParameters{9.8, "statics", 1.0, 1.0, {{"0", {}, {}}, {"1", {}, {}}}};
  imu.uncertainty = results::ImuUncertainty{"crb", kNan, {{"0", {}, {}}, {"1", {}, {}}}, {}};
  for (int i = 0; i < 24; ++i) imu.diagnostics.statics.push_back({10.0 * i, 10.0 * i + 4, 400});
  imu.diagnostics.threshold_choice = "best of 3";
  for (const double rms : {1.2e-3, 3.4e-3}) {
    results::ImuFitDiagnostics fit;
    fit.name = std::to_string(imu.diagnostics.imus.size());
    fit.usable = true;
    fit.accel_norm_rms_after = rms;
    fit.chi2_per_dof = rms * 1000;
    fit.coverage.verdict = "sufficient";
    imu.diagnostics.imus.push_back(fit);
  }
  const std::string i = KeyFigures("imu", results::ToJson(imu));
  // The worst IMU's residual and fit, and the statics.
  EXPECT_EQ(i,
            "|a|\xE2\x88\x92g RMS \xE2\x89\xA4 3.4 mm/s\xC2\xB2 \xC2\xB7 \xCF\x87\xC2\xB2/"
            "\xCE\xBD \xE2\x89\xA4 3.40 \xC2\xB7 24 statics");
  json unreadable = results::ToJson(imu);
  unreadable["diagnostics"]["imus"][0]["chi2_per_dof"] = "big";
  EXPECT_EQ(
      KeyFigures("imu", unreadable).rfind("not available: imu result: diagnostics.imus[0]", 0), 0u)
      << KeyFigures("imu", unreadable);

  results::NoiseResult noise;
  noise.envelope.method = "noise";
  noise.envelope.model = "the Allan variance";
  const double kNaN = std::numeric_limits<double>::quiet_NaN();
  for (const char* name : {"a0_x", "a0_y", "a0_z", "g0_x", "g0_y", "g0_z"}) {
    const bool gyro = name[0] == 'g';
    noise.channels.push_back({name, gyro ? "rad/s" : "m/s^2",
                              gyro ? (name[3] == 'y' ? 1.2e-4 : 9e-5) : kNaN, kNaN, kNaN, kNaN});
    noise.channel_stds.push_back({name, kNaN, kNaN, kNaN, "crb", kNaN, std::nullopt});
  }
  std::string n = KeyFigures("noise", results::ToJson(noise));
  EXPECT_EQ(n, "accel N not visible \xC2\xB7 gyro N \xE2\x89\xA4 120 \xC2\xB5rad/s/\xE2\x88\x9AHz");
  noise.channels[1].white_noise = 2e-3;
  noise.diagnostics.stationary = false;
  n = KeyFigures("noise", results::ToJson(noise));
  EXPECT_EQ(
      n.rfind("not stationary \xC2\xB7 accel N \xE2\x89\xA4 2.0 mm/s\xC2\xB2/\xE2\x88\x9AHz", 0),
      0u)
      << n;
  // The history page shows them instead of a dash.
  HistoryView h;
  h.jobs = {Job(5, "IMU-1", "imu", "succeeded", "2026-01-01T08:00:00Z", results::ToJson(imu)),
            Job(4, "IMU-1", "noise", "succeeded", "2026-01-01T07:00:00Z", results::ToJson(noise))};
  const std::string page = RenderHistoryPage(h);
  EXPECT_TRUE(Has(page, "24 statics"));
  EXPECT_TRUE(Has(page, "gyro N \xE2\x89\xA4 120"));
}

// A result a person accepted (overriding the gate, or after a revoke) carries a badge with the
// person's reason; one the gate accepted carries none.
TEST(HistoryPage, MarksResultsAPersonAccepted) {
  JobSummary overridden = Job(9, "D", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult());
  overridden.state = ServeState::kAccepted;
  overridden.result["verdict"] = {{"status", "rejected"}, {"reasons", {"too noisy"}}};
  overridden.events = {{"accept", "checked <b>on the rig</b>", "token", "2026-01-01T09:00:00Z"}};
  JobSummary reaccepted = Job(8, "D", "pca", "succeeded", "2026-01-01T07:00:00Z", PcaResult());
  reaccepted.state = ServeState::kAccepted;
  reaccepted.events = {{"revoke", "wrong board", "token", "2026-01-01T09:00:00Z"},
                       {"accept", "right board after all", "token", "2026-01-01T09:05:00Z"}};
  JobSummary gate = Job(7, "D", "pca", "succeeded", "2026-01-01T06:00:00Z", PcaResult());
  HistoryView h;
  h.jobs = {overridden, reaccepted, gate};
  const std::string page = RenderHistoryPage(h);
  EXPECT_EQ(Count(page, "<span class=\"badge badge-accepted badge-accepted-by-person\""), 2u)
      << page;
  EXPECT_TRUE(Has(page, "accepted by a person: checked &lt;b&gt;on the rig&lt;/b&gt;"));
  EXPECT_TRUE(Has(page, ">right board after all</span>"));
  // The gate-accepted job's row has no badge besides its status.
  const size_t row = page.find("href=\"/jobs/7\"");
  ASSERT_NE(row, std::string::npos);
  EXPECT_EQ(page.find("badge-accepted", row), std::string::npos);
  // The device page marks them the same way.
  DeviceView d;
  d.serial = "D";
  d.jobs = h.jobs;
  EXPECT_EQ(Count(RenderDevicePage(d), "badge-accepted-by-person\""), 2u);
}

TEST(DevicePage, ShowsCalibrationsAndDriftTablesAndPlots) {
  DeviceView d;
  d.serial = "IMU-0042";
  d.jobs = {Job(3, "IMU-0042", "pca", "succeeded", "2026-03-01T08:00:00Z", PcaResult("g", 2e-4)),
            Job(1, "IMU-0042", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult()),
            Job(2, "IMU-0042", "pca", "failed", "2026-02-01T08:00:00Z", json()),
            Job(4, "IMU-0042", "pca", "succeeded", "2026-04-01T08:00:00Z", PcaResult("g", 5e-4)),
            Job(5, "IMU-0042", "array", "succeeded", "2026-04-02T08:00:00Z", ArrayResult(0)),
            Job(6, "IMU-0042", "array", "succeeded", "2026-05-02T08:00:00Z", ArrayResult(0, 3e-6))};
  const std::string page = RenderDevicePage(d);
  ExpectDocument(page, "page-device");
  EXPECT_TRUE(Has(page, "class=\"table-calibrations\""));
  EXPECT_TRUE(Has(page, "class=\"table-drift-pca\""));
  EXPECT_TRUE(Has(page, "class=\"table-drift-array\""));
  for (const char* plot : {"drift-scale", "drift-axis", "drift-position"}) {
    EXPECT_TRUE(Has(page, std::string("class=\"plot plot-") + plot + "\"")) << plot;
  }
  // Drift pairs skip the failed job: 1 -> 3 -> 4.
  EXPECT_TRUE(Has(page, ">#1</a> \xE2\x86\x92 <a href=\"/jobs/3\">#3</a>"));
  EXPECT_TRUE(Has(page, ">#3</a> \xE2\x86\x92 <a href=\"/jobs/4\">#4</a>"));
  EXPECT_TRUE(Has(page, "days since 2026-01-01 08:00 UTC"));
  // The array shift of 3 µm in x shows up (RMS over 31 moved triads).
  EXPECT_TRUE(Has(page, ">3.0</td>"));
  // Calibrations table: newest first.
  EXPECT_LT(page.find("/jobs/6\""), page.find("/jobs/1\""));
}

TEST(DevicePage, SingleCalibrationHasNoDrift) {
  DeviceView d;
  d.serial = "X";
  d.jobs = {Job(1, "X", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult())};
  const std::string page = RenderDevicePage(d);
  ExpectDocument(page, "page-device");
  EXPECT_TRUE(Has(page, "Drift needs at least two accepted (not revoked) calibrations"));
  ExpectDocument(RenderDevicePage(DeviceView{}), "page-device");
}

TEST(DevicePage, MarksRejectedAndRevokedResultsAndComparesOnlyAcceptedOnes) {
  DeviceView d;
  d.serial = "DRONE-1";
  JobSummary rejected =
      Job(2, "DRONE-1", "pca", "succeeded", "2026-02-01T08:00:00Z", PcaResult("g", 0.3));
  rejected.result["verdict"] = {
      {"status", "rejected"},
      {"reasons", {"the orientations are poorly spread: add positions with the -y axis up"}}};
  JobSummary revoked =
      Job(3, "DRONE-1", "pca", "succeeded", "2026-03-01T08:00:00Z", PcaResult("g", 0.2));
  revoked.state = ServeState::kRevoked;
  revoked.events = {{"revoke", "board <dropped> on the rig", "token", "2026-03-02T08:00:00Z"}};
  d.jobs = {Job(1, "DRONE-1", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult()), rejected,
            revoked,
            Job(4, "DRONE-1", "pca", "succeeded", "2026-04-01T08:00:00Z", PcaResult("g", 5e-4))};
  const std::string page = RenderDevicePage(d);
  ExpectDocument(page, "page-device");
  EXPECT_TRUE(Has(page, "<span class=\"badge badge-rejected\""));
  EXPECT_TRUE(Has(page, "add positions with the -y axis up"));
  EXPECT_TRUE(Has(page, "<span class=\"badge badge-revoked\""));
  EXPECT_TRUE(Has(page, "board &lt;dropped&gt; on the rig"));  // escaped
  // Drift compares 1 -> 4 only: neither the rejected #2 nor the revoked #3 is a calibration
  // anyone could have flashed.
  EXPECT_TRUE(Has(page, ">#1</a> \xE2\x86\x92 <a href=\"/jobs/4\">#4</a>"));
  EXPECT_FALSE(Has(page, "/jobs/2\">#2</a> \xE2\x86\x92"));
  EXPECT_FALSE(Has(page, "\xE2\x86\x92 <a href=\"/jobs/3\">"));
  EXPECT_TRUE(Has(page, "2 accepted calibrations"));
  // Biases and the frame-free angle between axes are compared.
  EXPECT_TRUE(Has(page, "bias (reading units)"));
  EXPECT_TRUE(Has(page, "largest change of an angle between axes (mrad)"));
}

TEST(DevicePage, ResultsInDifferentFramesAreNotComparedByAxisDirection) {
  DeviceView d;
  d.serial = "DRONE-2";
  JobSummary nominal = Job(1, "DRONE-2", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult());
  nominal.result["parameters"]["frame"] = "nominal";
  JobSummary canonical = Job(2, "DRONE-2", "pca", "succeeded", "2026-02-01T08:00:00Z", PcaResult());
  canonical.result["parameters"]["frame"] = "canonical";
  d.jobs = {nominal, canonical};
  const std::string page = RenderDevicePage(d);
  EXPECT_TRUE(Has(page, "frames differ (nominal \xE2\x86\x92 canonical)"));
  d.jobs[1].result["parameters"]["frame"] = "nominal";
  EXPECT_FALSE(Has(RenderDevicePage(d), "frames differ"));
}

TEST(JobPage, ShowsTheVerdictWithReasonsAndTheDecisions) {
  JobView v;
  v.job = Job(7, "DRONE-3", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult());
  v.job.result["verdict"] = {{"status", "rejected"},
                             {"reasons",
                              {"scale factors physically implausible, readings look "
                               "like g but magnitude is 9.81: units?"}}};
  std::string page = RenderJobPage(v);
  ExpectDocument(page, "page-job");
  EXPECT_TRUE(Has(page, "Rejected by the acceptance gate"));
  EXPECT_TRUE(Has(page, "readings look like g but magnitude is 9.81"));
  EXPECT_LT(page.find("Rejected by the acceptance gate"), page.find("Parameters"));  // prominent
  v.job.state = ServeState::kAccepted;
  v.job.events = {{"accept", "checked on the rig", "token", "2026-01-02T08:00:00Z"}};
  page = RenderJobPage(v);
  EXPECT_TRUE(Has(page, "overriding the acceptance gate"));
  EXPECT_TRUE(Has(page, "class=\"table-events\""));
  EXPECT_TRUE(Has(page, "checked on the rig"));
  v.job.result.erase("verdict");  // results from before the gate count as accepted
  v.job.state = ServeState::kNone;
  v.job.events.clear();
  EXPECT_TRUE(Has(RenderJobPage(v), "Accepted</strong> by the acceptance gate"));
}

TEST(HistoryPage, MarksRejectedResults) {
  HistoryView h;
  JobSummary rejected = Job(9, "D", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult());
  rejected.state = ServeState::kRejected;
  rejected.result["verdict"] = {{"status", "rejected"}, {"reasons", {"too noisy"}}};
  h.jobs = {rejected, Job(8, "D", "pca", "succeeded", "2026-01-01T07:00:00Z", PcaResult())};
  const std::string page = RenderHistoryPage(h);
  EXPECT_TRUE(Has(page, "<span class=\"badge badge-rejected\" title=\"too noisy\""));
  EXPECT_TRUE(Has(page, "<span class=\"verdict-reason\">too noisy</span>"));
  EXPECT_FALSE(Has(page, "<span class=\"badge badge-revoked\""));
  EXPECT_FALSE(Has(page, "<span class=\"badge badge-accepted\""));  // accepted: no mark
  // The filter form offers the gate's states and keeps the chosen one in the pager link.
  h.filter.verdict = ServeState::kRejected;
  h.next_before = "8";
  const std::string filtered = RenderHistoryPage(h);
  EXPECT_TRUE(Has(filtered, "<select name=\"verdict\">"));
  EXPECT_TRUE(Has(filtered, "verdict=rejected"));
}

TEST(DevicePage, ManyCalibrationsKeepThePageSmall) {
  DeviceView d;
  d.serial = "ARRAY-7";
  char ts[32];
  for (int i = 0; i < 300; ++i) {
    std::snprintf(ts, sizeof(ts), "2026-%02d-%02dT08:00:00Z", 1 + i / 28, 1 + i % 28);
    d.jobs.push_back(
        Job(i + 1, "ARRAY-7", "array", "succeeded", ts, ArrayResult(0, 1e-7 * (i % 7))));
  }
  const std::string page = RenderDevicePage(d);
  ExpectDocument(page, "page-device");
  EXPECT_TRUE(Has(page, "239 older pairs not listed"));
  EXPECT_TRUE(Has(page, "plot-drift-position"));
  EXPECT_LT(page.size(), 2u * 1024u * 1024u);
}

TEST(ErrorPage, EscapesMessageAndLinksHome) {
  const std::string page = RenderErrorPage(404, std::string("no job ") + kScript + kImg);
  ExpectDocument(page, "page-error");
  ExpectNoInjection(page);
  EXPECT_TRUE(Has(page, "404"));
  EXPECT_TRUE(Has(page, "Not found"));
  EXPECT_TRUE(Has(page, "href=\"/\""));
  EXPECT_TRUE(Has(page, "&lt;script&gt;alert(1)&lt;/script&gt;"));
}

TEST(Escaping, HostileDeviceAndSensorNamesNeverAppearUnescapedInAnyPage) {
  for (const std::string& evil :
       {std::string(kScript), std::string(kImg), std::string(kScript) + kImg + "'\xFF"}) {
    json pca = PcaResult(evil);
    pca["warnings"] = json::array({evil});
    pca["diagnostics"][evil] = evil;
    json arr = ArrayResult(10);
    arr["parameters"]["positions"][3]["name"] = evil;
    arr["uncertainty"]["positions"][3]["name"] = evil;
    arr["diagnostics"]["solver"] = evil;
    arr["diagnostics"]["excitation"]["verdict"] = evil;
    json config = PcaConfig();
    config["device"] = evil;
    config[evil] = evil;

    JobView pj;
    pj.job = Job(1, evil, "pca", "succeeded", evil, pca);
    pj.config = config;
    pj.recording_sha256 = evil;
    JobView aj;
    aj.job = Job(2, evil, "array", "succeeded", "2026-01-01T00:00:00Z", arr);
    aj.config = config;
    JobView fj;
    fj.job = Job(3, evil, evil, "failed", "2026-01-01T00:00:00Z", json());
    fj.job.error = evil;
    JobView sj;  // hostile method (a status that is not one of the four cannot be set)
    sj.job = Job(4, evil, evil, evil, evil, json());

    ExpectNoInjection(RenderJobPage(pj));
    ExpectNoInjection(RenderJobPage(aj));
    ExpectNoInjection(RenderJobPage(fj));
    ExpectNoInjection(RenderJobPage(sj));

    HistoryView h;
    h.jobs = {pj.job, aj.job, fj.job, sj.job};
    h.filter = {evil, evil, std::nullopt, std::nullopt};  // status and verdict are enums
    h.devices = {evil};
    h.next_before = evil;
    const std::string hp = RenderHistoryPage(h);
    ExpectNoInjection(hp);
    EXPECT_TRUE(Has(hp, "/devices/%3Cscript%3E") || Has(hp, "/devices/%22%3E%3Cimg"));

    DeviceView d;
    d.serial = evil;
    JobSummary second = pj.job;
    second.id = 5;
    second.created_at = "2026-02-01T00:00:00Z";
    JobSummary a2 = aj.job;
    a2.id = 6;
    a2.created_at = "2026-03-01T00:00:00Z";
    d.jobs = {pj.job, second, aj.job, a2, fj.job};
    ExpectNoInjection(RenderDevicePage(d));
    ExpectNoInjection(RenderErrorPage(400, evil));
  }
}

// Writes the sample pages to $CALIBD_WEB_DUMP_DIR (when set) for a look in a browser.
TEST(PageSnapshots, WritesSamplePagesWhenAsked) {
  const char* dir = std::getenv("CALIBD_WEB_DUMP_DIR");
  if (dir == nullptr) GTEST_SKIP() << "set CALIBD_WEB_DUMP_DIR to write the sample pages";
  auto write = [&](const std::string& name, const std::string& html) {
    std::ofstream(std::string(dir) + "/" + name) << html;
  };
  JobView p;
  p.job = Job(17, "IMU-0042", "pca", "succeeded", "2026-11-20T09:15:02Z", PcaResult());
  p.job.finished_at = "2026-11-20T09:15:04.250Z";
  p.recording_id = 5;
  p.recording_bytes = 18234;
  p.recording_rows = 24;
  p.config = PcaConfig();
  write("job_pca.html", RenderJobPage(p));
  JobView a;
  a.job = Job(23, "ARRAY-7", "array", "succeeded", "2026-11-21 10:00:00", ArrayResult(100000));
  a.job.finished_at = "2026-11-21 10:00:03";
  a.recording_id = 9;
  a.config = ArrayConfig();
  write("job_array.html", RenderJobPage(a));
  JobView f;
  f.job = Job(31, "IMU-0042", "pca", "failed", "2026-11-20T09:20:00Z", json());
  f.job.error = "the singular values show no gap between 3 and 4 (rank gap 1.3)";
  f.config = PcaConfig();
  write("job_failed.html", RenderJobPage(f));
  HistoryView h;
  h.jobs = {
      a.job, f.job, p.job,
      Job(12, std::string("IMU ") + kScript, "pca", "running", "2026-11-20T08:00:00Z", json())};
  h.devices = {"IMU-0042", "ARRAY-7"};
  h.next_before = "12";
  write("history.html", RenderHistoryPage(h));
  DeviceView d;
  d.serial = "IMU-0042";
  d.jobs = {Job(3, "IMU-0042", "pca", "succeeded", "2026-03-01T08:00:00Z", PcaResult("g", 2e-4)),
            Job(1, "IMU-0042", "pca", "succeeded", "2026-01-01T08:00:00Z", PcaResult()),
            Job(2, "IMU-0042", "pca", "failed", "2026-02-01T08:00:00Z", json()),
            Job(4, "IMU-0042", "pca", "succeeded", "2026-04-01T08:00:00Z", PcaResult("g", 5e-4)),
            Job(5, "IMU-0042", "array", "succeeded", "2026-04-02T08:00:00Z", ArrayResult(0)),
            Job(6, "IMU-0042", "array", "succeeded", "2026-05-02T08:00:00Z", ArrayResult(0, 3e-6))};
  write("device.html", RenderDevicePage(d));
  write("error.html", RenderErrorPage(404, "no job 999"));
}

}  // namespace
}  // namespace calibd::web
