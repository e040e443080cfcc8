// The mag method end to end through the CSV reader (mK_* columns) and Method::Run: config errors
// naming the key, the SPEC §8 result keys, recovery of a simulated truth within its σ, disturbed
// spans, the gate's refusals (poor coverage naming the missing directions, a field implausible
// for the Earth), and the firmware files applied as the firmwares apply them:
//   ArduPilot (libraries/AP_Compass/AP_Compass_Backend.cpp, correct_field):
//     mag += offsets; mag = [DIA ODI] * mag   (milligauss)
//   PX4 (src/lib/sensor_calibration/Magnetometer.hpp, Correct):
//     _rotation * (_scale * (data - _offset))  (gauss; _scale from SCALE and ODIAG)
// Also CK-Explorer's public acc+mag log (tests/core/mag_data_test.cc; skips when absent).
#include "methods/mag/mag_method.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>
#include <sstream>

#include "tests/lib/mag_public_log.h"

namespace calibd::server {
namespace {

using nlohmann::json;

Status RunMag(const std::string& csv, const json& config, json* result) {
  RecordingParser parser("mag.csv", true);
  const Status s = ParseRecording(csv, &parser);
  if (!s.ok()) return s;
  return MagMethod().Run(&parser, config, RunContext{}, result);
}

Verdict Judge(const json& result, const json& config) {
  Verdict v;
  MagMethod().Judge(result, config, EffectiveAcceptance("mag", json(), json::object()), &v);
  return v;
}

std::string Reasons(const Verdict& v) {
  std::string out;
  for (const std::string& r : v.reasons()) out += r + "\n";
  return out;
}

struct Simulated {
  std::string csv;
  json config, truth, result;
  Status status;
};

Simulated Simulate(const core::MagSimulationOptions& o) {
  Simulated s;
  EXPECT_TRUE(SimulateMagFiles(o, &s.csv, &s.config, &s.truth).ok());
  s.status = RunMag(s.csv, s.config, &s.result);
  return s;
}

TEST(MagMethod, ConfigErrorsNameTheKey) {
  const struct {
    json config;
    const char* field;
  } cases[] = {
      {{{"method", "mag"}, {"mag_unit", "tesla"}}, "mag_unit"},
      {{{"method", "mag"}, {"mag_unit", -2}}, "mag_unit"},
      {{{"method", "mag"}, {"field", -50}}, "field"},
      {{{"method", "mag"}, {"field", "50"}}, "field"},
      {{{"method", "mag"}, {"static_window", 0}}, "static_window"},
      {{{"method", "mag"}, {"colour", "red"}}, "colour"},
      {{{"method", "mag"}, {"device_id", "MMC5983"}}, "device_id"},
      {{{"method", "mag"}, {"device_id", {1, -2}}}, "device_id"},
  };
  for (const auto& c : cases) {
    const Status s = MagMethod().ValidateConfig(c.config);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << c.config.dump();
    EXPECT_EQ(s.field(), c.field) << s.message();
    EXPECT_EQ(s.reason(), Reason::kInvalidConfig);
  }
  for (const json& unit : {json("uT"), json("gauss"), json("mG"), json("nT"), json(0.15)}) {
    EXPECT_TRUE(MagMethod().ValidateConfig({{"method", "mag"}, {"mag_unit", unit}}).ok());
  }
  json result;
  const Status s =
      RunMag("t,a0_x,a0_y,a0_z\n0,0,0,9.8\n0.01,0,0,9.8\n", {{"method", "mag"}}, &result);
  EXPECT_EQ(s.reason(), Reason::kInvalidRecording);
  EXPECT_NE(s.message().find("m0_x"), std::string::npos) << s.message();
}

// Over seeds, the hard iron, soft iron and dip lie within their σ of the truth (z RMS near 1: a
// σ too small by 2× gives z RMS 2, which the bound 1.6 over 3 × 9 + 1 values per log × 6 logs
// excludes), the result has SPEC §8's keys, and the gate accepts.
TEST(MagMethod, RecoversTheSimulatedTruthWithinItsSigmaAndAccepts) {
  double z2 = 0;
  int n = 0;
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    core::MagSimulationOptions o;
    o.seed = seed;
    o.turns = 60;
    const Simulated s = Simulate(o);
    ASSERT_TRUE(s.status.ok()) << s.status.ToString();
    const json& p = s.result.at("parameters").at("mags").at(0);
    const json& u = s.result.at("uncertainty").at("mags").at(0);
    ASSERT_EQ(p.at("name"), "m0");
    for (const char* key :
         {"hard_iron", "soft_iron", "alignment", "dip", "field", "field_estimate"}) {
      EXPECT_TRUE(p.contains(key)) << key;
    }
    for (const char* key : {"hard_iron_std", "soft_iron_std", "alignment_std", "dip_std"}) {
      EXPECT_TRUE(u.contains(key)) << key;
      EXPECT_TRUE(u.at("crb").contains(key)) << key;
    }
    EXPECT_TRUE(s.result.at("uncertainty").contains("basis"));
    for (int a = 0; a < 3; ++a) {
      const double z = (p["hard_iron"][a].get<double>() - s.truth["hard_iron"][a].get<double>()) /
                       u["hard_iron_std"][a].get<double>();
      z2 += z * z;
      ++n;
      for (int c = 0; c < 3; ++c) {
        const double zs =
            (p["soft_iron"][a][c].get<double>() - s.truth["soft_iron"][a][c].get<double>()) /
            u["soft_iron_std"][a][c].get<double>();
        z2 += zs * zs;
        ++n;
      }
    }
    const double zd =
        (p["dip"].get<double>() - s.truth["dip"].get<double>()) / u["dip_std"].get<double>();
    z2 += zd * zd;
    ++n;
    const Verdict v = Judge(s.result, s.config);
    EXPECT_TRUE(v.accepted()) << Reasons(v);
    const json& d = s.result.at("diagnostics").at("mags").at(0);
    EXPECT_LT(d.at("chi2").get<double>(), 2);  // white noise: the residual is the sensor's noise
    EXPECT_LE(d.at("plot").at("t").size(), static_cast<size_t>(kMagPlotPoints));
    // The sandwich's blocking: batch lengths doubling from 2 s; white noise reaches a plateau.
    const json& blocking = d.at("blocking");
    ASSERT_GE(blocking.size(), 2u) << d.dump();
    for (size_t i = 1; i < blocking.size(); ++i) {
      EXPECT_DOUBLE_EQ(blocking[i]["seconds"].get<double>(),
                       2 * blocking[i - 1]["seconds"].get<double>());
      EXPECT_LT(blocking[i]["batches"].get<int64_t>(), blocking[i - 1]["batches"].get<int64_t>());
    }
    // White noise: a plateau, no warning, no wander. (On these 114 s logs the last step has 15
    // batches, whose sandwich runs ~20 % high, and seed 2 grows 1.42× there, over
    // plateau_growth: σ is the bound, so core/mag.cc's CheckPlateau does not judge it. This
    // fails if it did.)
    EXPECT_TRUE(d.at("plateau").get<bool>()) << blocking.dump();
    EXPECT_EQ(s.result.at("warnings").dump().find("no plateau"), std::string::npos);
    const json& wander = d.at("wander");
    EXPECT_EQ(wander.at("rate_unit"), "uT/sqrt(s)");
    EXPECT_FALSE(wander.at("included").get<bool>());
    EXPECT_TRUE(wander.at("rate").is_null());
  }
  const double z_rms = std::sqrt(z2 / n);
  EXPECT_GT(z_rms, 0.6);
  EXPECT_LT(z_rms, 1.6);
}

TEST(MagMethod, ADisturbedSpanIsFoundAndTheHardIronStaysPut) {
  core::MagSimulationOptions o;
  o.disturbances.push_back({40, 43, Eigen::Vector3d(15, -5, 8)});
  const Simulated s = Simulate(o);
  ASSERT_TRUE(s.status.ok()) << s.status.ToString();
  const json& spans = s.result["diagnostics"]["mags"][0]["disturbed_spans"];
  ASSERT_FALSE(spans.empty());
  bool covered = false;
  for (const json& span : spans) {
    covered |= span["start"].get<double>() < 43 && span["end"].get<double>() > 40;
  }
  EXPECT_TRUE(covered) << spans.dump();
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(s.result["parameters"]["mags"][0]["hard_iron"][a].get<double>(),
                s.truth["hard_iron"][a].get<double>(), 0.2);
  }
}

