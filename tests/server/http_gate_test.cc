// The acceptance gate over HTTP (SPEC §4 verdict, §5 calibration/revoke/accept), against a real
// server on a loopback port: what production tooling fetches is never a rejected or revoked
// result; people's decisions are recorded; ?job= never crosses devices; a re-upload never moves a
// recording to its old device.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "core/pca_simulation.h"
#include "server/http_util.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

json Body(const httplib::Result& res) {
  if (!res) return json();
  return json::parse(res->body, nullptr, false);
}

bool HasReason(const json& verdict, const std::string& text) {
  for (const json& r : verdict["reasons"]) {
    if (r.get<std::string>().find(text) != std::string::npos) return true;
  }
  return false;
}

// A static accelerometer triad (pca averaged layout) at the given field directions, scale 1.01,
// biases 0.1·(1,2,3), noise 0.002 (field units).
std::string TriadCsv(const std::vector<Eigen::Vector3d>& directions, double field, uint64_t seed) {
  core::PcaRandom random(seed + 1000003);
  std::string csv = "position,a0_x,a0_y,a0_z\n";
  for (size_t j = 0; j < directions.size(); ++j) {
    const Eigen::Vector3d v = directions[j].normalized() * field;
    csv += "p" + std::to_string(j + 1);
    for (int i = 0; i < 3; ++i) {
      char buf[40];
      std::snprintf(buf, sizeof buf, ",%.12g",
                    1.01 * v[i] + 0.1 * (i + 1) + 0.002 * random.Normal());
      csv += buf;
    }
    csv += "\n";
  }
  return csv;
}

std::string GoodCsv(uint64_t seed, double field = 9.80665) {
  core::PcaRandom random(seed);
  std::vector<Eigen::Vector3d> dirs;
  for (int j = 0; j < 30; ++j) dirs.emplace_back(random.UnitVector(3));
  return TriadCsv(dirs, field, seed);
}

// The issue's poorly spread recording: the six faces of a box plus four positions near faces.
std::string BoxFacesCsv(uint64_t seed) {
  return TriadCsv({{1, 0, 0},
                   {-1, 0, 0},
                   {0, 1, 0},
                   {0, -1, 0},
                   {0, 0, 1},
                   {0, 0, -1},
                   {1, 0.08, 0.05},
                   {0.06, 1, 0},
                   {0, 0.07, 1},
                   {-1, 0, 0.06}},
                  9.80665, seed);
}

std::string UploadPath(const std::string& device, const std::string& extra = "") {
  std::string q = "/api/v1/recordings?method=pca&magnitude=9.80665&bias=estimate";
  if (!device.empty()) q += "&device=" + device;
  return q + extra;
}

class HttpGate : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_EQ(server_.error(), ""); }

  // Uploads, waits for the job, returns it.
  json Calibrate(const std::string& csv, const std::string& device, const std::string& extra = "") {
    auto res = server_.Client().Post(UploadPath(device, extra).c_str(), csv, "text/csv");
    EXPECT_TRUE(res);
    if (!res) return json();
    EXPECT_EQ(res->status, 201) << res->body;
    return server_.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  }

  // The job id production tooling gets for the device, 0 on 404.
  int64_t Served(const std::string& device) {
    auto res =
        server_.Client().Get(("/api/v1/devices/" + device + "/calibration?method=pca").c_str());
    EXPECT_TRUE(res);
    if (!res || res->status == 404) return 0;
    EXPECT_EQ(res->status, 200) << res->body;
    EXPECT_EQ(res->get_header_value("X-Calibd-State"), "accepted");
    return Body(res)["job_id"].get<int64_t>();
  }

  httplib::Result Decide(int64_t job, const std::string& action, const std::string& reason) {
    return server_.Client().Post(("/api/v1/jobs/" + std::to_string(job) + "/" + action).c_str(),
                                 json{{"reason", reason}}.dump(), "application/json");
  }

  TestServer server_;
};

