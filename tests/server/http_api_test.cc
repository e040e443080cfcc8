// Integration tests of the HTTP API (SPEC §5) against a real server on a loopback port with a
// real SQLite file, through a real HTTP client.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>

#include "methods/array/array_method.h"
#include "methods/pca/pca_method.h"
#include "tests/lib/sanitizer.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

struct PcaData {
  std::string csv;
  json config;
};

PcaData SimulatedPca(uint64_t seed, int positions = 40) {
  core::PcaSimulationOptions options;
  options.seed = seed;
  options.positions = positions;
  options.noise_std = 0.001;
  PcaData data;
  json truth;
  Status s = SimulatePcaFiles(options, &data.csv, &data.config, &truth);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return data;
}

std::string Query(const json& config) {
  std::string q;
  for (auto& [key, value] : config.items()) {
    q += q.empty() ? "?" : "&";
    q += key + "=" + UrlEncode(value.is_string() ? value.get<std::string>() : value.dump());
  }
  return q;
}

json Body(const httplib::Result& res) {
  if (!res) return json();
  return json::parse(res->body, nullptr, false);
}

class HttpApi : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_EQ(server_.error(), ""); }
  TestServer server_;
};

TEST_F(HttpApi, HealthzMetricsAndOpenApiAnswer) {
  auto client = server_.Client();
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
  EXPECT_EQ(Body(health)["status"], "ok");
  EXPECT_EQ(Body(health)["backend"], "sqlite");
  EXPECT_EQ(Body(health)["database"], "reachable");
  EXPECT_EQ(client.Get("/api/v1/healthz")->status, 200);
  // A request is counted by the access logger after its answer is sent, so the count of the
  // /healthz requests above may trail by a moment: poll briefly.
  auto metrics = client.Get("/api/v1/metrics");
  for (int i = 0;
       i < 100 && metrics && metrics->body.find("route=\"/healthz\"") == std::string::npos; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    metrics = client.Get("/api/v1/metrics");
  }
  ASSERT_TRUE(metrics);
  EXPECT_EQ(metrics->status, 200);
  EXPECT_NE(metrics->body.find("calibd_http_requests_total{method=\"GET\",route=\"/healthz\""),
            std::string::npos)
      << metrics->body;
  EXPECT_NE(metrics->body.find("calibd_jobs{state=\"queued\"} 0"), std::string::npos);
  EXPECT_NE(metrics->body.find("calibd_database_up{backend=\"sqlite\"} 1"), std::string::npos);
  EXPECT_NE(metrics->body.find("# TYPE calibd_http_request_duration_seconds histogram"),
            std::string::npos);
  auto openapi = client.Get("/api/v1/openapi.json");
  ASSERT_TRUE(openapi);
  EXPECT_EQ(Body(openapi)["openapi"], "3.0.3");
}

