// The typed array result (results/array_result.h) has every key the real adapter writes: results
// of RunArray on simulated recordings (both models, several option combinations, failing runs'
// partial documents) read with FromJson and write back with ToJson to exactly the same JSON.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>

#include "core/array_simulation.h"
#include "core/pca.h"
#include "results/array_result.h"
#include "server/array_method.h"
#include "server/pca_method.h"
#include "server/recording.h"

namespace calibd::server {
namespace {

using nlohmann::json;

ArrayRecording RecordingFromCsv(const std::string& csv) {
  RecordingParser parser("recording.csv", true);
  const Status s = ParseRecording(csv, &parser);
  EXPECT_TRUE(s.ok()) << s.ToString();
  ArrayRecording rec;
  EXPECT_TRUE(parser.TakeArray(&rec).ok());
  return rec;
}

// FromJson(doc) succeeds, and ToJson of what it read is doc exactly.
void ExpectRoundTrip(const json& doc, bool usable, bool full) {
  results::ArrayResult r;
  const Status s = results::FromJson(doc, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.envelope.usable, usable);
  EXPECT_EQ(r.full, full);
  EXPECT_EQ(doc["schema_version"], results::kArraySchemaVersion);
  const json back = results::ToJson(r);
  EXPECT_EQ(back, doc) << "adapter: " << doc.dump() << "\nround trip: " << back.dump();
}

// A real pca result (frame nominal) of the same simulated board's static recording.
json PcaOfTheBoard(const ArraySimulationFileOptions& so) {
  std::string csv;
  json config;
  EXPECT_TRUE(SimulateArrayStaticFiles(so, 30, &csv, &config).ok());
  RecordingParser parser("static.csv", true);
  EXPECT_TRUE(ParseRecording(csv, &parser).ok());
  PcaRecording rec;
  EXPECT_TRUE(parser.TakePca(&rec).ok());
  core::PcaOptions options;
  EXPECT_TRUE(ParsePcaConfig(config, &options).ok());
  json result;
  const Status s = RunPca(rec, options, &result);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

TEST(ArrayResultSchema, PositionsModelJointSolverRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 5;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["solver"], "joint");
  EXPECT_TRUE(result["diagnostics"]["accelerometer_calibration"].is_null());
  ExpectRoundTrip(result, true, false);
}

TEST(ArrayResultSchema, PositionsModelBcdWithCalibrationAndNoiseJobRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 6;
  so.gyro_unit = "deg/s";
  so.accel_bias = 0.05;
  so.accel_scale_error = 0.01;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  config["solver"] = "bcd";
  config["max_iterations"] = 30;
  config["gyro_noise"] = {{"job", 12}, {"sigma", 0.06 * core::kDegree}};  // resolved reference
  config["accelerometer_calibration"] = {{"job", 7}, {"result", PcaOfTheBoard(so)}};
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json& d = result["diagnostics"];
  EXPECT_EQ(d["solver"], "bcd");
  EXPECT_EQ(d["gyro_unit"], "deg/s");
  EXPECT_EQ(d["noise_jobs"]["gyroscope"], 12);
  EXPECT_EQ(d["accelerometer_calibration"]["job"], 7);
  ExpectRoundTrip(result, true, false);
}

TEST(ArrayResultSchema, PositionsModelFailingRunsPartialDocumentRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 2;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_EQ(result["usable"], false);
  EXPECT_FALSE(result.contains("parameters"));
  ExpectRoundTrip(result, false, false);
}

TEST(ArrayResultSchema, FullModelRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 8;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["parameters"]["model"], "full");
  ExpectRoundTrip(result, true, true);
}

TEST(ArrayResultSchema, FullModelWithResidualAwareSigmaInDegreesRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 9;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  // A configured accelerometer noise a tenth of the true one: the residuals exceed it, so the
  // result carries the residual-aware σ (uncertainty.imus[].robust).
  config["accel_noise"] = so.accel_noise / 10;
  config["dynamic_weighting"] = "residual";
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["gyro_unit"], "deg/s");
  EXPECT_TRUE(result["diagnostics"]["robust"]["used"].get<bool>()) << result["diagnostics"].dump();
  EXPECT_TRUE(result["uncertainty"]["imus"][1].contains("robust"));
  ExpectRoundTrip(result, true, true);
}

TEST(ArrayResultSchema, FullModelFailingRunsPartialDocumentRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 100;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  config["min_static"] = 100;  // s: no static of 1.5 s qualifies
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(result["usable"], false) << result.dump();
  EXPECT_EQ(result["diagnostics"]["model"], "full");
  ExpectRoundTrip(result, false, true);
}

// The exports read the result typed: the real adapter's result exports, a damaged one is an
// internal error naming the path of the problem.
TEST(ArrayResultSchema, ExportsReadTheTypedResultAndNameWhatDoesNotRead) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 5;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  ASSERT_TRUE(RunArray(RecordingFromCsv(csv), config, &result).ok());
  std::string out;
  ASSERT_TRUE(ArrayResultToCsv(result, &out).ok());
  EXPECT_EQ(out.substr(0, out.find('\n')),
            "name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z");
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 33);  // header and 32 triads
  result["parameters"]["positions"][4]["offset"] = {1, 2};
  Status s = ArrayResultToCsv(result, &out);
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_NE(s.message().find("parameters.positions[4].offset"), std::string::npos) << s.message();
  s = ArrayResultToHeader(result, {1, "D", "array", "2026-01-01T00:00:00Z"}, &out);
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_NE(s.message().find("parameters.positions[4].offset"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::server
