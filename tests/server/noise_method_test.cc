// The `noise` method through the real server (upload, queue, job, result JSON of SPEC §7) and
// offline: recovery of the simulated terms, SI units after the reading-unit conversion, and every
// bad-input path with the key or column it names.
#include "methods/noise/noise_method.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <nlohmann/json.hpp>

#include "server/config.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

json Upload(TestServer& server, const std::string& csv, const std::string& query) {
  auto res = server.Client().Post(("/api/v1/recordings?" + query).c_str(), csv, "text/csv");
  EXPECT_TRUE(res);
  if (!res) return json();
  json body = json::parse(res->body);
  body["status"] = res->status;
  return body;
}

TEST(NoiseMethod, RecoversWhiteNoiseAndRandomWalkOfAnHourLogThroughTheServer) {
  NoiseSimulationFileOptions sim;
  sim.rate = 50;
  sim.seconds = 3600;
  sim.seed = 7;
  // Random walks that dominate from ~10-20 s on, so an hour shows them in every channel.
  sim.accel_random_walk = 4e-4;
  sim.gyro_random_walk = 2e-5;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  TestServer server;
  ASSERT_EQ(server.error(), "");
  json answer = Upload(server, csv, "method=noise&device=IMU-N1");
  ASSERT_EQ(answer["status"], 201) << answer.dump();
  json job = server.WaitForJob(answer["job"]["id"]);
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  const json& r = job["result"];
  EXPECT_EQ(r["method"], "noise");
  EXPECT_NEAR(r["diagnostics"]["rate"].get<double>(), 50, 1e-6);
  EXPECT_EQ(r["diagnostics"]["samples"], 180000);
  ASSERT_EQ(r["parameters"]["channels"].size(), 6u);
  for (size_t c = 0; c < 6; ++c) {
    const json& p = r["parameters"]["channels"][c];
    const json& u = r["uncertainty"]["channels"][c];
    const json& t = truth["channels"][c];
    EXPECT_EQ(p["name"], t["name"]);
    EXPECT_EQ(p["unit"], t["unit"]);
    // N from an hour: 1σ ≈ 0.2 %; 4σ bounds (a wrong unit or a missing √ fails by far).
    const double n = p["white_noise"], n_std = u["white_noise_std"], n_true = t["white_noise"];
    EXPECT_GT(n_std, 0);
    EXPECT_LT(std::abs(n - n_true), 4 * n_std) << p.dump() << u.dump();
    EXPECT_LT(std::abs(n - n_true), 0.02 * n_true);
    // The σ convention (issue 28): the model fits white noise + random walk, so the primary σ
    // is the noise model's own (basis "crb", kept under crb), χ²/dof near 1.
    EXPECT_EQ(u["basis"], "crb") << u.dump();
    EXPECT_EQ(u["crb"]["white_noise_std"], u["white_noise_std"]) << u.dump();
    EXPECT_LT(u["chi2_per_dof"].get<double>(), 3) << u.dump();
    // K is visible in an hour at these levels; within 4 reported σ of the truth.
    ASSERT_TRUE(p["random_walk"].is_number()) << p.dump() << r["warnings"].dump();
    const double k = p["random_walk"], k_std = u["random_walk_std"], k_true = t["random_walk"];
    EXPECT_LT(std::abs(k - k_true), 4 * k_std) << p.dump() << u.dump();
    // The Allan curve: octaves from one sample to a quarter of the log, intervals around it.
    const json& a = r["diagnostics"]["allan"][c];
    if (c == 0) {
      EXPECT_EQ(r["uncertainty"]["basis"], "crb") << r["uncertainty"].dump();
    }
    ASSERT_GT(a["tau"].size(), 10u);
    EXPECT_NEAR(a["tau"][0].get<double>(), 1.0 / 50, 1e-9);
    EXPECT_LE(a["tau"].back().get<double>(), 3600.0 / 4 + 1e-6);
    for (size_t i = 0; i < a["tau"].size(); ++i) {
      EXPECT_LE(a["adev_lower"][i].get<double>(), a["adev"][i].get<double>());
      EXPECT_GE(a["adev_upper"][i].get<double>(), a["adev"][i].get<double>());
    }
  }
  // Exports: Kalibr's imu.yaml with the largest axis per sensor type, the CSV with empty cells
  // for the terms the log does not show, no C header.
  auto client = server.Client();
  auto yaml = client.Get("/api/v1/devices/IMU-N1/calibration?format=yaml");
  ASSERT_TRUE(yaml);
  ASSERT_EQ(yaml->status, 200) << yaml->body;
  for (const char* key :
       {"accelerometer_noise_density: ", "accelerometer_random_walk: ", "gyroscope_noise_density: ",
        "gyroscope_random_walk: ", "update_rate: "}) {
    const size_t at = yaml->body.find(std::string("\n") + key);
    ASSERT_NE(at, std::string::npos) << key << "\n" << yaml->body;
    const double v = std::atof(yaml->body.c_str() + at + 1 + std::strlen(key));
    EXPECT_GT(v, 0) << key;
  }
  double worst_gyro_n = 0;
  for (size_t c = 3; c < 6; ++c) {
    worst_gyro_n =
        std::max(worst_gyro_n, r["parameters"]["channels"][c]["white_noise"].get<double>());
  }
  const size_t at = yaml->body.find("gyroscope_noise_density: ");
  EXPECT_DOUBLE_EQ(std::atof(yaml->body.c_str() + at + 25), worst_gyro_n);
  auto csv_export = client.Get("/api/v1/devices/IMU-N1/calibration?format=csv");
  ASSERT_TRUE(csv_export);
  EXPECT_EQ(csv_export->status, 200);
  EXPECT_NE(csv_export->body.find("\na0_x,m/s^2,"), std::string::npos);
  EXPECT_NE(csv_export->body.find(",,,"), std::string::npos) << "B must be empty, not 0";
  // The C header (C99 and C++; compiled and run in c_header_test).
  auto header = client.Get("/api/v1/devices/IMU-N1/calibration?format=h");
  ASSERT_TRUE(header);
  EXPECT_EQ(header->status, 200) << header->body;
  // The report: the terms with units and 1σ, a log-log Allan plot per sensor type, the yaml link.
  auto page = client.Get(("/jobs/" + std::to_string(job["id"].get<int64_t>())).c_str());
  ASSERT_TRUE(page);
  ASSERT_EQ(page->status, 200);
  for (const char* part : {"class=\"table-noise-parameters\"", "class=\"plot plot-allan-accel\"",
                           "class=\"plot plot-allan-gyro\"", "format=yaml", "not visible"}) {
    EXPECT_NE(page->body.find(part), std::string::npos) << part;
  }
  EXPECT_NE(page->body.find("format=h\""), std::string::npos);

  // Bias instability is absent from the simulation: null with a warning, not a number.
  EXPECT_TRUE(r["parameters"]["channels"][0]["bias_instability"].is_null());
  EXPECT_NE(r["warnings"].dump().find("bias_instability not visible"), std::string::npos);
}