TEST_F(HttpGate, PoorlySpreadPcaRecordingIsRejectedAndNeverServed) {
  const json good = Calibrate(GoodCsv(1), "DRONE-1");
  ASSERT_EQ(good["status"], "succeeded");
  EXPECT_EQ(good["verdict"], "accepted");
  EXPECT_EQ(good["result"]["verdict"]["status"], "accepted");
  EXPECT_EQ(Served("DRONE-1"), good["id"]);

  const json box = Calibrate(BoxFacesCsv(2), "DRONE-1");
  ASSERT_EQ(box["status"], "succeeded");  // computed, but not to be flashed
  EXPECT_EQ(box["verdict"], "rejected");
  EXPECT_EQ(box["state"], "rejected");
  EXPECT_TRUE(HasReason(box["result"]["verdict"], "orientations are poorly spread"))
      << box["result"]["verdict"].dump();
  EXPECT_EQ(Served("DRONE-1"), good["id"]);  // the newer, rejected result is not served

  // /devices names the accepted one; the job list filters by verdict.
  const json devices = Body(server_.Client().Get("/api/v1/devices"));
  EXPECT_EQ(devices["devices"][0]["latest"]["pca"]["job_id"], good["id"]);
  const json rejected = Body(server_.Client().Get("/api/v1/jobs?verdict=rejected"));
  ASSERT_EQ(rejected["jobs"].size(), 1u);
  EXPECT_EQ(rejected["jobs"][0]["id"], box["id"]);
  EXPECT_EQ(server_.Client().Get("/api/v1/jobs?verdict=maybe")->status, 400);
  // Monitoring sees the rejections.
  const std::string metrics = server_.Client().Get("/metrics")->body;
  EXPECT_NE(metrics.find("calibd_verdicts_total{method=\"pca\",verdict=\"rejected\"} 1"),
            std::string::npos)
      << metrics;
  EXPECT_NE(metrics.find("calibd_verdicts_total{method=\"pca\",verdict=\"accepted\"} 1"),
            std::string::npos);
}

TEST_F(HttpGate, UnitMixUpsAreRejectedWithTheProbableCause) {
  // Readings in g (field 1) uploaded with magnitude 9.80665.
  const json g = Calibrate(GoodCsv(3, 1.0), "DRONE-2");
  ASSERT_EQ(g["status"], "succeeded");
  EXPECT_EQ(g["verdict"], "rejected");
  EXPECT_TRUE(HasReason(g["result"]["verdict"], "readings look like g but magnitude is 9.81"))
      << g["result"]["verdict"].dump();
  // Readings in m/s^2 uploaded with magnitude 1.
  auto res = server_.Client().Post(
      "/api/v1/recordings?method=pca&magnitude=1&bias=estimate&device=DRONE-2", GoodCsv(4),
      "text/csv");
  ASSERT_EQ(res->status, 201);
  const json ms2 = server_.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  EXPECT_TRUE(HasReason(ms2["result"]["verdict"], "readings look like m/s^2 but magnitude is 1"))
      << ms2["result"]["verdict"].dump();
  EXPECT_EQ(Served("DRONE-2"), 0);
  auto latest = server_.Client().Get("/api/v1/devices/DRONE-2/calibration");
  EXPECT_EQ(latest->status, 404);
  EXPECT_NE(latest->body.find("rejected and revoked results are never served"), std::string::npos);
}

TEST_F(HttpGate, RevokeFallsBackAcceptServesARejectedOneAndBothAreRecorded) {
  const json first = Calibrate(GoodCsv(5), "DRONE-3");
  const json rejected = Calibrate(BoxFacesCsv(6), "DRONE-3");
  const json second = Calibrate(GoodCsv(7), "DRONE-3");
  ASSERT_EQ(rejected["verdict"], "rejected");
  EXPECT_EQ(Served("DRONE-3"), second["id"]);

  // Revoke the latest: the device falls back to the previous accepted one (not the rejected).
  auto res = Decide(second["id"], "revoke", "board dropped during calibration");
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(Body(res)["job"]["state"], "revoked");
  EXPECT_EQ(Served("DRONE-3"), first["id"]);
  EXPECT_EQ(Decide(second["id"], "revoke", "again")->status, 409);         // already revoked
  EXPECT_EQ(Decide(first["id"], "accept", "it is fine")->status, 409);     // already accepted
  EXPECT_EQ(Decide(rejected["id"], "revoke", "not served")->status, 409);  // rejected: not served
  EXPECT_EQ(Decide(first["id"], "revoke", "")->status, 400);               // a reason is required
  res = Decide(first["id"], "revoke", "   ");
  EXPECT_EQ(res->status, 400);
  EXPECT_EQ(Body(res)["error"]["field"], "reason");
  res = Decide(first["id"], "revoke", std::string(501, 'x'));
  EXPECT_EQ(res->status, 400);
  EXPECT_EQ(Decide(999, "revoke", "no such job")->status, 404);

  // Accepting the rejected one overrides the gate: it is newer than the first, so it is served.
  res = Decide(rejected["id"], "accept", "coverage checked by hand on the rig");
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(Served("DRONE-3"), rejected["id"]);
  // Re-accepting the revoked one makes it the latest again.
  ASSERT_EQ(Decide(second["id"], "accept", "the drop was another board")->status, 200);
  EXPECT_EQ(Served("DRONE-3"), second["id"]);

  // The history keeps who, when and why.
  const json job = Body(server_.Client().Get(
      ("/api/v1/jobs/" + std::to_string(second["id"].get<int64_t>())).c_str()));
  ASSERT_EQ(job["events"].size(), 2u) << job.dump();
  EXPECT_EQ(job["events"][0]["action"], "revoke");
  EXPECT_EQ(job["events"][0]["reason"], "board dropped during calibration");
  EXPECT_EQ(job["events"][0]["actor"], "anonymous");
  EXPECT_FALSE(job["events"][0]["at"].get<std::string>().empty());
  EXPECT_EQ(job["events"][1]["action"], "accept");
  EXPECT_EQ(job["verdict"], "accepted");
  EXPECT_EQ(job["revoked"], false);
}

