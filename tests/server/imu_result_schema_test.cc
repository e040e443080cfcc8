// The typed imu result (results/imu_result.h) holds every key the real adapter writes: results of
// `imu` runs on small simulated logs (gyro_bias statics and estimate, counts with nominal biases,
// a gap in t, resolved noise-job references, and a failed run's partial diagnostics) read with
// FromJson and write back with ToJson to the same document; the consumers refuse a result that
// does not read, naming the path.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "results/imu_result.h"
#include "server/config.h"
#include "server/failure_reasons.h"
#include "server/imu_method.h"
#include "server/method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The stored form of a result: its JSON text parsed back (NaN as null, as the store keeps it).
json Stored(const json& result) { return json::parse(result.dump()); }

void ExpectRoundTrip(const json& stored) {
  results::ImuResult typed;
  const Status s = results::FromJson(stored, &typed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(results::ToJson(typed), stored)
      << "ToJson: " << results::ToJson(typed).dump() << "\nstored: " << stored.dump();
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
    // Resolved references (server/noise_reference.h), as the server leaves them in the config.
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
    EXPECT_EQ(e.code(), StatusCode::kInternal) << format;
    EXPECT_NE(e.message().find("diagnostics.imus[0].residuals.accel_norm_rms_after"),
              std::string::npos)
        << e.message();
  }
}

}  // namespace
}  // namespace calibd::server