TEST(NoiseMethod, ReadingUnitsAreConvertedToSi) {
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 600;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  json si, scaled;
  ASSERT_TRUE(Calibrate(csv, "log.csv", config, &si).ok());
  // The same numbers declared as milli-units: every term 1000x smaller in SI.
  config["accel_unit"] = 1e-3;
  config["gyro_unit"] = 1e-3;
  ASSERT_TRUE(Calibrate(csv, "log.csv", config, &scaled).ok());
  for (size_t c = 0; c < 6; ++c) {
    EXPECT_NEAR(scaled["parameters"]["channels"][c]["white_noise"].get<double>() * 1e3,
                si["parameters"]["channels"][c]["white_noise"].get<double>(),
                1e-5 * si["parameters"]["channels"][c]["white_noise"].get<double>());
  }
}

TEST(NoiseMethod, FloatCollectionGivesTheSameResultAsConvertingTheParsersDoubles) {
  // The server prepares the parser (PrepareParser: the samples collected as float, 4 bytes a
  // value); a parser that was not prepared hands out doubles that Run converts. Both round
  // reading × unit once to float, so the results are identical, units and all.
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 300;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  config["accel_unit"] = 0.00239420;
  config["gyro_unit"] = "deg/s";
  RecordingParser prepared("log.csv", true), plain("log.csv", true);
  PrepareParser(config, &prepared);
  ASSERT_TRUE(prepared.collects_float());
  ASSERT_FALSE(plain.collects_float());
  ASSERT_TRUE(ParseRecording(csv, &prepared).ok());
  ASSERT_TRUE(ParseRecording(csv, &plain).ok());
  json a, b;
  ASSERT_TRUE(CalibrateParsed(&prepared, "log.csv", config, &a).ok());
  ASSERT_TRUE(CalibrateParsed(&plain, "log.csv", config, &b).ok());
  EXPECT_EQ(a.dump(), b.dump());
  // A parser prepared with other scales (e.g. a config changed afterwards) is not misread.
  RecordingParser other("log.csv", true);
  other.CollectArrayAsFloat(1.0, 1.0);
  ASSERT_TRUE(ParseRecording(csv, &other).ok());
  json c;
  EXPECT_EQ(CalibrateParsed(&other, "log.csv", config, &c).code(), StatusCode::kInternal);
}

TEST(NoiseMethod, BadInputIsNamed) {
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 60;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  // Unknown key, bad units, bad spacing: refused before anything runs, naming the key.
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, json>>{{"colour", "red"},
                                                 {"accel_unit", "furlong"},
                                                 {"gyro_unit", -1},
                                                 {"taus_per_decade", 2.5}}) {
    json bad = config;
    bad[key] = value;
    Status s = Calibrate(csv, "log.csv", bad, &result);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << key;
    EXPECT_EQ(s.field(), key) << s.ToString();
  }
  // No time column.
  const std::string no_t = "a0_x,a0_y,a0_z\n1,2,3\n1,2,3\n";
  Status s = Calibrate(no_t, "log.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "t");
  // Time going backwards.
  const std::string back = "t,a0_x,a0_y,a0_z\n0,1,2,3\n0.01,1,2,3\n0.005,1,2,3\n";
  s = Calibrate(back, "log.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.line(), 4) << s.ToString();  // the row of t = 0.005, named by its line
  EXPECT_NE(s.message().find("comes after"), std::string::npos) << s.message();
  // Too short to say anything: not determinable, saying so.
  std::string shorter = "t,a0_x,a0_y,a0_z\n";
  for (int i = 0; i < 100; ++i) shorter += std::to_string(i * 0.01) + ",0.1,0.2,9.8\n";
  s = Calibrate(shorter, "log.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
}

TEST(NoiseMethod, UploadWithABadKeyIs400AndStoresNothing) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const std::string csv = "t,a0_x,a0_y,a0_z\n0,1,2,3\n0.01,1,2,3\n";
  json answer = Upload(server, csv, "method=noise&accel_unit=furlong");
  EXPECT_EQ(answer["status"], 400);
  EXPECT_EQ(answer["error"]["field"], "accel_unit");
  EXPECT_EQ(server.Client().Get("/api/v1/recordings/1")->status, 404);
}

}  // namespace
}  // namespace calibd::server
