// The acceptance gate (methods/acceptance.h, each method's Judge): limits and their validation, and
// the verdicts of real calibrations of simulated recordings (pca) and of results whose numbers sit
// just inside and just outside each limit (imu, array, noise), so that a wrong rule fails.
#include "methods/acceptance.h"

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "core/pca_simulation.h"
#include "methods/array/array_result.h"
#include "methods/imu/imu_result.h"
#include "methods/method.h"
#include "methods/noise/noise_result.h"
#include "methods/registry.h"
#include "server/config.h"

namespace calibd::server {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

using nlohmann::json;

bool HasReason(const json& verdict, const std::string& text) {
  for (const json& r : verdict["reasons"]) {
    if (r.get<std::string>().find(text) != std::string::npos) return true;
  }
  return false;
}

// A static accelerometer triad recording (pca averaged layout): readings m_ij = a_iᵀ v_j + b_i +
// noise at the given field directions (scaled to `field`), a = scale × (I + small tilt).
std::string TriadCsv(const std::vector<Eigen::Vector3d>& directions, double field, double scale,
                     double bias, double noise, uint64_t seed) {
  core::PcaRandom random(seed + 1000003);  // a stream of its own, not the directions'
  Eigen::Matrix3d a = scale * Eigen::Matrix3d::Identity();
  a(0, 1) = 0.004 * scale;  // small misalignments
  a(2, 0) = -0.003 * scale;
  std::string csv = "position,a0_x,a0_y,a0_z\n";
  for (size_t j = 0; j < directions.size(); ++j) {
    const Eigen::Vector3d v = directions[j].normalized() * field;
    csv += "p" + std::to_string(j + 1);
    for (int i = 0; i < 3; ++i) {
      char buf[40];
      std::snprintf(buf, sizeof buf, ",%.12g",
                    a.col(i).dot(v) + bias * (i + 1) + noise * random.Normal());
      csv += buf;
    }
    csv += "\n";
  }
  return csv;
}

std::vector<Eigen::Vector3d> RandomDirections(int n, uint64_t seed) {
  core::PcaRandom random(seed);
  std::vector<Eigen::Vector3d> out;
  for (int j = 0; j < n; ++j) out.emplace_back(random.UnitVector(3));
  return out;
}

// The recording: the six faces of a box plus four positions close to faces.
std::vector<Eigen::Vector3d> BoxFaces() {
  return {{1, 0, 0},  {-1, 0, 0},      {0, 1, 0},    {0, -1, 0},   {0, 0, 1},
          {0, 0, -1}, {1, 0.08, 0.05}, {0.06, 1, 0}, {0, 0.07, 1}, {-1, 0, 0.06}};
}

json Calib(const std::string& csv, const json& config, const json& server = json()) {
  json result;
  Status s = Calibrate(csv, "test.csv", config, &result, nullptr, server);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

json TriadConfig(double magnitude) {
  return {{"method", "pca"},
          {"magnitude", magnitude},
          {"bias", "estimate"},
          {"nominal", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}};
}

TEST(Gate, AcceptsGoodPcaCalibrationsOfRandomOrientations) {
  // 30 random orientations, 0.002 m/s² noise (an averaged MEMS reading): every trial accepted.
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const json r = Calib(TriadCsv(RandomDirections(30, seed), 9.80665, 1.02, 0.1, 0.002, seed),
                         TriadConfig(9.80665));
    EXPECT_EQ(r["verdict"]["status"], "accepted") << "seed " << seed << ": " << r["verdict"].dump();
  }
}

TEST(Gate, RejectsPositionsOnlyOnBoxFacesNamingTheMissingOrientations) {
  const json r = Calib(TriadCsv(BoxFaces(), 9.80665, 1.0, 0.1, 0.002, 3), TriadConfig(9.80665));
  EXPECT_EQ(r["diagnostics"]["coverage"]["verdict"], "poor");
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  ASSERT_TRUE(HasReason(r["verdict"], "orientations are poorly spread")) << r["verdict"].dump();
  // The reason carries the coverage advice: which positions to add.
  EXPECT_TRUE(HasReason(r["verdict"], "add positions")) << r["verdict"].dump();
}

TEST(Gate, RejectsReadingsInGWithMagnitudeInMetresPerSecondSquared) {
  // Readings in g (field 1) but magnitude 9.80665: every scale comes out 0.102.
  json config = TriadConfig(9.80665);
  config.erase("nominal");
  const json r = Calib(TriadCsv(RandomDirections(30, 5), 1.0, 1.0, 0.01, 0.0002, 5), config);
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_TRUE(HasReason(r["verdict"], "readings look like g but magnitude is 9.81"))
      << r["verdict"].dump();
}

TEST(Gate, RejectsReadingsInMetresPerSecondSquaredWithMagnitudeOne) {
  json config = TriadConfig(1.0);
  config.erase("nominal");
  const json r = Calib(TriadCsv(RandomDirections(30, 6), 9.80665, 1.0, 0.1, 0.002, 6), config);
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_TRUE(HasReason(r["verdict"], "readings look like m/s^2 but magnitude is 1"))
      << r["verdict"].dump();
}

TEST(Gate, ScaleRangeIsJudgedAgainstTheNominalNorm) {
  // Nominal sensitivities of norm 2: a true scale of 2.16 is 8 % off (accepted with the default
  // 10 %), 2.24 is 12 % off (rejected); a limit of 5 % rejects the first too.
  json config = TriadConfig(9.80665);
  config["nominal"] = {{2, 0, 0}, {0, 2, 0}, {0, 0, 2}};
  const auto dirs = RandomDirections(40, 7);
  json r = Calib(TriadCsv(dirs, 9.80665, 2.16, 0.1, 0.002, 7), config);
  EXPECT_EQ(r["verdict"]["status"], "accepted") << r["verdict"].dump();
  r = Calib(TriadCsv(dirs, 9.80665, 2.24, 0.1, 0.002, 7), config);
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_TRUE(HasReason(r["verdict"], "more than 10 % from the nominal")) << r["verdict"].dump();
  config["acceptance"] = {{"scale_range", 0.05}};
  r = Calib(TriadCsv(dirs, 9.80665, 2.16, 0.1, 0.002, 7), config);
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_EQ(r["verdict"]["limits"]["scale_range"], 0.05);
}

TEST(Gate, ScaleUncertaintyLimitSeparatesNoiseLevels) {
  // σ(scale) grows with the noise: 30 positions with noise 0.02 m/s² give about 0.1 %, with 0.5
  // m/s² about 2.5 %: the 1 % default accepts the first and rejects the second.
  const auto dirs = RandomDirections(30, 8);
  json r = Calib(TriadCsv(dirs, 9.80665, 1.0, 0.1, 0.02, 8), TriadConfig(9.80665));
  EXPECT_EQ(r["verdict"]["status"], "accepted") << r["verdict"].dump();
  r = Calib(TriadCsv(dirs, 9.80665, 1.0, 0.1, 0.5, 8), TriadConfig(9.80665));
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_TRUE(HasReason(r["verdict"], "scale factor too uncertain")) << r["verdict"].dump();
}

TEST(Gate, ResidualAgainstAGivenNoiseIsBounded) {
  // Readings with noise 0.01 judged against a claimed noise_std: the true σ passes, a σ 3 times
  // too small (χ² ≈ 9 > 4) is rejected.
  const auto dirs = RandomDirections(40, 9);
  json config = TriadConfig(9.80665);
  config["noise_std"] = 0.01;
  json r = Calib(TriadCsv(dirs, 9.80665, 1.0, 0.1, 0.01, 9), config);
  EXPECT_EQ(r["verdict"]["status"], "accepted") << r["verdict"].dump();
  config["noise_std"] = 0.01 / 3;
  r = Calib(TriadCsv(dirs, 9.80665, 1.0, 0.1, 0.01, 9), config);
  EXPECT_TRUE(HasReason(r["verdict"], "times the given noise_std")) << r["diagnostics"].dump();
}

TEST(Gate, ServerDefaultsApplyAndTheConfigOverridesThemPerKey) {
  const json server = {{"pca", {{"max_scale_std", 0.002}, {"scale_range", 0.5}}}};
  json config = {{"method", "pca"}, {"acceptance", {{"scale_range", 0.2}, {"max_chi2", nullptr}}}};
  const AcceptanceLimits limits = EffectiveAcceptance("pca", server, config);
  EXPECT_EQ(*limits.Get("max_scale_std"), 0.002);    // server
  EXPECT_EQ(*limits.Get("scale_range"), 0.2);        // config wins
  EXPECT_FALSE(limits.Get("max_chi2").has_value());  // null: no limit
  EXPECT_EQ(*limits.Get("max_axis_std"), 0.01);      // built-in default
  // The server defaults of another method do not leak.
  EXPECT_EQ(*EffectiveAcceptance("imu", server, json::object()).Get("max_scale_std"), 0.01);
}

TEST(Gate, InvalidAcceptanceKeysAreErrorsNamingThem) {
  CommonConfig common;
  json config = {{"method", "pca"}, {"acceptance", {{"max_sclae_std", 0.1}}}};
  Status s = ValidateConfig(config, &common);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "acceptance.max_sclae_std");
  EXPECT_NE(s.message().find("max_scale_std"), std::string::npos) << s.message();  // known keys
  config["acceptance"] = {{"max_scale_std", -1}};
  s = ValidateConfig(config, &common);
  EXPECT_EQ(s.field(), "acceptance.max_scale_std");
  config["acceptance"] = {{"max_offset", 0.001}};  // an array key is not a pca key
  EXPECT_EQ(ValidateConfig(config, &common).field(), "acceptance.max_offset");
  config["acceptance"] = "strict";
  EXPECT_EQ(ValidateConfig(config, &common).field(), "acceptance");
  config["acceptance"] = {{"max_scale_std", 0.001}, {"scale_range", nullptr}};
  EXPECT_TRUE(ValidateConfig(config, &common).ok());
  EXPECT_EQ(ValidateServerAcceptance(json{{"pcb", json::object()}}, "f.json").field(), "pcb");
  EXPECT_EQ(ValidateServerAcceptance(json{{"imu", {{"max_offset", 1}}}}, "f.json").field(),
            "imu.max_offset");
}

