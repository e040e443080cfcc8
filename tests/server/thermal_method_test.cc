// The thermal method through the CSV reader (temp0 column) and server::Calibrate, and its
// firmware exports evaluated as each firmware evaluates them (ArduPilot
// AP_InertialSensor_tempcal.cpp correct_sensor, PX4 calc_thermal_offsets_3D): the correction
// each applies between two temperatures equals the simulated bias change within calibd's σ.
#include "methods/thermal/thermal_method.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>

#include "core/thermal.h"
#include "server/config.h"
#include "tests/lib/test_paths.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;

json Simulated(std::string* csv, json* truth) {
  core::ThermalSimulationOptions o;
  o.rate = 50;
  o.seed = 7;
  json config;
  EXPECT_TRUE(SimulateThermalFiles(o, csv, &config, truth).ok());
  json result;
  const Status s = Calibrate(*csv, "log.csv", config, &result);
  EXPECT_TRUE(s.ok()) << s.message();
  return result;
}

double TrueBias(const json& truth, int s, int a, double temp) {
  const char* sensor = s ? "gyroscope" : "accelerometer";
  const auto c = truth.at(sensor).at("coefficients").at(a).get<std::vector<double>>();
  Eigen::VectorXd v =
      Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size()));
  return core::ThermalCurve(v, temp - truth.at("t_ref").get<double>());
}

std::map<std::string, double> Params(const std::string& text, char sep, int name_field,
                                     int value_field) {
  std::map<std::string, double> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> f;
    std::string cell;
    std::istringstream ls(line);
    while (std::getline(ls, cell, sep)) f.push_back(cell);
    out[f.at(static_cast<size_t>(name_field))] = std::stod(f.at(static_cast<size_t>(value_field)));
  }
  return out;
}

TEST(ThermalMethodTest, CalibratesThroughTheReaderAndAccepts) {
  std::string csv;
  json truth;
  const json r = Simulated(&csv, &truth);
  EXPECT_EQ(r.at("verdict").at("status"), "accepted") << r.at("verdict").dump();
  // The curves average orders min_order (3)..max_order (5) with BIC weights: the order is the
  // highest, the table holds orders 3, 4, 5 and says so.
  const int order = r.at("parameters").at("imus").at(0).at("gyroscope").at("bias").at("order");
  EXPECT_EQ(order, 5);
  const json& d = r.at("diagnostics");
  EXPECT_NE(d.at("order_selection").get<std::string>().find("orders 3..5"), std::string::npos)
      << d.at("order_selection");
  for (const json& ch : d.at("imus").at(0).at("channels")) {
    const json& table = ch.at("order_table");
    ASSERT_EQ(table.size(), 3u) << ch.at("name");
    double total = 0;
    for (size_t i = 0; i < table.size(); ++i) {
      EXPECT_EQ(table[i].at("order"), static_cast<int>(3 + i));
      total += table[i].at("weight").get<double>();
    }
    EXPECT_NEAR(total, 1.0, 1e-12) << ch.at("name");
  }
}

TEST(ThermalMethodTest, MinOrderKeyIsCheckedNamingIt) {
  for (const json& v : {json(-1), json(9), json(2.5), json("cubic")}) {
    const Status s = ThermalMethod().ValidateConfig({{"method", "thermal"}, {"min_order", v}});
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << v;
    EXPECT_EQ(s.field(), "min_order") << v;
  }
  for (const json& v : {json(0), json(3), json(8)}) {
    EXPECT_TRUE(ThermalMethod().ValidateConfig({{"method", "thermal"}, {"min_order", v}}).ok())
        << v;
  }
}

