// methods/array/array_result.h: the typed array result (both models) round-trips through JSON, and
// a document that does not fit is refused naming the path of the problem.
#include "methods/array/array_result.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "methods/array/array_full_report.h"

namespace calibd::results {
namespace {

using nlohmann::json;

ArrayResult PositionsResult() {
  ArrayResult r;
  r.envelope.method = "array";
  r.envelope.model = "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k";
  r.envelope.warnings = {"few samples"};
  ArrayParameters p;
  p.reference = 1;
  p.positions = {{"a0", {0.01, 0.02, -0.003}, {1e-5, -2e-5, 3e-6}},
                 {"a1", {0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}}};
  ArrayUncertainty u;
  u.positions = {{"a0", {4e-6, 5e-6, 6e-6}, std::nullopt}, {"a1", {NAN, NAN, NAN}, std::nullopt}};
  u.std_rms = 5.1e-6;
  r.parameters = p;
  r.uncertainty = u;
  ArrayPositionsDiagnostics& d = r.diagnostics;
  d.solver = "bcd";
  d.termination = "converged";
  d.iterations = 37;
  d.samples = 12345;
  d.samples_dropped = 3;
  d.gyro_triads = 2;
  d.gyro_unit = "deg/s";
  d.excitation = {10.5, 400.25, 0.125, {0, 0, 1}, "good"};
  d.converged = true;
  d.cost = {100.5, 2.25, 2.125};
  d.residual_rms = {0.04, 0.06};
  d.noise_estimate = {0.041, NAN};
  d.noise_jobs.gyroscope = 17;
  d.noise_configured = {0.04, 0.06};
  d.parallel_fraction = 0.75;
  d.motion.stride = 3;
  d.motion.omega_norm = {1.5, 2.5};
  d.motion.omega_dot_norm = {10, 20};
  ArrayCalibrationUsed c;
  c.job = 9;
  c.sensors = 6;
  c.frame = "nominal";
  c.magnitude = 9.80665;
  c.max_condition_number = 1.02;
  d.accelerometer_calibration = c;
  return r;
}

ArrayResult FullResult() {
  ArrayResult r;
  r.envelope.method = "array";
  r.envelope.model = "a_k = M_a,k (y_a,k - b_a,k)";
  r.full = true;
  ArrayParameters p;
  p.reference = 0;
  p.positions = {{"0", {0, 0, 0}, {0, 0, 0}}, {"1", {0.02, 0, 0}, {1e-4, 0, 0}}};
  ArrayUncertainty u;
  u.positions = {{"0", {0, 0, 0}, std::nullopt}, {"1", {1e-5, 2e-5, 3e-5}, std::nullopt}};
  for (int k = 0; k < 2; ++k) {
    ArrayImu imu;
    imu.triads.name = std::to_string(k);
    imu.triads.accelerometer.bias = {0.1 * k, -0.2, 0.3};
    imu.triads.gyroscope.scale = {0.0174, 0.0175, 0.0176};
    imu.triads.gyroscope.misalignment(0, 1) = 0.01;
    imu.position = p.positions[k].position;
    p.imus.push_back(imu);
    ArrayImuStd s;
    s.triads.name = std::to_string(k);
    s.triads.accelerometer.bias_std = {1e-3, 2e-3, 3e-3};
    s.position_std = u.positions[k].std;
    if (k == 1) {
      ArrayImuCrbStd crb;
      crb.accelerometer.scale_std = {1e-4, 1e-4, 2e-4};
      crb.position_std = {2e-5, 3e-5, 4e-5};
      s.crb = crb;
    }
    u.imus.push_back(s);
  }
  r.parameters = p;
  r.uncertainty = u;
  ArrayFullDiagnostics& d = r.full_diagnostics;
  d.termination = "converged";
  d.iterations = 8;
  d.statics = 20;
  d.static_samples = 3000;
  d.dynamic_samples = 5000;
  d.rotation_excitation = {{1, 2, 3}, 0.5, {1, 0, 0}, "good", "(rad/s)^2"};
  d.null_directions = {"common rotation"};
  d.gauge = {"sum_trace_gyroscope", 0, "the reference triad is held"};
  d.solver = "joint";
  d.converged = true;
  d.cost = {5, 1};
  d.samples_dropped = 0;
  d.dof = 1234;
  d.chi2_per_dof = 1.01;
  d.gyro_unit = "rad/s";
  d.noise = {0.04, 0.001, "statics", "noise", 0.05, 0.002};
  d.static_noise = {0.039, 0.0011};
  d.static_intervals = {{0.5, 2.5, 400, 0.002, 5e-5}, {3.0, 4.75, 350, 0.0021, NAN}};
  d.residual_rms_dynamic = {0.05, 0.002};
  d.residual_rms_imus = {{"0", {0.04, 0.001}, {0.05, 0.002}}, {"1", {0.03, 0.001}, {0.06, NAN}}};
  d.time_offsets.offsets_ms = {{"0", 0.1}, {"1", -0.1}};
  d.time_offsets.explained_fraction = 0.2;
  d.time_offsets.per_sample_rms_ms = 0.01;
  d.time_offsets.per_sample_explained_fraction = 0.3;
  d.time_offsets.note = "diagnostic";
  d.robust = {true, 12, 2.0, 1.5};
  d.positions_only_start = true;
  ArrayPositionChange c0;
  c0.name = "0";
  c0.positions_only = {0, 0, 0};
  c0.position_change = {0, 0, 0};
  c0.position_change_norm = 0;
  ArrayPositionChange c1 = c0;
  c1.name = "1";
  c1.positions_only_std = Eigen::Vector3d(1e-5, 1e-5, 1e-5);
  c1.position_change_sigma = {0.5, -1.0, 2.0};
  d.changed_from_positions_only = {c0, c1};
  return r;
}

// A failed positions run's partial document, as the adapter writes it.
json PositionsPartial() {
  return {{"method", "array"},
          {"usable", false},
          {"diagnostics",
           {{"solver", "joint"},
            {"termination", "not_run"},
            {"iterations", 0},
            {"samples", 12},
            {"samples_dropped", 5},
            {"gyro_triads", 1},
            {"gyro_unit", "rad/s"},
            {"excitation",
             {{"min_eigenvalue", nullptr},
              {"max_eigenvalue", nullptr},
              {"noise_floor", nullptr},
              {"weakest_direction", {nullptr, nullptr, nullptr}},
              {"verdict", ""}}}}},
          {"warnings", {"too few samples"}}};
}

json FullPartial() {
  return {{"method", "array"},
          {"usable", false},
          {"schema_version", 1},
          {"diagnostics",
           {{"model", "full"},
            {"termination", "not_run"},
            {"iterations", 0},
            {"statics", 2},
            {"static_samples", 300},
            {"dynamic_samples", 0},
            {"rotation",
             {{"eigenvalues", {0, 0, 0}},
              {"noise_floor", 0.5},
              {"weakest_axis", {1, 0, 0}},
              {"verdict", "insufficient"}}},
            {"null_directions", json::array()}}},
          {"warnings", json::array()}};
}

TEST(ArrayResult, PositionsModelRoundTripsWithEveryField) {
  const json j = ToJson(PositionsResult());
  EXPECT_EQ(j["schema_version"], kArraySchemaVersion);
  EXPECT_FALSE(j["diagnostics"].contains("model"));
  EXPECT_TRUE(j["uncertainty"]["positions"][1]["std"][0].is_null());
  ArrayResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_FALSE(back.full);
  ASSERT_TRUE(back.parameters.has_value());
  EXPECT_EQ(back.parameters->reference, 1);
  EXPECT_DOUBLE_EQ(back.parameters->positions[0].offset.y(), -2e-5);
  EXPECT_TRUE(std::isnan(back.uncertainty->positions[1].std.x()));
  EXPECT_EQ(back.diagnostics.solver, "bcd");
  EXPECT_EQ(back.diagnostics.motion.stride, 3);
  EXPECT_FALSE(back.diagnostics.noise_jobs.accelerometer.has_value());
  EXPECT_EQ(back.diagnostics.noise_jobs.gyroscope, 17);
  ASSERT_TRUE(back.diagnostics.accelerometer_calibration.has_value());
  EXPECT_EQ(back.diagnostics.accelerometer_calibration->job, 9);
  EXPECT_FALSE(back.diagnostics.accelerometer_calibration->bias.has_value());
  EXPECT_EQ(ToJson(back), j);
}

TEST(ArrayResult, WithoutAccelerometerCalibrationWritesNull) {
  ArrayResult r = PositionsResult();
  r.diagnostics.accelerometer_calibration.reset();
  const json j = ToJson(r);
  ASSERT_TRUE(j["diagnostics"].contains("accelerometer_calibration"));
  EXPECT_TRUE(j["diagnostics"]["accelerometer_calibration"].is_null());
  ArrayResult back;
  ASSERT_TRUE(FromJson(j, &back).ok());
  EXPECT_FALSE(back.diagnostics.accelerometer_calibration.has_value());
  EXPECT_EQ(ToJson(back), j);
}

TEST(ArrayResult, FullModelRoundTripsWithEveryField) {
  const json j = ToJson(FullResult());
  EXPECT_EQ(j["parameters"]["model"], "full");
  EXPECT_EQ(j["diagnostics"]["model"], "full");
  EXPECT_FALSE(j["uncertainty"].contains("std_rms"));
  EXPECT_FALSE(j["uncertainty"]["imus"][0].contains("crb"));
  EXPECT_TRUE(j["uncertainty"]["imus"][1].contains("crb"));
  EXPECT_FALSE(j["diagnostics"]["changed_from_positions_only"][0].contains("positions_only_std"));
  ArrayResult back;
  const Status s = FromJson(j, &back);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(back.full);
  ASSERT_EQ(back.parameters->imus.size(), 2u);
  EXPECT_DOUBLE_EQ(back.parameters->imus[1].triads.accelerometer.bias.x(), 0.1);
  EXPECT_DOUBLE_EQ(back.parameters->imus[0].triads.gyroscope.misalignment(0, 1), 0.01);
  EXPECT_FALSE(back.uncertainty->imus[0].crb.has_value());
  ASSERT_TRUE(back.uncertainty->imus[1].crb.has_value());
  EXPECT_DOUBLE_EQ(back.uncertainty->imus[1].crb->position_std.z(), 4e-5);
  EXPECT_EQ(back.full_diagnostics.gauge.scale, "sum_trace_gyroscope");
  EXPECT_EQ(back.full_diagnostics.robust.batches, 12);
  EXPECT_TRUE(std::isnan(back.full_diagnostics.residual_rms_imus[1].dynamic_rms.gyroscope));
  ASSERT_EQ(back.full_diagnostics.static_intervals.size(), 2u);
  EXPECT_EQ(back.full_diagnostics.static_intervals[1].samples, 350);
  EXPECT_TRUE(std::isnan(back.full_diagnostics.static_intervals[1].gyro_residual_rms));
  EXPECT_FALSE(back.full_diagnostics.changed_from_positions_only[0].positions_only_std);
  EXPECT_TRUE(back.full_diagnostics.changed_from_positions_only[1].positions_only_std);
  EXPECT_EQ(ToJson(back), j);
}

TEST(ArrayResult, PositionsPartialDocumentReadsWithoutParameters) {
  const json j = PositionsPartial();
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(r.envelope.usable);
  EXPECT_FALSE(r.full);
  EXPECT_FALSE(r.parameters.has_value());
  EXPECT_FALSE(r.uncertainty.has_value());
  EXPECT_EQ(r.diagnostics.samples_dropped, 5);
  EXPECT_EQ(r.diagnostics.excitation.verdict, "");
  json expected = j;
  expected["schema_version"] = kArraySchemaVersion;
  // The units are constants: written back even where an earlier calibd left them out.
  expected["diagnostics"]["accel_unit"] = "m/s^2";
  expected["diagnostics"]["excitation"]["units"] = "rad^2/s^4";
  EXPECT_EQ(ToJson(r), expected);
}

TEST(ArrayResult, FullPartialDocumentReadsItsRotation) {
  const json j = FullPartial();
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(r.full);
  EXPECT_EQ(r.full_diagnostics.statics, 2);
  EXPECT_EQ(r.full_diagnostics.rotation_excitation.verdict, "insufficient");
  EXPECT_EQ(ToJson(r), j);
}

TEST(ArrayResult, WrongTypeIsRefusedNamingThePath) {
  json j = ToJson(PositionsResult());
  j["parameters"]["positions"][1]["offset"] = "1 mm";
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("array result"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("parameters.positions[1].offset"), std::string::npos) << s.message();

  json f = ToJson(FullResult());
  f["uncertainty"]["imus"][1]["crb"]["gyroscope"]["bias_std"] = {1, 2};
  const Status sf = FromJson(f, &r);
  ASSERT_FALSE(sf.ok());
  EXPECT_NE(sf.message().find("uncertainty.imus[1].crb.gyroscope.bias_std"), std::string::npos)
      << sf.message();
}

TEST(ArrayResult, MissingSpecKeyIsRefusedNamingThePath) {
  // Keys SPEC §4 (positions model) and §7 (full model) require.
  json j = ToJson(PositionsResult());
  j["diagnostics"]["noise_estimate"].erase("gyroscope");
  ArrayResult r;
  Status s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("diagnostics.noise_estimate.gyroscope"), std::string::npos)
      << s.message();