TEST_F(HttpApi, UploadCsvRunsPcaJobAndServesTheLatestCalibration) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(7);
  json config = data.config;
  config["device"] = "SN-001";
  auto res = client.Post(("/api/v1/recordings" + Query(config)).c_str(), data.csv, "text/csv");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  json body = Body(res);
  EXPECT_GT(body["recording"]["id"].get<int64_t>(), 0);
  EXPECT_EQ(body["recording"]["sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(body["recording"]["bytes"], data.csv.size());
  EXPECT_EQ(body["recording"]["rows"], 40);
  ASSERT_TRUE(body.contains("job"));
  const int64_t job_id = body["job"]["id"];
  EXPECT_EQ(res->get_header_value("Location"), "/api/v1/jobs/" + std::to_string(job_id));

  json job = server_.WaitForJob(job_id);
  ASSERT_EQ(job["status"], "succeeded") << job.dump(2);
  EXPECT_EQ(job["device"], "SN-001");
  EXPECT_EQ(job["method"], "pca");
  EXPECT_EQ(job["attempts"], 1);
  for (const char* key : {"created_at", "started_at", "finished_at"}) {
    EXPECT_TRUE(job[key].is_string()) << key;
  }
  const json& result = job["result"];
  EXPECT_EQ(result["method"], "pca");
  EXPECT_EQ(result["parameters"]["sensors"].size(), 12u);
  EXPECT_EQ(result["parameters"]["frame"], "nominal");
  EXPECT_TRUE(result["uncertainty"]["sensors"].is_array());
  EXPECT_TRUE(result["diagnostics"]["singular_values"].is_array());
  EXPECT_TRUE(result["warnings"].is_array());

  // Devices list it; production tooling fetches the latest parameters.
  json devices = Body(client.Get("/api/v1/devices"));
  ASSERT_EQ(devices["devices"].size(), 1u);
  EXPECT_EQ(devices["devices"][0]["serial"], "SN-001");
  EXPECT_EQ(devices["devices"][0]["latest"]["pca"]["job_id"], job_id);

  auto latest = client.Get("/api/v1/devices/SN-001/calibration?method=pca");
  ASSERT_TRUE(latest);
  ASSERT_EQ(latest->status, 200);
  EXPECT_EQ(Body(latest)["result"], result);
  EXPECT_EQ(Body(latest)["job_id"], job_id);
  const std::string etag = latest->get_header_value("ETag");
  EXPECT_FALSE(etag.empty());
  EXPECT_EQ(latest->get_header_value("Cache-Control"), "no-cache");
  auto not_modified =
      client.Get("/api/v1/devices/SN-001/calibration?method=pca", {{"If-None-Match", etag}});
  ASSERT_TRUE(not_modified);
  EXPECT_EQ(not_modified->status, 304);
  EXPECT_TRUE(not_modified->body.empty());
  // Without ?method the single method is used.
  EXPECT_EQ(client.Get("/api/v1/devices/SN-001/calibration")->status, 200);

  auto csv = client.Get("/api/v1/devices/SN-001/calibration?method=pca&format=csv");
  ASSERT_TRUE(csv);
  EXPECT_EQ(csv->status, 200);
  EXPECT_EQ(csv->get_header_value("Content-Type"), "text/csv");
  EXPECT_EQ(csv->body.rfind("name,scale,scale_std,axis_x,axis_y,axis_z", 0), 0u) << csv->body;
  EXPECT_EQ(std::count(csv->body.begin(), csv->body.end(), '\n'), 13);
  EXPECT_NE(csv->get_header_value("ETag"), etag);

  auto header = client.Get("/api/v1/devices/SN-001/calibration?method=pca&format=h");
  ASSERT_TRUE(header);
  EXPECT_EQ(header->status, 200);
  EXPECT_NE(header->body.find("static const double CALIBD_SN_001_PCA_SENSITIVITY[12][3]"),
            std::string::npos);
  EXPECT_NE(header->body.find("job " + std::to_string(job_id)), std::string::npos);
  EXPECT_NE(header->body.find("SN-001"), std::string::npos);

  EXPECT_EQ(client.Get("/api/v1/devices/SN-001/calibration?method=array")->status, 404);
  EXPECT_EQ(client.Get("/api/v1/devices/NOPE/calibration?method=pca")->status, 404);
  // A serial in the wrong case is another device; the 404 names the stored one (API and page).
  for (const char* path : {"/api/v1/devices/sn-001/calibration?method=pca",
                           "/api/v1/devices/sn-001/calibration", "/devices/sn-001"}) {
    auto wrong_case = client.Get(path);
    ASSERT_TRUE(wrong_case);
    EXPECT_EQ(wrong_case->status, 404) << path;
    const bool html = path[1] == 'd';
    EXPECT_NE(wrong_case->body.find(html ? "no device &#39;sn-001&#39;; did you mean "
                                           "&#39;SN-001&#39;?"
                                         : "no device 'sn-001'; did you mean 'SN-001'?"),
              std::string::npos)
        << path << ": " << wrong_case->body;
  }
  // The devices page lists the device with its latest calibration, linked, times in UTC.
  auto devices_page = client.Get("/devices");
  ASSERT_TRUE(devices_page);
  EXPECT_EQ(devices_page->status, 200);
  for (const std::string& part :
       {std::string("class=\"table-devices\""), std::string("<th>first seen (UTC)</th>"),
        std::string("<th>latest pca (UTC)</th>"), std::string("<a href=\"/devices/SN-001\">"),
        "href=\"/jobs/" + std::to_string(job_id) + "\">",
        std::string("/api/v1/devices/SN-001/calibration?method=pca")}) {
    EXPECT_NE(devices_page->body.find(part), std::string::npos) << part;
  }
  EXPECT_EQ(devices_page->body.find("<script"), std::string::npos);
  EXPECT_EQ(client.Get("/api/v1/devices/SN-001/calibration?format=xml")->status, 400);

  // The recording's metadata and original bytes.
  const int64_t rec_id = body["recording"]["id"];
  json meta = Body(client.Get(("/api/v1/recordings/" + std::to_string(rec_id)).c_str()));
  EXPECT_EQ(meta["layout"], "pca_averaged");
  EXPECT_EQ(meta["sha256"], body["recording"]["sha256"]);
  auto bytes = client.Get(("/api/v1/recordings/" + std::to_string(rec_id) + "/data").c_str());
  ASSERT_TRUE(bytes);
  EXPECT_EQ(bytes->status, 200);
  EXPECT_EQ(bytes->body, data.csv);
}

TEST_F(HttpApi, IdenticalUploadIsStoredOnce) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(8);
  auto first = client.Post("/api/v1/recordings?device=A", data.csv, "text/csv");
  auto second = client.Post("/api/v1/recordings?device=A", data.csv, "text/csv");
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->status, 201);
  EXPECT_EQ(second->status, 201);
  EXPECT_EQ(Body(first)["recording"]["id"], Body(second)["recording"]["id"]);
  EXPECT_FALSE(Body(first)["recording"]["existed"].get<bool>());
  EXPECT_TRUE(Body(second)["recording"]["existed"].get<bool>());
  EXPECT_FALSE(Body(first).contains("job"));
}

