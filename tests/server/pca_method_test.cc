// Tests of the pca JSON glue (methods/pca/pca_method.h): config keys, the SPEC §4 result keys, raw
// vs averaged layouts, and `simulate pca`.
#include "methods/pca/pca_method.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <set>
#include <string>

#include "core/pca_simulation.h"
#include "formats/recording.h"

namespace calibd::server {
namespace {

using nlohmann::json;

std::set<std::string> Keys(const json& object) {
  std::set<std::string> keys;
  for (const auto& [key, value] : object.items()) keys.insert(key);
  return keys;
}

// Every number in the tree is finite (NaN/Inf must have become null).
void ExpectNoNonFinite(const json& x) {
  if (x.is_number_float()) {
    EXPECT_TRUE(std::isfinite(x.get<double>()));
  }
  if (x.is_structured()) {
    for (const auto& item : x) ExpectNoNonFinite(item);
  }
}

Status ParseCsv(const std::string& csv, PcaRecording* out) {
  RecordingParser parser("test.csv", true);
  Status s = ParseRecording(csv, &parser);
  if (!s.ok()) return s;
  return parser.TakePca(out);
}

TEST(PcaConfig, ParsesEveryKey) {
  const json config = json::parse(R"({"method":"pca","device":"SN1","dimension":2,
      "magnitude":9.81,"nominal":[[1,0],[0,1],[1,1]],"refine":true,"bias":"estimate",
      "noise_std":0.01})");
  core::PcaOptions o;
  ASSERT_TRUE(ParsePcaConfig(config, &o).ok());
  EXPECT_EQ(o.dimension, 2);
  EXPECT_EQ(*o.magnitude, 9.81);
  ASSERT_TRUE(o.nominal.has_value());
  EXPECT_EQ(o.nominal->rows(), 2);
  EXPECT_EQ(o.nominal->cols(), 3);
  EXPECT_EQ((*o.nominal)(1, 2), 1.0);  // sensor 3's second component
  EXPECT_TRUE(o.refine);
  EXPECT_EQ(o.bias, core::BiasModel::kEstimate);
  EXPECT_EQ(*o.noise_std, 0.01);
}

TEST(PcaConfig, DefaultsAndNullMeanUnknown) {
  core::PcaOptions o;
  ASSERT_TRUE(ParsePcaConfig(json::parse(R"({"method":"pca","magnitude":null})"), &o).ok());
  EXPECT_EQ(o.dimension, 3);
  EXPECT_FALSE(o.magnitude.has_value());
  EXPECT_FALSE(o.nominal.has_value());
  EXPECT_FALSE(o.refine);
  EXPECT_EQ(o.bias, core::BiasModel::kNone);
}

TEST(PcaConfig, RejectsUnknownKeysAndWrongTypesNamingTheKey) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {R"({"method":"pca","magnitud":1})", "magnitud"},
      {R"({"method":"pca","dimension":"3"})", "dimension"},
      {R"({"method":"pca","dimension":2.5})", "dimension"},
      {R"({"method":"pca","dimension":0})", "dimension"},
      {R"({"method":"pca","magnitude":-1})", "magnitude"},
      {R"({"method":"pca","magnitude":"9.81"})", "magnitude"},
      {R"({"method":"pca","noise_std":0})", "noise_std"},
      {R"({"method":"pca","refine":"yes"})", "refine"},
      {R"({"method":"pca","bias":"auto"})", "bias"},
      {R"({"method":"pca","nominal":[[1,0,0],[0,1]]})", "nominal"},
      {R"({"method":"pca","nominal":[[1,0,"x"]]})", "nominal"},
      {R"({"method":"pca","nominal":[[0,0,0]]})", "nominal"},
      {R"({"method":"pca","nominal":{"a":1}})", "nominal"},
  };
  for (const auto& [text, key] : cases) {
    core::PcaOptions o;
    const Status s = ParsePcaConfig(json::parse(text), &o);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << text;
    EXPECT_EQ(s.field(), key) << text;
    EXPECT_NE(s.message().find("'" + key + "'"), std::string::npos) << s.message();
  }
  core::PcaOptions o;
  EXPECT_EQ(ParsePcaConfig(json::array(), &o).code(), StatusCode::kInvalidInput);
}

