// The typed imu result (methods/imu/imu_result.h) holds every key the real adapter writes: results
// of `imu` runs on small simulated logs (gyro_bias statics and estimate, counts with nominal
// biases, a gap in t, resolved noise-job references, and a failed run's partial diagnostics) read
// with FromJson and write back with ToJson to the same document; the consumers refuse a result that
// does not read, naming the path.
#include <gtest/gtest.h>

#include <cmath>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "methods/exports.h"
#include "methods/imu/imu_method.h"
#include "methods/imu/imu_result.h"
#include "methods/method.h"
#include "methods/registry.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "tests/server/result_schema_util.h"
#include "web/method_report.h"
#include "web/pages.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The paths SPEC §4/§7 requires of an imu result ("[]": every element of an array). Everything
// else in the document is an extension, which a result stored by an earlier calibd may lack.
const char* const kSpecPaths[] = {
    "method",
    "model",
    "verdict.status",
    "verdict.reasons",
    "warnings",
    "parameters.imus[].name",
    "parameters.imus[].accelerometer.bias",
    "parameters.imus[].accelerometer.scale",
    "parameters.imus[].accelerometer.misalignment",
    "parameters.imus[].accelerometer.matrix",
    "parameters.imus[].gyroscope.bias",
    "parameters.imus[].gyroscope.scale",
    "parameters.imus[].gyroscope.misalignment",
    "parameters.imus[].gyroscope.matrix",
    "uncertainty.imus[].name",
    "uncertainty.imus[].accelerometer.bias_std",
    "uncertainty.imus[].accelerometer.scale_std",
    "uncertainty.imus[].accelerometer.misalignment_std",
    "uncertainty.imus[].gyroscope.bias_std",
    "uncertainty.imus[].gyroscope.scale_std",
    "uncertainty.imus[].gyroscope.misalignment_std",
    // §7 static detection: the intervals and the threshold used.
    "diagnostics.statics[].start",
    "diagnostics.statics[].end",
    "diagnostics.statics[].samples",
    "diagnostics.threshold_choice",
    // §7 imu: per IMU its statics (with per-channel mean and std), rotations, coverage, residuals.
    "diagnostics.imus[].statics[].start",
    "diagnostics.imus[].statics[].end",
    "diagnostics.imus[].statics[].samples",
    "diagnostics.imus[].statics[].accel_mean",
    "diagnostics.imus[].statics[].accel_std",
    "diagnostics.imus[].statics[].gyro_mean",
    "diagnostics.imus[].statics[].gyro_std",
    "diagnostics.imus[].rotations[].angle",
    "diagnostics.imus[].rotations[].direction_error_before",
    "diagnostics.imus[].rotations[].direction_error_after",
    "diagnostics.imus[].coverage.verdict",
    "diagnostics.imus[].residuals.accel_norm_rms_before",
    "diagnostics.imus[].residuals.accel_norm_rms_after",
    "diagnostics.imus[].residuals.gyro_direction_rms_before",
    "diagnostics.imus[].residuals.gyro_direction_rms_after",
};

json SpecOnly(const json& j) {
  return testing::SpecOnly(j,
                           std::vector<std::string>(std::begin(kSpecPaths), std::end(kSpecPaths)));
}
using testing::Stored;

void ExpectRoundTrip(const json& stored) {
  testing::ExpectTypedRoundTrip<results::ImuResult>(stored);
}

// Drops the rows with t in (from, to): a gap in the log.
std::string WithGap(const std::string& csv, double from, double to) {
  std::string out;
  size_t pos = 0;
  while (pos < csv.size()) {
    const size_t end = csv.find('\n', pos);
    const std::string line = csv.substr(pos, end - pos);
    pos = end + 1;
    if (line[0] != 't') {
      const double t = std::stod(line.substr(0, line.find(',')));
      if (t > from && t < to) continue;
    }
    out += line + "\n";
  }
  return out;
}