TEST(ThermalMethodTest, RefusesAFourDegreeRangeNamingIt) {
  core::ThermalSimulationOptions o;
  o.rate = 20;
  o.delta = 4;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  const Status s = Calibrate(csv, "log.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("below min_range 10"), std::string::npos) << s.message();
}

TEST(ThermalMethodTest, LagKeyIsCheckedNamingIt) {
  for (const json& lag : {json("later"), json(-5), json(0)}) {
    const Status s = ThermalMethod().ValidateConfig({{"method", "thermal"}, {"lag", lag}});
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << lag;
    EXPECT_EQ(s.field(), "lag") << lag;
  }
  for (const json& lag : {json("none"), json("estimate"), json(45.5)}) {
    EXPECT_TRUE(ThermalMethod().ValidateConfig({{"method", "thermal"}, {"lag", lag}}).ok()) << lag;
  }
}

// Warm-up then cool-down, the sensor 60 s behind the reading: with lag none a rejected verdict
// pointing at the lag; with lag "estimate" τ within 4σ, its σ and bound in the result, accepted;
// the same config on a warm-up alone is not determinable, naming why.
TEST(ThermalMethodTest, LagEstimateThroughTheReader) {
  core::ThermalSimulationOptions o;
  o.rate = 20;
  o.warmup = o.cooldown = 1200;
  o.lag = 60;
  o.seed = 9;
  std::string csv;
  json config, truth, r;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  EXPECT_EQ(truth.at("lag"), 60);
  // Without the lag the branches disagree: rejected as hysteresis, pointing at the lag.
  Status s = Calibrate(csv, "log.csv", config, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r["verdict"]["status"], "rejected");
  EXPECT_NE(r["verdict"].dump().find("try lag \\\"estimate\\\""), std::string::npos)
      << r["verdict"].dump();
  config["lag"] = "estimate";
  s = Calibrate(csv, "log.csv", config, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  const double tau = r["parameters"]["imus"][0]["lag"];
  const double sd = r["uncertainty"]["imus"][0]["lag_std"];
  EXPECT_LT(std::abs(tau - 60), 4 * sd) << tau << " ± " << sd;
  EXPECT_GT(r["uncertainty"]["imus"][0]["crb"]["lag_std"].get<double>(), 0);
  EXPECT_EQ(r["diagnostics"]["imus"][0]["lag"]["mode"], "estimate");
  EXPECT_EQ(r["verdict"]["status"], "accepted") << r["verdict"].dump();
  o.cooldown = 0;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  config["lag"] = "estimate";
  s = Calibrate(csv, "log.csv", config, &r);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_NE(s.message().find("single warm-up"), std::string::npos) << s.message();
}

// Both firmwares correct by the difference of their polynomial between the flight temperature and
// a reference (ArduPilot: the calibration temperature; PX4: X0 holds the absolute bias at TREF,
// so the difference P(T) − P(TREF) is the deviation). Checked at 9 temperatures across the range
// against the truth, with the tolerance 4 × calibd's 1σ band at T plus float rounding.
TEST(ThermalMethodTest, FirmwareFilesReproduceTheCurveAsTheFirmwareEvaluatesIt) {
  std::string csv;
  json truth;
  const json r = Simulated(&csv, &truth);
  ExportContext context;
  context.device = "unit-1";
  std::string ap, px4;
  ASSERT_TRUE(ThermalResultToArduPilot(r, context, &ap).ok());
  ASSERT_TRUE(ThermalResultToPx4(r, context, &px4).ok());
  const auto apm = Params(ap, ',', 0, 1);
  const auto pxm = Params(px4, '\t', 2, 3);
  const json& imu = r.at("parameters").at("imus").at(0);
  const json& unc = r.at("uncertainty").at("imus").at(0);
  const double t_ref = imu.at("t_ref"), lo = apm.at("INS_TCAL1_TMIN"),
               hi = apm.at("INS_TCAL1_TMAX");
  EXPECT_EQ(apm.at("INS_TCAL1_ENABLE"), 1);
  const auto grid =
      unc.at("accelerometer").at("bias").at("temperatures").get<std::vector<double>>();
  for (int s = 0; s < 2; ++s) {
    const char* sensor = s ? "gyroscope" : "accelerometer";
    for (int a = 0; a < 3; ++a) {
      const auto sd = unc.at(sensor).at("bias").at("std").at(a).get<std::vector<double>>();
      for (size_t g = 0; g < grid.size(); g += 2) {
        const double temp = grid[g];
        const double truth_dev = TrueBias(truth, s, a, temp) - TrueBias(truth, s, a, t_ref);
        const double tol = 4 * sd[g] + (s ? 1e-7 : 1e-6);
        // ArduPilot: P(d) = (c1 + (c2 + c3 d) d) d × 1e-6, d = clamp(T) − 35.
        auto ap_poly = [&](double t) {
          const double d = std::clamp(t, lo, hi) - 35.0;
          const std::string base = std::string("INS_TCAL1_") + (s ? "GYR" : "ACC");
          const std::string ax(1, static_cast<char>('X' + a));
          const double c1 = apm.at(base + "1_" + ax), c2 = apm.at(base + "2_" + ax),
                       c3 = apm.at(base + "3_" + ax);
          return (c1 + (c2 + c3 * d) * d) * d * 1e-6;
        };
        EXPECT_NEAR(ap_poly(temp) - ap_poly(t_ref), truth_dev, tol)
            << "ardupilot " << sensor << " " << a << " at " << temp;
        // PX4: offset = X0 + X1 dT + X2 dT² + X3 dT³, dT = clamp(T) − TREF.
        const std::string base = std::string("TC_") + (s ? "G" : "A") + "0_";
        const double tref = pxm.at(base + "TREF");
        auto px_poly = [&](double t) {
          const double d = std::clamp(t, pxm.at(base + "TMIN"), pxm.at(base + "TMAX")) - tref;
          const std::string ax = "_" + std::to_string(a);
          return pxm.at(base + "X0" + ax) + pxm.at(base + "X1" + ax) * d +
                 pxm.at(base + "X2" + ax) * d * d + pxm.at(base + "X3" + ax) * d * d * d;
        };
        EXPECT_NEAR(px_poly(temp) - px_poly(tref), truth_dev, tol)
            << "px4 " << sensor << " " << a << " at " << temp;
      }
    }
  }
  // PX4's gyroscope X0 is the absolute bias at TREF (truth b0 = 0 plus the curve at TREF), within
  // 4 σ of calibd's bias at t_ref.
  const auto at_std = unc.at("gyroscope").at("bias").at("at_t_ref_std").get<std::vector<double>>();
  for (int a = 0; a < 3; ++a) {
    const double expected = TrueBias(truth, 1, a, t_ref);
    EXPECT_NEAR(pxm.at("TC_G0_X0_" + std::to_string(a)), expected, 4 * at_std[a] + 1e-7)
        << "axis " << a << " sigma " << at_std[a];
  }
}

// +z through a warm-up, −z through the cool-down over the same temperatures, with a scale drift:
// the result holds z's scale curve (SPEC shape, with covariance, temperatures and std) and bias at
// t_ref, x and y null with the reason; the PX4 file's TC_A0_X0_2 is that bias at t_ref and x, y
// keep 0; both firmware files still say the scale is left out.
TEST(ThermalMethodTest, ScaleCurveAndBiasAtTRefWithOppositeFaces) {
  core::ThermalSimulationOptions o;
  o.rate = 50;
  o.warmup = o.cooldown = 3600;
  o.cool_delta = 40;
  o.tau = 1200;
  o.orientations = 2;
  o.seed = 11;
  o.b0.head<3>() << 0.05, -0.03, 0.08;
  o.scale_coefficients = core::DefaultThermalScaleTruth(2);
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  json r;
  const Status s = Calibrate(csv, "log.csv", config, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  const json& a = r.at("parameters").at("imus").at(0).at("accelerometer");
  const json& scale = a.at("scale");
  ASSERT_TRUE(scale.is_object()) << a.dump();
  EXPECT_TRUE(scale.at("coefficients").at(0).is_null());
  EXPECT_TRUE(scale.at("coefficients").at(1).is_null());
  EXPECT_EQ(scale.at("coefficients").at(2).size(), scale.at("orders").at(2).get<size_t>());
  EXPECT_NE(scale.at("not_estimated").at(0).get<std::string>().find("+x and -x"),
            std::string::npos);
  EXPECT_TRUE(scale.at("not_estimated").at(2).is_null());
  const json& at = a.at("bias").at("at_t_ref");
  ASSERT_TRUE(at.is_array());
  EXPECT_TRUE(at.at(0).is_null());
  const double t_ref = r.at("parameters").at("imus").at(0).at("t_ref");
  const json& unc = r.at("uncertainty").at("imus").at(0).at("accelerometer");
  const double at_std = unc.at("bias").at("at_t_ref_std").at(2);
  EXPECT_NEAR(at.at(2).get<double>(), 0.08 + TrueBias(truth, 0, 2, t_ref), 5 * at_std);
  const json& us = unc.at("scale");
  const size_t p = scale.at("orders").at(2).get<size_t>();
  EXPECT_EQ(us.at("covariance").at(2).size(), p);
  EXPECT_EQ(us.at("std").at(2).size(), us.at("temperatures").size());
  EXPECT_TRUE(us.at("std").at(0).is_null());
  ExportContext context;
  context.device = "unit-1";
  std::string ap, px4;
  ASSERT_TRUE(ThermalResultToArduPilot(r, context, &ap).ok());
  ASSERT_TRUE(ThermalResultToPx4(r, context, &px4).ok());
  EXPECT_NE(ap.find("left out"), std::string::npos);
  EXPECT_NE(px4.find("left out"), std::string::npos);
  const auto pxm = Params(px4, '\t', 2, 3);
  // X0 also carries the order-3 refit's constant (~1e-6 here), far below the bias (0.08).
  EXPECT_NEAR(pxm.at("TC_A0_X0_0"), 0.0, 1e-4);
  EXPECT_NEAR(pxm.at("TC_A0_X0_2"), at.at(2).get<double>(), 1e-4);
  EXPECT_GT(std::abs(pxm.at("TC_A0_X0_2")), 0.05);
}

// `calibd simulate thermal` then `calibd calibrate`, as a user runs them: exit status, the result
// read back from stdout.
json SimulateAndCalibrate(const std::string& simulate_flags, const std::string& dir) {
  const std::string bin = calibd::test_paths::CalibdBinary();
  const std::string command = bin + " simulate thermal --out " + dir + " " + simulate_flags +
                              " >/dev/null 2>&1 && " + bin + " calibrate " + dir +
                              "/recording.csv --config " + dir + "/config.json 2>/dev/null";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return json();
  std::string out;
  char buf[65536];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) out.append(buf, n);
  const int status = ::pclose(pipe);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << command;
  return json::parse(out, nullptr, false);
}

// --cycles repeats the six faces through the warm-up and the cool-down, so each axis's opposite
// faces share a temperature span and every accelerometer axis gets its scale curve; the simulated
// first-order drift (--scale-order 1: 1e-4, 1.5e-4, 2e-4 /°C about 35 °C) comes back within 4σ
// (one log: a false failure per axis ~6e-5). Held once each (no --cycles), the faces sit at
// different temperatures and no axis has one.
TEST(ThermalSimulateCommand, CyclesGiveEveryAxisItsScaleCurve) {
  testing::TempDir dir;
  const std::string flags =
      "--seed 5 --rate 10 --orientations 6 --scale-order 1 --warmup 1800 --cooldown 1800";
  const json tumble = SimulateAndCalibrate(flags + " --cycles 3", (dir.path() / "tumble").string());
  ASSERT_TRUE(tumble.is_object());
  std::ifstream truth_file(dir.path() / "tumble" / "truth.json");
  const json truth = json::parse(truth_file);
  const json& p = tumble.at("parameters").at("imus").at(0);
  const json& scale = p.at("accelerometer").at("scale");
  ASSERT_TRUE(scale.is_object()) << p.dump();
  const double t_ref = p.at("t_ref").get<double>(), t0 = truth.at("t_ref").get<double>();
  for (int a = 0; a < 3; ++a) {
    EXPECT_TRUE(scale.at("not_estimated").at(a).is_null()) << a;
    // The gain relative to its value at t_ref: d1 / (1 + d1 (t_ref − t0)) per °C.
    const double d1 = truth.at("accelerometer").at("scale_coefficients").at(a).at(0);
    const double expected = d1 / (1 + d1 * (t_ref - t0));
    const double got = scale.at("coefficients").at(a).at(0);
    const double sd = std::sqrt(tumble.at("uncertainty")
                                    .at("imus")
                                    .at(0)
                                    .at("accelerometer")
                                    .at("scale")
                                    .at("covariance")
                                    .at(a)
                                    .at(0)
                                    .at(0)
                                    .get<double>());
    EXPECT_NEAR(got, expected, 4 * sd) << "axis " << a;
  }
  const json once = SimulateAndCalibrate(flags, (dir.path() / "once").string());
  ASSERT_TRUE(once.is_object());
  EXPECT_TRUE(once.at("parameters").at("imus").at(0).at("accelerometer").at("scale").is_null());
}

}  // namespace
}  // namespace calibd::server
