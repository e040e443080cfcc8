// GET /api/v1/recordings/{id}/check (SPEC §10, issue #27 item 2) on a real server: the check's
// statics and saturation counts are the imu job's (same count, bounds and pinned samples), a
// millisecond time column, an accelerometer in g and a gyroscope in deg/s declared as SI are
// named, and bad requests are refused naming what. Real data, skipped when absent: imu_tk's Xsens
// recording ($CALIBD_IMU_TK_DATA, default /work/data/imu_tk; statics agree with the imu job's)
// and the MIMU4444 recordings ($CALIBD_MIMU4444_DATA; the gyroscopes' saturation named).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

#include "core/array_full_simulation.h"
#include "core/imu_simulation.h"
#include "core/thermal_simulation.h"
#include "methods/imu/imu_method.h"
#include "methods/thermal/thermal_method.h"
#include "tests/lib/array_geometry.h"
#include "tests/lib/mimu4444.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

// An imu log as CSV: t times `t_scale`, accelerometer times `a_scale`, gyroscope times `g_scale`,
// the gyroscope clipped at ±clip (clip <= 0: not clipped).
std::string ImuCsv(const core::ImuSimulation& sim, double t_scale = 1, double a_scale = 1,
                   double g_scale = 1, double clip = 0) {
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (Eigen::Index i = 0; i < sim.t.size(); ++i) {
    double g[3];
    for (int a = 0; a < 3; ++a) {
      g[a] = sim.gyro(i, a) * g_scale;
      if (clip > 0) g[a] = std::min(std::max(g[a], -clip), clip);
    }
    std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n",
                  sim.t[i] * t_scale, sim.accel(i, 0) * a_scale, sim.accel(i, 1) * a_scale,
                  sim.accel(i, 2) * a_scale, g[0], g[1], g[2]);
    csv += line;
  }
  return csv;
}

core::ImuSimulation Simulated() {
  core::ImuSimulationOptions o;
  o.statics = 24;
  o.rotation_duration = 1;
  o.seed = 11;
  core::ImuSimulation sim;
  EXPECT_TRUE(core::SimulateImu(o, &sim).ok());
  return sim;
}

// Uploads `csv` without a method (a recording, no job); its id.
int64_t Store(const TestServer& server, const std::string& csv) {
  auto res = server.Client().Post("/api/v1/recordings", csv, "text/csv");
  if (!res || res->status != 201) {
    ADD_FAILURE() << "upload: " << (res ? std::to_string(res->status) + res->body : "no answer");
    return 0;
  }
  return json::parse(res->body).at("recording").at("id").get<int64_t>();
}

// GET the check; its status and JSON body.
int Check(const TestServer& server, const std::string& path, json* body) {
  auto res = server.Client().Get(path.c_str());
  if (!res) return 0;
  *body = json::parse(res->body, nullptr, false);
  return res->status;
}

// GET the check of `job`'s recording with that job's config (?job=ID); its status and body.
int CheckOfJob(const TestServer& server, const json& job, json* body) {
  return Check(server,
               "/api/v1/recordings/" + std::to_string(job.value("recording_id", int64_t{0})) +
                   "/check?job=" + std::to_string(job.value("id", int64_t{0})),
               body);
}

std::string Query(const json& config) {
  std::string q;
  for (const auto& [key, value] : config.items()) {
    q += (q.empty() ? "?" : "&") + key + "=" +
         httplib::detail::encode_query_param(value.is_string() ? value.get<std::string>()
                                                               : value.dump());
  }
  return q;
}