TEST_F(HttpGate, RevokingAFailedJobIsAConflict) {
  // Three positions cannot determine a triad: the job fails.
  auto res =
      server_.Client().Post(UploadPath("DRONE-4").c_str(),
                            "position,a0_x,a0_y,a0_z\np1,1,0,0\np2,0,1,0\np3,0,0,1\n", "text/csv");
  ASSERT_EQ(res->status, 201);
  const json failed = server_.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  ASSERT_EQ(failed["status"], "failed");
  res = Decide(failed["id"], "revoke", "bad");
  EXPECT_EQ(res->status, 409);
  EXPECT_NE(Body(res)["error"]["message"].get<std::string>().find("failed"), std::string::npos);
  EXPECT_EQ(Decide(failed["id"], "accept", "bad")->status, 409);
}

TEST_F(HttpGate, JobParameterServesThatJobOnlyForItsOwnDevice) {
  const json good = Calibrate(GoodCsv(8), "DRONE-5");
  const json box = Calibrate(BoxFacesCsv(9), "DRONE-5");
  Calibrate(GoodCsv(10), "DRONE-6");
  auto client = server_.Client();
  const std::string own = "/api/v1/devices/DRONE-5/calibration?job=";
  auto res = client.Get((own + std::to_string(box["id"].get<int64_t>())).c_str());
  ASSERT_EQ(res->status, 200) << res->body;  // asked for by id: served, and labelled rejected
  EXPECT_EQ(res->get_header_value("X-Calibd-State"), "rejected");
  EXPECT_EQ(Body(res)["state"], "rejected");
  EXPECT_EQ(Body(res)["job_id"], box["id"]);
  // ETag and 304 as for the latest.
  const std::string etag = res->get_header_value("ETag");
  EXPECT_EQ(
      client
          .Get((own + std::to_string(box["id"].get<int64_t>())).c_str(), {{"If-None-Match", etag}})
          ->status,
      304);
  // Another device's job: 404, never its calibration.
  res = client.Get(
      ("/api/v1/devices/DRONE-6/calibration?job=" + std::to_string(good["id"].get<int64_t>()))
          .c_str());
  EXPECT_EQ(res->status, 404);
  EXPECT_EQ(client.Get((own + "12345").c_str())->status, 404);
  EXPECT_EQ(client.Get((own + "abc").c_str())->status, 400);
  EXPECT_EQ(
      client.Get((own + std::to_string(good["id"].get<int64_t>()) + "&method=imu").c_str())->status,
      404);
}

TEST_F(HttpGate, AReuploadNeverMovesTheRecordingToItsOldDevice) {
  const std::string csv = GoodCsv(11);
  const json first = Calibrate(csv, "DRONE-7");
  ASSERT_EQ(Served("DRONE-7"), first["id"]);
  // The same bytes without a device: the recording is reused, the job is for no device.
  auto res = server_.Client().Post(UploadPath("").c_str(), csv, "text/csv");
  ASSERT_EQ(res->status, 201);
  EXPECT_EQ(Body(res)["recording"]["existed"], true);
  const json anonymous = server_.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  EXPECT_TRUE(anonymous["device"].is_null()) << anonymous.dump();
  EXPECT_EQ(Served("DRONE-7"), first["id"]);
  // Under another device: the job is that device's.
  const json other = Calibrate(csv, "DRONE-8");
  EXPECT_EQ(other["device"], "DRONE-8");
  EXPECT_EQ(other["recording_id"], first["recording_id"]);
  EXPECT_EQ(Served("DRONE-7"), first["id"]);
  EXPECT_EQ(Served("DRONE-8"), other["id"]);
}

