// Units everywhere in diagnostics (issue 28 item 3): simulated runs of pca, array (both models),
// imu and noise that trigger warnings and failures; every non-integer number in their warnings
// and reasons is followed by its unit or stands in a clause naming a dimensionless quantity, and
// every non-integer number in their diagnostics has its unit named by a key
// (tests/lib/units_check.h). Each test also strips the unit keys and checks that the checker then
// complains, so a result that loses a unit fails here.
#include <gtest/gtest.h>

#include <iterator>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/array.h"
#include "core/array_full.h"
#include "core/array_simulation.h"
#include "core/pca_simulation.h"
#include "formats/recording.h"
#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "methods/pca/pca_method.h"
#include "methods/registry.h"
#include "server/config.h"
#include "tests/lib/array_csv.h"
#include "tests/lib/units_check.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::DiagnosticsWithoutUnit;
using testing::NumbersWithoutUnit;

std::string Join(const std::vector<std::string>& v) {
  std::string out;
  for (const std::string& s : v) out += "\n  " + s;
  return out;
}

// Every number of every message in `messages` names its unit; returns how many non-integer
// numbers the messages hold (so that a test can require it checked some).
int ExpectUnitsInMessages(const std::vector<std::string>& messages) {
  int decimals = 0;
  static const std::regex kDecimal(R"(\d\.\d|\d[eE][-+]?\d)");
  for (const std::string& m : messages) {
    EXPECT_TRUE(NumbersWithoutUnit(m).empty()) << m << Join(NumbersWithoutUnit(m));
    decimals += static_cast<int>(
        std::distance(std::sregex_iterator(m.begin(), m.end(), kDecimal), std::sregex_iterator()));
  }
  return decimals;
}

std::vector<std::string> Warnings(const json& result) {
  std::vector<std::string> out;
  if (result.contains("warnings"))
    for (const json& w : result["warnings"]) out.push_back(w.get<std::string>());
  return out;
}

// The gate's reasons for `result` (written by `method` with `config`) under `acceptance`.
std::vector<std::string> GateReasons(const char* method, json result, json config,
                                     const json& acceptance) {
  config["acceptance"] = acceptance;
  JudgeResult(*FindMethod(method), config, json(), &result);
  std::vector<std::string> out;
  for (const json& r : result["verdict"]["reasons"]) out.push_back(r.get<std::string>());
  EXPECT_FALSE(out.empty()) << result["verdict"].dump();
  return out;
}

void Append(std::vector<std::string>* to, const std::vector<std::string>& from) {
  to->insert(to->end(), from.begin(), from.end());
}

bool AnyContains(const std::vector<std::string>& v, const std::string& what) {
  for (const std::string& s : v)
    if (s.find(what) != std::string::npos) return true;
  return false;
}

// The diagnostics name every unit; without the keys listed in `unit_keys` (paths "a.b") they do
// not (the check can fail).
void ExpectUnitsInDiagnostics(const json& diagnostics, const std::vector<std::string>& unit_keys) {
  int checked = 0;
  const std::vector<std::string> missing = DiagnosticsWithoutUnit(diagnostics, &checked);
  EXPECT_TRUE(missing.empty()) << Join(missing);
  EXPECT_GE(checked, 10) << diagnostics.dump();
  json stripped = diagnostics;
  for (const std::string& key : unit_keys) {
    const json::json_pointer ptr("/" + std::regex_replace(key, std::regex("\\."), "/"));
    ASSERT_TRUE(stripped.contains(ptr)) << key;
    stripped[ptr.parent_pointer()].erase(ptr.back());
  }
  int ignored = 0;
  EXPECT_FALSE(DiagnosticsWithoutUnit(stripped, &ignored).empty()) << "without " << Join(unit_keys);
}

TEST(UnitsCheck, FlagsANumberWithoutItsUnitAndAcceptsUnitsAndNamedRatios) {
  EXPECT_EQ(NumbersWithoutUnit("noise estimated (0.012) differs").size(), 1u);
  EXPECT_EQ(NumbersWithoutUnit("the residuals suggest a noise level of 3.1e-05, not").size(), 1u);
  EXPECT_TRUE(NumbersWithoutUnit("noise estimated (0.012 m/s^2) differs").empty());
  EXPECT_TRUE(NumbersWithoutUnit("a log of 3.2 h would; 40.5 s; 0.3 °/s; 1.5e-3 rad/s").empty());
  EXPECT_TRUE(NumbersWithoutUnit("(χ²/dof 26.1, of the static means 3.4)").empty());
  EXPECT_TRUE(NumbersWithoutUnit("σ is 5.09× the bound; 3.00 times the given").empty());
  EXPECT_TRUE(NumbersWithoutUnit("12 of 100 samples; IMU 0; a0_z; T[0]").empty());
  EXPECT_TRUE(NumbersWithoutUnit("along the direction (0.12, -0.99, 0.00): the").empty());
  EXPECT_EQ(NumbersWithoutUnit("the gap: 0.5 then 1.5 m").size(), 1u);
  EXPECT_TRUE(NumbersWithoutUnit("g0_x (1.02 against 1 reading units per field unit)").empty());
  EXPECT_TRUE(NumbersWithoutUnit("pinned at -0.05/0.06 m/s^2; 4.5 um").empty());
  EXPECT_EQ(NumbersWithoutUnit("between 0.5 and 0.25 (limit)").size(), 2u);
}

