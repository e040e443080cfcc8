// The typed noise result (results/noise_result.h) holds every key the real adapter writes:
// results of `noise` runs on small simulated logs (several option combinations, and a failed
// run's partial diagnostics) read with FromJson and write back with ToJson to the same document;
// Judge and the exports refuse a result that does not read, naming the path.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "results/noise_result.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "server/method.h"
#include "server/noise_method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The stored form of a result: its JSON text parsed back (NaN as null, as the store keeps it).
json Stored(const json& result) { return json::parse(result.dump()); }

void ExpectRoundTrip(const json& stored) {
  results::NoiseResult typed;
  const Status s = results::FromJson(stored, &typed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(results::ToJson(typed), stored)
      << "ToJson: " << results::ToJson(typed).dump() << "\nstored: " << stored.dump();
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
    EXPECT_EQ(e.code(), StatusCode::kInternal) << format;
    EXPECT_NE(e.message().find("uncertainty.channels[2].white_noise_std"), std::string::npos)
        << e.message();
  }
}

}  // namespace
}  // namespace calibd::server