TEST_F(HttpApi, MultipartUploadWithConfigPart) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(9);
  json config = data.config;
  config["device"] = "SN-MP";
  httplib::MultipartFormDataItems items = {{"recording", data.csv, "recording.csv", "text/csv"},
                                           {"config", config.dump(), "", "application/json"}};
  auto res = client.Post("/api/v1/recordings", items);
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  json job = server_.WaitForJob(Body(res)["job"]["id"]);
  EXPECT_EQ(job["status"], "succeeded");
  EXPECT_EQ(job["device"], "SN-MP");
}

TEST_F(HttpApi, MultipartErrorsNameThePart) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(10);
  auto no_recording =
      client.Post("/api/v1/recordings",
                  httplib::MultipartFormDataItems{{"config", "{}", "", "application/json"}});
  ASSERT_TRUE(no_recording);
  EXPECT_EQ(no_recording->status, 400);
  EXPECT_EQ(Body(no_recording)["error"]["field"], "recording");
  auto bad_json = client.Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", data.csv, "r.csv", "text/csv"},
                                      {"config", "{\"method\": pca}", "", "application/json"}});
  ASSERT_TRUE(bad_json);
  EXPECT_EQ(bad_json->status, 400);
  EXPECT_EQ(Body(bad_json)["error"]["field"], "config");
  EXPECT_EQ(Body(bad_json)["error"]["line"], 1);
  auto unknown = client.Post("/api/v1/recordings",
                             httplib::MultipartFormDataItems{{"file", "x", "x.csv", "text/csv"}});
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 400);
}

TEST_F(HttpApi, MalformedCsvIs400WithLineAndColumnAndNothingStored) {
  auto client = server_.Client();
  const std::string csv = "position,s1,s2,s3\np1,1,2,3\np2,1,NaN,3\n";
  auto res = client.Post("/api/v1/recordings?method=pca&dimension=2", csv, "text/csv");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400);
  json error = Body(res)["error"];
  EXPECT_EQ(error["code"], "invalid_input");
  EXPECT_EQ(error["line"], 3);
  EXPECT_EQ(error["column"], 3);
  EXPECT_EQ(error["field"], "s2");
  EXPECT_NE(error["message"].get<std::string>().find("not a finite number"), std::string::npos);
  EXPECT_EQ(Body(client.Get("/api/v1/jobs"))["jobs"].size(), 0u);
  EXPECT_EQ(client.Get("/api/v1/recordings/1")->status, 404);
  // No staged file is left behind.
  EXPECT_EQ(testing::StagedUploads(server_.dir()), 0);
}

