// Tests of the array method's JSON glue (methods/array/array_method.h).
#include "methods/array/array_method.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/array_simulation.h"
#include "formats/recording.h"
#include "tests/lib/array_csv.h"

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

  const ArrayRecording rec = testing::ArrayRecordingFromCsv(csv);
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
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv_rad), config_rad, &a).ok());
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv_deg), config_deg, &b).ok());
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
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
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
  Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
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

// --- accelerometer_calibration (issue #8) ---

// A pca result (SPEC §4) in the nominal frame for triads a0..a{K-1}: triad k's sensor i has the
// sensitivity column i of a_k and the bias b_k(i).
json PcaResult(const std::vector<core::AccelerometerTriadModel>& models) {
  json sensors = json::array(), stds = json::array();
  for (size_t k = 0; k < models.size(); ++k)
    for (int i = 0; i < 3; ++i) {
      const Eigen::Vector3d a = models[k].sensitivity.col(i);
      const std::string name = "a" + std::to_string(k) + "_" + "xyz"[i];
      sensors.push_back({{"name", name},
                         {"sensitivity", {a(0), a(1), a(2)}},
                         {"scale", a.norm()},
                         {"axis", {a(0) / a.norm(), a(1) / a.norm(), a(2) / a.norm()}},
                         {"bias", models[k].bias(i)}});
      stds.push_back(
          {{"name", name}, {"scale_std", 1e-4}, {"axis_std_rad", 1e-4}, {"bias_std", 1e-4}});
    }
  // Every key of the typed pca result (methods/pca/pca_result.h), which the chain reads.
  return {{"method", "pca"},
          {"model", "r_i = a_i^T v + b_i"},
          {"parameters",
           {{"dimension", 3},
            {"magnitude", 9.80665},
            {"magnitude_known", true},
            {"frame", "nominal"},
            {"bias", "estimate"},
            {"sensors", sensors}}},
          {"uncertainty", {{"sensors", stds}, {"noise_std", 0.001}}},
          {"diagnostics",
           {{"usable", true},
            {"singular_values", json::array()},
            {"rank_gap", nullptr},
            {"positions", 30},
            {"min_positions", 9},
            {"g_eigenvalues", json::array()},
            {"residual_rms", json::array()},
            {"magnitude_error", json::array()},
            {"degrees_of_freedom", 100},
            {"coverage",
             {{"verdict", "good"},
              {"scatter_eigenvalues", json::array()},
              {"scatter_min", 1.0},
              {"design_min", 1.0},
              {"positions_per_direction", json::object()},
              {"advice", ""}}},
            {"noise_std", 0.001},
            {"noise_std_given", false},
            {"noise_std_estimated", 0.001},
            {"cost_closed_form", 0.1},
            {"cost", 0.1},
            {"refined", false},
            {"refine_iterations", 0},
            {"reflection", false}}},
          {"warnings", json::array()}};
}

json IdealPcaResult(int triads = 32) {
  return PcaResult(std::vector<core::AccelerometerTriadModel>(triads));
}

// The index of sensor `name` in a PcaResult.
json& Sensor(json& pca, const std::string& name) {
  for (json& s : pca["parameters"]["sensors"])
    if (s["name"] == name) return s;
  ADD_FAILURE() << name;
  return pca;
}

// Renames sensor i (its parameters and its uncertainty, which are read in step).
void RenameSensor(json& pca, size_t i, const std::string& name) {
  pca["parameters"]["sensors"][i]["name"] = name;
  pca["uncertainty"]["sensors"][i]["name"] = name;
}

// Removes sensor i (parameters and uncertainty).
void EraseSensor(json& pca, size_t i) {
  pca["parameters"]["sensors"].erase(i);
  pca["uncertainty"]["sensors"].erase(i);
}

void ExpectCalibrationError(const json& calibration, const std::string& phrase) {
  json c = BaseConfig();
  c["accelerometer_calibration"] = calibration;
  ExpectKeyError(c, "accelerometer_calibration", phrase);
}

