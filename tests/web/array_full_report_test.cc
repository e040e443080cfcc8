// The job-page sections of an `array` result with model full (methods/array/array_full_report.h,
// issue #18): the numbers of the result appear, at the precision of their σ; values beyond the
// acceptance limits are marked; names are escaped; 32 triads give 32 rows; odd results render.
#include "methods/array/array_full_report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "methods/array/array_result.h"
#include "web/html.h"
#include "web/pages.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

constexpr double kDeg = 3.14159265358979323846 / 180;

json Vec(double x, double y, double z) { return json::array({x, y, z}); }
Eigen::Matrix3d Mat(double off, double diag = 1) {
  Eigen::Matrix3d m;
  m << diag, off, -off, 2 * off, diag, off, -off, 3 * off, diag;
  return m;
}

// A model-full result (methods/array/array_result.h, every key methods/array/array_full_method.cc
// writes): K triads named `prefix`K, the gyroscopes in deg/s, gains 1 + 0.0123 (accelerometers) and
// 1 + 0.01 (gyroscopes), biases 0.0217 m/s^2 and -0.5 deg/s, misalignment entries of 2 mrad,
// position shift (10, 0, -4) µm at σ 2 µm, residuals at the noise.
json FullResult(int K, const std::string& prefix = "", bool with_limits = true) {
  results::ArrayResult r;
  r.envelope.method = "array";
  r.envelope.model = "a_k = M_a,k (y_a,k - b_a,k), ...";
  r.full = true;
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  results::ArrayFullDiagnostics& d = r.full_diagnostics;
  for (int k = 0; k < K; ++k) {
    const std::string name = prefix + std::to_string(k);
    const double gu = 1.01 * kDeg;
    results::ArrayImu imu;
    imu.triads.name = name;
    imu.triads.accelerometer.bias = {0.0217, -0.0301, 0.0042};
    imu.triads.accelerometer.scale = Eigen::Vector3d::Constant(1.0123);
    imu.triads.accelerometer.misalignment = Mat(0.002);
    imu.triads.accelerometer.matrix = Mat(0.002, 1.0123);
    imu.triads.gyroscope.bias = {-0.5, 0.25, 0.125};
    imu.triads.gyroscope.scale = Eigen::Vector3d::Constant(gu);
    imu.triads.gyroscope.misalignment = Mat(0.002);
    imu.triads.gyroscope.matrix = Mat(0.002 * gu, gu);
    imu.position = {0.01 * k, 0.02, 0.001};
    params.imus.push_back(imu);
    const double sa = 1e-4 * 1.0123;  // relative σ 0.01 %
    results::ArrayImuStd u;
    u.triads.name = name;
    u.triads.accelerometer.bias_std = Eigen::Vector3d::Constant(0.001);
    u.triads.accelerometer.scale_std = Eigen::Vector3d::Constant(sa);
    u.triads.accelerometer.misalignment_std = Mat(2e-4, 0);
    u.triads.gyroscope = u.triads.accelerometer;
    u.triads.gyroscope.bias_std = Eigen::Vector3d::Constant(0.01);
    u.triads.gyroscope.scale_std = Eigen::Vector3d::Constant(1e-4 * gu);
    u.position_std = Eigen::Vector3d::Constant(2e-6);
    unc.imus.push_back(u);
    params.positions.push_back({name, imu.position, Eigen::Vector3d::Zero()});
    unc.positions.push_back({name, Eigen::Vector3d::Constant(2e-6), std::nullopt});
    d.residual_rms_imus.push_back({name, {0.04, 0.06}, {0.041, 0.061}});
    results::ArrayPositionChange c;
    c.name = name;
    c.positions_only = {0.01 * k - 1e-5, 0.02, 0.001 + 4e-6};
    c.position_change = {1e-5, 0, -4e-6};
    c.position_change_norm = std::hypot(1e-5, 4e-6);
    c.position_change_sigma = {5, 0, -2};
    d.changed_from_positions_only.push_back(c);
    d.time_offsets.offsets_ms.push_back({name, 0.0});
  }
  r.parameters = params;
  r.uncertainty = unc;
  d.termination = "converged";
  d.iterations = 6;
  d.statics = 20;
  d.static_samples = 2000;
  d.dynamic_samples = 400;
  d.rotation_excitation = {{5, 6, 7}, 0.1, {1, 0, 0}, "good", "(rad/s)^2"};
  d.gauge = {"sum_trace_gyroscope", 0, "sum of the gyroscope traces is 3K"};
  d.solver = "joint";
  d.converged = true;
  d.cost = {100.0, 10.0, 9.0};
  d.dof = 1000;
  d.chi2_per_dof = 1.01;
  d.gyro_unit = "deg/s";
  d.noise = {0.04, 0.06, "configured", "noise", 0.04, 0.06};
  d.static_noise = {0.04, 0.06};
  d.static_intervals = {{0.5, 2.5, 400, 0.002, 0.003}, {3.0, 4.75, 350, 0.0021, 0.0031}};
  d.residual_rms_dynamic = {0.041, 0.061};
  d.time_offsets.note = "diagnostic";
  d.robust = {false, 0, 2.0, 1.5};
  d.positions_only_start = true;
  if (with_limits) {
    results::StoredVerdict v;
    v.status = GateVerdict::kAccepted;
    v.limits = {{"scale_range", 0.1},   {"max_scale_std", 0.01},     {"implausible_factor", 3.0},
                {"max_axis_std", 0.01}, {"max_accel_bias", 2.0},     {"max_accel_bias_std", 0.05},
                {"max_gyro_bias", 0.2}, {"max_gyro_bias_std", 0.005}};
    r.envelope.verdict = v;
  }
  return results::ToJson(r);
}