// The check and the job on the same recording with the same config: same statics (count and
// bounds) and the same saturation (per channel and rows). Returns the check.
json ExpectCheckAgreesWithJob(const TestServer& server, const std::string& csv, const json& config,
                              json* job_out = nullptr) {
  const json job = server.UploadAndWait(csv, config);
  if (job_out != nullptr) *job_out = job;
  EXPECT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 600);
  json check;
  EXPECT_EQ(CheckOfJob(server, job, &check), 200) << check.dump();
  const json& d = job.at("result").at("diagnostics");
  const json& statics = check.at("statics");
  EXPECT_EQ(statics.size(), d.at("statics").size());
  for (size_t i = 0; i < statics.size() && i < d.at("statics").size(); ++i) {
    EXPECT_EQ(statics[i].at("start"), d["statics"][i].at("start")) << i;
    EXPECT_EQ(statics[i].at("end"), d["statics"][i].at("end")) << i;
    EXPECT_EQ(statics[i].at("samples"), d["statics"][i].at("samples")) << i;
  }
  EXPECT_EQ(check.at("saturation").at("samples"), d.at("saturated_samples"));
  if (d.contains("saturation")) {
    EXPECT_EQ(check.at("saturation"), d.at("saturation"));
  } else {
    EXPECT_TRUE(check.at("saturation").at("channels").empty()) << check["saturation"].dump();
  }
  EXPECT_EQ(check.at("threshold_choice"), d.at("threshold_choice"));
  return check;
}

// Every σ of the check's prediction against the job's reported σ (its CRB, uncertainty.crb: on a
// log whose residuals exceed the noise the primary σ is the CRB χ²-scaled, which no prediction
// from the noise alone can know; uncertainty.imus[].crb): the ratios predicted / reported.
std::vector<double> PredictedOverReported(const json& check, const json& job) {
  std::vector<double> ratios;
  const json& predicted = check.at("predicted").at("uncertainty").at("imus");
  const json& reported = job.at("result").at("uncertainty").at("imus");
  EXPECT_EQ(predicted.size(), reported.size());
  for (size_t k = 0; k < predicted.size() && k < reported.size(); ++k) {
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json& p = predicted[k].at(sensor);
      const json& r = reported[k].at("crb").at(sensor);
      for (const char* key : {"bias_std", "scale_std"}) {
        for (int a = 0; a < 3; ++a)
          ratios.push_back(p[key][a].get<double>() / r[key][a].get<double>());
      }
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          const json& pm = p.at("misalignment_std")[i][j];
          const json& rm = r.at("misalignment_std")[i][j];
          if (pm.is_number() && rm.is_number() && rm.get<double>() > 0) {
            ratios.push_back(pm.get<double>() / rm.get<double>());
          }
        }
      }
    }
  }
  return ratios;
}

TEST(RecordingCheck, StaticsAndSaturationAreTheJobs) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  const core::ImuSimulation sim = Simulated();
  std::string unused;
  json config, truth;
  core::ImuSimulationOptions o;
  o.statics = 24;
  ASSERT_TRUE(SimulateImuFiles(o, &unused, &config, &truth).ok());
  // Clean: 24 statics, nothing pinned, every direction covered.
  json check = ExpectCheckAgreesWithJob(server, ImuCsv(sim), config);
  EXPECT_EQ(check.at("statics").size(), 24u);
  EXPECT_TRUE(check.at("coverage").at(0).at("sufficient").get<bool>()) << check["coverage"];
  EXPECT_TRUE(check.at("units").empty()) << check["units"];
  EXPECT_FALSE(check.contains("job_would_fail"));
  EXPECT_NEAR(check.at("timing").at("rate").get<double>(), 100, 1e-3);
  EXPECT_EQ(check.at("timing").at("gap_count"), 0);
  for (const json& s : check.at("statics")) {
    EXPECT_NEAR(s.at("accel_norm").get<double>(), 9.80665, 0.3) << s;  // a few % scale errors
  }
  // Clipped at 0.7 of the largest rate: the pinned samples are the job's, channel by channel.
  check = ExpectCheckAgreesWithJob(
      server, ImuCsv(sim, 1, 1, 1, 0.7 * sim.gyro.cwiseAbs().maxCoeff()), config);
  EXPECT_GT(check.at("saturation").at("samples").get<int64_t>(), 20);
  EXPECT_FALSE(check.at("saturation").at("channels").empty());
}