// ---- pca ----

json RunPcaCase(const core::PcaSimulation& sim, const core::PcaOptions& o, Status* s) {
  PcaRecording rec;
  rec.sensor_names = sim.sensor_names;
  rec.readings = sim.m;
  json result;
  *s = RunPca(rec, o, &result);
  return result;
}

TEST(UnitsInResults, Pca) {
  core::PcaSimulationOptions so;
  so.positions = 40;
  const core::PcaSimulation sim = core::SimulatePca(so);
  std::vector<std::string> messages;
  Status s;
  // noise_std 10× the true one: "the residuals suggest a noise level of ..."
  core::PcaOptions o;
  o.magnitude = so.magnitude;
  o.noise_std = 10 * so.noise_std;
  json r = RunPcaCase(sim, o, &s);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(AnyContains(Warnings(r), "suggest a noise level")) << r["warnings"].dump();
  for (const std::string& w : Warnings(r)) messages.push_back(w);
  ExpectUnitsInDiagnostics(r["diagnostics"], {"units"});
  // noise_std a third of the true one: χ²-scaled σ; a swapped nominal: axes far from it.
  o.noise_std = so.noise_std / 3;
  Eigen::MatrixXd nominal = sim.a_model;
  nominal.col(0).swap(nominal.col(1));
  o.nominal = nominal;
  r = RunPcaCase(sim, o, &s);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(AnyContains(Warnings(r), "times the given noise_std")) << r["warnings"].dump();
  ASSERT_TRUE(AnyContains(Warnings(r), "degrees from its nominal")) << r["warnings"].dump();
  for (const std::string& w : Warnings(r)) messages.push_back(w);
  // The gate's reasons: residuals against noise_std, coverage, scale factors, their σ.
  const json pca_config = {
      {"method", "pca"}, {"magnitude", so.magnitude}, {"noise_std", *o.noise_std}};
  std::vector<std::string> reasons = GateReasons("pca", r, pca_config,
                                                 {{"max_chi2", 1.5},
                                                  {"min_scatter", 0.99},
                                                  {"scale_range", 1e-6},
                                                  {"max_scale_std", 1e-9},
                                                  {"max_axis_std", 1e-12},
                                                  {"max_bias_std", 1e-12}});
  ASSERT_TRUE(AnyContains(reasons, "times the given noise_std")) << Join(reasons);
  ASSERT_TRUE(AnyContains(reasons, "against")) << Join(reasons);
  Append(&messages, reasons);
  reasons = GateReasons("pca", r, pca_config, {{"implausible_factor", 1.000001}});
  ASSERT_TRUE(AnyContains(reasons, "x the nominal")) << Join(reasons);
  Append(&messages, reasons);
  // Orientations within 30° of +z: poor coverage and a small rank gap.
  core::PcaSimulation cone = sim;
  for (int j = 0; j < cone.v.cols(); ++j) {
    Eigen::Vector3d u = sim.v.col(j).normalized();
    u.head<2>() *= 0.3;
    u(2) = std::abs(u(2)) + 1;
    cone.v.col(j) = so.magnitude * u.normalized();
  }
  cone.m = cone.a_true.transpose() * cone.v +
           so.noise_std * core::PcaRandom(5).NormalMatrix(cone.m.rows(), cone.m.cols());
  r = RunPcaCase(cone, core::PcaOptions(), &s);
  for (const std::string& w : Warnings(r)) messages.push_back(w);
  if (!s.ok()) messages.push_back(s.message());
  ASSERT_TRUE(AnyContains(messages, "poorly spread")) << Join(messages);
  // Readings in a plane: not determinable, the singular values' ratio named.
  core::PcaSimulation flat = sim;
  flat.v.row(2).setZero();
  flat.m = flat.a_true.transpose() * flat.v;
  r = RunPcaCase(flat, core::PcaOptions(), &s);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable);
  messages.push_back(s.message());
  EXPECT_GE(ExpectUnitsInMessages(messages), 8) << Join(messages);
}

// ---- imu ----

json RunImuCase(const core::ImuSimulationOptions& sim, const json& extra, Status* s) {
  std::string csv;
  json config, truth, result;
  EXPECT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  config.update(extra);
  *s = Calibrate(csv, "imu.csv", config, &result);
  return result;
}

