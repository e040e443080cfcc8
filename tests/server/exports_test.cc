// The export functions (methods/exports.h) called directly on results of real calibrations of
// simulated recordings: the CSV round-trips every number exactly, an undefined σ is an empty cell
// (never 0), and Kalibr's imu.yaml has Kalibr's keys with each figure in Kalibr's unit.
#include "methods/exports.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "core/pca_simulation.h"
#include "methods/array/array_method.h"
#include "methods/noise/noise_method.h"
#include "methods/pca/pca_method.h"
#include "server/config.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// Rows of cells (no quoted fields in these exports: the simulated names are plain).
std::vector<std::vector<std::string>> ParseCsv(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> cells;
    std::string cell;
    std::istringstream l(line);
    while (std::getline(l, cell, ',')) cells.push_back(cell);
    if (!line.empty() && line.back() == ',') cells.push_back("");
    rows.push_back(cells);
  }
  return rows;
}

// The cell's number, exactly as written (%.17g round-trips a double); NaN when the cell is empty.
double Cell(const std::string& cell) {
  if (cell.empty()) return std::nan("");
  char* end = nullptr;
  const double v = std::strtod(cell.c_str(), &end);
  EXPECT_EQ(*end, '\0') << "not a number: " << cell;
  return v;
}

json PcaResult(uint64_t seed, double bias_std) {
  core::PcaSimulationOptions so;
  so.seed = seed;
  so.bias_std = bias_std;
  std::string csv;
  json config, truth, result;
  EXPECT_TRUE(SimulatePcaFiles(so, &csv, &config, &truth).ok());
  const Status s = Calibrate(csv, "pca.csv", config, &result);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

json ArrayResult() {
  ArraySimulationFileOptions so;
  so.seed = 11;
  std::string csv;
  json config, truth, result;
  EXPECT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  const Status s = Calibrate(csv, "array.csv", config, &result);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

// A stationary log at 50 Hz; `accel_random_walk` 4e-4 dominates from ~10-20 s on, so an hour
// shows every channel's random walk (the default 1e-4 needs longer).
json NoiseResult(double seconds, double accel_random_walk, json* truth) {
  NoiseSimulationFileOptions so;
  so.rate = 50;
  so.seconds = seconds;
  so.accel_random_walk = accel_random_walk;
  so.seed = 12;
  std::string csv;
  json config, result;
  EXPECT_TRUE(SimulateNoiseFiles(so, &csv, &config, truth).ok());
  const Status s = Calibrate(csv, "noise.csv", config, &result);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

// A JSON number equals the CSV cell bit for bit; a JSON null is an empty cell.
void ExpectSameNumber(const json& v, const std::string& cell, const std::string& what) {
  if (v.is_null()) {
    EXPECT_EQ(cell, "") << what << ": an undefined value must be an empty cell";
  } else {
    ASSERT_TRUE(v.is_number()) << what;
    EXPECT_EQ(Cell(cell), v.get<double>()) << what << ": cell " << cell;
  }
}

TEST(Exports, PcaCsvRoundTripsEveryNumberExactly) {
  const json r = PcaResult(21, 0.05);
  std::string csv;
  ASSERT_TRUE(ResultToCsv(r, &csv).ok());
  const auto rows = ParseCsv(csv);
  const std::vector<std::string> header = {
      "name",         "scale", "scale_std", "axis_x",        "axis_y",        "axis_z",
      "axis_std_rad", "bias",  "bias_std",  "sensitivity_x", "sensitivity_y", "sensitivity_z"};
  ASSERT_EQ(rows.size(), 13u) << csv;
  EXPECT_EQ(rows[0], header);
  const json& sensors = r["parameters"]["sensors"];
  const json& unc = r["uncertainty"]["sensors"];
  ASSERT_EQ(sensors.size(), 12u);
  for (size_t i = 0; i < 12; ++i) {
    const auto& row = rows[i + 1];
    ASSERT_EQ(row.size(), header.size()) << csv;
    const json& s = sensors[i];
    const json& u = unc[i];
    const std::string at = "sensor " + std::to_string(i);
    EXPECT_EQ(row[0], s["name"].get<std::string>());
    ExpectSameNumber(s["scale"], row[1], at + " scale");
    ExpectSameNumber(u["scale_std"], row[2], at + " scale_std");
    for (int k = 0; k < 3; ++k) ExpectSameNumber(s["axis"][k], row[3 + k], at + " axis");
    ExpectSameNumber(u["axis_std_rad"], row[6], at + " axis_std_rad");
    ExpectSameNumber(s["bias"], row[7], at + " bias");
    ExpectSameNumber(u["bias_std"], row[8], at + " bias_std");
    for (int k = 0; k < 3; ++k)
      ExpectSameNumber(s["sensitivity"][k], row[9 + k], at + " sensitivity");
    // Estimated biases: every σ is defined and positive here.
    EXPECT_GT(Cell(row[2]), 0);
    EXPECT_GT(Cell(row[8]), 0);
  }
}

TEST(Exports, ArrayCsvRoundTripsPositionsOffsetsAndStd) {
  const json r = ArrayResult();
  std::string csv;
  ASSERT_TRUE(ResultToCsv(r, &csv).ok());
  const auto rows = ParseCsv(csv);
  const json& positions = r["parameters"]["positions"];
  const json& unc = r["uncertainty"]["positions"];
  ASSERT_EQ(rows.size(), positions.size() + 1) << csv;
  EXPECT_EQ(rows[0], (std::vector<std::string>{"name", "x", "y", "z", "offset_x", "offset_y",
                                               "offset_z", "std_x", "std_y", "std_z"}));
  for (size_t i = 0; i < positions.size(); ++i) {
    const auto& row = rows[i + 1];
    ASSERT_EQ(row.size(), 10u);
    const std::string at = positions[i]["name"].get<std::string>();
    EXPECT_EQ(row[0], at);
    for (int k = 0; k < 3; ++k) {
      ExpectSameNumber(positions[i]["position"][k], row[1 + k], at + " position");
      ExpectSameNumber(positions[i]["offset"][k], row[4 + k], at + " offset");
      ExpectSameNumber(unc[i]["std"][k], row[7 + k], at + " std");
    }
  }
}

TEST(Exports, UndefinedSigmaIsAnEmptyCellNeverZero) {
  // A stored result states an undefined σ as null (e.g. a parameter the data cannot show).
  json r = PcaResult(22, 0.05);
  r["uncertainty"]["sensors"][3]["scale_std"] = nullptr;
  r["uncertainty"]["sensors"][3]["bias_std"] = nullptr;
  std::string csv;
  ASSERT_TRUE(ResultToCsv(r, &csv).ok());
  const auto rows = ParseCsv(csv);
  ASSERT_EQ(rows.size(), 13u);
  EXPECT_EQ(rows[4][2], "") << csv;  // sensor 3: scale_std
  EXPECT_EQ(rows[4][8], "") << csv;  // bias_std
  EXPECT_GT(Cell(rows[5][2]), 0);    // its neighbour keeps its σ
  // The header omits it (with a comment) instead of writing 0.
  std::string header;
  ExportContext context{7, "SN-1", "pca", "2026-11-24T00:00:00Z"};
  ASSERT_TRUE(ResultToHeader(r, context, &header).ok());
  std::string defined;
  ASSERT_TRUE(ResultToHeader(PcaResult(22, 0.05), context, &defined).ok());
  EXPECT_NE(defined.find("SCALE_STD["), std::string::npos) << defined;
  EXPECT_NE(defined.find("BIAS_STD["), std::string::npos) << defined;
  EXPECT_EQ(header.find("SCALE_STD["), std::string::npos) << header;
  EXPECT_EQ(header.find("BIAS_STD["), std::string::npos) << header;
  const std::string name = r["parameters"]["sensors"][3]["name"];
  EXPECT_NE(header.find("SCALE_STD is not written: scale_std is undefined for " + name),
            std::string::npos)
      << header;

  // A real undefined σ: a noise log of 2 minutes cannot show the random walk (crossing ~35 s
  // would need many times that), and its CSV cells stay empty.
  json truth;
  const json noise = NoiseResult(120, 1e-4, &truth);
  ASSERT_TRUE(ResultToCsv(noise, &csv).ok());
  const auto nrows = ParseCsv(csv);
  ASSERT_EQ(nrows[0][7], "random_walk");
  ASSERT_EQ(nrows[0][8], "random_walk_std");
  int undefined = 0;
  for (size_t i = 1; i < nrows.size(); ++i) {
    const json& c = noise["parameters"]["channels"][i - 1];
    const json& u = noise["uncertainty"]["channels"][i - 1];
    ExpectSameNumber(c["white_noise"], nrows[i][2], "white_noise");
    ExpectSameNumber(u["white_noise_std"], nrows[i][3], "white_noise_std");
    ExpectSameNumber(c["random_walk"], nrows[i][7], "random_walk");
    ExpectSameNumber(u["random_walk_std"], nrows[i][8], "random_walk_std");
    for (size_t k = 2; k < nrows[i].size(); ++k) {
      EXPECT_NE(nrows[i][k], "0") << csv;
      EXPECT_NE(nrows[i][k], "0.0") << csv;
    }
    undefined += c["random_walk"].is_null();
  }
  EXPECT_GT(undefined, 0) << "the short log was meant to leave a random walk undefined: " << csv;
  // ... and Kalibr's file, which needs every figure, is refused naming what is missing.
  std::string yaml;
  const Status s = ResultToKalibrYaml(noise, context, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_NE(s.message().find("random walk"), std::string::npos) << s.message();
}

TEST(Exports, KalibrYamlHasKalibrsKeysWithTheLargestAxisInKalibrsUnits) {
  json truth;
  const json r = NoiseResult(3600, 4e-4, &truth);
  std::string yaml;
  ExportContext context{9, "IMU-N1", "noise", "2026-11-24T00:00:00Z"};
  const Status s = ResultToKalibrYaml(r, context, &yaml);
  ASSERT_TRUE(s.ok()) << s.ToString();
  // key: value  # unit, axis
  std::map<std::string, std::pair<double, std::string>> entries;
  std::istringstream in(yaml);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    const size_t colon = line.find(": ");
    ASSERT_NE(colon, std::string::npos) << line;
    const std::string key = line.substr(0, colon);
    const size_t hash = line.find("  # ");
    const std::string value =
        line.substr(colon + 2, hash == std::string::npos ? std::string::npos : hash - colon - 2);
    const std::string comment = hash == std::string::npos ? "" : line.substr(hash + 4);
    entries[key] = {key == "rostopic" ? 0.0 : Cell(value), comment};
  }
  for (const char* key :
       {"accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
        "gyroscope_random_walk", "update_rate", "rostopic"}) {
    EXPECT_EQ(entries.count(key), 1u) << key << "\n" << yaml;
  }
  EXPECT_EQ(entries.size(), 6u) << yaml;
  // Each figure is the largest over the sensor's three axes, exactly, and its unit is Kalibr's
  // (continuous-time density: per √Hz).
  auto largest = [&](char type, const char* key) {
    double best = -1;
    for (const json& c : r["parameters"]["channels"])
      if (c["name"].get<std::string>()[0] == type) best = std::max(best, c[key].get<double>());
    return best;
  };
  EXPECT_EQ(entries["accelerometer_noise_density"].first, largest('a', "white_noise"));
  EXPECT_EQ(entries["accelerometer_random_walk"].first, largest('a', "random_walk"));
  EXPECT_EQ(entries["gyroscope_noise_density"].first, largest('g', "white_noise"));
  EXPECT_EQ(entries["gyroscope_random_walk"].first, largest('g', "random_walk"));
  EXPECT_EQ(entries["accelerometer_noise_density"].second.rfind("m/s^2/sqrt(Hz), a0_", 0), 0u);
  EXPECT_EQ(entries["accelerometer_random_walk"].second.rfind("m/s^3/sqrt(Hz), a0_", 0), 0u);
  EXPECT_EQ(entries["gyroscope_noise_density"].second.rfind("rad/s/sqrt(Hz), g0_", 0), 0u);
  EXPECT_EQ(entries["gyroscope_random_walk"].second.rfind("rad/s^2/sqrt(Hz), g0_", 0), 0u);
  // The values are the simulated densities in those units (an hour: N within a few percent, K
  // within a factor well under 2; a unit slip such as deg for rad, or a per-sample σ for a
  // density, is off by 57× or 7×).
  const double n_a = truth["channels"][0]["white_noise"], k_a = truth["channels"][0]["random_walk"];
  const double n_g = truth["channels"][3]["white_noise"], k_g = truth["channels"][3]["random_walk"];
  EXPECT_NEAR(entries["accelerometer_noise_density"].first, n_a, 0.05 * n_a);
  EXPECT_NEAR(entries["gyroscope_noise_density"].first, n_g, 0.05 * n_g);
  EXPECT_NEAR(entries["accelerometer_random_walk"].first, k_a, 0.5 * k_a);
  EXPECT_NEAR(entries["gyroscope_random_walk"].first, k_g, 0.5 * k_g);
  // The measured rate to its precision (6 significant digits), not 100.01013117051603.
  const double rate = r["diagnostics"]["rate"].get<double>();
  EXPECT_NEAR(entries["update_rate"].first, rate, 5e-6 * rate);
  EXPECT_NEAR(entries["update_rate"].first, 50, 1e-6);
  EXPECT_NE(yaml.find("update_rate: 50.0  # Hz"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("noise job 9 of device 'IMU-N1'"), std::string::npos) << yaml;
}

// A parameter value that is undefined in a stored result is never written as a number a device
// would apply: the C header of a pca result with a null bias, and Kalibr's file of a noise result
// without a rate, are refused naming what is missing (the CSV keeps the empty cell).
TEST(Exports, AnUndefinedParameterIsRefusedNeverWrittenAsZero) {
  json r = PcaResult(24, 0.05);
  r["parameters"]["sensors"][2]["bias"] = nullptr;
  const std::string name = r["parameters"]["sensors"][2]["name"];
  std::string out;
  ExportContext context{7, "SN-1", "pca", "2026-11-24T00:00:00Z"};
  Status s = ResultToHeader(r, context, &out);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_NE(s.message().find("sensor '" + name + "' has undefined parameters"), std::string::npos)
      << s.message();
  ASSERT_TRUE(ResultToCsv(r, &out).ok());
  EXPECT_EQ(ParseCsv(out)[3][7], "") << out;  // sensor 2's bias cell
  json truth;
  json noise = NoiseResult(3600, 4e-4, &truth);
  ASSERT_TRUE(ResultToKalibrYaml(noise, context, &out).ok());
  noise["diagnostics"]["rate"] = nullptr;
  s = ResultToKalibrYaml(noise, context, &out);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_NE(s.message().find("update_rate"), std::string::npos) << s.message();
}

TEST(Exports, KalibrYamlIsOnlyForNoiseResults) {
  std::string yaml;
  const Status s = ResultToKalibrYaml(PcaResult(23, 0), ExportContext{}, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("noise"), std::string::npos) << s.message();
  EXPECT_EQ(yaml, "");
}

// Issue 27: names are the user's text (CSV headers of the recording): one a spreadsheet would run
// as a formula is written with a leading apostrophe (OWASP CSV injection); plain names as they are.
TEST(Exports, NamesThatASpreadsheetWouldRunAsFormulasAreNeutralised) {
  json r = PcaResult(21, 0.05);
  const std::vector<std::string> names = {"=HYPERLINK(\"x\")", "+1",    "-2",
                                          "@SUM(A1)",          "\tcmd", "a0_x"};
  json& sensors = r["parameters"]["sensors"];
  json& unc = r["uncertainty"]["sensors"];
  for (size_t i = 0; i < names.size(); ++i) {
    sensors[i]["name"] = names[i];
    unc[i]["name"] = names[i];
  }
  std::string csv;
  ASSERT_TRUE(ResultToCsv(r, &csv).ok());
  const auto rows = ParseCsv(csv);
  ASSERT_GE(rows.size(), names.size() + 1);
  EXPECT_EQ(rows[1][0], "\"'=HYPERLINK(\"\"x\"\")\"");  // quoted: it holds a quote
  EXPECT_EQ(rows[2][0], "'+1");
  EXPECT_EQ(rows[3][0], "'-2");
  EXPECT_EQ(rows[4][0], "'@SUM(A1)");
  EXPECT_EQ(rows[5][0], "'\tcmd");
  EXPECT_EQ(rows[6][0], "a0_x");
  // Negative numbers in number cells are numbers, not formulas: untouched.
  for (size_t i = 1; i < rows.size(); ++i) {
    for (size_t c = 1; c < rows[i].size(); ++c) EXPECT_NE(rows[i][c].rfind("'", 0), 0u);
  }
}

// Issue 27: a negative zero (a product, a rotation's entry) is written as 0, in CSV and C.
TEST(Exports, NegativeZeroIsWrittenAsZero) {
  json r = PcaResult(21, 0.05);
  r["parameters"]["sensors"][0]["axis"][1] = -0.0;
  std::string csv, header;
  ASSERT_TRUE(ResultToCsv(r, &csv).ok());
  EXPECT_EQ(ParseCsv(csv)[1][4], "0");
  ASSERT_TRUE(
      ResultToHeader(r, ExportContext{7, "SN-1", "pca", "2026-11-24T00:00:00Z"}, &header).ok());
  // A negative zero literal: "-0.0" not followed by another digit (-0.01 is a number).
  EXPECT_FALSE(std::regex_search(header, std::regex("-0\\.0[^0-9eE]"))) << header;
  EXPECT_NE(header.find("0.0"), std::string::npos);
}

// Issue 27: a log too short to show the random walk of one axis still exports Kalibr's file: the
// largest of the axes that show it, with a comment naming the one that does not. Only when no
// axis of a sensor shows a figure is the file refused.
TEST(Exports, KalibrYamlWritesWhatTheAxesShowAndNamesTheOneThatIsShort) {
  json truth;
  json r = NoiseResult(3600, 4e-4, &truth);
  for (json& c : r["parameters"]["channels"]) {
    if (c["name"] == "a0_z") c["random_walk"] = nullptr;
  }
  for (json& u : r["uncertainty"]["channels"]) {
    if (u["name"] == "a0_z") u["random_walk_std"] = nullptr;
  }
  const ExportContext context{9, "IMU-N1", "noise", "2026-11-24T00:00:00Z"};
  std::string yaml;
  Status s = ResultToKalibrYaml(r, context, &yaml);
  ASSERT_TRUE(s.ok()) << s.ToString();
  double largest = -1;
  for (const json& c : r["parameters"]["channels"]) {
    if (c["name"] != "a0_z" && c["name"].get<std::string>()[0] == 'a') {
      largest = std::max(largest, c["random_walk"].get<double>());
    }
  }
  const size_t at = yaml.find("accelerometer_random_walk: ");
  ASSERT_NE(at, std::string::npos) << yaml;
  const std::string line = yaml.substr(at, yaml.find('\n', at) - at);
  EXPECT_EQ(Cell(line.substr(27, line.find("  #") - 27)), largest) << line;
  EXPECT_NE(line.find("does not show the random walk of a0_z"), std::string::npos) << line;
  // No accelerometer axis shows it: refused, naming them.
  for (json& c : r["parameters"]["channels"]) {
    if (c["name"].get<std::string>()[0] == 'a') c["random_walk"] = nullptr;
  }
  s = ResultToKalibrYaml(r, context, &yaml);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_NE(s.message().find("a0_x, a0_y, a0_z"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::server