TEST(RecordingCheck, NamesMillisecondsGAndDegreesPerSecond) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  const core::ImuSimulation sim = Simulated();
  json check;
  // t in ms: named (the job would refuse it), no statics found on it.
  const int64_t ms = Store(server, ImuCsv(sim, 1000));
  ASSERT_EQ(Check(server, "/api/v1/recordings/" + std::to_string(ms) + "/check?method=imu", &check),
            200)
      << check.dump();
  ASSERT_EQ(check.at("units").size(), 1u) << check["units"];
  EXPECT_EQ(check["units"][0].at("quantity"), "time");
  EXPECT_EQ(check["units"][0].at("likely"), "ms");
  EXPECT_NE(check["units"][0].at("message").get<std::string>().find("milliseconds"),
            std::string::npos);
  EXPECT_TRUE(check.contains("job_would_fail"));
  EXPECT_TRUE(check.at("statics").is_null());
  // With time_unit the same log checks like the seconds one.
  ASSERT_EQ(
      Check(server, "/api/v1/recordings/" + std::to_string(ms) + "/check?method=imu&time_unit=ms",
            &check),
      200);
  EXPECT_TRUE(check.at("units").empty()) << check["units"];
  EXPECT_EQ(check.at("statics").size(), 24u);
  // Accelerometer in g and gyroscope in deg/s, declared as SI (the default).
  const int64_t g = Store(server, ImuCsv(sim, 1, 1 / 9.80665, 180 / M_PI));
  ASSERT_EQ(Check(server, "/api/v1/recordings/" + std::to_string(g) + "/check?method=imu", &check),
            200)
      << check.dump();
  ASSERT_EQ(check.at("units").size(), 2u) << check["units"];
  EXPECT_EQ(check["units"][0].at("quantity"), "accelerometer");
  EXPECT_EQ(check["units"][0].at("likely"), "g");
  EXPECT_EQ(check["units"][1].at("quantity"), "gyroscope");
  EXPECT_EQ(check["units"][1].at("likely"), "deg/s");
  // Declared right, nothing is named.
  ASSERT_EQ(Check(server,
                  "/api/v1/recordings/" + std::to_string(g) +
                      "/check?method=imu&accel_unit=g&gyro_unit=deg%2Fs",
                  &check),
            200);
  EXPECT_TRUE(check.at("units").empty()) << check["units"];
}

TEST(RecordingCheck, RefusesNamingWhat) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  const int64_t id = Store(server, ImuCsv(Simulated()));
  const std::string base = "/api/v1/recordings/" + std::to_string(id) + "/check";
  json body;
  EXPECT_EQ(Check(server, "/api/v1/recordings/999999/check?method=imu", &body), 404);
  EXPECT_EQ(Check(server, "/api/v1/recordings/x/check?method=imu", &body), 404);
  EXPECT_EQ(Check(server, base, &body), 400);
  EXPECT_EQ(body.at("error").value("field", ""), "method") << body;
  EXPECT_EQ(Check(server, base + "?method=nope", &body), 400);
  EXPECT_EQ(Check(server, base + "?method=pca", &body), 400);
  EXPECT_EQ(Check(server, base + "?method=imu&static_window=-1", &body), 400);
  EXPECT_EQ(body.at("error").value("field", ""), "static_window") << body;
  EXPECT_EQ(Check(server, base + "?method=imu&bogus=1", &body), 400);
  EXPECT_EQ(Check(server, base + "?job=77", &body), 404);
  EXPECT_EQ(Check(server, base + "?job=1&method=imu", &body), 400);
  // A method without statics gives timing and says what it leaves out.
  ASSERT_EQ(Check(server, base + "?method=noise", &body), 200) << body;
  EXPECT_TRUE(body.at("statics").is_null());
  EXPECT_TRUE(body.at("saturation").at("channels").empty()) << body;
  EXPECT_FALSE(body.at("notes").empty());
  EXPECT_NEAR(body.at("timing").at("rate").get<double>(), 100, 1e-3);
}

TEST(RecordingCheck, NoiseSaturationIsTheJobs) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  const core::ImuSimulation sim = Simulated();
  // A clipped log: the noise job refuses it naming the channels; the check names the same.
  const json job = server.UploadAndWait(ImuCsv(sim, 1, 1, 1, 0.7 * sim.gyro.cwiseAbs().maxCoeff()),
                                        {{"method", "noise"}});
  ASSERT_EQ(job.value("status", ""), "failed") << job.dump().substr(0, 400);
  json check;
  ASSERT_EQ(CheckOfJob(server, job, &check), 200) << check.dump();
  // The failed job keeps its partial diagnostics with its error.
  const json& sat = job.at("error").at("diagnostics").at("diagnostics").at("saturation");
  EXPECT_EQ(check.at("saturation"), sat);
  EXPECT_GT(sat.at("samples").get<int64_t>(), 20);
  EXPECT_NE(job.at("error").at("message").get<std::string>().find(
                check.at("job_would_fail").get<std::string>()),
            std::string::npos)
      << job.at("error") << check.at("job_would_fail");
}