TEST(AccelerometerCalibration, ReadsTheSensitivityVectorsAsColumns) {
  std::vector<core::AccelerometerTriadModel> models(32);
  models[3].sensitivity << 1.01, 0.02, -0.01,  //
      0.005, 0.99, 0.03,                       //
      -0.02, 0.01, 1.02;
  models[3].bias << 0.1, -0.2, 0.3;
  ArrayAccelerometerCalibration cal;
  Status s = ParseAccelerometerCalibration(PcaResult(models), 32, &cal);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(cal.present);
  EXPECT_TRUE(cal.job.is_null());
  EXPECT_EQ(cal.sensors, 96);
  EXPECT_EQ(cal.frame, "nominal");
  EXPECT_EQ(cal.bias, "estimate");
  EXPECT_DOUBLE_EQ(cal.magnitude, 9.80665);
  ASSERT_EQ(cal.triads.size(), 32u);
  EXPECT_EQ(cal.triads[3].sensitivity, models[3].sensitivity);  // a3_y's vector is column 1
  EXPECT_EQ(cal.triads[3].bias, models[3].bias);
  EXPECT_EQ(cal.triads[0].sensitivity, Eigen::Matrix3d::Identity());
  EXPECT_GT(cal.max_condition_number, 1.0);
  EXPECT_TRUE(cal.warnings.empty());
  // The server's form {"job": ID, "result": {...}} gives the same, and records the job.
  ArrayAccelerometerCalibration by_job;
  ASSERT_TRUE(
      ParseAccelerometerCalibration({{"job", 12}, {"result", PcaResult(models)}}, 32, &by_job)
          .ok());
  EXPECT_EQ(by_job.job, 12);
  EXPECT_EQ(by_job.triads[3].sensitivity, models[3].sensitivity);
  const json j = by_job.ToJson();
  EXPECT_EQ(j["job"], 12);
  EXPECT_EQ(j["sensors"], 96);
  EXPECT_EQ(j["frame"], "nominal");
  EXPECT_TRUE(ArrayAccelerometerCalibration().ToJson().is_null());
  // Through ParseArrayConfig; null means none.
  json c = BaseConfig();
  c["accelerometer_calibration"] = PcaResult(models);
  core::ArrayProblem p;
  core::ArrayOptions o;
  bool deg = false;
  ASSERT_TRUE(ParseArrayConfig(c, &p, &o, &deg, &cal).ok());
  EXPECT_TRUE(cal.present);
  EXPECT_TRUE(ParseArrayConfig(c, &p, &o, &deg).ok());  // validation only
  c["accelerometer_calibration"] = nullptr;
  ASSERT_TRUE(ParseArrayConfig(c, &p, &o, &deg, &cal).ok());
  EXPECT_FALSE(cal.present);
}