  j = ToJson(PositionsResult());
  j["diagnostics"]["excitation"].erase("verdict");
  s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("diagnostics.excitation.verdict"), std::string::npos) << s.message();

  j = ToJson(PositionsResult());
  j["diagnostics"].erase("samples");
  s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("diagnostics.samples"), std::string::npos) << s.message();

  json f = ToJson(FullResult());
  f["diagnostics"]["gauge"].erase("scale");
  s = FromJson(f, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("diagnostics.gauge.scale"), std::string::npos) << s.message();

  f = ToJson(FullResult());
  f["uncertainty"]["imus"][1].erase("position_std");
  s = FromJson(f, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("uncertainty.imus[1].position_std"), std::string::npos) << s.message();
}

// Results stored by an earlier calibd lack our extensions: they read, the members at their
// defaults (NaN, empty, nullopt).
TEST(ArrayResult, PositionsResultWithoutExtensionsReadsWithDefaults) {
  json j = ToJson(PositionsResult());
  for (const char* key :
       {"termination", "gyro_triads", "gyro_unit", "noise_jobs", "noise_configured",
        "parallel_fraction", "motion", "accelerometer_calibration"})
    j["diagnostics"].erase(key);
  for (const char* key : {"max_eigenvalue", "noise_floor", "weakest_direction"})
    j["diagnostics"]["excitation"].erase(key);
  j["uncertainty"].erase("std_rms");
  j.erase("schema_version");
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  const ArrayPositionsDiagnostics& d = r.diagnostics;
  EXPECT_EQ(d.samples, 12345);
  EXPECT_EQ(d.termination, "");
  EXPECT_FALSE(d.gyro_triads.has_value());
  EXPECT_FALSE(d.noise_jobs.accelerometer.has_value());
  EXPECT_FALSE(d.noise_jobs.gyroscope.has_value());
  EXPECT_TRUE(std::isnan(d.noise_configured.accelerometer));
  EXPECT_TRUE(std::isnan(d.parallel_fraction));
  EXPECT_TRUE(d.motion.omega_norm.empty());
  EXPECT_FALSE(d.accelerometer_calibration.has_value());
  EXPECT_TRUE(std::isnan(d.excitation.noise_floor));
  EXPECT_DOUBLE_EQ(d.excitation.min_eigenvalue, 10.5);
  EXPECT_TRUE(std::isnan(r.uncertainty->std_rms));
}