// ----- Real data (skipped when absent).

// The check predicts the σ the job reports (issue #27: within 15 %), at the log's rate and at 4×
// it (the replay then runs at 100 Hz with the noise density kept: a replay at the same σ per
// sample would understate every σ by 2), with the noise from the statics (as the job takes it)
// and from the config. What differs between the two: the replay's IMU is nominal (the truth has
// 1 % scale and 5 mrad misalignment errors) and its noise realisation is another.
TEST(RecordingCheck, PredictedSigmaIsTheJobs) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  std::vector<double> all;
  for (const auto& [seed, rate, config_noise] : {std::tuple<int, double, bool>{21, 100, false},
                                                 {22, 400, false},
                                                 {23, 100, true},
                                                 {24, 400, true}}) {
    core::ImuSimulationOptions o;
    o.statics = 20;
    o.rate = rate;
    o.seed = static_cast<uint64_t>(seed);
    std::string csv;
    json config, truth;
    ASSERT_TRUE(SimulateImuFiles(o, &csv, &config, &truth).ok());
    if (config_noise) {
      config["accel_noise"] = o.accel_noise;
      config["gyro_noise"] = o.gyro_noise;
    }
    const json job = server.UploadAndWait(csv, config);
    ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 600);
    json check;
    ASSERT_EQ(CheckOfJob(server, job, &check), 200);
    const json& predicted = check.at("predicted");
    ASSERT_TRUE(predicted.at("uncertainty").is_object()) << predicted.dump();
    EXPECT_EQ(predicted.at("rate"), 100.0);
    EXPECT_EQ(predicted.at("noise").at(0).at("accel_source"), config_noise ? "config" : "statics");
    const std::vector<double> ratios = PredictedOverReported(check, job);
    EXPECT_EQ(ratios.size(), 21u);  // 6 + 6 per triad, T_a's 3 and T_g's 6 misalignments
    for (double r : ratios) {
      EXPECT_GT(r, 0.85) << "seed " << seed << ", " << rate << " Hz";
      EXPECT_LT(r, 1.15) << "seed " << seed << ", " << rate << " Hz";
      all.push_back(r);
    }
  }
  double sum = 0, max_dev = 0;
  for (double r : all) {
    sum += r;
    max_dev = std::max(max_dev, std::abs(r - 1));
  }
  std::printf("predicted / reported σ over %zu values: mean %.3f, largest deviation %.3f\n",
              all.size(), sum / static_cast<double>(all.size()), max_dev);
}

// The thermal checks' log: a 15-minute warm-up and a 10-minute cool-down, a cubic truth.
core::ThermalSimulationOptions WarmupAndCooldown() {
  core::ThermalSimulationOptions o;
  o.warmup = 900;
  o.cooldown = 600;
  o.coefficients = core::DefaultThermalTruth(3);
  return o;
}