TEST_F(HttpGate, ARejectedPcaJobCannotCalibrateAnArray) {
  const json box = Calibrate(BoxFacesCsv(14), "DRONE-11");
  ASSERT_EQ(box["state"], "rejected");
  const json config = {{"method", "array"},
                       {"geometry", {{"positions", {{0, 0, 0}}}}},
                       {"accel_noise", 0.04},
                       {"gyro_noise", 0.001},
                       {"accelerometer_calibration", {{"job", box["id"]}}}};
  auto res = server_.Client().Post(
      "/api/v1/jobs", json{{"recording_id", box["recording_id"]}, {"config", config}}.dump(),
      "application/json");
  ASSERT_EQ(res->status, 400) << res->body;
  EXPECT_EQ(Body(res)["error"]["field"], "accelerometer_calibration");
  EXPECT_NE(res->body.find("rejected by the acceptance gate"), std::string::npos) << res->body;
}

TEST(HttpGateAuth, DecisionsNeedTheTokenAndRecordIt) {
  testing::TempDir dir;
  const auto token_file = dir.path() / "token";
  std::ofstream(token_file) << "line-7-token-0123456789\n";
  ServeOptions options;
  options.token_file = token_file.string();
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  auto client = server.Client();
  client.set_bearer_token_auth("line-7-token-0123456789");
  auto res = client.Post(UploadPath("DRONE-9").c_str(), GoodCsv(12), "text/csv");
  ASSERT_EQ(res->status, 201);
  const int64_t id = Body(res)["job"]["id"].get<int64_t>();
  server.WaitForJob(id);
  const std::string path = "/api/v1/jobs/" + std::to_string(id) + "/revoke";
  const std::string body = json{{"reason", "wrong fixture"}}.dump();
  EXPECT_EQ(server.Client().Post(path.c_str(), body, "application/json")->status, 401);
  res = client.Post(path.c_str(), body, "application/json");
  ASSERT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(Body(res)["job"]["event"]["actor"], "token");
  EXPECT_EQ(server.Client().Get("/api/v1/devices/DRONE-9/calibration")->status, 404);
}

TEST(HttpGateDefaults, ServerWideLimitsApplyAndTheConfigOverridesThem) {
  testing::TempDir dir;
  const auto file = dir.path() / "acceptance.json";
  std::ofstream(file) << R"({"pca": {"max_scale_std": 1e-6}})";
  ServeOptions options;
  options.acceptance_file = file.string();
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  auto res = server.Client().Post(UploadPath("DRONE-10").c_str(), GoodCsv(13), "text/csv");
  ASSERT_EQ(res->status, 201);
  json job = server.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  EXPECT_EQ(job["verdict"], "rejected");
  EXPECT_EQ(job["result"]["verdict"]["limits"]["max_scale_std"], 1e-6);
  res = server.Client().Post(
      UploadPath("DRONE-10", "&acceptance=" + UrlEncode(R"({"max_scale_std": 0.02})")).c_str(),
      GoodCsv(13), "text/csv");
  ASSERT_EQ(res->status, 201) << res->body;
  job = server.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  EXPECT_EQ(job["verdict"], "accepted") << job["result"]["verdict"].dump();

  // A bad defaults file refuses to start, naming the key.
  std::ofstream(file) << R"({"pca": {"max_scale": 0.01}})";
  TestServer refused(options);
  EXPECT_NE(refused.error().find("max_scale"), std::string::npos) << refused.error();
}