json RunImu(const core::ImuSimulationOptions& sim, const json& extra, Status* status,
            double gap_from = 0, double gap_to = 0) {
  std::string csv;
  json config, truth, result;
  EXPECT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  config.update(extra);
  if (gap_to > gap_from) csv = WithGap(csv, gap_from, gap_to);
  *status = Calibrate(csv, "imu.csv", config, &result);
  return result;
}

TEST(ImuResultSchema, AdapterResultsRoundTripExactly) {
  core::ImuSimulationOptions small;
  small.statics = 12;
  small.static_duration = 2;
  small.rotation_duration = 1.5;
  small.seed = 4;
  {
    SCOPED_TRACE("gyro_bias statics");
    Status s;
    const json r = RunImu(small, json::object(), &s);
    ASSERT_TRUE(s.ok()) << s.ToString();
    ASSERT_TRUE(r.contains("verdict"));
    EXPECT_EQ(r["parameters"]["gyro_bias"], "statics");
    EXPECT_EQ(r["schema_version"], results::kImuSchemaVersion);
    ExpectRoundTrip(Stored(r));
  }
  {
    SCOPED_TRACE("gyro_bias estimate, counts with nominal biases");
    core::ImuSimulationOptions counts = small;
    counts.accel_unit = 0.0024;
    counts.gyro_unit = 2e-4;
    counts.accel_offset = 32768;
    counts.gyro_offset = 32768;
    counts.quantize = true;
    counts.gyro_bias_drift = 1e-4;
    Status s;
    const json r = RunImu(counts, {{"gyro_bias", "estimate"}}, &s);
    ASSERT_TRUE(s.ok()) << s.ToString();
    EXPECT_EQ(r["parameters"]["gyro_bias"], "estimate");
    ExpectRoundTrip(Stored(r));
  }
  {
    SCOPED_TRACE("a gap in t during a rotation, noise levels from noise jobs");
    // Resolved references (methods/noise/noise_reference.h), as the server leaves them in the
    // config.
    const json extra = {{"accel_noise",
                         {{"job", 3},
                          {"sigma", 0.01},
                          {"white_noise", 1e-3},
                          {"random_walk", nullptr},
                          {"rate", 100},
                          {"channels", json::array()}}},
                        {"gyro_noise",
                         {{"job", 4},
                          {"sigma", 0.002},
                          {"white_noise", 2e-4},
                          {"random_walk", 2e-5},
                          {"rate", 100},
                          {"channels", json::array()}}}};
    Status s;
    // The first rotation runs from 2 s to 3.5 s.
    const json r = RunImu(small, extra, &s, 2.6, 2.9);
    ASSERT_TRUE(s.ok()) << s.ToString();
    ASSERT_EQ(r["diagnostics"]["gaps"].size(), 1u) << r["diagnostics"].dump();
    EXPECT_EQ(r["diagnostics"]["noise_jobs"]["gyroscope"], 4);
    EXPECT_TRUE(r["diagnostics"]["noise_model"]["accelerometer"]["random_walk"].is_null());
    ExpectRoundTrip(Stored(r));
  }
}

TEST(ImuResultSchema, FailedRunsPartialDiagnosticsRoundTripExactly) {
  core::ImuSimulationOptions few;
  few.statics = 5;
  Status s;
  const json r = RunImu(few, json::object(), &s);
  ASSERT_FALSE(s.ok());
  ASSERT_EQ(r.value("usable", true), false) << r.dump();
  const json stored = Stored(r);
  ExpectRoundTrip(stored);
  results::ImuResult typed;
  ASSERT_TRUE(results::FromJson(stored, &typed).ok());
  EXPECT_FALSE(typed.parameters.has_value());
  ASSERT_EQ(typed.diagnostics.imus.size(), 1u);
  EXPECT_EQ(typed.diagnostics.imus[0].termination, "too_few_statics");
  EXPECT_EQ(typed.diagnostics.statics.size(), 5u);
  // Trimmed to fit the store (one byte under the document): the largest diagnostics member is
  // dropped, the statics still read, and the document writes back.
  const json trimmed = json::parse(PartialDiagnosticsText(stored, stored.dump().size() - 1));
  ASSERT_TRUE(trimmed.contains("trimmed")) << trimmed.dump();
  ExpectRoundTrip(trimmed);
  results::ImuResult cut;
  ASSERT_TRUE(results::FromJson(trimmed, &cut).ok());
  EXPECT_EQ(cut.dropped, std::vector<std::string>{"imus"});
  EXPECT_EQ(cut.diagnostics.statics.size(), 5u);
  // A partial document is not a calibration: the exports refuse it.
  std::string out;
  EXPECT_EQ(FindMethod("imu")->Export("csv", stored, {}, &out).code(), StatusCode::kInternal);
}

