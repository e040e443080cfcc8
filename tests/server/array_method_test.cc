// Tests of the array method's JSON glue (server/array_method.h).
#include "server/array_method.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/array_simulation.h"
#include "server/recording.h"

namespace calibd::server {
namespace {

using nlohmann::json;

json BaseConfig() {
  json positions = json::array();
  const Eigen::Matrix3Xd r = core::PaperArrayNominalPositions();
  for (int k = 0; k < r.cols(); ++k) positions.push_back({r(0, k), r(1, k), r(2, k)});
  return {{"method", "array"},
          {"device", "SN-1"},
          {"geometry", {{"positions", positions}, {"reference", 0}}},
          {"accel_noise", 0.04},
          {"gyro_noise", 0.06 * core::kDegree}};
}

Status Parse(const json& config, core::ArrayProblem* p, core::ArrayOptions* o, bool* deg) {
  return ParseArrayConfig(config, p, o, deg);
}

void ExpectKeyError(const json& config, const std::string& field, const std::string& phrase) {
  core::ArrayProblem p;
  core::ArrayOptions o;
  bool deg = false;
  const Status s = Parse(config, &p, &o, &deg);
  ASSERT_EQ(s.code(), StatusCode::kInvalidInput) << config.dump();
  EXPECT_EQ(s.field(), field) << s.message();
  EXPECT_NE(s.message().find(field), std::string::npos) << s.message();
  EXPECT_NE(s.message().find(phrase), std::string::npos) << s.message();
}

TEST(ParseArrayConfig, ReadsEveryKey) {
  json c = BaseConfig();
  c["gyro_unit"] = "deg/s";
  c["gyro_noise"] = 0.06;
  c["gyro_saturation"] = 2000;
  c["solver"] = "bcd";
  c["max_iterations"] = 300;
  c["tolerance"] = 1e-8;
  c["geometry"]["reference"] = 3;
  core::ArrayProblem p;
  core::ArrayOptions o;
  bool deg = false;
  ASSERT_TRUE(Parse(c, &p, &o, &deg).ok());
  EXPECT_TRUE(deg);
  EXPECT_EQ(p.nominal_positions.cols(), 32);
  EXPECT_EQ(p.nominal_positions, core::PaperArrayNominalPositions());
  EXPECT_EQ(p.reference, 3);
  EXPECT_DOUBLE_EQ(o.accel_noise, 0.04);
  EXPECT_DOUBLE_EQ(o.gyro_noise, 0.06 * core::kDegree);
  ASSERT_TRUE(o.gyro_saturation.has_value());
  EXPECT_DOUBLE_EQ(*o.gyro_saturation, 2000 * core::kDegree);
  EXPECT_EQ(o.solver, core::ArraySolver::kBcd);
  EXPECT_EQ(o.max_iterations, 300);
  EXPECT_DOUBLE_EQ(o.tolerance, 1e-8);
  // Defaults.
  ASSERT_TRUE(Parse(BaseConfig(), &p, &o, &deg).ok());
  EXPECT_FALSE(deg);
  EXPECT_EQ(p.reference, 0);
  EXPECT_EQ(o.solver, core::ArraySolver::kJoint);
  EXPECT_FALSE(o.gyro_saturation.has_value());
}

TEST(ParseArrayConfig, ErrorsNameTheKey) {
  json c = BaseConfig();
  c["bogus"] = 1;
  ExpectKeyError(c, "bogus", "unknown key");
  c = BaseConfig();
  c.erase("geometry");
  ExpectKeyError(c, "geometry", "missing");
  c = BaseConfig();
  c.erase("accel_noise");
  ExpectKeyError(c, "accel_noise", "missing");
  c = BaseConfig();
  c.erase("gyro_noise");
  ExpectKeyError(c, "gyro_noise", "missing");
  c = BaseConfig();
  c["accel_noise"] = "0.04";
  ExpectKeyError(c, "accel_noise", "number");
  c = BaseConfig();
  c["accel_noise"] = -1;
  ExpectKeyError(c, "accel_noise", "> 0");
  c = BaseConfig();
  c["gyro_unit"] = "rpm";
  ExpectKeyError(c, "gyro_unit", "deg/s");
  c = BaseConfig();
  c["solver"] = "ceres";
  ExpectKeyError(c, "solver", "joint");
  c = BaseConfig();
  c["max_iterations"] = 2.5;
  ExpectKeyError(c, "max_iterations", "integer");
  c = BaseConfig();
  c["tolerance"] = -1;
  ExpectKeyError(c, "tolerance", ">= 0");
  c = BaseConfig();
  c["gyro_saturation"] = true;
  ExpectKeyError(c, "gyro_saturation", "number");
  c = BaseConfig();
  c["geometry"] = json::array();
  ExpectKeyError(c, "geometry", "object");
  c = BaseConfig();
  c["geometry"]["positions"][4] = {1, 2};
  ExpectKeyError(c, "geometry.positions[4]", "3 numbers");
  c = BaseConfig();
  c["geometry"]["reference"] = 32;
  ExpectKeyError(c, "geometry.reference", "integer");
  c = BaseConfig();
  c["geometry"]["origin"] = 0;
  ExpectKeyError(c, "geometry.origin", "unknown key");
  c = BaseConfig();
  c["accelerometer_calibration"] = json::object();
  ExpectKeyError(c, "accelerometer_calibration", "is not a pca result");
}

ArrayRecording RecordingFromCsv(const std::string& csv) {
  RecordingParser parser("recording.csv", true);
  const Status s = ParseRecording(csv, &parser);
  EXPECT_TRUE(s.ok()) << s.ToString();
  ArrayRecording rec;
  EXPECT_TRUE(parser.TakeArray(&rec).ok());
  return rec;
}

TEST(RunArray, SimulatedFilesGiveTheSpecResult) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 3;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  EXPECT_EQ(csv.substr(0, 20), "t,a0_x,a0_y,a0_z,a1_");
  EXPECT_NE(csv.find(",g31_z\n"), std::string::npos);
  EXPECT_EQ(config["method"], "array");
  EXPECT_EQ(config["geometry"]["positions"].size(), 32u);
  EXPECT_EQ(truth["positions"].size(), 32u);
  EXPECT_EQ(truth["seed"], 3);