// Issue 27: the ETag is the answer's, not the result's. Two jobs with the same result (a rerun of
// one recording) differ in job id, time and the C header's guard, so their ETags differ; and after
// a revoke, the revoked job's old ETag no longer answers 304: its body now says "revoked".
TEST_F(HttpGate, EveryAnswerHasItsOwnETagAndARevokeChangesIt) {
  const json first = Calibrate(GoodCsv(21), "DRONE-9");
  ASSERT_EQ(first["status"], "succeeded");
  auto client = server_.Client();
  const json rerun_request = {
      {"recording_id", first["recording_id"]},
      {"config",
       {{"method", "pca"}, {"magnitude", 9.80665}, {"bias", "estimate"}, {"device", "DRONE-9"}}}};
  auto res = client.Post("/api/v1/jobs", rerun_request.dump(), "application/json");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  const json second = server_.WaitForJob(Body(res)["job"]["id"].get<int64_t>());
  ASSERT_EQ(second["status"], "succeeded");
  ASSERT_EQ(first["result"]["parameters"], second["result"]["parameters"]);  // deterministic
  const std::string base = "/api/v1/devices/DRONE-9/calibration?format=h&job=";
  auto etag_of = [&](const json& job) {
    auto r = client.Get((base + std::to_string(job["id"].get<int64_t>())).c_str());
    EXPECT_TRUE(r && r->status == 200);
    return r ? r->get_header_value("ETag") : std::string();
  };
  const std::string etag1 = etag_of(first), etag2 = etag_of(second);
  EXPECT_NE(etag1, etag2);
  ASSERT_EQ(Decide(second["id"], "revoke", "fixture was loose")->status, 200);
  res = client.Get((base + std::to_string(second["id"].get<int64_t>())).c_str(),
                   {{"If-None-Match", etag2}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << "a revoked calibration kept by If-None-Match";
  EXPECT_NE(res->get_header_value("ETag"), etag2);
  // The latest falls back to the first job; its ETag as the flashing script saw it before the
  // revoke (of the second, then latest) does not match it either.
  res = client.Get("/api/v1/devices/DRONE-9/calibration?method=pca&format=h",
                   {{"If-None-Match", etag2}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_EQ(res->get_header_value("X-Calibd-Job"), std::to_string(first["id"].get<int64_t>()));
}

// Issue 27: a rejected or revoked result fetched with ?job= says so inside the file, so a saved
// copy never looks like a served calibration.
TEST_F(HttpGate, FilesOfResultsNotServedSaySoInside) {
  const json good = Calibrate(GoodCsv(22), "DRONE-10");
  const json box = Calibrate(BoxFacesCsv(23), "DRONE-10");
  ASSERT_EQ(box["verdict"], "rejected");
  auto client = server_.Client();
  auto get = [&](const json& job, const std::string& format) {
    auto r = client.Get(("/api/v1/devices/DRONE-10/calibration?format=" + format +
                         "&job=" + std::to_string(job["id"].get<int64_t>()))
                            .c_str());
    EXPECT_TRUE(r && r->status == 200) << (r ? r->body : "no answer");
    return r ? r->body : std::string();
  };
  const std::string rejected_csv = get(box, "csv"), rejected_h = get(box, "h");
  EXPECT_EQ(rejected_csv.rfind("# NOT FOR USE: job " + std::to_string(box["id"].get<int64_t>()) +
                                   "'s result was rejected by the acceptance gate",
                               0),
            0u)
      << rejected_csv.substr(0, 200);
  EXPECT_NE(rejected_h.find("_ACCEPTED 0"), std::string::npos);
  EXPECT_NE(rejected_h.find("NOT FOR USE: this result was rejected"), std::string::npos);
  const std::string good_csv = get(good, "csv"), good_h = get(good, "h");
  EXPECT_EQ(good_csv.find("NOT FOR USE"), std::string::npos);
  EXPECT_NE(good_h.find("_ACCEPTED 1"), std::string::npos);
  // Revoked: the same mark, with the word.
  ASSERT_EQ(Decide(good["id"], "revoke", "dropped on the floor")->status, 200);
  EXPECT_NE(get(good, "csv").find("was revoked by a person"), std::string::npos);
  EXPECT_NE(get(good, "h").find("_ACCEPTED 0"), std::string::npos);
}

// Issue 27: a revoke (or accept) without a body says that it needs a reason, not only that a
// length is required or that the JSON is invalid.
TEST_F(HttpGate, ADecisionWithoutABodyAsksForItsReason) {
  const json good = Calibrate(GoodCsv(24), "DRONE-11");
  const std::string path = "/api/v1/jobs/" + std::to_string(good["id"].get<int64_t>()) + "/revoke";
  auto client = server_.Client();
  auto res = client.Post(path.c_str(), "", "application/json");  // Content-Length: 0
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  EXPECT_NE(res->body.find("needs a reason"), std::string::npos) << res->body;
  EXPECT_EQ(Body(res)["error"]["field"], "reason") << res->body;
  for (const std::string action : {"accept", "cancel"}) {
    res = client.Post(
        ("/api/v1/jobs/" + std::to_string(good["id"].get<int64_t>()) + "/" + action).c_str(), "",
        "application/json");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << action << ": " << res->body;
    EXPECT_NE(res->body.find("a " + action + " needs a reason"), std::string::npos) << res->body;
  }
  // No Content-Length at all (curl -X POST without -d): 411, saying what to send.
  testing::RawConnection c(server_.port());
  ASSERT_TRUE(c.Send("POST " + path + " HTTP/1.1\r\nHost: x\r\n\r\n"));
  const std::string bytes = c.Receive();
  EXPECT_EQ(testing::StatusOf(bytes), 411) << bytes;
  EXPECT_NE(bytes.find("a revoke needs a reason"), std::string::npos) << bytes;
  EXPECT_EQ(Served("DRONE-11"), good["id"]);  // nothing was revoked
}

}  // namespace
}  // namespace calibd::server