TEST(PcaResultJson, HasExactlyTheSpecKeysAndNoNonFiniteNumbers) {
  std::string csv;
  json config, truth;
  core::PcaSimulationOptions so;
  so.positions = 30;
  ASSERT_TRUE(SimulatePcaFiles(so, &csv, &config, &truth).ok());
  PcaRecording rec;
  ASSERT_TRUE(ParseCsv(csv, &rec).ok());
  core::PcaOptions o;
  ASSERT_TRUE(ParsePcaConfig(config, &o).ok());
  json result;
  ASSERT_TRUE(RunPca(rec, o, &result).ok());
  EXPECT_EQ(Keys(result), (std::set<std::string>{"method", "schema_version", "model", "parameters",
                                                 "uncertainty", "diagnostics", "warnings"}));
  EXPECT_EQ(result["method"], "pca");
  const json& p = result["parameters"];
  for (const char* key : {"dimension", "magnitude", "magnitude_known", "frame", "sensors"}) {
    EXPECT_TRUE(p.contains(key)) << key;
  }
  EXPECT_EQ(p["frame"], "nominal");
  EXPECT_EQ(p["sensors"].size(), 12u);
  EXPECT_EQ(Keys(p["sensors"][0]),
            (std::set<std::string>{"name", "sensitivity", "scale", "axis", "bias"}));
  EXPECT_EQ(p["sensors"][0]["name"], "g0_x");
  EXPECT_EQ(p["sensors"][0]["sensitivity"].size(), 3u);
  EXPECT_EQ(Keys(result["uncertainty"]["sensors"][0]),
            (std::set<std::string>{"name", "scale_std", "axis_std_rad", "bias_std"}));
  const json& d = result["diagnostics"];
  for (const char* key : {"singular_values", "rank_gap", "positions", "min_positions",
                          "g_eigenvalues", "residual_rms", "magnitude_error"}) {
    EXPECT_TRUE(d.contains(key)) << key;
  }
  EXPECT_EQ(d["singular_values"].size(), 12u);
  EXPECT_EQ(d["positions"], 30);
  EXPECT_EQ(d["min_positions"], 6);
  EXPECT_EQ(d["residual_rms"].size(), 12u);
  EXPECT_EQ(d["magnitude_error"].size(), 30u);
  // 30 random orientations span the sphere: coverage good, nothing to add.
  EXPECT_EQ(d["coverage"]["verdict"], "good") << d["coverage"].dump();
  EXPECT_EQ(d["coverage"]["advice"], "");
  EXPECT_EQ(d["coverage"]["scatter_eigenvalues"].size(), 3u);
  EXPECT_EQ(d["coverage"]["positions_per_direction"].size(), 18u);
  ExpectNoNonFinite(result);
  // Close to the truth (nominal frame ≈ the body frame of a_model).
  for (int i = 0; i < 12; ++i) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(p["sensors"][i]["sensitivity"][k].get<double>(),
                  truth["sensors"][i]["sensitivity"][k].get<double>(), 0.03);
    }
  }
  // Deterministic.
  json again;
  ASSERT_TRUE(RunPca(rec, o, &again).ok());
  EXPECT_EQ(result.dump(), again.dump());
}

TEST(PcaResultJson, UndefinedValuesAreNull) {
  // m = d = 3 and n = 6: no σ_{d+1} (rank gap undefined) and no redundancy to estimate noise.
  core::PcaRandom rng(3);
  const Eigen::MatrixXd a = rng.NormalMatrix(3, 3);
  const Eigen::MatrixXd v = rng.SphereColumns(3, 6, 1.0);
  PcaRecording rec;
  rec.sensor_names = {"x", "y", "z"};
  for (int j = 0; j < 6; ++j) rec.position_labels.push_back(std::to_string(j));
  rec.readings = a.transpose() * v;
  core::PcaOptions o;
  o.magnitude = 1.0;
  json result;
  ASSERT_TRUE(RunPca(rec, o, &result).ok());
  EXPECT_TRUE(result["diagnostics"]["rank_gap"].is_null());
  EXPECT_TRUE(result["uncertainty"]["sensors"][0]["scale_std"].is_null());
  EXPECT_TRUE(result["diagnostics"]["noise_std_estimated"].is_null());
  ExpectNoNonFinite(result);
}