  const ArrayRecording rec = RecordingFromCsv(csv);
  ASSERT_EQ(rec.accel.rows(), 400);
  json result;
  const Status s = RunArray(rec, config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();

  // Exactly the SPEC §4 keys.
  EXPECT_EQ(result["method"], "array");
  for (const char* key : {"parameters", "uncertainty", "diagnostics", "warnings"})
    EXPECT_TRUE(result.contains(key)) << key;
  EXPECT_EQ(result["parameters"]["reference"], 0);
  ASSERT_EQ(result["parameters"]["positions"].size(), 32u);
  const json& p5 = result["parameters"]["positions"][5];
  EXPECT_EQ(p5["name"], "a5");
  ASSERT_EQ(p5["position"].size(), 3u);
  ASSERT_EQ(p5["offset"].size(), 3u);
  ASSERT_EQ(result["uncertainty"]["positions"].size(), 32u);
  EXPECT_EQ(result["uncertainty"]["positions"][5]["name"], "a5");
  ASSERT_EQ(result["uncertainty"]["positions"][5]["std"].size(), 3u);
  const json& d = result["diagnostics"];
  for (const char* key : {"solver", "iterations", "converged", "cost", "samples", "samples_dropped",
                          "residual_rms", "noise_estimate", "excitation"})
    EXPECT_TRUE(d.contains(key)) << key;
  EXPECT_EQ(d["solver"], "joint");
  EXPECT_EQ(d["converged"], true);
  EXPECT_EQ(d["samples"], 400);
  EXPECT_EQ(d["samples_dropped"], 0);
  EXPECT_TRUE(d["cost"].is_array());
  EXPECT_TRUE(d["residual_rms"]["accelerometer"].is_number());
  EXPECT_TRUE(d["residual_rms"]["gyroscope"].is_number());
  EXPECT_NEAR(d["noise_estimate"]["accelerometer"].get<double>(), 0.04, 0.002);
  EXPECT_NEAR(d["noise_estimate"]["gyroscope"].get<double>(), 0.06 * core::kDegree, 0.06e-3);
  EXPECT_TRUE(d["excitation"]["min_eigenvalue"].is_number());
  EXPECT_EQ(d["excitation"]["verdict"], "good");
  EXPECT_EQ(d["motion"]["omega_norm"].size(), 400u);

  // Estimates against the truth: within 5 reported standard deviations.
  for (int k = 1; k < 32; ++k)
    for (int i = 0; i < 3; ++i) {
      const double est = result["parameters"]["positions"][k]["position"][i];
      const double tru = truth["positions"][k]["position"][i];
      const double sd = result["uncertainty"]["positions"][k]["std"][i];
      EXPECT_LT(std::abs(est - tru), 5 * sd) << k << " " << i;
    }
  // Deterministic.
  json again;
  ASSERT_TRUE(RunArray(rec, config, &again).ok());
  EXPECT_EQ(result.dump(), again.dump());
}

TEST(RunArray, GyroInDegreesGivesTheSameEstimate) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  std::string csv_rad, csv_deg;
  json config_rad, config_deg, truth;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv_rad, &config_rad, &truth).ok());
  so.gyro_unit = "deg/s";
  ASSERT_TRUE(SimulateArrayFiles(so, &csv_deg, &config_deg, &truth).ok());
  EXPECT_EQ(config_deg["gyro_unit"], "deg/s");
  EXPECT_DOUBLE_EQ(config_deg["gyro_noise"].get<double>(), 0.06);
  json a, b;
  ASSERT_TRUE(RunArray(RecordingFromCsv(csv_rad), config_rad, &a).ok());
  ASSERT_TRUE(RunArray(RecordingFromCsv(csv_deg), config_deg, &b).ok());
  for (int k = 0; k < 32; ++k)
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(a["parameters"]["positions"][k]["position"][i].get<double>(),
                  b["parameters"]["positions"][k]["position"][i].get<double>(), 1e-12);
  EXPECT_EQ(b["diagnostics"]["gyro_unit"], "deg/s");
  EXPECT_NEAR(b["diagnostics"]["noise_estimate"]["gyroscope"].get<double>(), 0.06, 0.006);
}