bool Has(const std::string& s, const std::string& what) {
  return s.find(what) != std::string::npos;
}

size_t Count(const std::string& s, const std::string& what) {
  size_t n = 0;
  for (size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + what.size())) ++n;
  return n;
}

// The part of `html` from `<table class="...NAME"` to its `</table>`.
std::string Table(const std::string& html, const std::string& name) {
  const size_t start = html.find("table-" + name + "\"");
  if (start == std::string::npos) return "";
  return html.substr(start, html.find("</table>", start) - start);
}

TEST(ArrayFullReport, ShowsEveryTriadsGainsMisalignmentsAndBiasesWithTheirSigma) {
  const std::string html = ArrayFullSections(FullResult(8));
  const std::string accel = Table(html, "array-full-accelerometer");
  const std::string gyro = Table(html, "array-full-gyroscope");
  ASSERT_FALSE(accel.empty());
  ASSERT_FALSE(gyro.empty());
  EXPECT_EQ(Count(accel, "<tr><td class=\"name\">"), 8u);
  EXPECT_EQ(Count(gyro, "<tr><td class=\"name\">"), 8u);
  // Gain - 1 in %, to the σ's precision (σ 0.01 %: three decimals), σ small beside it.
  EXPECT_TRUE(Has(accel,
                  ">+1.230<span class=\"sd\">\xC2\xB1"
                  "0.010</span>"))
      << accel;
  // The gyroscopes' gain against the nominal deg/s conversion: 1.01 -> +1.000 %.
  EXPECT_TRUE(Has(gyro, ">+1.000<span class=\"sd\">")) << gyro;
  // Biases in reading units (m/s^2, deg/s) to the σ's precision.
  EXPECT_TRUE(Has(accel,
                  ">+0.0217<span class=\"sd\">\xC2\xB1"
                  "0.0010</span>"));
  EXPECT_TRUE(Has(accel,
                  ">\xE2\x88\x92"
                  "0.0301<") ||
              Has(accel, ">-0.0301<"));
  EXPECT_TRUE(Has(gyro, "bias (\xC2\xB0/s)"));
  EXPECT_TRUE(Has(gyro, ">-0.500<") || Has(gyro,
                                           ">\xE2\x88\x92"
                                           "0.500<"));
  // Axis misalignment of x: the angle of column 0 = (1, 0.004, -0.002): atan(sqrt(2e-5)) rad.
  const std::string angle = FormatFixed(1e3 * std::atan(std::sqrt(2e-5)), 2);  // σ 0.37
  EXPECT_TRUE(Has(accel, ">" + angle + "<span class=\"sd\">")) << angle << "\n" << accel;
  EXPECT_TRUE(Has(html, "table-array-full-misalignment"));
  EXPECT_TRUE(Has(html, "(ref.)"));
  EXPECT_FALSE(Has(accel + gyro, "beyond")) << "nothing is beyond the limits";
  EXPECT_TRUE(Has(html, "sum of the gyroscope traces is 3K"));
}