TEST(ArrayResult, FullResultWithoutPositionsDerivesThemFromTheImus) {
  json j = ToJson(FullResult());
  j["parameters"].erase("positions");
  j["parameters"].erase("model");
  j["uncertainty"].erase("positions");
  j["diagnostics"].erase("model");  // the model is then told by parameters.imus
  for (const char* key :
       {"time_offsets", "dof", "chi2_per_dof", "noise", "robust", "changed_from_positions_only",
        "positions_only_start", "statics", "rotation_excitation", "residual_rms", "static_noise",
        "static_intervals"})
    j["diagnostics"].erase(key);
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(r.full);
  ASSERT_EQ(r.parameters->positions.size(), r.parameters->imus.size());
  EXPECT_EQ(r.parameters->positions[1].name, r.parameters->imus[1].triads.name);
  EXPECT_EQ(r.parameters->positions[1].position, r.parameters->imus[1].position);
  EXPECT_TRUE(r.parameters->positions[1].offset.array().isNaN().all());
  ASSERT_EQ(r.uncertainty->positions.size(), r.uncertainty->imus.size());
  EXPECT_EQ(r.uncertainty->positions[0].std, r.uncertainty->imus[0].position_std);
  const ArrayFullDiagnostics& d = r.full_diagnostics;
  EXPECT_FALSE(d.dof.has_value());
  EXPECT_FALSE(d.statics.has_value());
  EXPECT_FALSE(d.positions_only_start.has_value());
  EXPECT_TRUE(d.changed_from_positions_only.empty());
  EXPECT_TRUE(d.time_offsets.offsets_ms.empty());
  EXPECT_TRUE(std::isnan(d.noise.accelerometer));
  EXPECT_EQ(d.noise.source, "");
  EXPECT_TRUE(d.residual_rms_imus.empty());
  EXPECT_TRUE(d.static_intervals.empty());  // an earlier calibd's: its static RMS × √samples
  EXPECT_EQ(d.rotation_excitation.verdict, "");
  EXPECT_EQ(d.gauge.scale, "sum_trace_gyroscope");
}