TEST(AccelerometerCalibration, ErrorsSayWhatIsWrong) {
  ExpectCalibrationError("static/result.json", "only read by `calibd calibrate`");
  ExpectCalibrationError(42, "must be a pca result object");
  ExpectCalibrationError({{"job", 5}}, "only resolvable over HTTP");
  ExpectCalibrationError({{"job", "5"}, {"result", IdealPcaResult()}}, "integer id");
  ExpectCalibrationError({{"job", 5}, {"result", IdealPcaResult()}, {"note", 1}},
                         "unknown key 'note'");
  ExpectCalibrationError({{"job", 5}, {"result", "x"}}, "must be a JSON object");

  json pca = IdealPcaResult();
  pca["method"] = "array";
  ExpectCalibrationError(pca, "is not a pca result");
  pca = IdealPcaResult();
  pca.erase("parameters");
  ExpectCalibrationError(pca, "pca result: parameters: missing");
  pca = IdealPcaResult();
  pca["parameters"]["dimension"] = 2;
  ExpectCalibrationError(pca, "parameters.sensors[0].sensitivity: expected 2 numbers");
  pca = IdealPcaResult();
  pca["parameters"]["dimension"] = 2;
  for (json& s : pca["parameters"]["sensors"]) {
    s["sensitivity"].erase(2);
    s["axis"].erase(2);
  }
  ExpectCalibrationError(pca, "dimension 2");
  pca = IdealPcaResult();
  pca["parameters"]["frame"] = "canonical";
  ExpectCalibrationError(pca, "would not line up with the gyroscopes");
  pca = IdealPcaResult();
  pca["parameters"]["magnitude_known"] = false;
  ExpectCalibrationError(pca, "only relative");
  pca = IdealPcaResult();
  pca["diagnostics"]["usable"] = false;
  ExpectCalibrationError(pca, "not usable");

  // Names: the missing ones are listed.
  pca = IdealPcaResult();
  EraseSensor(pca, 95);  // a31_z
  EraseSensor(pca, 16);  // a5_y
  ExpectCalibrationError(pca, "missing a5_y, a31_z");
  pca = IdealPcaResult();
  for (size_t i = 0; i < 96; ++i)
    RenameSensor(pca, i,
                 "acc" + pca["parameters"]["sensors"][i]["name"].get<std::string>().substr(1));
  ExpectCalibrationError(pca, "no sensor for 96 of the 96 accelerometer columns: missing a0_x");
  ExpectCalibrationError(pca, "and 84 more");
  pca = IdealPcaResult();
  RenameSensor(pca, 21, "a7_y");  // a7_x
  ExpectCalibrationError(pca, "names sensor 'a7_y' twice");
  // Uncertainty out of step with the parameters: named by the reader.
  pca = IdealPcaResult();
  Sensor(pca, "a7_x")["name"] = "a7_q";
  ExpectCalibrationError(pca, "uncertainty.sensors[21].name");
  pca = IdealPcaResult();
  Sensor(pca, "a2_y")["sensitivity"] = {1, 0};
  ExpectCalibrationError(pca, "parameters.sensors[7].sensitivity: expected 3 numbers");
  pca = IdealPcaResult();
  Sensor(pca, "a2_y")["bias"] = "0.1";
  ExpectCalibrationError(pca, "parameters.sensors[7].bias: expected a number, found a string");
  pca = IdealPcaResult();
  Sensor(pca, "a2_y")["bias"] = nullptr;
  ExpectCalibrationError(pca,
                         "sensor 'a2_y' has a bias that is not a finite number "
                         "(parameters.sensors[7].bias)");
  // A geometry with fewer triads than the result: extra sensors are ignored.
  ArrayAccelerometerCalibration cal;
  ASSERT_TRUE(ParseAccelerometerCalibration(IdealPcaResult(), 31, &cal).ok());
  EXPECT_EQ(cal.sensors, 93);
  ASSERT_EQ(cal.warnings.size(), 1u);
  EXPECT_NE(cal.warnings[0].find("3 sensor(s)"), std::string::npos) << cal.warnings[0];
  // ... but a geometry with more triads lacks sensors.
  EXPECT_EQ(ParseAccelerometerCalibration(IdealPcaResult(), 33, &cal).field(),
            "accelerometer_calibration");

  // Singular and ill-conditioned triad blocks.
  pca = IdealPcaResult();
  Sensor(pca, "a9_z")["sensitivity"] = {1, 0, 0};  // = a9_x
  ExpectCalibrationError(pca,
                         "triad a9: the 3x3 block of sensitivity vectors of a9_x, a9_y, "
                         "a9_z is singular");
  pca = IdealPcaResult();
  Sensor(pca, "a9_z")["sensitivity"] = {1, 0, 1e-5};
  ExpectCalibrationError(pca, "ill-conditioned");

  // Suspicious but usable: warnings.
  pca = IdealPcaResult();
  pca["parameters"]["magnitude"] = 1.0;
  pca["parameters"]["bias"] = "none";
  ASSERT_TRUE(ParseAccelerometerCalibration(pca, 32, &cal).ok());
  ASSERT_EQ(cal.warnings.size(), 2u);
  EXPECT_NE(cal.warnings[0].find("not gravity in m/s^2"), std::string::npos) << cal.warnings[0];
  EXPECT_NE(cal.warnings[1].find("bias: none"), std::string::npos) << cal.warnings[1];
}