TEST(MagMethod, PoorCoverageIsRefusedOrRejectedNamingTheMissingDirections) {
  core::MagSimulationOptions flat;
  flat.yaw_only = true;
  const Simulated yaw = Simulate(flat);
  EXPECT_EQ(yaw.status.reason(), Reason::kPoorOrientationCoverage) << yaw.status.ToString();
  EXPECT_NE(yaw.status.message().find("z"), std::string::npos) << yaw.status.message();
  EXPECT_EQ(yaw.result.value("usable", true), false);
  EXPECT_TRUE(yaw.result.contains(json::json_pointer("/diagnostics/mags/0/coverage")));
  core::MagSimulationOptions upright;
  upright.max_tilt = 50;  // never turned over: the field never comes near one end of an axis
  const Simulated tilted = Simulate(upright);
  ASSERT_TRUE(tilted.status.ok()) << tilted.status.ToString();
  const Verdict v = Judge(tilted.result, tilted.config);
  EXPECT_FALSE(v.accepted());
  const std::string why = Reasons(v);
  EXPECT_NE(why.find("orientations poorly covered"), std::string::npos) << why;
  EXPECT_NE(why.find("never came near"), std::string::npos) << why;
}

TEST(MagMethod, AFieldImplausibleForTheEarthIsRejectedWithTheUnitThatFits) {
  core::MagSimulationOptions o;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateMagFiles(o, &csv, &config, &truth).ok());
  config = {{"method", "mag"}, {"mag_unit", "gauss"}};  // the readings are in µT
  ASSERT_TRUE(RunMag(csv, config, &result).ok());
  EXPECT_TRUE(result["parameters"]["mags"][0]["field"].is_null());
  EXPECT_NEAR(result["parameters"]["mags"][0]["field_estimate"].get<double>(), 5000, 500);
  const std::string why = Reasons(Judge(result, config));
  EXPECT_NE(why.find("implausible"), std::string::npos) << why;
  EXPECT_NE(why.find("mag_unit \"uT\""), std::string::npos) << why;
}

