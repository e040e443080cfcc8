// The typed noise result (methods/noise/noise_result.h) holds every key the real adapter writes:
// results of `noise` runs on small simulated logs (several option combinations, and a failed
// run's partial diagnostics) read with FromJson and write back with ToJson to the same document;
// Judge and the exports refuse a result that does not read, naming the path.
#include <gtest/gtest.h>

#include <cmath>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "methods/exports.h"
#include "methods/method.h"
#include "methods/noise/noise_method.h"
#include "methods/noise/noise_result.h"
#include "methods/registry.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "tests/server/result_schema_util.h"
#include "web/method_report.h"
#include "web/pages.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The paths SPEC §4/§7 requires of a noise result ("[]": every element of an array). Everything
// else in the document is an extension, which a result stored by an earlier calibd may lack.
const char* const kSpecPaths[] = {
    "method",
    "model",
    "verdict.status",
    "verdict.reasons",
    "warnings",
    "parameters.channels[].name",
    "parameters.channels[].unit",
    "parameters.channels[].white_noise",
    "parameters.channels[].bias_instability",
    "parameters.channels[].bias_instability_tau",
    "parameters.channels[].random_walk",
    "uncertainty.channels[].name",
    "uncertainty.channels[].white_noise_std",
    "uncertainty.channels[].bias_instability_std",
    "uncertainty.channels[].random_walk_std",
    "diagnostics.rate",
    "diagnostics.samples",
    "diagnostics.allan[].name",
    "diagnostics.allan[].tau",
    "diagnostics.allan[].adev",
    "diagnostics.allan[].adev_lower",
    "diagnostics.allan[].adev_upper",
};

json SpecOnly(const json& j) {
  return testing::SpecOnly(j,
                           std::vector<std::string>(std::begin(kSpecPaths), std::end(kSpecPaths)));
}
using testing::Stored;

void ExpectRoundTrip(const json& stored) {
  testing::ExpectTypedRoundTrip<results::NoiseResult>(stored);
}

std::string Log(const NoiseSimulationFileOptions& sim, json* config) {
  std::string csv;
  json truth;
  EXPECT_TRUE(SimulateNoiseFiles(sim, &csv, config, &truth).ok());
  return csv;
}