TEST(AccelerometerCalibration, TheTrueModelsMakeTheFitExact) {
  // Noise-free readings of a board with sensor errors; the calibration holding the true models
  // (in the pca result's convention) must give the positions to 1e-9 m. A transposed or
  // sign-flipped convention would leave errors of ~10 um.
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 31;
  so.accel_noise = 0;
  so.gyro_noise_dps = 0;
  so.accel_bias = 0.2;
  so.accel_scale_error = 0.02;
  so.accel_misalignment = 0.01;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  ASSERT_EQ(truth["accelerometer_sensors"].size(), 96u);
  EXPECT_EQ(truth["options"]["accel_bias"], 0.2);
  config["accel_noise"] = 0.04;
  config["gyro_noise"] = 0.001;
  json pca = IdealPcaResult();
  for (int i = 0; i < 96; ++i) {
    json& s = pca["parameters"]["sensors"][i];
    ASSERT_EQ(s["name"], truth["accelerometer_sensors"][i]["name"]);
    s["sensitivity"] = truth["accelerometer_sensors"][i]["sensitivity"];
    s["bias"] = truth["accelerometer_sensors"][i]["bias"];
  }
  const ArrayRecording rec = testing::ArrayRecordingFromCsv(csv);
  auto max_error = [&](const json& result) {
    double e = 0;
    for (int k = 0; k < 32; ++k)
      for (int i = 0; i < 3; ++i)
        e = std::max(e, std::abs(result["parameters"]["positions"][k]["position"][i].get<double>() -
                                 truth["positions"][k]["position"][i].get<double>()));
    return e;
  };
  json plain, calibrated;
  ASSERT_TRUE(RunArray(rec, config, &plain).ok());
  EXPECT_GT(max_error(plain), 1e-4);
  EXPECT_TRUE(plain["diagnostics"]["accelerometer_calibration"].is_null());
  config["accelerometer_calibration"] = pca;
  const Status s = RunArray(rec, config, &calibrated);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_LT(max_error(calibrated), 1e-9);
  const json& used = calibrated["diagnostics"]["accelerometer_calibration"];
  EXPECT_TRUE(used["job"].is_null());
  EXPECT_EQ(used["sensors"], 96);
  EXPECT_EQ(used["frame"], "nominal");
  EXPECT_EQ(used["bias"], "estimate");
  EXPECT_DOUBLE_EQ(used["magnitude"].get<double>(), 9.80665);
  EXPECT_TRUE(used["max_condition_number"].is_number());
  auto warned = [](const json& result) {
    for (const json& w : result["warnings"])
      if (w.get<std::string>().find("bias: none") != std::string::npos) return true;
    return false;
  };
  // Biases are applied whatever parameters.bias says (a result without the key reads as "none";
  // a raw log's removed biases are reported under "none"): no warning that they are not.
  config["accelerometer_calibration"]["parameters"]["bias"] = "none";
  ASSERT_TRUE(RunArray(rec, config, &calibrated).ok());
  EXPECT_LT(max_error(calibrated), 1e-9);
  EXPECT_FALSE(warned(calibrated)) << calibrated["warnings"].dump();
  // Bias-free readings assumed and no bias to apply: the warning reaches the result.
  for (json& sensor : config["accelerometer_calibration"]["parameters"]["sensors"])
    sensor["bias"] = 0.0;
  ASSERT_TRUE(RunArray(rec, config, &calibrated).ok());
  EXPECT_TRUE(warned(calibrated)) << calibrated["warnings"].dump();
}

TEST(SimulateArrayStaticFiles, PcaLayoutAndConfigOfTheSameBoard) {
  ArraySimulationFileOptions so;
  so.seed = 8;
  so.accel_bias = 0.1;
  so.static_samples = 400;  // noise 0.04 / 20 = 0.002
  std::string csv, csv2;
  json config, config2, array_config, truth;
  ASSERT_TRUE(SimulateArrayStaticFiles(so, 30, &csv, &config).ok());
  ASSERT_TRUE(SimulateArrayStaticFiles(so, 30, &csv2, &config2).ok());
  EXPECT_EQ(csv, csv2);
  EXPECT_EQ(config["method"], "pca");
  EXPECT_EQ(config["bias"], "estimate");
  EXPECT_DOUBLE_EQ(config["magnitude"].get<double>(), 9.80665);
  ASSERT_EQ(config["nominal"].size(), 96u);
  EXPECT_EQ(config["nominal"][0], json({1, 0, 0}));
  EXPECT_EQ(config["nominal"][4], json({0, 1, 0}));
  EXPECT_EQ(config["nominal"][95], json({0, 0, 1}));
  RecordingParser parser("static.csv", true);
  ASSERT_TRUE(ParseRecording(csv, &parser).ok());
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  ASSERT_EQ(rec.readings.rows(), 96);
  ASSERT_EQ(rec.readings.cols(), 30);
  EXPECT_EQ(rec.sensor_names[0], "a0_x");
  EXPECT_EQ(rec.sensor_names[95], "a31_z");
  EXPECT_EQ(rec.position_labels[29], "p30");
  // The biases of the array simulation's board are in the static readings: the mean over
  // orientations of each triad's readings is near its bias (gravity averages out roughly).
  ASSERT_TRUE(SimulateArrayFiles(so, &csv2, &array_config, &truth).ok());
  double agree = 0, total = 0;
  for (int i = 0; i < 96; ++i) {
    const double b = truth["accelerometer_sensors"][i]["bias"];
    agree += b * (rec.readings.row(i).mean());
    total += b * b;
  }
  EXPECT_GT(agree, 0.3 * total);
  // Errors.
  EXPECT_EQ(SimulateArrayStaticFiles(so, 0, &csv, &config).code(), StatusCode::kInvalidInput);
  so.static_samples = 0;
  EXPECT_EQ(SimulateArrayStaticFiles(so, 30, &csv, &config).code(), StatusCode::kInvalidInput);
  // Without sensor errors the truth has no accelerometer_sensors (outputs as before).
  so = ArraySimulationFileOptions();
  so.samples = 10;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv2, &array_config, &truth).ok());
  EXPECT_FALSE(truth.contains("accelerometer_sensors"));
  EXPECT_FALSE(truth["options"].contains("accel_bias"));
}

}  // namespace
}  // namespace calibd::server