TEST(RunArray, TriadCountMismatchNamesBothCounts) {
  ArraySimulationFileOptions so;
  so.samples = 50;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  config["geometry"]["positions"].erase(31);
  json result;
  const Status s = RunArray(RecordingFromCsv(csv), config, &result);
  ASSERT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("32"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("31"), std::string::npos) << s.message();
}

TEST(RunArray, NotDeterminableAndDecimatedMotion) {
  // Two samples only: kNotDeterminable with advice.
  ArrayRecording rec;
  ArraySimulationFileOptions so;
  so.samples = 2;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  Status s = RunArray(RecordingFromCsv(csv), config, &result);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("at least 3"), std::string::npos);

  // Plots are decimated to at most 2000 points.
  core::ArraySimulationOptions cs;
  cs.samples = 5000;
  core::ArraySimulation sim;
  ASSERT_TRUE(core::SimulateArray(cs, &sim).ok());
  rec.accel = sim.problem.accel;
  rec.gyro = sim.problem.gyro;
  rec.accel_names = sim.problem.accel_names;
  rec.gyro_names = sim.gyro_names;
  ASSERT_TRUE(RunArray(rec, BaseConfig(), &result).ok());
  EXPECT_LE(result["diagnostics"]["motion"]["omega_norm"].size(), 2000u);
  EXPECT_GE(result["diagnostics"]["motion"]["omega_norm"].size(), 1000u);
  EXPECT_EQ(result["diagnostics"]["motion"]["stride"], 3);
}

}  // namespace
}  // namespace calibd::server