// Every method of the registry names its own limits (Method::AcceptanceKeys), and the generic
// lookup adds the keys every method has (max_fleet_z): each with a meaning, a default that is a
// number >= 0 or none, no key twice. They are the limits in force when nothing overrides them,
// and a config may set each of them.
TEST(Gate, EveryRegisteredMethodSuppliesItsLimitsWithTheirDefaults) {
  for (const Method* m : AllMethods()) {
    SCOPED_TRACE(m->name());
    ASSERT_FALSE(m->AcceptanceKeys().empty());
    const std::vector<AcceptanceKey>& keys = AcceptanceKeys(m->name());
    ASSERT_EQ(keys.size(), m->AcceptanceKeys().size() + 2);
    EXPECT_STREQ(keys[keys.size() - 2].name, limit_keys::kMaxFleetZ.name);
    EXPECT_STREQ(keys.back().name, limit_keys::kMaxFleetFalseAlarm.name);
    EXPECT_EQ(&AcceptanceKeys(m->name()), &keys);  // one list per method, kept
    std::set<std::string> names;
    json defaults = json::object();
    for (const AcceptanceKey& k : keys) {
      EXPECT_TRUE(names.insert(k.name).second) << k.name << " is listed twice";
      EXPECT_GT(std::string(k.meaning).size(), 10u) << k.name;
      if (k.default_value) {
        EXPECT_TRUE(std::isfinite(*k.default_value)) << k.name;
        EXPECT_GE(*k.default_value, 0) << k.name;
      }
      defaults[k.name] = k.default_value ? json(*k.default_value) : json(nullptr);
    }
    EXPECT_EQ(EffectiveAcceptance(m->name(), json(), json::object()).ToJson(), defaults);
    EXPECT_TRUE(
        ValidateAcceptance(defaults, m->name(), "config key 'acceptance'", "acceptance").ok());
  }
  EXPECT_TRUE(AcceptanceKeys("no-such-method").empty());
}