TEST(ArrayResult, PartialDocumentWithoutDiagnosticsReads) {
  // What the worker keeps when even the trimmed partial diagnostics are over the cap.
  const json bare = {{"method", "array"},
                     {"usable", false},
                     {"trimmed", {{"bytes", 2000000}, {"dropped", {"diagnostics"}}}}};
  ArrayResult r;
  Status s = FromJson(bare, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(r.envelope.usable);
  EXPECT_FALSE(r.diagnostics.samples.has_value());
  EXPECT_EQ(r.diagnostics.excitation.verdict, "");

  json empty = PositionsPartial();
  empty["diagnostics"] = json::object();
  s = FromJson(empty, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_FALSE(r.diagnostics.iterations.has_value());
}

// The worker used to write the members it left out of over-sized partial diagnostics as null.
TEST(ArrayResult, PartialDocumentWithAnyMemberNullReads) {
  for (const json& doc : {PositionsPartial(), FullPartial()}) {
    for (const auto& item : doc["diagnostics"].items()) {
      if (item.key() == "model") continue;
      json j = doc;
      j["diagnostics"][item.key()] = nullptr;
      ArrayResult r;
      const Status s = FromJson(j, &r);
      EXPECT_TRUE(s.ok()) << item.key() << ": " << s.message();
    }
  }
}

TEST(ArrayResult, PartialDocumentLackingAnyOneMemberReads) {
  for (const json& doc : {PositionsPartial(), FullPartial()}) {
    for (const auto& item : doc["diagnostics"].items()) {
      if (item.key() == "model") continue;  // says which model: never left out alone (tiny)
      json j = doc;
      j["diagnostics"].erase(item.key());
      ArrayResult r;
      const Status s = FromJson(j, &r);
      EXPECT_TRUE(s.ok()) << item.key() << ": " << s.message();
      EXPECT_EQ(r.full, doc["diagnostics"].contains("model")) << item.key();
    }
  }
}

TEST(ArrayResult, UnknownModelIsRefused) {
  json j = ToJson(FullResult());
  j["diagnostics"]["model"] = "intrinsics";
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("diagnostics.model"), std::string::npos) << s.message();
}

TEST(ArrayResult, RefusalLeavesTheOutputUntouched) {
  ArrayResult r = PositionsResult();
  json j = ToJson(FullResult());
  j["parameters"]["imus"][0]["position"] = nullptr;
  ASSERT_FALSE(FromJson(j, &r).ok());
  EXPECT_FALSE(r.full);
  EXPECT_EQ(r.diagnostics.solver, "bcd");
}

TEST(ArrayResult, AbsentSchemaVersionReadsAsOne) {
  json j = ToJson(PositionsResult());
  j.erase("schema_version");
  ArrayResult r;
  ASSERT_TRUE(FromJson(j, &r).ok());
  EXPECT_EQ(r.envelope.schema_version, 1);
}

TEST(ArrayResult, NewerSchemaVersionIsRefusedNamingIt) {
  json j = ToJson(FullResult());
  j["schema_version"] = kArraySchemaVersion + 1;
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("schema_version"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find(std::to_string(kArraySchemaVersion + 1)), std::string::npos)
      << s.message();
}

TEST(ArrayResult, AnotherMethodsResultIsRefused) {
  json j = ToJson(PositionsResult());
  j["method"] = "imu";
  ArrayResult r;
  const Status s = FromJson(j, &r);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("method"), std::string::npos) << s.message();
  EXPECT_FALSE(FromJson(json::array(), &r).ok());
}

}  // namespace
}  // namespace calibd::results