// "NAME,VALUE" (ArduPilot) or "1<TAB>1<TAB>NAME<TAB>VALUE<TAB>TYPE" (QGroundControl) lines.
std::map<std::string, double> ReadParams(const std::string& text) {
  std::map<std::string, double> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (line.find('\t') != std::string::npos) {
      std::istringstream f(line);
      std::string v, c, name, value;
      std::getline(f, v, '\t');
      std::getline(f, c, '\t');
      std::getline(f, name, '\t');
      std::getline(f, value, '\t');
      out[name] = std::stod(value);
    } else {
      out[line.substr(0, line.find(','))] = std::stod(line.substr(line.find(',') + 1));
    }
  }
  return out;
}

// ArduPilot's matrix (AP_Compass_Backend.cpp): diagonals, offdiagonals x = 01, y = 02, z = 12.
Eigen::Matrix3d ArduPilotMatrix(const std::map<std::string, double>& p) {
  auto at = [&](const char* k) { return p.at(k); };
  const double o0 = at("COMPASS_ODI_X"), o1 = at("COMPASS_ODI_Y"), o2 = at("COMPASS_ODI_Z");
  Eigen::Matrix3d m;
  m << at("COMPASS_DIA_X"), o0, o1, o0, at("COMPASS_DIA_Y"), o2, o1, o2, at("COMPASS_DIA_Z");
  return m;
}