TEST(Gate, UnknownLimitKeysAreRefusedNamingTheKeyForEveryMethod) {
  for (const Method* m : AllMethods()) {
    SCOPED_TRACE(m->name());
    const std::string name = m->name();
    Status s = ValidateAcceptance(json{{"max_nonsense", 1}}, name, "config key 'acceptance'",
                                  "acceptance");
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_EQ(s.field(), "acceptance.max_nonsense");
    EXPECT_NE(s.message().find("'max_nonsense' is not an acceptance limit of " + name),
              std::string::npos)
        << s.message();
    for (const AcceptanceKey& k : m->AcceptanceKeys()) {
      EXPECT_NE(s.message().find(k.name), std::string::npos) << s.message();  // the known keys
    }
    s = ValidateServerAcceptance(json{{name, {{"max_nonsense", 1}}}}, "limits.json");
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
    EXPECT_EQ(s.field(), name + ".max_nonsense");
    EXPECT_EQ(s.message().rfind("limits.json: " + name + ": 'max_nonsense'", 0), 0u) << s.message();
  }
  // A name the registry does not know is no method; the message lists the registered ones.
  const Status s = ValidateServerAcceptance(json{{"pcb", json::object()}}, "limits.json");
  EXPECT_EQ(s.field(), "pcb");
  for (const Method* m : AllMethods()) {
    EXPECT_NE(s.message().find(m->name()), std::string::npos) << s.message();
  }
}