TEST(ImuResultSchema, ConsumersRefuseAResultThatDoesNotReadNamingThePath) {
  core::ImuSimulationOptions small;
  small.statics = 12;
  small.static_duration = 2;
  small.rotation_duration = 1.5;
  Status s;
  json r = Stored(RunImu(small, json::object(), &s));
  ASSERT_TRUE(s.ok()) << s.ToString();
  r.erase("verdict");
  r["diagnostics"]["imus"][0]["residuals"]["accel_norm_rms_after"] = "small";
  json judged = r;
  JudgeResult(*FindMethod("imu"), {{"method", "imu"}}, json(), &judged);
  EXPECT_EQ(judged["verdict"]["status"], "rejected");
  EXPECT_NE(judged["verdict"]["reasons"][0].get<std::string>().find(
                "the result cannot be judged: imu result: "
                "diagnostics.imus[0].residuals.accel_norm_rms_after"),
            std::string::npos)
      << judged["verdict"].dump();
  for (const char* format : {"csv", "h", "yaml"}) {
    std::string out;
    const Status e = FindMethod("imu")->Export(format, r, {1, "D", "imu", "now"}, &out);
    EXPECT_EQ(e.code(), StatusCode::kConflict) << format;
    EXPECT_NE(e.message().find("diagnostics.imus[0].residuals.accel_norm_rms_after"),
              std::string::npos)
        << e.message();
  }
}

