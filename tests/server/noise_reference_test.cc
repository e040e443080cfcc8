// accel_noise / gyro_noise as {"job": ID} of a succeeded noise job (SPEC §7) through a real
// server: resolved when the imu or array job is queued into the σ per sample of that noise log
// (N · √rate, SI), recorded in the job's config and in the result (diagnostics.noise_jobs), used
// by the method, linked from the report; bad references are refused at once naming the key, and
// offline a reference is an error saying it needs the server.
#include "methods/noise/noise_reference.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>

#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "server/config.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

json Upload(TestServer& server, const std::string& csv, const json& config) {
  auto res = server.Client().Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", csv, "log.csv", "text/csv"},
                                      {"config", config.dump(), "", "application/json"}});
  EXPECT_TRUE(res);
  if (!res) return json();
  json body = json::parse(res->body);
  body["status"] = res->status;
  return body;
}

// The largest white-noise density of the channels starting with `prefix`, times √rate.
double Sigma(const json& noise_result, char prefix) {
  double worst = 0;
  for (const json& c : noise_result["parameters"]["channels"]) {
    if (c["name"].get<std::string>()[0] == prefix) {
      worst = std::max(worst, c["white_noise"].get<double>());
    }
  }
  return worst * std::sqrt(noise_result["diagnostics"]["rate"].get<double>());
}

class NoiseReference : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_EQ(server_.error(), "");
    NoiseSimulationFileOptions sim;
    sim.rate = 50;
    sim.seconds = 3600;
    sim.seed = 9;
    // Random walks that dominate from ~10-20 s on, so an hour shows them in every channel (as in
    // noise_method_test).
    sim.accel_random_walk = 4e-4;
    sim.gyro_random_walk = 2e-5;
    std::string csv;
    json config, truth;
    ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
    config["device"] = "IMU-N";
    json up = Upload(server_, csv, config);
    ASSERT_EQ(up["status"], 201) << up.dump();
    noise_job_ = up["job"]["id"];
    json job = server_.WaitForJob(noise_job_);
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    noise_result_ = job["result"];
  }

  TestServer server_;
  int64_t noise_job_ = 0;
  json noise_result_;
};

TEST_F(NoiseReference, AnImuJobUsesTheNoiseJobsFiguresRecordsAndLinksIt) {
  core::ImuSimulationOptions sim;
  sim.statics = 20;
  sim.seed = 8;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  config["device"] = "IMU-N";
  config["accel_noise"] = {{"job", noise_job_}};
  config["gyro_noise"] = {{"job", noise_job_}};
  json up = Upload(server_, csv, config);
  ASSERT_EQ(up["status"], 201) << up.dump();
  json job = server_.WaitForJob(up["job"]["id"]);
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  const double sa = Sigma(noise_result_, 'a'), sg = Sigma(noise_result_, 'g');
  EXPECT_EQ(job["config"]["accel_noise"]["job"], noise_job_);
  EXPECT_DOUBLE_EQ(job["config"]["accel_noise"]["sigma"].get<double>(), sa);
  EXPECT_DOUBLE_EQ(job["config"]["gyro_noise"]["sigma"].get<double>(), sg);
  const json& diag = job["result"]["diagnostics"];
  EXPECT_EQ(diag["noise_jobs"]["accelerometer"], noise_job_);
  EXPECT_EQ(diag["noise_jobs"]["gyroscope"], noise_job_);
  for (int i = 0; i < 3; ++i) {  // the σ the fit used
    EXPECT_NEAR(diag["imus"][0]["noise"]["accelerometer"][i].get<double>(), sa, 1e-12 * sa);
    EXPECT_NEAR(diag["imus"][0]["noise"]["gyroscope"][i].get<double>(), sg, 1e-12 * sg);
  }
  // The OpenVINS export of this calibration carries the noise job's Kalibr figures.
  auto yaml = server_.Client().Get("/api/v1/devices/IMU-N/calibration?method=imu&format=yaml");
  ASSERT_TRUE(yaml);
  ASSERT_EQ(yaml->status, 200) << yaml->body;
  for (const char* sensor : {"accelerometer", "gyroscope"}) {
    double walk = 0;
    for (const json& c : noise_result_["parameters"]["channels"]) {
      if (c["name"].get<std::string>()[0] != sensor[0]) continue;
      ASSERT_TRUE(c["random_walk"].is_number()) << "an hour should show it: " << c.dump();
      walk = std::max(walk, c["random_walk"].get<double>());
    }
    const std::string key = std::string("  ") + sensor + "_random_walk: ";
    const size_t at = yaml->body.find(key);
    ASSERT_NE(at, std::string::npos) << yaml->body;
    EXPECT_DOUBLE_EQ(std::stod(yaml->body.substr(at + key.size())), walk);
  }
  auto page = server_.Client().Get(("/jobs/" + job["id"].dump()).c_str());
  ASSERT_TRUE(page);
  EXPECT_NE(page->body.find("<a href=\"/jobs/" + std::to_string(noise_job_) + "\">noise job #"),
            std::string::npos);
}