// The thermal check (Method::Check: the job's stages 1 and 5, no fit): the windows, their
// temperature span and phase counts are the job's; a 4 °C warm-up is named as the job refuses it,
// with the range found.
TEST(RecordingCheck, ThermalWindowsAndRangeAreTheJobs) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  core::ThermalSimulationOptions o = WarmupAndCooldown();
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  const json job = server.UploadAndWait(csv, config);
  ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 600);
  json check;
  ASSERT_EQ(CheckOfJob(server, job, &check), 200) << check.dump();
  EXPECT_FALSE(check.contains("job_would_fail")) << check["job_would_fail"];
  const json& p = job.at("result").at("parameters").at("imus").at(0);
  const json& d = job.at("result").at("diagnostics").at("imus").at(0);
  const json& c = check.at("thermal").at("imus").at(0);
  EXPECT_EQ(c.at("t_min"), p.at("t_min"));
  EXPECT_EQ(c.at("t_max"), p.at("t_max"));
  EXPECT_EQ(c.at("windows").get<size_t>(), d.at("windows").size());
  EXPECT_EQ(c.at("heating_windows"), d.at("heating_windows"));
  EXPECT_EQ(c.at("cooling_windows"), d.at("cooling_windows"));
  EXPECT_GT(c.at("heating_windows").get<int>(), 3);
  EXPECT_GT(c.at("cooling_windows").get<int>(), 3);
  EXPECT_EQ(check.at("statics").size(), d.at("statics").get<size_t>());
  for (const json& st : check.at("statics")) {
    EXPECT_NEAR(st.at("accel_norm").get<double>(), 9.80665, 0.5) << st;
    EXPECT_TRUE(st.at("temperature").at(0).is_number()) << st;
  }
  EXPECT_EQ(check.at("temperature").at(0).at("name"), "temp0");

  // A 4 °C warm-up: the job refuses it naming the range, and so does the check.
  o.delta = 4;
  o.cooldown = 0;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  const json narrow = server.UploadAndWait(csv, config);
  ASSERT_EQ(narrow.value("status", ""), "failed") << narrow.dump().substr(0, 600);
  ASSERT_EQ(CheckOfJob(server, narrow, &check), 200) << check.dump();
  const std::string why = check.value("job_would_fail", "");
  EXPECT_NE(why.find("below min_range 10"), std::string::npos) << why;
  EXPECT_NE(narrow.at("error").at("message").get<std::string>().find(why), std::string::npos)
      << narrow["error"].dump() << " vs " << why;
  EXPECT_LT(check.at("thermal").at("imus").at(0).at("range").get<double>(), 4.5);
}

// The thermal check's predicted σ (PredictThermalWindows) is the job's white-noise bound on the
// same windows: with the order fixed (min_order = max_order = 3) the job's crb band and
// coefficient covariance, to rounding (same windows, same σ per window, same least squares);
// with the default orders 3..5 a lower bound of the job's band (a nested model's fitted values
// are no less uncertain, the BIC average adds the orders' spread). A 4 °C warm-up predicts
// nothing and says why.
TEST(RecordingCheck, ThermalPredictedSigmaIsTheJobsBound) {
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  core::ThermalSimulationOptions o = WarmupAndCooldown();
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  for (bool fixed : {true, false}) {
    json c = config;
    if (fixed) c["min_order"] = c["max_order"] = 3;
    const json job = server.UploadAndWait(csv, c);
    ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 600);
    json check;
    ASSERT_EQ(CheckOfJob(server, job, &check), 200) << check.dump();
    const json& predicted = check.at("predicted");
    ASSERT_TRUE(predicted.at("uncertainty").is_object()) << predicted.dump();
    EXPECT_EQ(predicted.at("imus").at(0).at("orders").at("planned"), 3);
    const json& p = predicted.at("uncertainty").at("imus").at(0);
    const json& u = job.at("result").at("uncertainty").at("imus").at(0);
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json& band = p.at(sensor).at("bias").at("std");
      ASSERT_EQ(band.size(), 3u);
      ASSERT_EQ(p.at(sensor).at("bias").at("temperatures"),
                u.at(sensor).at("bias").at("temperatures"));
      for (size_t a = 0; a < 3; ++a) {
        const json& crb = u.at("crb").at(sensor).at("bias").at("std").at(a);
        const json& primary = u.at(sensor).at("bias").at("std").at(a);
        ASSERT_EQ(band[a].size(), crb.size());
        for (size_t i = 0; i < crb.size(); ++i) {
          const double b = band[a][i].get<double>();
          if (fixed) {
            EXPECT_NEAR(b, crb[i].get<double>(), 1e-9 * crb[i].get<double>() + 1e-15)
                << sensor << " " << a << " grid " << i;
          } else {
            EXPECT_LE(b, primary[i].get<double>() * (1 + 1e-9) + 1e-15)
                << sensor << " " << a << " grid " << i;
          }
        }
        if (fixed) {
          const json& pc = p.at(sensor).at("bias").at("covariance").at(a);
          const json& jc = u.at("crb").at(sensor).at("bias").at("covariance").at(a);
          for (size_t k = 0; k < 3; ++k) {
            EXPECT_NEAR(pc[k][k].get<double>(), jc[k][k].get<double>(),
                        1e-9 * jc[k][k].get<double>())
                << sensor << " " << a << " c_" << k + 1;
          }
        }
      }
    }
  }
  o.delta = 4;
  o.cooldown = 0;
  ASSERT_TRUE(SimulateThermalFiles(o, &csv, &config, &truth).ok());
  const json narrow = server.UploadAndWait(csv, config);
  json check;
  ASSERT_EQ(CheckOfJob(server, narrow, &check), 200) << check.dump();
  EXPECT_TRUE(check.at("predicted").at("uncertainty").is_null()) << check["predicted"].dump();
  EXPECT_NE(check.at("predicted").value("reason", "").find("below min_range 10"), std::string::npos)
      << check["predicted"].dump();
}