TEST_F(HttpApi, InvalidConfigIs400NamingTheKey) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(11);
  struct Case {
    std::string query;
    std::string field;
  } cases[] = {
      {"?method=magic", "method"},
      {"?method=pca&dimension=two", "dimension"},
      {"?method=pca&colour=red", "colour"},
      {"?method=array", "geometry"},
      {"?method=pca&device=", "device"},
      {"?method=pca&device=%FF%FE", ""},
      {"?method=pca&method=array", "method"},
  };
  for (const Case& c : cases) {
    auto res = client.Post(("/api/v1/recordings" + c.query).c_str(), data.csv, "text/csv");
    ASSERT_TRUE(res) << c.query;
    EXPECT_EQ(res->status, 400) << c.query << " " << res->body;
    if (!c.field.empty()) {
      EXPECT_EQ(Body(res)["error"]["field"], c.field) << c.query << " " << res->body;
    }
  }
  // A pca recording with the array method: 400 naming method.
  PcaData other = SimulatedPca(12);
  json geometry = {{"positions", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}}, {"reference", 0}};
  auto res =
      client.Post(("/api/v1/recordings?method=array&accel_noise=0.1&gyro_noise=0.1&geometry=" +
                   UrlEncode(geometry.dump()))
                      .c_str(),
                  other.csv, "text/csv");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  // A rerun whose config has a method that is not a string (JSON body: a number, an object):
  // 400 naming it, never a 500 from reading it as a string before validation.
  auto up = client.Post("/api/v1/recordings", data.csv, "text/csv");
  ASSERT_TRUE(up);
  ASSERT_EQ(up->status, 201) << up->body;
  const int64_t recording = Body(up)["recording"]["id"];
  for (const json& method : {json(5), json::object(), json::array({"imu"}), json(nullptr)}) {
    res = client.Post("/api/v1/jobs",
                      json{{"recording_id", recording}, {"config", {{"method", method}}}}.dump(),
                      "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << method.dump() << " " << res->body;
    EXPECT_EQ(Body(res)["error"]["field"], "method") << res->body;
  }
}

TEST_F(HttpApi, NotDeterminableDataFailsTheJobWithAdvice) {
  auto client = server_.Client();
  // 3 positions for d = 3 (needs 6).
  const std::string csv = "position,s1,s2,s3\np1,1,0,0\np2,0,1,0\np3,0,0,1\n";
  auto res = client.Post("/api/v1/recordings?method=pca&device=D3", csv, "text/csv");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  json job = server_.WaitForJob(Body(res)["job"]["id"]);
  EXPECT_EQ(job["status"], "failed");
  EXPECT_EQ(job["attempts"], 1);  // never retried
  EXPECT_EQ(job["error"]["code"], "not_determinable");
  EXPECT_NE(job["error"]["message"].get<std::string>().find("6"), std::string::npos) << job.dump();
  EXPECT_EQ(client.Get("/api/v1/devices/D3/calibration?method=pca")->status, 404);
}

TEST_F(HttpApi, RerunWithAnotherConfigAndListJobsNewestFirstWithCursor) {
  auto client = server_.Client();
  PcaData data = SimulatedPca(13);
  auto up = client.Post("/api/v1/recordings?device=R1", data.csv, "text/csv");
  ASSERT_EQ(up->status, 201);
  const int64_t rec = Body(up)["recording"]["id"];
  std::vector<int64_t> ids;
  for (int i = 0; i < 5; ++i) {
    json config = data.config;
    config["device"] = "R1";
    if (i % 2) config["refine"] = true;
    auto res = client.Post("/api/v1/jobs", json{{"recording_id", rec}, {"config", config}}.dump(),
                           "application/json");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 202) << res->body;
    ids.push_back(Body(res)["job"]["id"]);
    EXPECT_EQ(Body(res)["job"]["status"], "queued");
  }
  for (int64_t id : ids) EXPECT_EQ(server_.WaitForJob(id)["status"], "succeeded");
  json page1 = Body(client.Get("/api/v1/jobs?device=R1&limit=2"));
  ASSERT_EQ(page1["jobs"].size(), 2u);
  EXPECT_EQ(page1["jobs"][0]["id"], ids[4]);
  EXPECT_EQ(page1["jobs"][1]["id"], ids[3]);
  ASSERT_TRUE(page1["next"].is_string());
  json page2 = Body(client.Get(page1["next"].get<std::string>().c_str()));
  ASSERT_EQ(page2["jobs"].size(), 2u);
  EXPECT_EQ(page2["jobs"][0]["id"], ids[2]);
  json page3 = Body(client.Get(page2["next"].get<std::string>().c_str()));
  ASSERT_EQ(page3["jobs"].size(), 1u);
  EXPECT_TRUE(page3["next"].is_null());
  EXPECT_EQ(Body(client.Get("/api/v1/jobs?status=failed"))["jobs"].size(), 0u);
  EXPECT_EQ(client.Get("/api/v1/jobs?status=done")->status, 400);
  EXPECT_EQ(client.Get("/api/v1/jobs?limit=0")->status, 400);
  EXPECT_EQ(client.Get("/api/v1/jobs?colour=1")->status, 400);

  // Rerun errors.
  EXPECT_EQ(client
                .Post("/api/v1/jobs", "{\"recording_id\": 999, \"config\": {\"method\": \"pca\"}}",
                      "application/json")
                ->status,
            404);
  EXPECT_EQ(client.Post("/api/v1/jobs", "{\"recording_id\": 1}", "text/plain")->status, 415);
  auto bad = client.Post("/api/v1/jobs", "{\"recording_id\": 1,", "application/json");
  EXPECT_EQ(bad->status, 400);
  EXPECT_EQ(Body(bad)["error"]["line"], 1);
}