// ---- imu: results built by hand around the limits ----

// A complete imu result (methods/imu/imu_result.h) of IMU "0": both triads with these scales, the
// 1σ given, and the fit's chi2 and residuals.
json ImuResult(double accel_scale, double scale_std, double misalignment_std, double bias_std,
               double chi2, double accel_residual = 0.001, double gyro_residual = 0.005) {
  auto triad = [](double scale) {
    results::SensorTriad t;
    t.bias = Eigen::Vector3d(0.01, -0.02, 0.03);
    t.scale = Eigen::Vector3d::Constant(scale);
    t.matrix = scale * Eigen::Matrix3d::Identity();
    return t;
  };
  auto triad_std = [&](double scale) {
    results::SensorTriadStd t;
    t.bias_std = Eigen::Vector3d::Constant(bias_std);
    t.scale_std = Eigen::Vector3d::Constant(scale_std * scale);
    t.misalignment_std << 0, misalignment_std, misalignment_std, 0, 0, misalignment_std, 0, 0, 0;
    return t;
  };
  results::ImuResult r;
  r.envelope.method = "imu";
  r.envelope.model = "a = T_a K_a (y_a - b_a), omega = T_g K_g (y_g - b_g)";
  r.parameters =
      results::ImuParameters{9.80665, "statics", 1.0, 1.0, {{"0", triad(accel_scale), triad(1.0)}}};
  r.uncertainty =
      results::ImuUncertainty{"crb", kNan, {{"0", triad_std(accel_scale), triad_std(1.0)}}, {}};
  results::ImuFitDiagnostics fit;
  fit.name = "0";
  fit.usable = true;
  fit.chi2_per_dof = chi2;
  fit.accel_norm_rms_after = accel_residual;
  fit.gyro_direction_rms_after = gyro_residual;
  fit.coverage.sufficient = true;
  r.diagnostics.imus = {fit};
  return results::ToJson(r);
}

json JudgeWith(const char* method, const json& result, const json& config) {
  json r = result;
  JudgeResult(*FindMethod(method), config, json(), &r);
  return r["verdict"];
}