TEST(ArrayFullReport, MarksValuesBeyondTheAcceptanceLimitsAndNamesTheLimit) {
  json r = FullResult(8);
  r["parameters"]["imus"][3]["accelerometer"]["scale"][1] = 1.2;              // scale_range 10 %
  r["parameters"]["imus"][5]["gyroscope"]["bias"][2] = 20.0;                  // 0.35 rad/s > 0.2
  r["uncertainty"]["imus"][6]["accelerometer"]["bias_std"][0] = 0.2;          // > 0.05 m/s^2
  r["uncertainty"]["imus"][7]["gyroscope"]["misalignment_std"][0][1] = 0.02;  // > 10 mrad
  const std::string html = ArrayFullSections(r);
  EXPECT_EQ(Count(Table(html, "array-full-accelerometer"), " beyond\""), 2u);
  EXPECT_EQ(Count(Table(html, "array-full-gyroscope"), " beyond\""), 2u);
  EXPECT_TRUE(Has(html, "title=\"beyond scale_range 10.0 %\""));
  EXPECT_TRUE(Has(html, "title=\"beyond the bias limit 11.5 \xC2\xB0/s\""));
  EXPECT_TRUE(Has(html, "value(s) beyond the acceptance limits"));
  // Without the limits (an older result) nothing is marked.
  json old = r;
  old.erase("verdict");
  EXPECT_EQ(Count(Table(ArrayFullSections(old), "array-full-accelerometer"), " beyond\""), 0u);
}

TEST(ArrayFullReport, ThirtyTwoTriadsGiveOneRowEachAndOnePlotPerSensorKind) {
  const std::string html = ArrayFullSections(FullResult(32, "imu"));
  EXPECT_EQ(Count(Table(html, "array-full-accelerometer"), "<tr><td class=\"name\">"), 32u);
  EXPECT_EQ(Count(Table(html, "array-full-gyroscope"), "<tr><td class=\"name\">"), 32u);
  EXPECT_EQ(Count(Table(html, "array-full-change"), "<tr><td class=\"name\">"), 32u);
  EXPECT_EQ(Count(Table(html, "array-full-misalignment"), "<tr><td class=\"name\">"), 64u);
  EXPECT_EQ(Count(html, "class=\"plot plot-array-full-residuals-accelerometer\""), 1u);
  EXPECT_EQ(Count(html, "class=\"plot plot-array-full-residuals-gyroscope\""), 1u);
  EXPECT_EQ(Count(html, "class=\"plot plot-array-full-position-change\""), 1u);
  EXPECT_TRUE(Has(html, "imu31"));
  // Compact: a 32-triad report stays far below a megabyte.
  EXPECT_LT(html.size(), 400000u);
}

TEST(ArrayFullReport, EscapesTriadNamesEverywhere) {
  const std::string html = ArrayFullSections(FullResult(4, "<script>alert(1)</script>"));
  EXPECT_FALSE(Has(html, "<script"));
  EXPECT_TRUE(Has(html, "&lt;script&gt;alert(1)&lt;/script&gt;0"));
}

TEST(ArrayFullReport, ResidualsPerTriadNameTheTriadThatStandsOut) {
  json r = FullResult(8);
  r["diagnostics"]["residual_rms"]["imus"][5]["dynamic"]["accelerometer"] = 0.41;  // 10x
  const std::string html = ArrayFullSections(r);
  EXPECT_TRUE(Has(html, "id=\"triad-residuals\""));
  EXPECT_TRUE(Has(html, "sample noise 0.04"));
  // The statics: listed, and their residuals against the noise of a mean (0.04 / √400, the
  // median static of two being the upper one).
  EXPECT_TRUE(Has(html, "The 2 static intervals"));
  EXPECT_TRUE(Has(html, "noise of a static mean 0.002"));
  const size_t list = html.find("triad-outliers");
  ASSERT_NE(list, std::string::npos);
  EXPECT_TRUE(Has(html.substr(list),
                  "accelerometer residual in motion more than twice the "
                  "median of the triads: 5 (10.0\xC3\x97)"));
  // The others (all at the noise) are not named; the model fits, so no motion warning.
  EXPECT_FALSE(Has(html, "the model does not explain the motion"));
  // All triads' motion residual 30x the static noise: said in words.
  json bad = FullResult(8);
  for (auto& t : bad["diagnostics"]["residual_rms"]["imus"]) t["dynamic"]["gyroscope"] = 1.8;
  EXPECT_TRUE(Has(ArrayFullSections(bad),
                  "gyroscope residual in motion is 30\xC3\x97 the static "
                  "noise"));
}

