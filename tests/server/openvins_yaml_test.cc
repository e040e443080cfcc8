// format=yaml for imu results: OpenVINS's kalibr_imu_chain.yaml. The intrinsics it writes
// predict, for any raw reading, the same specific force and rate as calibd's model up to one
// common rotation of the frame (the convention mapping of methods/imu/openvins_yaml.h), in
// OpenVINS's `calibrated` (kalibr) form: Da, Dw lower triangular, R_IMUtoACC = I, Tg = 0; and the
// route serves it for a real imu job.
#include "methods/imu/openvins_yaml.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "methods/imu/imu_method.h"
#include "methods/imu/imu_result.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

using nlohmann::json;
using testing::TestServer;

// A stored imu result (methods/imu/imu_result.h) of one IMU with these matrices, biases, reading
// units, rate and per-sample noise of the statics; the rest as a run would leave it by default.
json ImuResult(const Eigen::Matrix3d& ma, const Eigen::Vector3d& ba, const Eigen::Matrix3d& mg,
               const Eigen::Vector3d& bg, double ua, double ug, double rate,
               const Eigen::Vector3d& sa, const Eigen::Vector3d& sg) {
  results::ImuResult r;
  r.envelope.method = "imu";
  r.envelope.model = "a = T_a K_a (y_a - b_a), omega = T_g K_g (y_g - b_g)";
  results::ImuParameters p;
  p.gravity = 9.80665;
  p.gyro_bias = "statics";
  p.accel_unit = ua;
  p.gyro_unit = ug;
  results::ImuTriads t;
  t.name = "0";
  t.accelerometer.matrix = ma;
  t.accelerometer.bias = ba;
  t.gyroscope.matrix = mg;
  t.gyroscope.bias = bg;
  p.imus = {t};
  r.parameters = p;
  results::ImuTriadsStd sd;
  sd.name = "0";
  r.uncertainty = results::ImuUncertainty{"crb", kNan, {sd}, {}};
  r.diagnostics.rate = rate;
  results::ImuFitDiagnostics fit;
  fit.name = "0";
  fit.accel_noise = sa;
  fit.gyro_noise = sg;
  r.diagnostics.imus = {fit};
  return results::ToJson(r);
}

// The 3x3 matrix under `  key:` of block `imuN:` in the YAML text.
Eigen::Matrix3d YamlMatrix(const std::string& yaml, const std::string& block,
                           const std::string& key) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Constant(NAN);
  size_t at = yaml.find("\n" + block + ":");
  if (at == std::string::npos) return m;
  at = yaml.find("\n  " + key + ":\n", at);
  if (at == std::string::npos) return m;
  std::istringstream in(yaml.substr(at + key.size() + 5));
  for (int r = 0; r < 3; ++r) {
    std::string line;
    std::getline(in, line);
    char dash, open, c1, c2;
    std::istringstream row(line);
    row >> dash >> open >> m(r, 0) >> c1 >> m(r, 1) >> c2 >> m(r, 2);
  }
  return m;
}

double YamlNumber(const std::string& yaml, const std::string& key) {
  const size_t at = yaml.find("  " + key + ": ");
  if (at == std::string::npos) return NAN;
  return std::stod(yaml.substr(at + key.size() + 4));
}