TEST(Gate, ImuLimitsHoldJustInsideAndFailJustOutside) {
  const json config = {{"method", "imu"}};
  EXPECT_EQ(JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 3.9), config)["status"],
            "accepted");
  json v = JudgeWith("imu", ImuResult(1.0, 0.011, 0.009, 0.001, 3.9), config);
  EXPECT_TRUE(HasReason(v, "scale factor too uncertain")) << v.dump();
  EXPECT_EQ(v["reasons"].size(), 1u) << v.dump();  // one reason per rule, listing every triad
  v = JudgeWith("imu", ImuResult(1.0, 0.009, 0.011, 0.001, 3.9), config);
  EXPECT_TRUE(HasReason(v, "misalignment too uncertain")) << v.dump();
  v = JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.006, 3.9),
                config);  // gyro 0.006 > 0.005 rad/s
  EXPECT_TRUE(HasReason(v, "bias too uncertain")) << v.dump();
  EXPECT_EQ(v["reasons"].size(), 1u) << v.dump();  // the accelerometer's 0.006 m/s² is fine
  // chi2 against the noise has no default for imu (real statics' means are far more precise
  // than their model: imu_tk's Xsens log has chi2/dof 30); the physical residuals judge the fit.
  EXPECT_EQ(JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 30.5), config)["status"],
            "accepted");
  v = JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 4.1),
                {{"method", "imu"}, {"acceptance", {{"max_chi2", 4}}}});
  EXPECT_TRUE(HasReason(v, "chi2/dof 4.1 above 4")) << v.dump();
  EXPECT_EQ(
      JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 1, 0.019, 0.019), config)["status"],
      "accepted");
  v = JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 1, 0.021, 0.019), config);
  EXPECT_TRUE(HasReason(v, "|a| still differs from gravity by 0.021 m/s^2")) << v.dump();
  EXPECT_EQ(v["reasons"].size(), 1u) << v.dump();
  v = JudgeWith("imu", ImuResult(1.0, 0.009, 0.009, 0.001, 1, 0.019, 0.021), config);
  EXPECT_TRUE(HasReason(v, "miss the measured gravity direction by 0.021 rad")) << v.dump();
  EXPECT_EQ(v["reasons"].size(), 1u) << v.dump();
  v = JudgeWith("imu", ImuResult(1.09, 0.009, 0.009, 0.001, 1), config);
  EXPECT_EQ(v["status"], "accepted") << v.dump();
  v = JudgeWith("imu", ImuResult(1.11, 0.009, 0.009, 0.001, 1), config);
  EXPECT_TRUE(HasReason(v, "more than 10 % from the nominal unit conversion")) << v.dump();
}

TEST(Gate, ImuUnitMixUpsNameTheProbableCause) {
  // Readings in g taken as m/s²: K ≈ 9.81 against the nominal 1.
  json v = JudgeWith("imu", ImuResult(9.80665, 0.001, 0.001, 0.001, 1), {{"method", "imu"}});
  EXPECT_TRUE(HasReason(v, "look like g but are taken as m/s^2")) << v.dump();
  // Readings in m/s² taken as g: K ≈ 1 against the nominal 9.80665.
  v = JudgeWith("imu", ImuResult(1.0, 0.001, 0.001, 0.001, 1),
                {{"method", "imu"}, {"accel_unit", "g"}});
  EXPECT_TRUE(HasReason(v, "look like m/s^2 but are taken as g")) << v.dump();
  EXPECT_TRUE(HasReason(v, "accel_unit g")) << v.dump();
}

// ---- array ----

// A positions-model array result (methods/array/array_result.h, every key the adapter writes):
// triads a1, a2 at `offset` from their nominal positions with 1 sigma `std`, the accelerometer
// residual RMS `accel_rms` against a configured noise of 0.04 m/s^2.
results::ArrayResult TypedArrayResult(double offset, double std, double accel_rms) {
  results::ArrayResult r;
  r.envelope.method = "array";
  r.envelope.model = "positions";
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  for (int k = 0; k < 3; ++k) {
    const double o = k == 0 ? 0.0 : offset;  // the reference stays at its nominal position
    const std::string name = "a" + std::to_string(k);
    params.positions.push_back({name, {o, 0, 0}, {o, 0, 0}});
    unc.positions.push_back({name, {k == 0 ? 0.0 : std, std / 2, 0}, std::nullopt});
  }
  r.parameters = params;
  r.uncertainty = unc;
  r.diagnostics.converged = true;
  r.diagnostics.residual_rms = {accel_rms, 0.001};
  r.diagnostics.noise_configured = {0.04, 0.001};
  return r;
}