// The whole workflow of issue #8 over HTTP: a static pca calibration with unknown biases, then an
// array job that names it by job id; the array result records which calibration it used.
TEST_F(HttpApi, ArrayJobUsesAPcaJobAsAccelerometerCalibration) {
  auto client = server_.Client();
  ArraySimulationFileOptions sim;
  sim.samples = 400;
  sim.accel_bias = 0.1;
  sim.accel_scale_error = 0.01;
  sim.accel_misalignment = 0.01;
  std::string static_csv, array_csv;
  json static_config, array_config, truth;
  ASSERT_TRUE(SimulateArrayStaticFiles(sim, 30, &static_csv, &static_config).ok());
  ASSERT_TRUE(SimulateArrayFiles(sim, &array_csv, &array_config, &truth).ok());
  static_config["device"] = "BOARD-9";
  auto up = client.Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", static_csv, "static.csv", "text/csv"},
                                      {"config", static_config.dump(), "", "application/json"}});
  ASSERT_TRUE(up);
  ASSERT_EQ(up->status, 201) << up->body;
  const int64_t pca_job = Body(up)["job"]["id"];
  ASSERT_EQ(server_.WaitForJob(pca_job)["status"], "succeeded");

  array_config["device"] = "BOARD-9";
  array_config["accelerometer_calibration"] = {{"job", pca_job}};
  auto arr = client.Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", array_csv, "array.csv", "text/csv"},
                                      {"config", array_config.dump(), "", "application/json"}});
  ASSERT_TRUE(arr);
  ASSERT_EQ(arr->status, 201) << arr->body;
  json job = server_.WaitForJob(Body(arr)["job"]["id"]);
  ASSERT_EQ(job["status"], "succeeded") << job.dump();
  EXPECT_EQ(job["config"]["accelerometer_calibration"]["job"], pca_job);
  EXPECT_EQ(job["result"]["diagnostics"]["accelerometer_calibration"]["job"], pca_job);

  // References that cannot work are refused at once, naming the key.
  const int64_t rec = Body(arr)["recording"]["id"];
  for (const json& ref : {json{{"job", 999}}, json{{"job", job["id"]}}, json{{"job", "x"}}}) {
    json config = array_config;
    config["accelerometer_calibration"] = ref;
    auto res = client.Post("/api/v1/jobs", json{{"recording_id", rec}, {"config", config}}.dump(),
                           "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << ref.dump() << " " << res->body;
    EXPECT_EQ(Body(res)["error"]["field"], "accelerometer_calibration") << res->body;
  }
}

TEST_F(HttpApi, UnknownRoutesAre404AndWrongMethodsAre405) {
  auto client = server_.Client();
  auto missing = client.Get("/api/v1/nothing");
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404);
  EXPECT_EQ(Body(missing)["error"]["code"], "not_found");
  auto wrong = client.Delete("/api/v1/jobs/1");
  ASSERT_TRUE(wrong);
  EXPECT_EQ(wrong->status, 405);
  EXPECT_EQ(wrong->get_header_value("Allow"), "GET");
  auto get_upload = client.Get("/api/v1/recordings");
  ASSERT_TRUE(get_upload);
  EXPECT_EQ(get_upload->status, 405);
  EXPECT_EQ(client.Get("/api/v1/jobs/abc")->status, 404);
  EXPECT_EQ(client.Get("/api/v1/jobs/999999")->status, 404);
  EXPECT_EQ(client.Get("/api/v1/recordings/..%2F..%2Fetc%2Fpasswd/data")->status, 404);
}