std::string ImuTkDir() {
  const char* env = std::getenv("CALIBD_IMU_TK_DATA");
  return env != nullptr && *env != '\0' ? env : "/work/data/imu_tk";
}

TEST(RecordingCheck, ImuTkXsensStaticsAreTheJobs) {
  std::ifstream acc(ImuTkDir() + "/xsens_acc.mat"), gyr(ImuTkDir() + "/xsens_gyro.mat");
  if (!acc || !gyr) GTEST_SKIP() << "imu_tk's xsens_*.mat not found in " << ImuTkDir();
  std::string csv = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  double v[8];
  char buf[256];
  while ((acc >> v[0] >> v[1] >> v[2] >> v[3]) && (gyr >> v[4] >> v[5] >> v[6] >> v[7])) {
    std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g\n", v[0], v[1], v[2],
                  v[3], v[5], v[6], v[7]);
    csv += buf;
  }
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  // As tests/core/imu_tk_data_test.cc: ±8 g over 16 bits, imu_tk's gyroscope guess, offset binary.
  const json config = {{"method", "imu"},
                       {"accel_unit", 8 * 9.80665 / 32768},
                       {"gyro_unit", 1.0 / 6258},
                       {"gravity", 9.81744},
                       {"max_scale_deviation", 0.5},
                       {"nominal_accel_bias", 32768},
                       {"nominal_gyro_bias", 32768}};
  json job;
  const json check = ExpectCheckAgreesWithJob(server, csv, config, &job);
  EXPECT_GE(check.at("statics").size(), 30u);  // imu_tk's protocol: 36 or more positions
  // The prediction is the σ at nominal values. imu_tk's gyroscope guess (1/6258 rad/s per count)
  // is 24 % below the calibrated scale, so rotations read with it are 24 % short and the
  // gyroscope's σ are predicted about that much too small. With the calibrated scales as the
  // nominal ones, 19 of the 21 σ are the job's within 15 % (measured: 0.85–1.13); the
  // accelerometer's z bias is predicted 1.47× and the gyroscope's y scale 1.35× the job's (not
  // explained yet: README, "Recording check"). The bounds below hold those and fail a prediction
  // off by the rate or the noise (2×).
  ASSERT_TRUE(check.at("predicted").at("uncertainty").is_object()) << check["predicted"].dump();
  json calibrated_nominal = config;
  for (const char* sensor : {"gyroscope"}) {
    const json& scale = job.at("result").at("parameters").at("imus").at(0).at(sensor).at("scale");
    calibrated_nominal[sensor[0] == 'a' ? "accel_unit" : "gyro_unit"] =
        (scale[0].get<double>() + scale[1].get<double>() + scale[2].get<double>()) / 3;
  }
  json at_calibrated;
  ASSERT_EQ(Check(server,
                  "/api/v1/recordings/" + std::to_string(check.at("recording_id").get<int64_t>()) +
                      "/check" + Query(calibrated_nominal),
                  &at_calibrated),
            200);
  ASSERT_EQ(at_calibrated.at("statics").size(), check.at("statics").size());
  for (size_t i = 0; i < check.at("statics").size(); ++i) {
    EXPECT_EQ(at_calibrated["statics"][i].at("start"), check["statics"][i].at("start"));
  }
  std::printf(
      "imu_tk Xsens, predicted / reported σ (the job's CRB), at the guessed and at the "
      "calibrated nominal scales:\n");
  for (const json* c : std::vector<const json*>{&check, &at_calibrated}) {
    for (double r : PredictedOverReported(*c, job)) std::printf(" %.3f", r);
    std::printf("\n");
  }
  int within_15_percent = 0;
  for (double r : PredictedOverReported(at_calibrated, job)) {
    EXPECT_GT(r, 0.8);
    EXPECT_LT(r, 1.5);
    within_15_percent += std::abs(r - 1) < 0.15;
  }
  EXPECT_GE(within_15_percent, 19);
  EXPECT_TRUE(check.at("units").empty()) << check["units"];
  // The query form of the same config gives the same statics.
  json by_query;
  ASSERT_EQ(Check(server,
                  "/api/v1/recordings/" + std::to_string(check.at("recording_id").get<int64_t>()) +
                      "/check" + Query(config),
                  &by_query),
            200);
  EXPECT_EQ(by_query.at("statics"), check.at("statics"));
}