json ArrayResult(double offset, double std, double accel_rms) {
  return results::ToJson(TypedArrayResult(offset, std, accel_rms));
}

TEST(Gate, ArrayLimitsHoldJustInsideAndFailJustOutside) {
  const json config = {{"method", "array"}};
  EXPECT_EQ(JudgeWith("array", ArrayResult(0.0049, 9e-5, 0.079), config)["status"], "accepted");
  json v = JudgeWith("array", ArrayResult(0.0051, 9e-5, 0.079), config);
  EXPECT_TRUE(HasReason(v, "more than 5 mm from its nominal position")) << v.dump();
  v = JudgeWith("array", ArrayResult(0.0049, 1.1e-4, 0.079), config);
  EXPECT_TRUE(HasReason(v, "position too uncertain")) << v.dump();
  v = JudgeWith("array", ArrayResult(0.0049, 9e-5, 0.081), config);  // (0.081/0.04)² = 4.1
  EXPECT_TRUE(HasReason(v, "accelerometer residuals are 2.02 times")) << v.dump();
}

TEST(Gate, ArrayModelFullTriadsAreJudgedLikeImu) {
  // The positions of a positions-model result, with the triads of an imu result.
  results::ArrayResult typed = TypedArrayResult(0.001, 1e-5, 0.04);
  typed.full = true;
  typed.full_diagnostics.converged = true;
  const json imu = ImuResult(1.0, 0.001, 0.001, 0.001, 1);
  for (size_t k = 0; k < imu["parameters"]["imus"].size(); ++k) {
    results::ArrayImu triads;
    results::ArrayImuStd stds;
    results::ReadImuTriads(results::JsonReader(imu["parameters"]["imus"][k], "imu"),
                           &triads.triads);
    results::ReadImuTriads(results::JsonReader(imu["uncertainty"]["imus"][k], "imu"), &stds.triads);
    typed.parameters->imus.push_back(triads);
    typed.uncertainty->imus.push_back(stds);
  }
  const json r = results::ToJson(typed);
  ASSERT_EQ(r["parameters"]["imus"].size(), imu["parameters"]["imus"].size());
  EXPECT_EQ(JudgeWith("array", r, {{"method", "array"}})["status"], "accepted");
  // Gyroscope readings in rad/s with gyro_unit deg/s: K ≈ 1 rad/s per reading, 57 × the nominal.
  const json w = JudgeWith("array", r, {{"method", "array"}, {"gyro_unit", "deg/s"}});
  EXPECT_TRUE(HasReason(w, "look like rad/s but are taken as deg/s")) << w.dump();
}

TEST(Gate, AnArrayResultThatDoesNotReadIsRejectedNamingThePath) {
  json r = ArrayResult(0.001, 1e-5, 0.04);
  r["uncertainty"]["positions"][2]["std"] = "small";
  const json v = JudgeWith("array", r, {{"method", "array"}});
  EXPECT_EQ(v["status"], "rejected");
  EXPECT_TRUE(HasReason(v, "cannot be judged: array result: uncertainty.positions[2].std"))
      << v.dump();
}

TEST(Gate, AResultThatCannotBeJudgedIsRejected) {
  // A damaged result (a string where a count belongs) fails closed instead of throwing, naming
  // the first problem the typed reader (methods/pca/pca_result.h) met.
  const json v =
      JudgeWith("pca", {{"method", "pca"}, {"diagnostics", {{"degrees_of_freedom", "x"}}}},
                {{"method", "pca"}});
  EXPECT_EQ(v["status"], "rejected");
  EXPECT_TRUE(HasReason(v, "the result cannot be judged: pca result: model: missing")) << v.dump();
}