TEST_F(HttpApi, OversizedAndWronglyTypedBodiesAreRefused) {
  auto client = server_.Client();
  // 413 from Content-Length alone, before the body is read: a raw request that never sends it.
  {
    httplib::Client raw = server_.Client();
    httplib::Request req;
    req.method = "POST";
    req.path = "/api/v1/recordings";
    req.headers = {{"Content-Type", "text/csv"}, {"Content-Length", "10737418240"}};
    auto res = raw.send(req);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 413);
    EXPECT_EQ(Body(res)["error"]["code"], "too_large");
  }
  auto type = client.Post("/api/v1/recordings", "x", "image/png");
  ASSERT_TRUE(type);
  EXPECT_EQ(type->status, 415);
  auto br = client.Post("/api/v1/recordings", {{"Content-Encoding", "br"}}, "xx", "text/csv");
  ASSERT_TRUE(br);
  EXPECT_EQ(br->status, 415);
  // gzip is accepted (tests/server/gzip_upload_test.cc); "xx" is not gzip: 400 at byte 0.
  auto gz = client.Post("/api/v1/recordings", {{"Content-Encoding", "gzip"}}, "xx", "text/csv");
  ASSERT_TRUE(gz);
  EXPECT_EQ(gz->status, 400);
  EXPECT_NE(gz->body.find("at byte 0"), std::string::npos) << gz->body;
}

TEST(HttpApiLimits, ChunkedUploadOverTheLimitIs413) {
  ServeOptions options;
  options.max_upload_bytes = 4096;
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  auto client = server.Client();
  std::string csv = "position,s1\n";
  while (csv.size() < 100000) csv += "p,1.0\n";
  size_t sent = 0;
  auto res = client.Post(
      "/api/v1/recordings",
      [&](size_t, httplib::DataSink& sink) {
        if (sent >= csv.size()) {
          sink.done();
          return true;
        }
        const size_t n = std::min<size_t>(1000, csv.size() - sent);
        sink.write(csv.data() + sent, n);
        sent += n;
        return true;
      },
      "text/csv");
  // The server answers 413 and closes; the client may see the answer or a broken connection.
  if (res) {
    EXPECT_EQ(res->status, 413) << res->body;
  }
  EXPECT_EQ(server.Client().Get("/healthz")->status, 200);
  EXPECT_EQ(testing::StagedUploads(server.dir()), 0);
}

int64_t ProcStatusKiB(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::stoll(line.substr(std::string(key).size()));
  }
  return 0;
}

// A 100 MB upload streams through the parser and the staging file into SQLite: the server (this
// process) never holds it whole, so its peak RSS grows by far less than the upload's size.
TEST(HttpApiLimits, LargeUploadIsStreamedWithBoundedMemory) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  // The raw static/moving layout, as a long rotary-table log: 1000 rows per phase and position.
  const std::string header = "position,phase,s1\n";
  const size_t kRowBytes = 21, kRows = 5000000;  // "p002500,moving,1.000\n"
  const size_t total = header.size() + kRowBytes * kRows;
  const int64_t rss_before = ProcStatusKiB("VmRSS:");
  auto client = server.Client();
  auto res = client.Post(
      "/api/v1/recordings?device=BIG", total,
      [&](size_t offset, size_t, httplib::DataSink& sink) {
        std::string block;
        if (offset == 0) block = header;
        size_t row = offset == 0 ? 0 : (offset - header.size()) / kRowBytes;
        char line[32];
        while (block.size() < (1 << 20) && row < kRows) {
          std::snprintf(line, sizeof line, "p%06zu,%s,1.000\n", row / 2000,
                        (row / 1000) % 2 ? "moving" : "static");
          ++row;
          block += line;
        }
        return sink.write(block.data(), block.size());
      },
      "text/csv");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  EXPECT_EQ(Body(res)["recording"]["bytes"], total);
  EXPECT_EQ(Body(res)["recording"]["rows"], kRows);
  const int64_t growth_kib = ProcStatusKiB("VmHWM:") - rss_before;
  EXPECT_LT(growth_kib, sanitizer::kMemoryBoundScale * 64 * 1024)
      << "peak RSS grew by " << growth_kib / 1024 << " MiB";
}