TEST(OpenVinsYaml, IntrinsicsPredictCalibdsModelUpToOneRotationInTheCalibratedForm) {
  std::mt19937_64 rng(42);
  std::normal_distribution<double> n01;
  for (int trial = 0; trial < 20; ++trial) {
    const double ua = 0.0024, ug = 2e-4;  // SI per count
    Eigen::Matrix3d ta = Eigen::Matrix3d::Identity(), tg = Eigen::Matrix3d::Identity();
    ta(0, 1) = 0.01 * n01(rng);
    ta(0, 2) = 0.01 * n01(rng);
    ta(1, 2) = 0.01 * n01(rng);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        if (r != c) tg(r, c) = 0.02 * n01(rng);
    Eigen::Vector3d ka, kg, ba, bg, sa, sg;
    for (int i = 0; i < 3; ++i) {
      ka(i) = ua * (1 + 0.02 * n01(rng));
      kg(i) = ug * (1 + 0.02 * n01(rng));
      ba(i) = 32768 + 30 * n01(rng);
      bg(i) = 32768 + 30 * n01(rng);
      sa(i) = 0.01 * (1 + i);
      sg(i) = 0.001 * (1 + i);
    }
    const Eigen::Matrix3d ma = ta * ka.asDiagonal(), mg = tg * kg.asDiagonal();
    const double rate = 200;
    json result = ImuResult(ma, ba, mg, bg, ua, ug, rate, sa, sg);
    std::string yaml;
    ASSERT_TRUE(ImuResultToOpenVinsYaml(result, {7, "SN-1", "imu", "2026-01-01"}, &yaml).ok());
    ASSERT_EQ(yaml.rfind("%YAML:1.0\n", 0), 0u);
    EXPECT_NE(yaml.find("\nimu0:"), std::string::npos);
    EXPECT_NE(yaml.find("  model: \"calibrated\"\n"), std::string::npos);
    const Eigen::Matrix3d tw_ov = YamlMatrix(yaml, "imu0", "Tw");
    const Eigen::Matrix3d ta_ov = YamlMatrix(yaml, "imu0", "Ta");
    const Eigen::Matrix3d r_gyro = YamlMatrix(yaml, "imu0", "R_IMUtoGYRO");
    ASSERT_TRUE(tw_ov.allFinite() && ta_ov.allFinite() && r_gyro.allFinite()) << yaml;
    EXPECT_TRUE(YamlMatrix(yaml, "imu0", "R_IMUtoACC").isIdentity(0)) << yaml;
    EXPECT_TRUE(YamlMatrix(yaml, "imu0", "Tg").isZero(0)) << yaml;
    const Eigen::Matrix3d da = ta_ov.inverse(), dw = tw_ov.inverse();
    // The calibrated (kalibr) model reads only the lower triangle of Da and Dw.
    EXPECT_LT(da.triangularView<Eigen::StrictlyUpper>().toDenseMatrix().norm(), 1e-12);
    EXPECT_LT(dw.triangularView<Eigen::StrictlyUpper>().toDenseMatrix().norm(), 1e-12);
    // OpenVINS on SI readings u·y: a_I = Da (u_a y_a - u_a b_a), w_I = R_GYROtoI Dw (...).
    // calibd: a = M_a (y_a - b_a). Per count, OpenVINS's maps are Da u_a and R_GYROtoI Dw u_g;
    // both must equal R0 M with one rotation R0.
    const Eigen::Matrix3d r0a = (da * ua) * ma.inverse();
    const Eigen::Matrix3d r0g = (r_gyro.transpose() * dw * ug) * mg.inverse();
    EXPECT_LT((r0a * r0a.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-9) << r0a;
    EXPECT_NEAR(r0a.determinant(), 1, 1e-9);
    EXPECT_LT((r0a - r0g).norm(), 1e-9) << r0a << "\n" << r0g;
    // The rotation is the small one of the misalignments, not a flip.
    EXPECT_LT(std::acos(std::min(1.0, (r0a.trace() - 1) / 2)), 0.1);
    EXPECT_NEAR(YamlNumber(yaml, "accelerometer_noise_density"), sa.maxCoeff() / std::sqrt(rate),
                1e-15);
    EXPECT_NEAR(YamlNumber(yaml, "gyroscope_noise_density"), sg.maxCoeff() / std::sqrt(rate),
                1e-15);
    // The measured rate to its precision: 6 significant digits.
    EXPECT_NEAR(YamlNumber(yaml, "update_rate"), rate, 5e-6 * rate);
    EXPECT_TRUE(std::isnan(YamlNumber(yaml, "accelerometer_random_walk"))) << yaml;
    // With noise jobs, their figures are written instead (Kalibr's keys, all four).
    result["diagnostics"]["noise_model"] = {
        {"accelerometer", {{"job", 3}, {"white_noise", 2e-3}, {"random_walk", 4e-4}}},
        {"gyroscope", {{"job", 3}, {"white_noise", 1e-4}, {"random_walk", 2e-5}}}};
    ASSERT_TRUE(ImuResultToOpenVinsYaml(result, {7, "SN-1", "imu", "2026-01-01"}, &yaml).ok());
    EXPECT_DOUBLE_EQ(YamlNumber(yaml, "accelerometer_noise_density"), 2e-3);
    EXPECT_DOUBLE_EQ(YamlNumber(yaml, "accelerometer_random_walk"), 4e-4);
    EXPECT_DOUBLE_EQ(YamlNumber(yaml, "gyroscope_noise_density"), 1e-4);
    EXPECT_DOUBLE_EQ(YamlNumber(yaml, "gyroscope_random_walk"), 2e-5);
  }
}

// The b_a = [..] / b_g = [..] comment's three numbers (NAN when missing).
Eigen::Vector3d YamlBias(const std::string& yaml, const std::string& key) {
  Eigen::Vector3d v = Eigen::Vector3d::Constant(NAN);
  const size_t at = yaml.find(key + " = [");
  if (at == std::string::npos) return v;
  char c1, c2;
  std::istringstream in(yaml.substr(at + key.size() + 4));
  in >> v(0) >> c1 >> v(1) >> c2 >> v(2);
  return v;
}

TEST(OpenVinsYaml, BiasesAreInSiAfterTheNominalOffsetOfCounts) {
  const double ua = 0.0024, ug = 2e-4;
  const Eigen::Vector3d ba(32768 + 10, 32768 - 20, 32768 + 5), bg(32768 + 50, 32768, 32768 - 25);
  const Eigen::Vector3d noise(0.01, 0.01, 0.01);
  const json result = ImuResult(ua * Eigen::Matrix3d::Identity(), ba,
                                ug * Eigen::Matrix3d::Identity(), bg, ua, ug, 100, noise, noise);
  ExportContext context{7, "SN-1", "imu", "2026-01-01"};
  context.config = {{"method", "imu"}, {"nominal_accel_bias", 32768}, {"nominal_gyro_bias", 32768}};
  std::string yaml;
  ASSERT_TRUE(ImuResultToOpenVinsYaml(result, context, &yaml).ok());
  const Eigen::Vector3d b_a = YamlBias(yaml, "b_a"), b_g = YamlBias(yaml, "b_g");
  ASSERT_TRUE(b_a.allFinite() && b_g.allFinite()) << yaml;
  EXPECT_LT((b_a - Eigen::Vector3d(10, -20, 5) * ua).norm(), 1e-12) << yaml;
  EXPECT_LT((b_g - Eigen::Vector3d(50, 0, -25) * ug).norm(), 1e-12) << yaml;
  // Without a nominal offset (signed readings), the bias is the reading bias x unit.
  context.config = {{"method", "imu"}, {"nominal_gyro_bias", nullptr}};
  ASSERT_TRUE(ImuResultToOpenVinsYaml(result, context, &yaml).ok());
  EXPECT_NEAR(YamlBias(yaml, "b_a")(0), ba(0) * ua, 1e-9) << yaml;
  EXPECT_NEAR(YamlBias(yaml, "b_g")(2), bg(2) * ug, 1e-9) << yaml;
  // A config whose offset is not a number is not silently taken as 0.
  context.config = {{"method", "imu"}, {"nominal_accel_bias", "32768"}};
  Status s = ImuResultToOpenVinsYaml(result, context, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_NE(s.message().find("nominal_accel_bias"), std::string::npos) << s.message();
}

TEST(OpenVinsYaml, AMirroringMatrixOrAnOldResultIsRefusedSayingWhy) {
  const Eigen::Vector3d zero = Eigen::Vector3d::Zero();
  json result = ImuResult(-Eigen::Matrix3d::Identity(), zero, Eigen::Matrix3d::Identity(), zero, 1,
                          1, 100, zero, zero);
  std::string yaml;
  Status s = ImuResultToOpenVinsYaml(result, {}, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("mirrors"), std::string::npos) << s.message();
  result["parameters"].erase("accel_unit");
  s = ImuResultToOpenVinsYaml(result, {}, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("run the job again"), std::string::npos) << s.message();
}

TEST(OpenVinsYaml, TheCalibrationRouteServesItForAnImuJobInCounts) {
  core::ImuSimulationOptions sim;
  sim.statics = 20;
  sim.seed = 5;
  sim.accel_unit = 0.0024;
  sim.gyro_unit = 2e-4;
  sim.accel_offset = 32768;
  sim.gyro_offset = 32768;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  config["device"] = "OV-1";
  TestServer server;
  ASSERT_EQ(server.error(), "");
  json job = server.UploadAndWait(csv, config, "imu.csv");
  ASSERT_FALSE(job.is_null());
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  EXPECT_DOUBLE_EQ(job["result"]["parameters"]["accel_unit"].get<double>(), 0.0024);
  EXPECT_NEAR(job["result"]["diagnostics"]["rate"].get<double>(), sim.rate, 1e-6);
  auto yaml = server.Client().Get("/api/v1/devices/OV-1/calibration?method=imu&format=yaml");
  ASSERT_TRUE(yaml);
  ASSERT_EQ(yaml->status, 200) << yaml->body;
  EXPECT_NE(yaml->get_header_value("Content-Disposition").find("kalibr_imu_chain.yaml"),
            std::string::npos);
  // Per SI reading, the gains are ≈ 1 (the counts' unit is divided out).
  const Eigen::Matrix3d ta = YamlMatrix(yaml->body, "imu0", "Ta");
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(ta(i, i), 1, 0.05) << yaml->body;
  // The biases in SI after the nominal offset of 32768 counts: the simulation's are small (not
  // 32768 x 0.0024 = 78.6 m/s^2), and equal to the result's (b - 32768) x unit.
  const Eigen::Vector3d b_a = YamlBias(yaml->body, "b_a"), b_g = YamlBias(yaml->body, "b_g");
  ASSERT_TRUE(b_a.allFinite() && b_g.allFinite()) << yaml->body;
  const json& bias = job["result"]["parameters"]["imus"][0]["accelerometer"]["bias"];
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(b_a(i), (bias[i].get<double>() - 32768) * 0.0024, 1e-9) << yaml->body;
  }
  EXPECT_LT(b_a.norm(), 2.0) << yaml->body;
  EXPECT_LT(b_g.norm(), 0.2) << yaml->body;
}

}  // namespace
}  // namespace calibd::server