// A value the gate would serve that is not a finite number (null in the JSON) is never accepted,
// even with every limit removed: pca's sensitivity, imu's matrices and biases, array's positions.
TEST(Gate, ParametersThatAreNotFiniteAreNeverServed) {
  auto no_limits = [](const char* method) {
    json limits = json::object();
    for (const AcceptanceKey& key : FindMethod(method)->AcceptanceKeys())
      limits[key.name] = nullptr;
    return json{{"method", method}, {"acceptance", limits}};
  };
  const json pca =
      Calib(TriadCsv(RandomDirections(30, 7), 9.80665, 1.02, 0.1, 0.002, 7), TriadConfig(9.80665));
  ASSERT_EQ(pca["verdict"]["status"], "accepted") << pca["verdict"].dump();
  json bad = pca;
  bad["parameters"]["sensors"][1]["sensitivity"][2] = nullptr;
  json v = JudgeWith("pca", bad, TriadConfig(9.80665));
  EXPECT_EQ(v["status"], "rejected");
  EXPECT_TRUE(HasReason(v, std::string(kNotFiniteRule) + ": a0_y")) << v.dump();
  json pca_config = no_limits("pca");
  pca_config.update(TriadConfig(9.80665));
  EXPECT_EQ(JudgeWith("pca", bad, pca_config)["status"], "rejected");

  bad = ImuResult(1.0, 0.001, 0.001, 0.001, 1);
  ASSERT_EQ(JudgeWith("imu", bad, {{"method", "imu"}})["status"], "accepted");
  bad["parameters"]["imus"][0]["gyroscope"]["bias"][1] = nullptr;
  v = JudgeWith("imu", bad, no_limits("imu"));
  EXPECT_EQ(v["status"], "rejected");
  EXPECT_TRUE(HasReason(v, std::string(kNotFiniteRule) + ": IMU 0 gyroscope")) << v.dump();

  bad = ArrayResult(0.001, 1e-5, 0.04);
  ASSERT_EQ(JudgeWith("array", bad, {{"method", "array"}})["status"], "accepted");
  bad["parameters"]["positions"][0]["position"][0] = nullptr;  // the reference's
  v = JudgeWith("array", bad, no_limits("array"));
  EXPECT_EQ(v["status"], "rejected");
  EXPECT_TRUE(HasReason(v, std::string(kNotFiniteRule) + ": a0")) << v.dump();
}

// ---- noise ----

TEST(Gate, NoiseNeedsAStationaryLogAndAPreciseWhiteNoise) {
  // A complete noise result (methods/noise/noise_result.h) of one channel.
  auto result = [](bool stationary, double rel_std, double density) {
    results::NoiseResult r;
    r.envelope.method = "noise";
    r.envelope.model = "the Allan variance";
    r.channels = {{"a0_x", "m/s^2", density, NAN, NAN, NAN}};
    r.channel_stds = {{"a0_x", rel_std * density, NAN, NAN, "crb", 1.0, std::nullopt}};
    r.diagnostics.stationary = stationary;
    return results::ToJson(r);
  };
  const json config = {{"method", "noise"}};
  EXPECT_EQ(JudgeWith("noise", result(true, 0.19, 0.002), config)["status"], "accepted");
  EXPECT_TRUE(HasReason(JudgeWith("noise", result(true, 0.21, 0.002), config), "too uncertain"));
  EXPECT_TRUE(HasReason(JudgeWith("noise", result(false, 0.1, 0.002), config), "not stationary"));
  EXPECT_TRUE(HasReason(JudgeWith("noise", result(true, 0.1, 0.2), config), "far above"));
  json missing = result(true, 0.1, 0.002);
  missing["parameters"]["channels"][0]["white_noise"] = nullptr;
  EXPECT_TRUE(HasReason(JudgeWith("noise", missing, config), "no white-noise density"));
}

}  // namespace
}  // namespace calibd::server