TEST_F(NoiseReference, AnArrayJobUsesItInSiWhateverItsGyroUnit) {
  ArraySimulationFileOptions sim;
  sim.samples = 400;
  sim.gyro_unit = "deg/s";
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFiles(sim, &csv, &config, &truth).ok());
  config["accel_noise"] = {{"job", noise_job_}};
  config["gyro_noise"] = {{"job", noise_job_}};
  json up = Upload(server_, csv, config);
  ASSERT_EQ(up["status"], 201) << up.dump();
  json job = server_.WaitForJob(up["job"]["id"]);
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  const json& diag = job["result"]["diagnostics"];
  EXPECT_EQ(diag["noise_jobs"]["accelerometer"], noise_job_);
  EXPECT_EQ(diag["noise_jobs"]["gyroscope"], noise_job_);
  // The σ the fit used: SI from the noise job, reported back in the log's gyro unit (deg/s).
  const double sa = Sigma(noise_result_, 'a'), sg = Sigma(noise_result_, 'g');
  EXPECT_NEAR(diag["noise_configured"]["accelerometer"].get<double>(), sa, 1e-12 * sa);
  EXPECT_NEAR(diag["noise_configured"]["gyroscope"].get<double>(), sg * 180 / M_PI,
              1e-9 * sg * 180 / M_PI);
}

TEST_F(NoiseReference, BadReferencesAreRefusedNamingTheKeyAndOfflineSaysItNeedsTheServer) {
  core::ImuSimulationOptions sim;
  sim.statics = 12;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  json up = Upload(server_, csv, config);
  ASSERT_EQ(up["status"], 201) << up.dump();
  const int64_t rec = up["recording"]["id"];
  const int64_t imu_job = up["job"]["id"];
  server_.WaitForJob(imu_job);
  for (const json& ref : {json{{"job", 999}}, json{{"job", imu_job}}, json{{"job", "x"}},
                          json{{"jobs", noise_job_}}}) {
    json c = config;
    c["gyro_noise"] = ref;
    auto res = server_.Client().Post(
        "/api/v1/jobs", json{{"recording_id", rec}, {"config", c}}.dump(), "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << ref.dump() << " " << res->body;
    EXPECT_EQ(json::parse(res->body)["error"]["field"], "gyro_noise") << res->body;
  }
  config["accel_noise"] = {{"job", noise_job_}};
  json result;
  Status s = Calibrate(csv, "imu.csv", config, &result);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "accel_noise");
  EXPECT_NE(s.message().find("resolved by the server"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::server

namespace calibd::server {
namespace {

// A succeeded noise job whose stored result this calibd cannot read (a newer schema, a damaged
// figure) is refused at enqueue naming the config key and the path of the problem.
TEST(NoiseReferenceChain, AStoredNoiseResultThatDoesNotReadIsRefusedNamingTheKeyAndThePath) {
  testing::TempDir dir;
  std::unique_ptr<storage::Store> store;
  ASSERT_TRUE(
      storage::Store::Open((dir.path() / "calibd.db").string(), storage::StoreOptions(), &store)
          .ok());
  NoiseSimulationFileOptions sim;
  sim.rate = 50;
  sim.seconds = 120;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  ASSERT_TRUE(Calibrate(csv, "noise.csv", config, &result).ok());
  int uploads = 0;  // each recording's bytes differ (identical bytes are stored once)
  auto stored_job = [&](const json& stored) {
    storage::NewRecording rec;
    const std::string data = csv + "#" + std::to_string(++uploads) + "\n";
    rec.data = data;
    rec.layout = "array";
    storage::RecordingInfo info;
    EXPECT_TRUE(store->PutRecording(rec, &info, nullptr).ok());
    storage::JobInfo job;
    EXPECT_TRUE(store->EnqueueJob(info.id, "noise", "IMU-N", config.dump(), &job).ok());
    bool claimed = false;
    EXPECT_TRUE(store->ClaimJob("test:1:1", 60000, &job, &claimed).ok());
    EXPECT_TRUE(claimed);
    EXPECT_TRUE(store->CompleteJob(job.id, "test:1:1", stored.dump()).ok());
    return job.id;
  };
  json newer = result;
  newer["schema_version"] = 99;
  const int64_t newer_job = stored_job(newer);
  json imu_config = {{"method", "imu"}, {"gyro_noise", {{"job", newer_job}}}};
  Status s = ResolveNoiseReferences(store.get(), &imu_config);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "gyro_noise");
  EXPECT_NE(s.message().find("config key 'gyro_noise': noise job " + std::to_string(newer_job) +
                             " cannot be used: noise result: schema_version"),
            std::string::npos)
      << s.message();
  json damaged = result;
  damaged["parameters"]["channels"][4]["white_noise"] = "2e-4";
  const int64_t damaged_job = stored_job(damaged);
  imu_config = {{"method", "array"}, {"accel_noise", {{"job", damaged_job}}}};
  s = ResolveNoiseReferences(store.get(), &imu_config);
  EXPECT_EQ(s.field(), "accel_noise");
  EXPECT_NE(s.message().find("parameters.channels[4].white_noise"), std::string::npos)
      << s.message();
  // The undamaged result resolves (the typed read is not stricter than the document).
  const int64_t good_job = stored_job(result);
  imu_config = {{"method", "imu"}, {"accel_noise", {{"job", good_job}}}};
  ASSERT_TRUE(ResolveNoiseReferences(store.get(), &imu_config).ok());
  EXPECT_EQ(imu_config["accel_noise"]["job"], good_job);
  EXPECT_GT(imu_config["accel_noise"]["sigma"].get<double>(), 0);
}

}  // namespace
}  // namespace calibd::server