TEST(RecordingCheck, Mimu4444SaturationNamed) {
  const std::string f = testing::Mimu4444Dir() + "/exp_1/data.bin";
  ArrayRecording rec;
  if (!testing::ReadMimu4444(f, &rec)) GTEST_SKIP() << "MIMU4444 exp_1 not found at " << f;
  std::string csv = "t";
  for (const auto* names : {&rec.accel_names, &rec.gyro_names}) {
    for (const std::string& n : *names) csv += "," + n + "_x," + n + "_y," + n + "_z";
  }
  csv += "\n";
  char buf[32];
  for (Eigen::Index i = 0; i < rec.t.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%.9f", rec.t[i]);
    csv += buf;
    for (const Eigen::MatrixXd* m : {&rec.accel, &rec.gyro}) {
      for (Eigen::Index c = 0; c < m->cols(); ++c) {
        std::snprintf(buf, sizeof buf, ",%.10g", (*m)(i, c));
        csv += buf;
      }
    }
    csv += "\n";
  }
  TestServer server;
  ASSERT_TRUE(server.error().empty()) << server.error();
  const int64_t id = Store(server, csv);
  json check;
  ASSERT_EQ(
      Check(server,
            "/api/v1/recordings/" + std::to_string(id) + "/check?method=imu&gyro_unit=deg%2Fs",
            &check),
      200)
      << check.dump().substr(0, 400);
  const json& sat = check.at("saturation");
  // The 1 035 samples of exp_1 pinned at the int16 full scale (tests/server/
  // array_full_mimu4444_test.cc), gyroscopes only.
  ASSERT_FALSE(sat.at("channels").empty());
  int64_t pinned = 0;
  for (const json& c : sat.at("channels")) {
    EXPECT_EQ(c.at("name").get<std::string>()[0], 'g') << c;
    pinned += c.at("pinned_low").get<int64_t>() + c.at("pinned_high").get<int64_t>();
  }
  EXPECT_GE(pinned, 1000);
  EXPECT_GT(sat.at("samples").get<int64_t>(), 0);

  // The array method's own check (its job's saturation search, either model): the channels and
  // the dropped samples are its job's, which a positions job here shows.
  const Eigen::Matrix3Xd p = core::Mimu4444NominalPositions();
  const json positions = calibd::testing::GeometryPositions(p);
  json config = {{"method", "array"},
                 {"gyro_unit", "deg/s"},
                 {"accel_noise", 0.05},
                 {"gyro_noise", 0.2},
                 {"geometry", {{"positions", positions}, {"reference", 0}}}};
  json array_check;
  ASSERT_EQ(Check(server, "/api/v1/recordings/" + std::to_string(id) + "/check" + Query(config),
                  &array_check),
            200)
      << array_check.dump().substr(0, 400);
  const json job = server.UploadAndWait(csv, config);  // the same bytes: the same recording
  ASSERT_EQ(job.value("status", ""), "succeeded") << job.dump().substr(0, 600);
  EXPECT_EQ(job.at("recording_id"), id);
  EXPECT_EQ(array_check.at("saturation"), job.at("result").at("diagnostics").at("saturation"));
  EXPECT_TRUE(array_check.at("timing").at("rate").is_number());
  // The full model's check: the same search (its job reads t for statics, not for the search).
  config["model"] = "full";
  json full_check;
  ASSERT_EQ(Check(server, "/api/v1/recordings/" + std::to_string(id) + "/check" + Query(config),
                  &full_check),
            200)
      << full_check.dump().substr(0, 400);
  EXPECT_EQ(full_check.at("saturation"), array_check.at("saturation"));
}

}  // namespace
}  // namespace calibd::server