TEST(NoiseResultSchema, AdapterResultsRoundTripExactly) {
  struct Case {
    const char* what;
    double seconds;
    double bias_instability;
    json extra;  // config keys
  } cases[] = {
      {"two minutes, octaves", 120, 0, json::object()},
      {"decades, bias instability", 300, 0.5, {{"taus_per_decade", 10}}},
      {"reading units", 120, 0, {{"accel_unit", "g"}, {"gyro_unit", "deg/s"}}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    NoiseSimulationFileOptions sim;
    sim.rate = 50;
    sim.seconds = c.seconds;
    sim.bias_instability = c.bias_instability;
    sim.seed = 3;
    json config;
    const std::string csv = Log(sim, &config);
    config.update(c.extra);
    json result;
    const Status s = Calibrate(csv, "noise.csv", config, &result);
    ASSERT_TRUE(s.ok()) << s.ToString();
    ASSERT_TRUE(result.contains("verdict"));
    EXPECT_EQ(result["schema_version"], results::kNoiseSchemaVersion);
    // Two minutes cannot show the random walk: nulls are part of the document.
    if (c.seconds == 120) {
      EXPECT_TRUE(result["parameters"]["channels"][0]["random_walk"].is_null()) << result.dump();
    }
    ExpectRoundTrip(Stored(result));
  }
}

TEST(NoiseResultSchema, FailedRunsPartialDiagnosticsRoundTripExactly) {
  // A minute at rest whose a0_x jumps by 1 m/s² halfway: not stationary.
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 60;
  json config;
  std::string csv = Log(sim, &config), moved;
  size_t pos = 0, row = 0;
  while (pos < csv.size()) {
    const size_t end = csv.find('\n', pos);
    std::string line = csv.substr(pos, end - pos);
    pos = end + 1;
    if (line[0] != 't' && row++ >= 3000) {
      const size_t c1 = line.find(','), c2 = line.find(',', c1 + 1);
      line = line.substr(0, c1 + 1) +
             std::to_string(std::stod(line.substr(c1 + 1, c2 - c1 - 1)) + 1.0) + line.substr(c2);
    }
    moved += line + "\n";
  }
  json result;
  const Status s = Calibrate(moved, "noise.csv", config, &result);
  ASSERT_FALSE(s.ok());
  ASSERT_EQ(result.value("usable", true), false) << result.dump();
  const json stored = Stored(result);
  ExpectRoundTrip(stored);
  results::NoiseResult typed;
  ASSERT_TRUE(results::FromJson(stored, &typed).ok());
  EXPECT_FALSE(typed.envelope.usable);
  EXPECT_TRUE(typed.channels.empty());
  EXPECT_FALSE(typed.diagnostics.stationary);
  ASSERT_FALSE(typed.diagnostics.channels.empty());
  EXPECT_EQ(typed.diagnostics.channels[0].status, "not_stationary");
  // Trimmed to fit the store (the worker's cap, here one byte under the document): the largest
  // diagnostics member is dropped, the rest still reads, and the document writes back.
  const json trimmed = json::parse(PartialDiagnosticsText(stored, stored.dump().size() - 1));
  ASSERT_TRUE(trimmed.contains("trimmed")) << trimmed.dump();
  ExpectRoundTrip(trimmed);
  ASSERT_TRUE(results::FromJson(trimmed, &typed).ok());
  EXPECT_FALSE(typed.dropped.empty());
  EXPECT_TRUE(typed.diagnostics.allan.empty()) << "the Allan curves are the largest member";
  EXPECT_EQ(typed.diagnostics.channels[0].status, "not_stationary");
  const json bare = json::parse(PartialDiagnosticsText(stored, 10));
  EXPECT_TRUE(results::FromJson(bare, &typed).ok()) << bare.dump();
}

TEST(NoiseResultSchema, ConsumersRefuseAResultThatDoesNotReadNamingThePath) {
  NoiseSimulationFileOptions sim;
  sim.rate = 50;
  sim.seconds = 120;
  std::string csv;
  json config, truth, r;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  ASSERT_TRUE(Calibrate(csv, "noise.csv", config, &r).ok());
  r = Stored(r);
  ASSERT_EQ(r["uncertainty"]["channels"].size(), 6u);
  r.erase("verdict");
  r["uncertainty"]["channels"][2]["white_noise_std"] = true;
  json judged = r;
  JudgeResult(*FindMethod("noise"), {{"method", "noise"}}, json(), &judged);
  EXPECT_EQ(judged["verdict"]["status"], "rejected");
  EXPECT_NE(judged["verdict"]["reasons"][0].get<std::string>().find(
                "the result cannot be judged: noise result: "
                "uncertainty.channels[2].white_noise_std"),
            std::string::npos)
      << judged["verdict"].dump();
  for (const char* format : {"csv", "h", "yaml"}) {
    std::string out;
    const Status e = FindMethod("noise")->Export(format, r, {1, "D", "noise", "now"}, &out);
    EXPECT_EQ(e.code(), StatusCode::kConflict) << format;
    EXPECT_NE(e.message().find("uncertainty.channels[2].white_noise_std"), std::string::npos)
        << e.message();
  }
}

TEST(NoiseResultSchema, AResultWithOnlyTheSpecsKeysStillReadsExportsAndRenders) {
  NoiseSimulationFileOptions sim;
  sim.rate = 50;
  sim.seconds = 300;
  sim.bias_instability = 0.5;
  sim.seed = 3;
  json config;
  const std::string csv = Log(sim, &config);
  json result;
  const Status s = Calibrate(csv, "noise.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json full = Stored(result);
  const json spec = SpecOnly(full);
  // The stripping took the extensions away.
  ASSERT_FALSE(spec.contains("schema_version"));
  for (const char* key :
       {"duration", "jitter", "stationary", "taus_per_decade", "confidence", "channels", "units"}) {
    ASSERT_TRUE(full["diagnostics"].contains(key)) << key;
    ASSERT_FALSE(spec["diagnostics"].contains(key)) << key;
  }
  ASSERT_FALSE(spec["diagnostics"]["allan"][0].contains("fitted_adev"));
  ASSERT_TRUE(spec["diagnostics"]["allan"][0].contains("adev_upper"));

  results::NoiseResult typed;
  ASSERT_TRUE(results::FromJson(spec, &typed).ok()) << results::FromJson(spec, &typed).ToString();
  EXPECT_TRUE(std::isnan(typed.diagnostics.duration));
  EXPECT_TRUE(typed.diagnostics.channels.empty());
  EXPECT_FALSE(typed.diagnostics.units.has_value());

  json judged = spec;
  judged.erase("verdict");
  JudgeResult(*FindMethod("noise"), {{"method", "noise"}}, json(), &judged);
  ASSERT_TRUE(judged.contains("verdict"));
  EXPECT_EQ(judged["verdict"]["reasons"].dump().find("cannot be judged"), std::string::npos)
      << judged["verdict"].dump();
  EXPECT_EQ(judged["verdict"]["status"], full["verdict"]["status"]) << judged["verdict"].dump();

  // Every export needs only the SPEC's keys (the rate for Kalibr's update_rate): the same
  // outcome as from the full result (the yaml needs the random walks, which 300 s do not show,
  // so both refuse it alike).
  const ExportContext context{1, "D", "noise", "now"};
  for (const char* format : {"csv", "h", "yaml"}) {
    std::string out, expected;
    const Status e = FindMethod("noise")->Export(format, spec, context, &out);
    const Status f = FindMethod("noise")->Export(format, full, context, &expected);
    if (std::string(format) != "yaml") {
      ASSERT_TRUE(e.ok()) << format << ": " << e.ToString();
    }
    EXPECT_EQ(e.code(), f.code()) << format << ": " << e.ToString() << " / " << f.ToString();
    EXPECT_EQ(e.message(), f.message()) << format;
    EXPECT_EQ(out, expected) << format;
  }
  // The job page's section and the device page's drift render without "not available".
  web::JobView view;
  view.job.id = 7;
  view.job.device = "D";
  view.job.method = "noise";
  view.job.status = JobStatus::kSucceeded;
  view.job.result = spec;
  const web::MethodReport* report = web::FindMethodReport("noise");
  ASSERT_NE(report, nullptr);
  const std::string section = report->Section(view);
  EXPECT_EQ(section.find("not available"), std::string::npos) << section;
  EXPECT_NE(section.find("table-noise-parameters"), std::string::npos);
  EXPECT_NE(section.find("plot-allan-accel"), std::string::npos) << section;
  web::JobSummary older = view.job;
  older.id = 6;
  const std::string drift = report->Drift({&older, &view.job});
  EXPECT_FALSE(drift.empty());
  EXPECT_EQ(drift.find("not available"), std::string::npos) << drift;
}

TEST(NoiseResultSchema, PartialDocumentsLackingAnyDiagnosticsRead) {
  // A minute at rest whose a0_x jumps by 1 m/s² halfway: not stationary, a failed run.
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 60;
  json config;
  const std::string csv = Log(sim, &config);
  std::string moved;
  size_t pos = 0, row = 0;
  while (pos < csv.size()) {
    const size_t end = csv.find('\n', pos);
    std::string line = csv.substr(pos, end - pos);
    pos = end + 1;
    if (line[0] != 't' && row++ >= 3000) {
      const size_t c1 = line.find(','), c2 = line.find(',', c1 + 1);
      line = line.substr(0, c1 + 1) +
             std::to_string(std::stod(line.substr(c1 + 1, c2 - c1 - 1)) + 1.0) + line.substr(c2);
    }
    moved += line + "\n";
  }
  json result;
  ASSERT_FALSE(Calibrate(moved, "noise.csv", config, &result).ok());
  const json stored = Stored(result);
  ASSERT_EQ(stored.value("usable", true), false);
  const web::MethodReport* report = web::FindMethodReport("noise");
  web::JobView view;
  view.job.method = "noise";
  view.job.status = JobStatus::kFailed;
  auto expect_reads = [&](const json& doc) {
    results::NoiseResult typed;
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
  // Nothing known is shown as a dash, not as 0 samples.
  EXPECT_NE(report->Partial(view).find("<dt>samples</dt><dd>\xE2\x80\x93</dd>"), std::string::npos)
      << report->Partial(view);
  ASSERT_GE(stored["diagnostics"].size(), 5u);
  for (const auto& [key, value] : stored["diagnostics"].items()) {
    SCOPED_TRACE(key);
    json one = stored;
    one["diagnostics"].erase(key);
    expect_reads(one);
  }
  // A result (usable) still requires the SPEC's diagnostics.
  json ok;
  ASSERT_TRUE(Calibrate(csv, "noise.csv", config, &ok).ok());
  ok = Stored(ok);
  ok["diagnostics"].erase("rate");
  results::NoiseResult typed;
  EXPECT_EQ(results::FromJson(ok, &typed).field(), "diagnostics.rate");
}

}  // namespace
}  // namespace calibd::server