TEST(PcaRun, RawLogGivesTheSameResultAsItsAveragedEquivalent) {
  core::PcaSimulationOptions so;
  so.positions = 12;
  so.noise_std = 0;
  const core::PcaSimulation sim = core::SimulatePca(so);
  core::PcaRandom rng(42);
  const Eigen::VectorXd bias = 0.5 * rng.NormalMatrix(12, 1);
  std::string raw = "# raw log\r\nposition,phase";
  std::string averaged = "position";
  for (const std::string& name : sim.sensor_names) {
    raw += "," + name;
    averaged += "," + name;
  }
  raw += "\r\n";
  averaged += "\n";
  auto row = [](const std::string& label, const Eigen::VectorXd& x) {
    std::string out = label;
    char buf[40];
    for (Eigen::Index i = 0; i < x.size(); ++i) {
      std::snprintf(buf, sizeof(buf), ",%.17g", x(i));
      out += buf;
    }
    return out;
  };
  Eigen::MatrixXd diff(12, so.positions);
  for (int j = 0; j < so.positions; ++j) {
    const std::string label = "pos" + std::to_string(j);
    // Three static and four moving rows per position, with noise that averages out exactly
    // (symmetric offsets), and a bias drifting slightly between positions.
    const Eigen::VectorXd b = bias + Eigen::VectorXd::Constant(12, 0.001 * j);
    const Eigen::VectorXd p = sim.m.col(j);
    const Eigen::VectorXd w = 0.01 * rng.NormalMatrix(12, 1);
    for (double s : {-1.0, 0.0, 1.0}) raw += row(label + ",static", b + s * w) + "\r\n";
    for (double s : {-1.0, -0.5, 0.5, 1.0}) raw += row(label + ",moving", b + p + s * w) + "\r\n";
    diff.col(j) = (b + p) - b;
    averaged += row(label, diff.col(j)) + "\n";
  }
  PcaRecording rec_raw, rec_avg;
  ASSERT_TRUE(ParseCsv(raw, &rec_raw).ok());
  ASSERT_TRUE(ParseCsv(averaged, &rec_avg).ok());
  ASSERT_TRUE(rec_raw.raw);
  core::PcaOptions o;
  o.magnitude = 1.0;
  json r_raw, r_avg;
  ASSERT_TRUE(RunPca(rec_raw, o, &r_raw).ok());
  ASSERT_TRUE(RunPca(rec_avg, o, &r_avg).ok());
  for (int i = 0; i < 12; ++i) {
    const json& s_raw = r_raw["parameters"]["sensors"][i];
    const json& s_avg = r_avg["parameters"]["sensors"][i];
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(s_raw["sensitivity"][k].get<double>(), s_avg["sensitivity"][k].get<double>(),
                  1e-9);
    }
    // The raw log reports the removed bias (mean static reading) with its standard error.
    const double expected_bias = bias(i) + 0.001 * (so.positions - 1) / 2.0;
    EXPECT_NEAR(s_raw["bias"].get<double>(), expected_bias, 1e-12);
    EXPECT_EQ(s_avg["bias"].get<double>(), 0.0);
    EXPECT_GT(r_raw["uncertainty"]["sensors"][i]["bias_std"].get<double>(), 0.0);
  }
}

TEST(PcaRun, NominalOfTheWrongSizeIsInvalidInput) {
  const core::PcaSimulation sim = core::SimulatePca(core::PcaSimulationOptions());
  PcaRecording rec;
  rec.sensor_names = sim.sensor_names;
  rec.readings = sim.m;
  core::PcaOptions o;
  o.nominal = Eigen::MatrixXd::Identity(3, 11);
  json result;
  const Status s = RunPca(rec, o, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "nominal");
}

TEST(PcaRun, CoplanarRecordingIsNotDeterminable) {
  const core::PcaSimulation sim = core::SimulatePca(core::PcaSimulationOptions());
  Eigen::MatrixXd v = sim.v;
  v.row(2).setZero();
  PcaRecording rec;
  rec.sensor_names = sim.sensor_names;
  rec.readings = sim.a_true.transpose() * v;
  json result;
  const Status s = RunPca(rec, core::PcaOptions(), &result);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("record orientations"), std::string::npos) << s.message();
}

TEST(PcaSimulateFiles, DeterministicAndComplete) {
  core::PcaSimulationOptions so;
  so.positions = 7;
  so.seed = 99;
  std::string csv1, csv2;
  json config1, config2, truth1, truth2;
  ASSERT_TRUE(SimulatePcaFiles(so, &csv1, &config1, &truth1).ok());
  ASSERT_TRUE(SimulatePcaFiles(so, &csv2, &config2, &truth2).ok());
  EXPECT_EQ(csv1, csv2);
  EXPECT_EQ(config1.dump(), config2.dump());
  EXPECT_EQ(truth1.dump(), truth2.dump());
  EXPECT_NE(csv1.find("position,g0_x,g0_y,g0_z,g1_x"), std::string::npos);
  EXPECT_EQ(config1["method"], "pca");
  EXPECT_EQ(config1["nominal"].size(), 12u);
  EXPECT_EQ(config1["nominal"][3], json::parse("[0.0,-1.0,0.0]"));
  EXPECT_EQ(truth1["seed"], 99);
  EXPECT_EQ(truth1["v"].size(), 7u);
  EXPECT_EQ(truth1["sensors"].size(), 12u);
  PcaRecording rec;
  ASSERT_TRUE(ParseCsv(csv1, &rec).ok());
  EXPECT_EQ(rec.readings.cols(), 7);
  // Full precision: the parsed readings are the simulated ones bit for bit.
  EXPECT_EQ(rec.readings, core::SimulatePca(so).m);
  so.positions = 0;
  EXPECT_EQ(SimulatePcaFiles(so, &csv1, &config1, &truth1).code(), StatusCode::kInvalidInput);
}

}  // namespace
}  // namespace calibd::server
