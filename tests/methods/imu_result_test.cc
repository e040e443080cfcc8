// methods/imu/imu_result.h: the typed imu result round-trips, reads results stored before the later
// keys existed, and names the path of the first problem.
#include "methods/imu/imu_result.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace calibd::results {
namespace {

using nlohmann::json;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

ImuFitDiagnostics Fit(const std::string& name) {
  ImuFitDiagnostics f;
  f.name = name;
  f.usable = true;
  f.termination = "converged";
  f.chi2_per_dof = 1.02;
  f.degrees_of_freedom = 120;
  f.accel_iterations = 6;
  f.gyro_iterations = 9;
  f.joint_iterations = 3;
  f.accel_noise = Eigen::Vector3d(0.01, 0.011, 0.012);
  f.gyro_noise = Eigen::Vector3d(1e-3, 1.1e-3, 1.2e-3);
  f.accel_norm_rms_before = 0.2;
  f.accel_norm_rms_after = 0.001;
  f.gyro_direction_rms_before = 0.05;
  f.gyro_direction_rms_after = 0.002;
  ImuStatic s;
  s.start = 1;
  s.end = 3;
  s.samples = 200;
  s.accel_mean = Eigen::Vector3d(0, 0, 9.8);
  s.gravity_direction = Eigen::Vector3d(0, 0, 1);
  s.norm_residual_after = kNaN;
  f.statics = {s, s};
  ImuRotation q;
  q.from = 0;
  q.to = 1;
  q.angle = 1.57;
  q.used = false;
  q.excluded = "gap in t";
  f.rotations = {q};
  f.coverage.gravity_eigenvalues = Eigen::Vector3d(0.9, 1, 1.1);
  f.coverage.missing_up = {"-z"};
  f.coverage.weak_axes = {"y"};
  f.coverage.sufficient = true;
  f.coverage.verdict = "good";
  f.threshold_trials = {{2, 12, 1.1, false}, {3, 14, kNaN, true}};
  f.threshold_choice = "3 x the noise floor";
  f.cost = {100, 10, 1};
  return f;
}

ImuResult HandBuilt() {
  ImuResult r;
  r.envelope.method = "imu";
  r.envelope.model = "a = T_a K_a (y_a - b_a)";
  r.envelope.warnings = {"IMU 0: one rotation not used"};
  ImuParameters p;
  p.gravity = 9.80665;
  p.gyro_bias = "statics";
  p.accel_unit = 0.0024;
  p.gyro_unit = 2e-4;
  ImuTriads t;
  t.name = "0";
  t.accelerometer.bias = Eigen::Vector3d(32768, 32760, 32770);
  t.accelerometer.scale = Eigen::Vector3d(0.0024, 0.00241, 0.00239);
  t.gyroscope.misalignment(0, 1) = 0.01;
  ImuTriads t1 = t;
  t1.name = "1";
  p.imus = {t, t1};
  r.parameters = p;
  ImuUncertainty u;
  ImuTriadsStd sd;
  sd.name = "0";
  sd.accelerometer.bias_std = Eigen::Vector3d(0.5, 0.5, kNaN);
  ImuTriadsStd sd1 = sd;
  sd1.name = "1";
  u.imus = {sd, sd1};
  r.uncertainty = u;
  ImuDiagnostics& d = r.diagnostics;
  d.statics = {{1, 3, 200}, {5, 7.5, 250}};
  d.rate = 100;
  d.gaps = std::vector<ImuGap>{{400, 3.99, 4.5}};
  d.noise_jobs = ImuDiagnostics::NoiseJobs{7, std::nullopt};
  ImuNoiseModel m;
  m.job = 7;
  m.white_noise = 2e-3;
  d.noise_model = ImuDiagnostics::NoiseModels{m, std::nullopt};
  d.saturated_samples = 3;
  d.static_window = 1;
  d.min_static = 1;
  d.threshold_choice = "from the noise floor";
  d.imus = {Fit("0"), Fit("1")};
  return r;
}

TEST(ImuResult, HandBuiltResultRoundTripsThroughJson) {
  const json j = ToJson(HandBuilt());
  EXPECT_EQ(j["schema_version"], kImuSchemaVersion);
  EXPECT_TRUE(j["diagnostics"]["noise_model"]["gyroscope"].is_null());
  EXPECT_TRUE(j["diagnostics"]["noise_model"]["accelerometer"]["random_walk"].is_null());
  ImuResult back;
  const Status s = FromJson(j, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(ToJson(back), j);
  ASSERT_TRUE(back.parameters && back.uncertainty);
  EXPECT_EQ(back.parameters->imus[1].name, "1");
  EXPECT_EQ(back.parameters->imus[0].accelerometer.bias.y(), 32760);
  EXPECT_EQ(*back.parameters->accel_unit, 0.0024);
  EXPECT_TRUE(std::isnan(back.uncertainty->imus[0].accelerometer.bias_std.z()));
  EXPECT_EQ(*back.diagnostics.noise_jobs->accelerometer, 7);
  EXPECT_FALSE(back.diagnostics.noise_jobs->gyroscope.has_value());
  EXPECT_EQ(back.diagnostics.imus[1].rotations[0].excluded, "gap in t");
  EXPECT_EQ(back.diagnostics.imus[0].coverage.missing_up, std::vector<std::string>{"-z"});
  EXPECT_EQ(back.diagnostics.imus[0].joint_iterations, 3);
  EXPECT_TRUE(back.diagnostics.imus[0].threshold_trials[1].chosen);
}

TEST(ImuResult, AResultStoredBeforeTheLaterKeysReadsAndWritesBackUnchanged) {
  json j = ToJson(HandBuilt());
  j["parameters"].erase("accel_unit");
  j["parameters"].erase("gyro_unit");
  for (const char* key : {"rate", "gaps", "noise_jobs", "noise_model", "saturated_samples"}) {
    j["diagnostics"].erase(key);
  }
  j.erase("schema_version");
  ImuResult r;
  ASSERT_TRUE(FromJson(j, &r).ok()) << FromJson(j, &r).ToString();
  EXPECT_EQ(r.envelope.schema_version, 1);
  EXPECT_FALSE(r.parameters->accel_unit.has_value());
  EXPECT_FALSE(r.diagnostics.rate.has_value());
  EXPECT_FALSE(r.diagnostics.gaps.has_value());
  json written = ToJson(r);
  written.erase("schema_version");
  EXPECT_EQ(written, j);
}

TEST(ImuResult, AWrongTypeIsNamedByItsPath) {
  json j = ToJson(HandBuilt());
  j["parameters"]["imus"][1]["gyroscope"]["scale"] = {1, "2", 3};
  ImuResult r;
  Status s = FromJson(j, &r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field().rfind("parameters.imus[1].gyroscope.scale", 0), 0u) << s.ToString();
  j = ToJson(HandBuilt());
  j["diagnostics"]["imus"][0]["coverage"]["sufficient"] = "yes";
  s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "diagnostics.imus[0].coverage.sufficient");
  EXPECT_NE(s.message().find("imu result: diagnostics.imus[0].coverage.sufficient: expected a "
                             "boolean"),
            std::string::npos)
      << s.message();
}

TEST(ImuResult, AMissingKeyIsNamedByItsPath) {
  json j = ToJson(HandBuilt());
  j["diagnostics"]["imus"][1]["rotations"][0].erase("direction_error_after");
  ImuResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "diagnostics.imus[1].rotations[0].direction_error_after");
  EXPECT_NE(s.message().find("missing"), std::string::npos) << s.message();
}