// The files applied to raw readings as each firmware does give the calibrated field (P (y − h)
// in the firmware's unit), for a known and an unknown field.
TEST(MagMethod, FirmwareFilesReproduceTheCorrectionAsTheFirmwaresApplyIt) {
  core::MagSimulationOptions o;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateMagFiles(o, &csv, &config, &truth).ok());
  for (const json& cfg : {config, json{{"method", "mag"}}}) {
    json result;
    ASSERT_TRUE(RunMag(csv, cfg, &result).ok());
    const json& m = result["parameters"]["mags"][0];
    Eigen::Matrix3d p;
    Eigen::Vector3d h(m["hard_iron"][0].get<double>(), m["hard_iron"][1].get<double>(),
                      m["hard_iron"][2].get<double>());
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) p(r, c) = m["soft_iron_symmetric"][r][c].get<double>();
    }
    const double to_ut = cfg.contains("field") ? 1 : m["field_estimate"].get<double>();
    ExportContext context;
    std::string ap, px4, header, table;
    ASSERT_TRUE(MagMethod().Export("ardupilot", result, context, &ap).ok());
    ASSERT_TRUE(MagMethod().Export("px4", result, context, &px4).ok());
    ASSERT_TRUE(MagMethod().Export("h", result, context, &header).ok());
    ASSERT_TRUE(MagMethod().Export("csv", result, context, &table).ok());
    EXPECT_NE(ap.find("alignment is not carried"), std::string::npos) << ap;
    EXPECT_NE(header.find("_correct(const double raw[3]"), std::string::npos) << header;
    EXPECT_EQ(std::count(table.begin(), table.end(), '\n'), 2) << table;
    // Without config device_id the files say that the id must be set; with it, they carry it.
    EXPECT_NE(ap.find("# COMPASS_DEV_ID not written"), std::string::npos) << ap;
    EXPECT_NE(px4.find("# CAL_MAG0_ID not written"), std::string::npos) << px4;
    ExportContext with_id;
    with_id.config = {{"device_id", 7340553}};
    std::string ap_id, px4_id;
    ASSERT_TRUE(MagMethod().Export("ardupilot", result, with_id, &ap_id).ok());
    ASSERT_TRUE(MagMethod().Export("px4", result, with_id, &px4_id).ok());
    EXPECT_EQ(ReadParams(ap_id).at("COMPASS_DEV_ID"), 7340553) << ap_id;
    EXPECT_EQ(ReadParams(px4_id).at("CAL_MAG0_ID"), 7340553) << px4_id;
    json two_ids = cfg;
    two_ids["device_id"] = {7340553, 7340554};  // the log has one magnetometer
    json refused;
    const Status s = RunMag(csv, two_ids, &refused);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << s.ToString();
    EXPECT_NE(s.message().find("device_id has 2 entries"), std::string::npos) << s.message();
    const auto a = ReadParams(ap), x = ReadParams(px4);
    const Eigen::Matrix3d ap_m = ArduPilotMatrix(a);
    const Eigen::Vector3d ap_ofs(a.at("COMPASS_OFS_X"), a.at("COMPASS_OFS_Y"),
                                 a.at("COMPASS_OFS_Z"));
    Eigen::Matrix3d px_scale;  // Magnetometer.cpp ParametersUpdate: diag, then X=01, Y=02, Z=12
    const double xo = x.at("CAL_MAG0_XODIAG"), yo = x.at("CAL_MAG0_YODIAG"),
                 zo = x.at("CAL_MAG0_ZODIAG");
    px_scale << x.at("CAL_MAG0_XSCALE"), xo, yo, xo, x.at("CAL_MAG0_YSCALE"), zo, yo, zo,
        x.at("CAL_MAG0_ZSCALE");
    const Eigen::Vector3d px_off(x.at("CAL_MAG0_XOFF"), x.at("CAL_MAG0_YOFF"),
                                 x.at("CAL_MAG0_ZOFF"));
    std::istringstream rows(csv);
    std::string line;
    std::getline(rows, line);
    for (int i = 0; i < 200 && std::getline(rows, line); ++i) {
      double v[7];
      std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &v[0], &v[1], &v[2], &v[3], &v[4],
                  &v[5], &v[6]);
      const Eigen::Vector3d y(v[4], v[5], v[6]);                     // µT (mag_unit uT)
      const Eigen::Vector3d want = to_ut * p * (y - h);              // µT
      const Eigen::Vector3d ap_out = ap_m * (10 * y + ap_ofs);       // raw in mG
      const Eigen::Vector3d px_out = px_scale * (y / 100 - px_off);  // raw in gauss
      EXPECT_LT((ap_out / 10 - want).norm(), 1e-6 * want.norm()) << i;
      EXPECT_LT((px_out * 100 - want).norm(), 1e-6 * want.norm()) << i;
    }
  }
}