TEST(ArrayFullReport, ChangeFromThePositionsOnlyFitInMicrometresAndSigma) {
  const std::string html = ArrayFullSections(FullResult(8));
  const std::string t = Table(html, "array-full-change");
  ASSERT_FALSE(t.empty());
  EXPECT_TRUE(Has(t, ">10.00<"));  // Δx µm
  EXPECT_TRUE(Has(t, ">-4.00<") || Has(t,
                                       ">\xE2\x88\x92"
                                       "4.00<"));
  EXPECT_TRUE(Has(t, ">10.77<"));                                       // |Δ| µm
  EXPECT_TRUE(Has(t, "beyond\" title=\"more than 3\xCF\x83\">5.00<"));  // 5σ marked
  EXPECT_TRUE(Has(t, ">9.9900<"));  // positions-only x of triad 1, mm
  EXPECT_TRUE(Has(html, "Largest: triad 0, 5.0\xCF\x83"));
  // A damaged result (a shift that is not three numbers): the sections say what does not read.
  json bad = FullResult(8);
  bad["diagnostics"]["changed_from_positions_only"][2]["position_change"] = "?";
  const std::string damaged = ArrayFullSections(bad);
  EXPECT_FALSE(Has(damaged, "table-array-full-change"));
  EXPECT_TRUE(Has(damaged, "diagnostics.changed_from_positions_only[2].position_change"))
      << damaged;
  EXPECT_TRUE(Has(damaged, "not available"));
}

// Real hardware: the residuals exceed the noise and the primary σ is the residual-aware one
// (uncertainty.basis "sandwich"); the tables show it, the limits and the shift are judged by it.
TEST(ArrayFullReport, ShowsTheResidualAwareSigmaWhenTheResultHasIt) {
  json r = FullResult(8);
  r["uncertainty"]["basis"] = "sandwich";
  for (auto& u : r["uncertainty"]["imus"]) {
    u["crb"] = {{"accelerometer", u["accelerometer"]},
                {"gyroscope", u["gyroscope"]},
                {"position_std", u["position_std"]}};
    u["position_std"] = Vec(5e-5, 5e-5, 5e-5);
    u["accelerometer"]["bias_std"] = Vec(0.07, 0.07, 0.07);  // beyond 0.05 m/s^2
  }
  for (auto& c : r["diagnostics"]["changed_from_positions_only"])
    for (int a = 0; a < 3; ++a)
      c["position_change_sigma"][a] = c["position_change"][a].get<double>() / 5e-5;
  const std::string html = ArrayFullSections(r);
  const std::string accel = Table(html, "array-full-accelerometer");
  EXPECT_TRUE(Has(accel,
                  ">+0.022<span class=\"sd\">\xC2\xB1"
                  "0.070</span>"))
      << accel;                                   // σ 0.07: 3 decimals
  EXPECT_EQ(Count(accel, " beyond\""), 8u * 3u);  // every bias σ beyond the limit
  EXPECT_TRUE(Has(html, "class=\"sigma-shown\">residual-aware"));
  // The 10 µm shift is 0.2 residual-aware σ, no longer 5 σ: nothing marked.
  const std::string change = Table(html, "array-full-change");
  EXPECT_TRUE(Has(change, ">0.20<")) << change;
  EXPECT_FALSE(Has(change, "beyond"));
  // Without it: the Cramér–Rao bound.
  EXPECT_TRUE(Has(ArrayFullSections(FullResult(8)), "class=\"sigma-shown\">Cram"));
}