TEST(UnitsInResults, Imu) {
  core::ImuSimulationOptions sim;
  sim.statics = 12;  // fewer than recommended: a warning
  Status s;
  // The configured noise a tenth of the simulated one: the χ²-scaled σ and its warning.
  const json extra = {{"accel_noise", sim.accel_noise / 10}};
  const json r = RunImuCase(sim, extra, &s);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const std::vector<std::string> w = Warnings(r);
  json imu_config = {{"method", "imu"}};
  imu_config.update(extra);
  const std::vector<std::string> reasons = GateReasons("imu", r, imu_config,
                                                       {{"max_accel_residual", 1e-9},
                                                        {"max_gyro_residual", 1e-12},
                                                        {"max_chi2", 1.1},
                                                        {"scale_range", 1e-7},
                                                        {"max_scale_std", 1e-12},
                                                        {"max_axis_std", 1e-12},
                                                        {"max_accel_bias_std", 1e-12},
                                                        {"max_accel_bias", 1e-12}});
  ASSERT_TRUE(AnyContains(reasons, "differs from gravity")) << Join(reasons);
  ASSERT_TRUE(AnyContains(w, "CRB scaled")) << r["warnings"].dump();
  ASSERT_TRUE(AnyContains(w, "are recommended")) << r["warnings"].dump();
  ExpectUnitsInDiagnostics(r["diagnostics"], {"units"});
  std::vector<std::string> messages = w;
  Append(&messages, reasons);
  // A gyroscope gain 1.31 times the nominal gyro_unit: refused, the limit named as relative.
  core::ImuSimulationOptions off = sim;
  off.statics = 24;
  off.seed = 23;
  off.gyro_unit = 2.09e-4;
  off.gyro_offset = 32768;
  RunImuCase(off, {{"gyro_unit", 1.0 / 6258}}, &s);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  messages.push_back(s.message());
  // Let through (max_scale_deviation 0.5), the gate finds the gain implausible.
  const json through = {{"gyro_unit", 1.0 / 6258}, {"max_scale_deviation", 0.5}};
  const json r_off = RunImuCase(off, through, &s);
  ASSERT_TRUE(s.ok()) << s.ToString();
  json off_config = {{"method", "imu"}};
  off_config.update(through);
  const std::vector<std::string> implausible =
      GateReasons("imu", r_off, off_config, {{"implausible_factor", 1.2}});
  ASSERT_TRUE(AnyContains(implausible, "times the nominal")) << Join(implausible);
  Append(&messages, implausible);
  // Statics shorter than min_static: refused, listing the detection's thresholds and stretches.
  RunImuCase(sim, {{"min_static", 1e4}}, &s);
  ASSERT_FALSE(s.ok());
  ASSERT_NE(s.message().find("static detection (static_window"), std::string::npos) << s.message();
  messages.push_back(s.message());
  EXPECT_GE(ExpectUnitsInMessages(messages), 8) << Join(messages);
}

// ---- noise ----

// `csv` with column `name` replaced by `value` in every row.
std::string WithConstantColumn(const std::string& csv, const std::string& name, double value) {
  std::istringstream in(csv);
  std::string line, out;
  int column = -1;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::string cell;
    std::istringstream row(line);
    while (std::getline(row, cell, ',')) cells.push_back(cell);
    if (column < 0) {
      for (size_t i = 0; i < cells.size(); ++i)
        if (cells[i] == name) column = static_cast<int>(i);
    } else if (static_cast<size_t>(column) < cells.size() && !line.empty() && line[0] != '#') {
      cells[static_cast<size_t>(column)] = std::to_string(value);
    }
    for (size_t i = 0; i < cells.size(); ++i) out += (i ? "," : "") + cells[i];
    out += "\n";
  }
  EXPECT_GE(column, 0) << name;
  return out;
}