TEST(ImuResultSchema, AResultWithOnlyTheSpecsKeysStillReadsExportsAndRenders) {
  core::ImuSimulationOptions small;
  small.statics = 12;
  small.static_duration = 2;
  small.rotation_duration = 1.5;
  small.seed = 4;
  Status s;
  const json full = Stored(RunImu(small, json::object(), &s));
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json spec = SpecOnly(full);
  // The stripping took the extensions away (schema_version, gravity, the fit's name, cost, ...).
  ASSERT_FALSE(spec.contains("schema_version"));
  ASSERT_FALSE(spec["parameters"].contains("gravity"));
  ASSERT_FALSE(spec["diagnostics"]["imus"][0].contains("name"));
  ASSERT_FALSE(spec["diagnostics"]["imus"][0]["coverage"].contains("sufficient"));
  ASSERT_TRUE(spec["diagnostics"]["imus"][0]["rotations"][0].contains("angle"));

  results::ImuResult typed;
  ASSERT_TRUE(results::FromJson(spec, &typed).ok()) << results::FromJson(spec, &typed).ToString();
  EXPECT_TRUE(std::isnan(typed.parameters->gravity));
  EXPECT_TRUE(typed.diagnostics.imus[0].coverage.sufficient);
  EXPECT_EQ(typed.diagnostics.imus[0].name, full["parameters"]["imus"][0]["name"]);

  // Judge gives a verdict from the SPEC's keys.
  json judged = spec;
  judged.erase("verdict");
  JudgeResult(*FindMethod("imu"), {{"method", "imu"}}, json(), &judged);
  ASSERT_TRUE(judged.contains("verdict"));
  EXPECT_EQ(judged["verdict"]["reasons"].dump().find("cannot be judged"), std::string::npos)
      << judged["verdict"].dump();
  // The same verdict as the full result's, but for the coverage: coverage.sufficient is an
  // extension (absent: not rejected on it; the stored verdict of such a result stands).
  std::vector<std::string> expected;
  for (const std::string reason : full["verdict"]["reasons"]) {
    if (reason.find("the orientations do not determine") == std::string::npos) {
      expected.push_back(reason);
    }
  }
  EXPECT_EQ(judged["verdict"]["reasons"].get<std::vector<std::string>>(), expected)
      << "full: " << full["verdict"].dump();
  EXPECT_EQ(judged["verdict"]["status"], expected.empty() ? "accepted" : "rejected");
  // The CSV and the C header need only the SPEC's parameters; OpenVINS' yaml needs the reading
  // units and the rate (extensions): refused as not determinable, saying what to do.
  const ExportContext context{1, "D", "imu", "now"};
  for (const char* format : {"csv", "h"}) {
    std::string out, expected;
    const Status e = FindMethod("imu")->Export(format, spec, context, &out);
    ASSERT_TRUE(e.ok()) << format << ": " << e.ToString();
    ASSERT_TRUE(FindMethod("imu")->Export(format, full, context, &expected).ok());
    EXPECT_EQ(out, expected) << format;
  }
  std::string yaml;
  const Status y = FindMethod("imu")->Export("yaml", spec, context, &yaml);
  EXPECT_EQ(y.code(), StatusCode::kNotDeterminable) << y.ToString();

  // The job page's section and the device page's drift render without "not available".
  web::JobView view;
  view.job.id = 7;
  view.job.device = "D";
  view.job.method = "imu";
  view.job.status = JobStatus::kSucceeded;
  view.job.result = spec;
  const web::MethodReport* report = web::FindMethodReport("imu");
  ASSERT_NE(report, nullptr);
  const std::string section = report->Section(view);
  EXPECT_EQ(section.find("not available"), std::string::npos) << section;
  EXPECT_NE(section.find("table-imu-parameters"), std::string::npos);
  EXPECT_EQ(section.find(">nan"), std::string::npos) << section;
  web::JobSummary older = view.job;
  older.id = 6;
  const std::string drift = report->Drift({&older, &view.job});
  EXPECT_FALSE(drift.empty());
  EXPECT_EQ(drift.find("not available"), std::string::npos) << drift;
}

TEST(ImuResultSchema, PartialDocumentsLackingAnyDiagnosticsRead) {
  core::ImuSimulationOptions few;
  few.statics = 5;
  Status s;
  const json stored = Stored(RunImu(few, json::object(), &s));
  ASSERT_FALSE(s.ok());
  ASSERT_EQ(stored.value("usable", true), false);
  const web::MethodReport* report = web::FindMethodReport("imu");
  web::JobView view;
  view.job.method = "imu";
  view.job.status = JobStatus::kFailed;
  auto expect_reads = [&](const json& doc) {
    results::ImuResult typed;
    const Status r = results::FromJson(doc, &typed);
    EXPECT_TRUE(r.ok()) << r.ToString() << "\n" << doc.dump();
    view.job.error_detail = doc;
    const std::string partial = report->Partial(view);
    EXPECT_EQ(partial.find("not available"), std::string::npos) << partial;
  };
  json empty = stored;
  empty["diagnostics"] = json::object();
  expect_reads(empty);
  json none = stored;
  none.erase("diagnostics");
  expect_reads(none);
  ASSERT_GE(stored["diagnostics"].size(), 5u);
  for (const auto& [key, value] : stored["diagnostics"].items()) {
    SCOPED_TRACE(key);
    json one = stored;
    one["diagnostics"].erase(key);
    expect_reads(one);
  }
  // A result (usable) still requires the SPEC's diagnostics.
  core::ImuSimulationOptions small;
  small.statics = 12;
  small.static_duration = 2;
  small.rotation_duration = 1.5;
  json full = Stored(RunImu(small, json::object(), &s));
  ASSERT_TRUE(s.ok());
  full["diagnostics"].erase("statics");
  results::ImuResult typed;
  EXPECT_EQ(results::FromJson(full, &typed).field(), "diagnostics.statics");
}

}  // namespace
}  // namespace calibd::server