TEST(HttpApiAuth, WritesNeedTheBearerTokenReadsDoNot) {
  testing::TempDir dir;
  const auto token_file = dir.path() / "token";
  std::ofstream(token_file) << "s3cret-token-0123456789\n";
  ServeOptions options;
  options.token_file = token_file.string();
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  auto client = server.Client();
  PcaData data = SimulatedPca(14);
  auto anonymous = client.Post("/api/v1/recordings", data.csv, "text/csv");
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);
  EXPECT_EQ(Body(anonymous)["error"]["code"], "unauthorized");
  auto wrong =
      client.Post("/api/v1/recordings", {{"Authorization", "Bearer nope"}}, data.csv, "text/csv");
  EXPECT_EQ(wrong->status, 401);
  client.set_bearer_token_auth("s3cret-token-0123456789");
  auto ok = client.Post("/api/v1/recordings", data.csv, "text/csv");
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 201);
  EXPECT_EQ(server.Client().Get("/api/v1/jobs")->status, 200);
}

TEST(HttpApiSecurity, RefusesNonLoopbackWithoutTokenUnlessInsecure) {
  testing::TempDir dir;
  ServeOptions options;
  options.db_path = (dir.path() / "x.db").string();
  options.listen = "0.0.0.0:0";
  std::unique_ptr<Service> service;
  Status s = Service::Create(options, &service);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("--insecure"), std::string::npos);
  options.insecure = true;
  EXPECT_TRUE(Service::Create(options, &service).ok());
}

// cpp-httplib's default socket options set SO_REUSEPORT, under which a second calibd could bind
// the same port and take half the requests to another database. Bind must refuse it.
TEST(HttpApiSecurity, ASecondServerOnTheSamePortIsRefused) {
  TestServer first;
  ASSERT_EQ(first.error(), "");
  ServeOptions options;
  options.db_path = (first.dir() / "second.db").string();
  options.listen = "127.0.0.1:" + std::to_string(first.port());
  options.workers = 1;
  options.access_log = false;
  std::unique_ptr<Service> second;
  ASSERT_TRUE(Service::Create(options, &second).ok());
  const Status s = second->Bind();
  EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
  EXPECT_NE(s.message().find("address in use"), std::string::npos) << s.ToString();
  // The first server still answers every request.
  for (int i = 0; i < 20; ++i) {
    auto res = first.Client().Get("/healthz");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
  }
}

TEST_F(HttpApi, OpenApiDocumentsEveryRouteTheServerHas) {
  auto client = server_.Client();
  json doc = Body(client.Get("/api/v1/openapi.json"));
  std::set<std::string> documented;
  for (auto& [path, item] : doc["paths"].items()) {
    for (auto& [method, op] : item.items()) {
      documented.insert(ToLower(method) + " " + path);
      // Every documented GET path answers something other than 404/405 route errors.
      if (method == "get") {
        std::string concrete = std::regex_replace(path, std::regex(R"(\{id\})"), "1");
        concrete = std::regex_replace(concrete, std::regex(R"(\{serial\})"), "X");
        concrete = std::regex_replace(concrete, std::regex(R"(\{product\})"), "P");
        auto res = client.Get(("/api/v1" + concrete).c_str());
        ASSERT_TRUE(res) << path;
        EXPECT_NE(res->status, 405) << path;
        if (res->status == 404) {
          EXPECT_NE(Body(res)["error"]["message"].get<std::string>().find("no such resource"), 0u)
              << path << " is documented but not routed";
        }
      }
    }
  }
  const std::set<std::string> served = {"post /recordings",
                                        "post /plan",
                                        "post /jobs",
                                        "get /jobs",
                                        "get /jobs/{id}",
                                        "post /jobs/{id}/revoke",
                                        "post /jobs/{id}/accept",
                                        "post /jobs/{id}/cancel",
                                        "get /devices",
                                        "get /devices/{serial}/calibration",
                                        "get /products/{product}/fleet",
                                        "get /recordings/{id}",
                                        "get /recordings/{id}/data",
                                        "get /recordings/{id}/check",
                                        "get /recordings/{id}/segments",
                                        "get /healthz",
                                        "get /metrics",
                                        "get /openapi.json"};
  EXPECT_EQ(documented, served);
}

}  // namespace
}  // namespace calibd::server
