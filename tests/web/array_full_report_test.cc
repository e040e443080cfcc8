// The job-page sections of an `array` result with model full (web/array_full_report.h, issue
// #18): the numbers of the result appear, at the precision of their σ; values beyond the
// acceptance limits are marked; names are escaped; 32 triads give 32 rows; odd results render.
#include "web/array_full_report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "web/html.h"
#include "web/pages.h"

namespace calibd::web {
namespace {

using json = nlohmann::json;

constexpr double kDeg = 3.14159265358979323846 / 180;

json Vec(double x, double y, double z) { return json::array({x, y, z}); }
json Mat(double off, double diag = 1) {
  return json::array({Vec(diag, off, -off), Vec(2 * off, diag, off), Vec(-off, 3 * off, diag)});
}

// A model-full result as server/array_method.cc writes it: K triads named `prefix`K, the
// gyroscopes in deg/s, gains 1 + 0.0123 (accelerometers) and 1 + 0.01 (gyroscopes), biases
// 0.0217 m/s^2 and -0.5 deg/s, misalignment entries of 2 mrad, position shift (10, 0, -4) µm at
// σ 2 µm, residuals at the noise.
json FullResult(int K, const std::string& prefix = "", bool with_limits = true) {
  json imus = json::array(), stds = json::array(), positions = json::array(),
       position_stds = json::array(), residuals = json::array(), changed = json::array();
  for (int k = 0; k < K; ++k) {
    const std::string name = prefix + std::to_string(k);
    const double gu = 1.01 * kDeg;
    imus.push_back({{"name", name},
                    {"accelerometer",
                     {{"bias", Vec(0.0217, -0.0301, 0.0042)},
                      {"scale", Vec(1.0123, 1.0123, 1.0123)},
                      {"misalignment", Mat(0.002)},
                      {"matrix", Mat(0.002, 1.0123)}}},
                    {"gyroscope",
                     {{"bias", Vec(-0.5, 0.25, 0.125)},
                      {"scale", Vec(gu, gu, gu)},
                      {"misalignment", Mat(0.002)},
                      {"matrix", Mat(0.002 * gu, gu)}}},
                    {"position", Vec(0.01 * k, 0.02, 0.001)}});
    const double sa = 1e-4 * 1.0123;  // relative σ 0.01 %
    json sensor_std = {{"bias_std", Vec(0.001, 0.001, 0.001)},
                       {"scale_std", Vec(sa, sa, sa)},
                       {"misalignment_std", Mat(2e-4, 0)}};
    json gyro_std = sensor_std;
    gyro_std["bias_std"] = Vec(0.01, 0.01, 0.01);
    gyro_std["scale_std"] = Vec(1e-4 * gu, 1e-4 * gu, 1e-4 * gu);
    stds.push_back({{"name", name},
                    {"accelerometer", sensor_std},
                    {"gyroscope", gyro_std},
                    {"position_std", Vec(2e-6, 2e-6, 2e-6)}});
    positions.push_back(
        {{"name", name}, {"position", Vec(0.01 * k, 0.02, 0.001)}, {"offset", Vec(0, 0, 0)}});
    position_stds.push_back({{"name", name}, {"std", Vec(2e-6, 2e-6, 2e-6)}});
    residuals.push_back({{"name", name},
                         {"static", {{"accelerometer", 0.04}, {"gyroscope", 0.06}}},
                         {"dynamic", {{"accelerometer", 0.041}, {"gyroscope", 0.061}}}});
    changed.push_back({{"name", name},
                       {"positions_only", Vec(0.01 * k - 1e-5, 0.02, 0.001 + 4e-6)},
                       {"position_change", Vec(1e-5, 0, -4e-6)},
                       {"position_change_norm", std::hypot(1e-5, 4e-6)},
                       {"position_change_sigma", Vec(5, 0, -2)}});
  }
  json result = {
      {"method", "array"},
      {"parameters",
       {{"model", "full"}, {"reference", 0}, {"imus", imus}, {"positions", positions}}},
      {"uncertainty", {{"imus", stds}, {"positions", position_stds}}},
      {"diagnostics",
       {{"model", "full"},
        {"gauge", {{"description", "sum of the gyroscope traces is 3K"}}},
        {"solver", "joint"},
        {"iterations", 6},
        {"converged", true},
        {"cost", {100.0, 10.0, 9.0}},
        {"statics", 20},
        {"static_samples", 2000},
        {"dynamic_samples", 400},
        {"chi2_per_dof", 1.01},
        {"gyro_unit", "deg/s"},
        {"noise", {{"accelerometer", 0.04}, {"gyroscope", 0.06}, {"source", "configured"}}},
        {"static_noise", {{"accelerometer", 0.04}, {"gyroscope", 0.06}}},
        {"residual_rms", {{"imus", residuals}}},
        {"robust", {{"used", false}}},
        {"positions_only_start", true},
        {"changed_from_positions_only", changed}}},
      {"warnings", json::array()}};
  if (with_limits)
    result["verdict"] = {{"status", "accepted"},
                         {"reasons", json::array()},
                         {"limits",
                          {{"scale_range", 0.1},
                           {"max_scale_std", 0.01},
                           {"implausible_factor", 3.0},
                           {"max_axis_std", 0.01},
                           {"max_accel_bias", 2.0},
                           {"max_accel_bias_std", 0.05},
                           {"max_gyro_bias", 0.2},
                           {"max_gyro_bias_std", 0.005}}}};
  return result;
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
  EXPECT_TRUE(Has(html, "static noise 0.04"));
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
  // An older result without positions_only / position_change_sigma: σ from
  // uncertainty.positions.
  json old = FullResult(8);
  for (auto& c : old["diagnostics"]["changed_from_positions_only"]) {
    c.erase("positions_only");
    c.erase("position_change_sigma");
  }
  EXPECT_TRUE(Has(Table(ArrayFullSections(old), "array-full-change"), ">5.00<"));
}

// Real hardware: the residuals exceed the noise and the result carries the residual-aware σ
// (uncertainty.imus[].robust); the tables show it, the limits and the shift are judged by it.
TEST(ArrayFullReport, ShowsTheResidualAwareSigmaWhenTheResultHasIt) {
  json r = FullResult(8);
  for (auto& u : r["uncertainty"]["imus"]) {
    json robust = {{"accelerometer", u["accelerometer"]},
                   {"gyroscope", u["gyroscope"]},
                   {"position_std", Vec(5e-5, 5e-5, 5e-5)}};
    robust["accelerometer"]["bias_std"] = Vec(0.07, 0.07, 0.07);  // beyond 0.05 m/s^2
    u["robust"] = robust;
  }
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
  EXPECT_TRUE(IsArrayFullResult(FullResult(3)));
  EXPECT_FALSE(IsArrayFullResult(json{{"method", "array"}, {"parameters", {{"positions", {}}}}}));
  for (const json& odd :
       {json(), json::array(), json{{"parameters", 3}},
        json{{"parameters", {{"model", "full"}, {"imus", {1, "x", nullptr}}}}},
        json{{"parameters", {{"model", "full"}, {"imus", {{{"name", 3}, {"gyroscope", "?"}}}}}},
             {"diagnostics",
              {{"residual_rms", {{"imus", {{{"static", 1}}}}}},
               {"changed_from_positions_only", {{{"position_change", "?"}}}}}}}}) {
    EXPECT_NO_THROW(ArrayFullSections(odd)) << odd;
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

}  // namespace
}  // namespace calibd::web