TEST(ImuResult, UncertaintiesOfAnotherCountAreRefused) {
  json j = ToJson(HandBuilt());
  j["uncertainty"]["imus"].erase(0);
  ImuResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "uncertainty.imus");
  EXPECT_NE(s.message().find("2 IMUs in parameters but 1"), std::string::npos) << s.message();
}

TEST(ImuResult, ANewerSchemaVersionIsRefused) {
  json j = ToJson(HandBuilt());
  j["schema_version"] = kImuSchemaVersion + 1;
  ImuResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "schema_version");
  EXPECT_NE(s.message().find("newer"), std::string::npos) << s.message();
}

TEST(ImuResult, PartialDocumentReadsWithoutParameters) {
  ImuResult partial = HandBuilt();
  partial.envelope.usable = false;
  partial.envelope.model.clear();
  partial.parameters.reset();
  partial.uncertainty.reset();
  partial.diagnostics.imus[0].usable = false;
  partial.diagnostics.imus[0].termination = "too_few_statics";
  const json j = ToJson(partial);
  EXPECT_FALSE(j.contains("parameters"));
  EXPECT_FALSE(j.contains("uncertainty"));
  EXPECT_EQ(j["usable"], false);
  ImuResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).ToString();
  EXPECT_FALSE(back.envelope.usable);
  EXPECT_FALSE(back.parameters.has_value());
  EXPECT_EQ(back.diagnostics.imus[0].termination, "too_few_statics");
  EXPECT_EQ(ToJson(back), j);
}