TEST(UnitsInResults, Noise) {
  NoiseSimulationFileOptions sim;
  sim.seconds = 120;  // too short for the random walk: warnings with the log length it needs
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  csv = WithConstantColumn(csv, "a0_z", 9.81);
  const Status s = Calibrate(csv, "noise.csv", config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  std::vector<std::string> messages = Warnings(result);
  ASSERT_TRUE(AnyContains(messages, "random_walk not visible")) << result["warnings"].dump();
  ASSERT_TRUE(AnyContains(messages, "a0_z: every sample is 9.81 m/s^2"))
      << result["warnings"].dump();
  for (const json& c : result["diagnostics"]["channels"]) {
    EXPECT_EQ(c["unit"], c["name"].get<std::string>()[0] == 'a' ? "m/s^2" : "rad/s") << c.dump();
    if (!c["reason"].get<std::string>().empty()) messages.push_back(c["reason"]);
  }
  for (const json& c : result["diagnostics"]["allan"])
    EXPECT_EQ(c["unit"], c["name"].get<std::string>()[0] == 'a' ? "m/s^2" : "rad/s") << c.dump();
  Append(&messages, GateReasons("noise", result, config,
                                {{"max_white_noise_std", 1e-9},
                                 {"max_accel_white_noise", 1e-12},
                                 {"max_gyro_white_noise", 1e-12}}));
  EXPECT_GE(ExpectUnitsInMessages(messages), 6) << Join(messages);
  ExpectUnitsInDiagnostics(result["diagnostics"], {"rate_unit", "duration_unit"});
}

// ---- array ----

TEST(UnitsInResults, ArrayPositions) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  // Both noise levels configured 10× too high: the estimates from the residuals differ.
  config["accel_noise"] = 10 * so.accel_noise;
  config["gyro_noise"] = 10 * so.gyro_noise_dps;
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const std::vector<std::string> w = Warnings(result);
  ASSERT_TRUE(AnyContains(w, "gyroscope noise estimated")) << result["warnings"].dump();
  // In the config's gyro_unit, as the diagnostics are.
  EXPECT_TRUE(AnyContains(w, " deg/s) differs from the configured ")) << result["warnings"].dump();
  // The gate: residuals against the configured noise, position σ and offset.
  config["accel_noise"] = so.accel_noise / 10;
  config["gyro_noise"] = so.gyro_noise_dps / 10;
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &result).ok());
  const std::vector<std::string> reasons =
      GateReasons("array", result, config,
                  {{"max_chi2", 1.5}, {"max_position_std", 1e-12}, {"max_offset", 1e-12}});
  ASSERT_TRUE(AnyContains(reasons, "times the configured noise")) << Join(reasons);
  std::vector<std::string> messages = w;
  Append(&messages, reasons);
  EXPECT_GE(ExpectUnitsInMessages(messages), 6) << Join(messages);
  EXPECT_EQ(result["diagnostics"]["accel_unit"], "m/s^2");
  EXPECT_EQ(result["diagnostics"]["gyro_unit"], "deg/s");
  ExpectUnitsInDiagnostics(result["diagnostics"], {"accel_unit", "units", "excitation.units"});
}

TEST(UnitsInResults, ArrayFull) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 9;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  // The accelerometer noise configured a tenth of the true one: the residual-aware σ's warning
  // and the dynamic samples' own weights.
  config["accel_noise"] = so.accel_noise / 10;
  config["dynamic_weighting"] = "residual";
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const std::vector<std::string> w = Warnings(result);
  ASSERT_TRUE(AnyContains(w, "residual-aware sandwich")) << result["warnings"].dump();
  EXPECT_TRUE(AnyContains(w, " deg/s against noise ")) << result["warnings"].dump();
  EXPECT_FALSE(AnyContains(w, " rad/s")) << result["warnings"].dump();
  std::vector<std::string> messages = w;
  Append(&messages, GateReasons("array", result, config,
                                {{"scale_range", 1e-7},
                                 {"max_scale_std", 1e-12},
                                 {"max_axis_std", 1e-12},
                                 {"max_accel_bias_std", 1e-12},
                                 {"max_gyro_bias_std", 1e-12},
                                 {"max_accel_bias", 1e-12},
                                 {"max_gyro_bias", 1e-12},
                                 {"max_position_std", 1e-12}}));
  Append(&messages, GateReasons("array", result, config, {{"implausible_factor", 1.000001}}));
  EXPECT_GE(ExpectUnitsInMessages(messages), 6) << Join(messages);
  ExpectUnitsInDiagnostics(result["diagnostics"], {"accel_unit", "units"});
}

TEST(UnitsInResults, TheGyroscopeMessageUnitIsValidatedNamingIt) {
  core::ArrayOptions positions;
  positions.accel_noise = positions.gyro_noise = 1;
  std::string error;
  ASSERT_TRUE(positions.IsValid(&error)) << error;
  EXPECT_EQ(positions.gyro_message_unit.Quote(core::kDegree * 0.5), "0.00873 rad/s");
  positions.gyro_message_unit = {"deg/s", core::kDegree};
  EXPECT_EQ(positions.gyro_message_unit.Quote(core::kDegree * 0.5), "0.5 deg/s");
  positions.gyro_message_unit.rad_per_unit = 0;
  EXPECT_FALSE(positions.IsValid(&error));
  EXPECT_NE(error.find("gyro_message_unit"), std::string::npos) << error;
  core::ArrayFullOptions full;
  full.gyro_message_unit.name.clear();
  EXPECT_FALSE(full.IsValid(&error));
  EXPECT_NE(error.find("gyro_message_unit"), std::string::npos) << error;
}

}  // namespace
}  // namespace calibd::server
