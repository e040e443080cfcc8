// A CSV from a phone app (';' separated, decimal commas, its own column names, time in ms)
// uploaded through the real server with config columns/delimiter/decimal/time_unit, the config
// part after the file part and before it: the imu and noise jobs read exactly what the same log
// in calibd's own CSV gives (issue 30 / #24 item 4).
#include <gtest/gtest.h>

#include <cstdio>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>
#include <string>

#include "methods/imu/imu_method.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

// calibd's CSV "t,a0_x,...,g0_z" (t in s) as a phone app writes it: time in ms, ';' between
// fields, decimal commas, its own names in another order and a column calibd does not read.
std::string AsPhoneApp(const std::string& csv) {
  std::istringstream in(csv);
  std::string line, out = "gyrX;gyrY;gyrZ;time_ms;accX;accY;accZ;battery\n";
  std::getline(in, line);  // calibd's header
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) f.push_back(cell);
    std::string t = f[0];  // seconds with a decimal point → ms: the point moved 3 places
    const size_t dot = t.find('.');
    std::string whole = dot == std::string::npos ? t : t.substr(0, dot);
    std::string frac = dot == std::string::npos ? "" : t.substr(dot + 1);
    frac.resize(std::max<size_t>(frac.size(), 3), '0');
    t = whole + frac.substr(0, 3) + (frac.size() > 3 ? "," + frac.substr(3) : "");
    std::string row_out =
        f[4] + ";" + f[5] + ";" + f[6] + ";" + t + ";" + f[1] + ";" + f[2] + ";" + f[3] + ";87\n";
    for (size_t i = 0; i < row_out.size(); ++i) {
      if (row_out[i] == '.') row_out[i] = ',';
    }
    out += row_out;
  }
  return out;
}

json Post(const TestServer& server, const httplib::MultipartFormDataItems& items) {
  auto res = server.Client().Post("/api/v1/recordings", items);
  if (!res || res->status != 201) {
    ADD_FAILURE() << (res ? std::to_string(res->status) + " " + res->body : "no answer");
    return nullptr;
  }
  return json::parse(res->body);
}

TEST(ForeignCsv, PhoneAppLogRunsImuAndNoiseWhateverThePartOrder) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  core::ImuSimulationOptions sim;
  sim.statics = 24;
  sim.seed = 7;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateImuFiles(sim, &csv, &config, &truth).ok());
  const json reference = server.UploadAndWait(csv, config);
  ASSERT_EQ(reference["status"], "succeeded") << reference.dump();

  const std::string phone = AsPhoneApp(csv);
  json foreign = config;
  foreign["time_unit"] = "ms";
  foreign["delimiter"] = ";";
  foreign["decimal"] = ",";
  foreign["columns"] = {{"t", "time_ms"}, {"a0_x", "accX"}, {"a0_y", "accY"}, {"a0_z", "accZ"},
                        {"g0_x", "gyrX"}, {"g0_y", "gyrY"}, {"g0_z", "gyrZ"}};
  const httplib::MultipartFormData file{"recording", phone, "log.txt", "text/plain"};
  const httplib::MultipartFormData part{"config", foreign.dump(), "", "application/json"};
  for (bool config_first : {false, true}) {
    SCOPED_TRACE(config_first ? "config part first" : "config part after the file");
    const json answer = Post(server, config_first ? httplib::MultipartFormDataItems{part, file}
                                                  : httplib::MultipartFormDataItems{file, part});
    ASSERT_TRUE(answer.is_object());
    const json job = server.WaitForJob(answer["job"]["id"].get<int64_t>());
    ASSERT_EQ(job["status"], "succeeded") << job.dump();
    // Exactly the numbers of the same log in calibd's CSV (whose recovery of the truth within
    // its σ the imu tests establish).
    EXPECT_EQ(job["result"]["parameters"], reference["result"]["parameters"]);
    EXPECT_EQ(job["result"]["uncertainty"], reference["result"]["uncertainty"]);
  }
  // The recording says how it was read; its bytes are served as uploaded.
  auto rec = server.Client().Get("/api/v1/recordings/2");
  ASSERT_TRUE(rec && rec->status == 200);
  const json recording = json::parse(rec->body);
  EXPECT_EQ(recording["csv"]["columns"]["a0_x"], "accX");
  EXPECT_EQ(recording["csv"]["ignored"], json::array({"battery"}));
  ASSERT_EQ(recording["warnings"].size(), 1u);
  auto data = server.Client().Get("/api/v1/recordings/2/data");
  ASSERT_TRUE(data);
  EXPECT_EQ(data->body, phone);
  // A job on the stored recording whose config gives none of the reading rules reads it as its
  // upload did (the rules stored with the recording), with the same numbers.
  json again = foreign;
  for (const char* key : {"columns", "delimiter", "decimal"}) again.erase(key);
  auto posted = server.Client().Post("/api/v1/jobs",
                                     json{{"recording_id", 2}, {"config", again}}.dump(),
                                     "application/json");
  ASSERT_TRUE(posted);
  ASSERT_EQ(posted->status, 202) << posted->body;
  const json rerun = server.WaitForJob(json::parse(posted->body)["job"]["id"].get<int64_t>());
  ASSERT_EQ(rerun["status"], "succeeded") << rerun.dump().substr(0, 2000);
  EXPECT_EQ(rerun["result"]["parameters"], reference["result"]["parameters"]);

  // A noise job on the same mapped layout: a still phone, 100 Hz for 60 s, white noise.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> white(0, 0.02);
  std::string still = "gyrX;gyrY;gyrZ;time_ms;accX;accY;accZ;battery\n";
  for (int i = 0; i < 6000; ++i) {
    char row[256];
    std::snprintf(row, sizeof row, "%.6f;%.6f;%.6f;%d;%.6f;%.6f;%.6f;87\n", white(rng), white(rng),
                  white(rng), 10 * i, white(rng), white(rng), 9.81 + white(rng));
    std::string text = row;
    for (char& c : text) c = c == '.' ? ',' : c;
    still += text;
  }
  json noise = foreign;
  for (const char* key : {"gravity", "accel_unit", "gyro_unit"}) noise.erase(key);
  noise["method"] = "noise";
  const json answer = Post(server, {{"recording", still, "still.txt", "text/plain"},
                                    {"config", noise.dump(), "", "application/json"}});
  ASSERT_TRUE(answer.is_object());
  const json job = server.WaitForJob(answer["job"]["id"].get<int64_t>());
  EXPECT_EQ(job["status"], "succeeded") << job.dump().substr(0, 2000);

  // Without the keys: the clear error naming them, nothing stored.
  auto res = server.Client().Post("/api/v1/recordings?method=noise", phone, "text/csv");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400);
  EXPECT_NE(res->body.find("delimiter"), std::string::npos) << res->body;
  // A mapped name the header lacks: 400 naming columns.<key>, config part after the file.
  json wrong = foreign;
  wrong["columns"]["g0_z"] = "gyroZ";
  res = server.Client().Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{file, {"config", wrong.dump(), "", "application/json"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400);
  EXPECT_EQ(json::parse(res->body)["error"]["field"], "columns.g0_z") << res->body;
}

}  // namespace
}  // namespace calibd::server