namespace calibd::results {
namespace {

// A result stored by an earlier calibd (no uncertainty.basis, no crb) reads with basis
// "crb_only", and the pages say its σ is the Cramér–Rao bound only.
TEST(ArrayResultTest, StoredWithoutBasisReadsAsCrbOnly) {
  const nlohmann::json doc = {
      {"method", "array"},
      {"usable", true},
      {"model", "y_a,k = s + A r_k"},
      {"warnings", nlohmann::json::array()},
      {"parameters",
       {{"reference", 0},
        {"positions", {{{"name", "a0"}, {"position", {0, 0, 0}}, {"offset", {0, 0, 0}}}}}}},
      {"uncertainty", {{"positions", {{{"name", "a0"}, {"std", {0, 0, 0}}}}}, {"std_rms", 0}}},
      {"diagnostics",
       {{"solver", "joint"},
        {"iterations", 3},
        {"samples", 100},
        {"samples_dropped", 0},
        {"converged", true},
        {"cost", {1.0}},
        {"excitation", {{"min_eigenvalue", 1.0}, {"verdict", "good"}}},
        {"residual_rms", {{"accelerometer", 0.1}, {"gyroscope", 0.01}}},
        {"noise_estimate", {{"accelerometer", 0.1}, {"gyroscope", 0.01}}}}}};
  ArrayResult r;
  const Status s = FromJson(doc, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.uncertainty->basis, "crb_only");
  EXPECT_FALSE(r.uncertainty->positions[0].crb.has_value());
  EXPECT_NE(web::ArraySigmaBasisText(*r.uncertainty).find("stored by an earlier calibd"),
            std::string::npos);
  nlohmann::json bad = doc;
  bad["uncertainty"]["basis"] = "guess";
  EXPECT_FALSE(FromJson(bad, &r).ok());
}

}  // namespace
}  // namespace calibd::results