// CK-Explorer's acc+mag log (tests/core/mag_data_test.cc) through the method: gauss, a nominal
// 100 Hz; the field comes out in the Earth's range, the residual drops, the alignment is
// estimated from the holds.
TEST(MagMethod, ThePublicAccMagLogCalibratesThroughTheMethod) {
  const std::optional<std::string> public_log = calibd::testing::CkExplorerAccMagCsv();
  if (!public_log) GTEST_SKIP() << "acc_mag_log.csv absent (see tests/core/mag_data_test.cc)";
  const std::string& csv = *public_log;
  json result;
  const Status s = RunMag(csv, {{"method", "mag"}, {"mag_unit", "gauss"}}, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json& p = result["parameters"]["mags"][0];
  const json& d = result["diagnostics"]["mags"][0];
  const json& u = result["uncertainty"]["mags"][0];
  std::printf(
      "field %.2f uT, dip %.2f ± %.2f, |m| RMS %.3f -> %.3f uT, chi2 %.2f, basis %s (%.1f× the "
      "bound), alignment σ %s\n",
      p["field_estimate"].get<double>(), p["dip"].get<double>(), u["dip_std"].get<double>(),
      d["residual_rms_before"].get<double>(), d["residual_rms_clean"].get<double>(),
      d["chi2"].get<double>(), result["uncertainty"]["basis"].get<std::string>().c_str(),
      d["sandwich_ratio"].get<double>(), u["alignment_std"].dump().c_str());
  EXPECT_GT(p["field_estimate"].get<double>(), 20);
  EXPECT_LT(p["field_estimate"].get<double>(), 70);
  EXPECT_LT(d["residual_rms_clean"].get<double>(), d["residual_rms_before"].get<double>() / 3);
  EXPECT_TRUE(p["alignment"].is_array()) << d["alignment_note"];
  EXPECT_EQ(result["uncertainty"]["basis"], "sandwich");
  // Its offsets wander at every time scale (README, mag): no plateau, said in the diagnostics and
  // by a warning.
  EXPECT_FALSE(d["plateau"].get<bool>()) << d["blocking"].dump();
  EXPECT_NE(result["warnings"].dump().find("no plateau"), std::string::npos)
      << result["warnings"].dump();
  // So σ predicts the next log (core/mag.h step 3c), in the configured unit per √s.
  const json& wander = d["wander"];
  EXPECT_TRUE(wander["included"].get<bool>()) << wander.dump();
  EXPECT_EQ(wander["rate_unit"], "gauss/sqrt(s)");
  EXPECT_EQ(wander["segments"], 12);
  for (int a = 0; a < 3; ++a) EXPECT_GE(wander["rate"][a].get<double>(), 0);
  EXPECT_NE(result["warnings"].dump().find("σ predicts the next log"), std::string::npos);
}

}  // namespace
}  // namespace calibd::server