// A partial document the server trimmed to fit the store still reads and writes back.
TEST(ImuResult, TrimmedPartialDocumentsRead) {
  ImuResult partial = HandBuilt();
  partial.envelope.usable = false;
  partial.envelope.model.clear();
  partial.parameters.reset();
  partial.uncertainty.reset();
  json j = ToJson(partial);
  j["diagnostics"].erase("imus");
  j["trimmed"] = {{"bytes", 2000000}, {"dropped", {"imus"}}, {"note", "left out"}};
  ImuResult back;
  Status s = FromJson(j, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(back.diagnostics.imus.empty());
  EXPECT_EQ(back.diagnostics.statics.size(), 2u);
  EXPECT_EQ(ToJson(back), j);
  const json bare = {
      {"method", "imu"},
      {"usable", false},
      {"trimmed", {{"bytes", 9000000}, {"dropped", {"diagnostics"}}, {"note", "x"}}}};
  s = FromJson(bare, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(back.diagnostics.statics.empty());
}

// Members beyond SPEC's keys (our extensions) may be absent, as in a result of an earlier calibd:
// they keep their defaults; SPEC's keys stay required.
TEST(ImuResult, AbsentExtensionsKeepTheirDefaults) {
  json j = ToJson(HandBuilt());
  j["parameters"].erase("gravity");
  j["parameters"].erase("gyro_bias");
  for (const char* key : {"static_window", "min_static"}) j["diagnostics"].erase(key);
  json& fit = j["diagnostics"]["imus"][1];
  for (const char* key :
       {"name", "usable", "termination", "reason", "chi2_per_dof", "degrees_of_freedom",
        "iterations", "noise", "threshold_trials", "threshold_choice", "cost"}) {
    fit.erase(key);
  }
  for (const char* key : {"gravity_eigenvalues", "min_eigenvalue", "least_covered_direction",
                          "missing_up", "rotation_per_axis", "weak_axes", "sufficient"}) {
    fit["coverage"].erase(key);
  }
  for (const char* key : {"from", "to", "start", "end", "used", "excluded"}) {
    fit["rotations"][0].erase(key);
  }
  for (const char* key : {"gravity_direction", "norm_residual_before", "norm_residual_after"}) {
    fit["statics"][0].erase(key);
  }
  ImuResult r;
  ASSERT_TRUE(FromJson(j, &r).ok()) << FromJson(j, &r).ToString();
  EXPECT_TRUE(std::isnan(r.parameters->gravity));
  EXPECT_EQ(r.parameters->gyro_bias, "");
  EXPECT_TRUE(std::isnan(r.diagnostics.static_window));
  const ImuFitDiagnostics& f = r.diagnostics.imus[1];
  EXPECT_EQ(f.name, r.parameters->imus[1].name) << "the parameters' name of the same IMU";
  EXPECT_TRUE(f.usable) << "the document's usable";
  EXPECT_TRUE(std::isnan(f.chi2_per_dof));
  EXPECT_TRUE(std::isnan(f.accel_noise.x()));
  EXPECT_TRUE(f.cost.empty());
  EXPECT_TRUE(f.coverage.sufficient);
  EXPECT_TRUE(std::isnan(f.coverage.min_eigenvalue));
  EXPECT_TRUE(f.coverage.missing_up.empty());
  EXPECT_TRUE(f.rotations[0].used);
  EXPECT_TRUE(std::isnan(f.rotations[0].start));
  EXPECT_TRUE(std::isnan(f.statics[0].norm_residual_after));
  // SPEC's keys are still required.
  fit["coverage"].erase("verdict");
  EXPECT_EQ(FromJson(j, &r).field(), "diagnostics.imus[1].coverage.verdict");
  j = ToJson(HandBuilt());
  j["diagnostics"]["imus"][0]["statics"][1].erase("gyro_std");
  EXPECT_EQ(FromJson(j, &r).field(), "diagnostics.imus[0].statics[1].gyro_std");
}

}  // namespace
}  // namespace calibd::results