TEST(ArrayFullReport, ResultsOfAnyShapeRenderAndOnlyFullResultsGetTheSections) {
  // A positions-model result has no triads to show. (A full result without diagnostics.model is
  // still one: its parameters.imus say so, SPEC §7.)
  results::ArrayResult typed;
  typed.envelope.method = "array";
  typed.envelope.model = "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k";
  typed.parameters = results::ArrayParameters{0, {{"a0", {0, 0, 0}, {0, 0, 0}}}, {}};
  typed.uncertainty = results::ArrayUncertainty();
  typed.uncertainty->positions = {{"a0", {0, 0, 0}, std::nullopt}};
  typed.uncertainty->std_rms = 0;
  const json positions = results::ToJson(typed);
  ASSERT_TRUE(results::FromJson(positions, &typed).ok());
  EXPECT_FALSE(Has(ArrayFullSections(positions), "id=\"triads\""));
  json unlabelled = FullResult(3);
  unlabelled["diagnostics"].erase("model");
  EXPECT_TRUE(Has(ArrayFullSections(unlabelled), "id=\"triads\""));
  for (const json& odd :
       {json(), json::array(), json{{"parameters", 3}},
        json{{"parameters", {{"model", "full"}, {"imus", {1, "x", nullptr}}}}},
        json{{"parameters", {{"model", "full"}, {"imus", {{{"name", 3}, {"gyroscope", "?"}}}}}},
             {"diagnostics",
              {{"residual_rms", {{"imus", {{{"static", 1}}}}}},
               {"changed_from_positions_only", {{{"position_change", "?"}}}}}}}}) {
    std::string html;
    EXPECT_NO_THROW(html = ArrayFullSections(odd)) << odd;
    EXPECT_TRUE(Has(html, "not available")) << odd;
    EXPECT_FALSE(Has(html, "id=\"triads\"")) << odd;
  }
}

TEST(ArrayFullReport, TheJobPageOfAFullResultCarriesTheSections) {
  JobView v;
  v.job.id = 41;
  v.job.status = JobStatus::kSucceeded;
  v.job.method = "array";
  v.job.device = "BOARD-1";
  v.job.result = FullResult(8);
  const std::string page = RenderJobPage(v);
  for (const char* id : {"id=\"triads\"", "id=\"triad-residuals\"", "id=\"full-vs-positions\"",
                         "plot-positions-xy", "table-array-parameters"})
    EXPECT_TRUE(Has(page, id)) << id;
  // The positions model's residual-per-sensor-type plot is replaced by the per-triad ones.
  EXPECT_FALSE(Has(page, "plot-residual-rms"));
}

// The array report reads the result typed: a result that does not read shows the "not available"
// line with the reader's message (the path of the problem) instead of tables of dashes, on the job
// page, in a failed job's partial diagnostics and in the device page's drift.
TEST(ArrayReport, AResultThatDoesNotReadSaysWhereOnEveryPage) {
  json bad = FullResult(4);
  bad["parameters"]["positions"][2]["offset"] = {1, 2};
  JobView v;
  v.job.id = 42;
  v.job.status = JobStatus::kSucceeded;
  v.job.method = "array";
  v.job.device = "BOARD-1";
  v.job.result = bad;
  std::string page = RenderJobPage(v);
  EXPECT_TRUE(Has(page, "parameters.positions[2].offset")) << page;
  EXPECT_TRUE(Has(page, "not available"));
  EXPECT_FALSE(Has(page, "table-array-parameters"));
  v.job.result = FullResult(4);
  EXPECT_TRUE(Has(RenderJobPage(v), "table-array-parameters"));

  JobView failed = v;
  failed.job.status = JobStatus::kFailed;
  failed.job.result = json();
  failed.job.error = "the motion does not determine the positions";
  results::ArrayResult partial;  // a failed full-model run's partial diagnostics, damaged
  partial.envelope.method = "array";
  partial.envelope.usable = false;
  partial.full = true;
  failed.job.error_detail = results::ToJson(partial);
  failed.job.error_detail["diagnostics"]["statics"] = "two";
  page = RenderJobPage(failed);
  EXPECT_TRUE(Has(page, "diagnostics.statics")) << page;
  EXPECT_FALSE(Has(page, "partial-array"));

  DeviceView d;
  d.serial = "BOARD-1";
  JobSummary a = v.job, b = v.job, c = v.job;
  a.id = 1;
  a.created_at = a.finished_at = "2026-01-01T00:00:00Z";
  b.id = 2;
  b.created_at = b.finished_at = "2026-02-01T00:00:00Z";
  b.result = bad;
  c.id = 3;
  c.created_at = c.finished_at = "2026-03-01T00:00:00Z";
  d.jobs = {a, b, c};
  page = RenderDevicePage(d);
  EXPECT_TRUE(Has(page, "table-drift-array"));
  EXPECT_TRUE(Has(page, "Job #2&#39;s result (array result: parameters.positions[2].offset") ||
              Has(page, "Job #2's result (array result: parameters.positions[2].offset"))
      << page;
}

}  // namespace
}  // namespace calibd::web
