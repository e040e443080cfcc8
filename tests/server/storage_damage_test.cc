// calibd serve on damaged copies of its database file, on a full database, and with start-up
// mistakes (issue 27, "Storage damage" and "Start-up"): never a 200 with damaged bytes, /healthz
// 503 naming the damage, a re-upload repairs a recording, a full disk is 507 disk_full without
// SQL. Real processes, real sockets, one keep-alive client per server.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

#include "storage/store.h"
#include "tests/lib/server_process.h"
#include "tests/lib/unprivileged.h"
#include "tests/server/http_test_util.h"
#include "tests/lib/test_paths.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::ServerProcess;
using testing::TempDir;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// Flips one bit of the byte at `offset` in `marker`'s only occurrence in the file.
void FlipBitOf(const std::string& path, const std::string& marker, size_t offset) {
  const std::string file = ReadFile(path);
  const size_t at = file.find(marker);
  ASSERT_NE(at, std::string::npos) << marker;
  ASSERT_EQ(file.find(marker, at + 1), std::string::npos) << marker << " twice";
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekp(static_cast<std::streamoff>(at + offset));
  const char flipped = static_cast<char>(file[at + offset] ^ 0x01);
  f.write(&flipped, 1);
}

// A pca recording the upload route accepts, with `rows` positions.
std::string Csv(int rows) {
  std::string csv = "position,s1,s2,s3\n";
  for (int i = 1; i <= rows; ++i) {
    csv +=
        "p" + std::to_string(i) + "," + std::to_string(i) + "," + std::to_string(i % 7) + ",0.5\n";
  }
  return csv;
}

// Builds a database with one recording of `csv` for SN1 and a succeeded pca job whose accepted
// result holds `result_marker`; closes it with everything in the main file. The job's id in *job.
void MakeDatabase(const std::string& path, const std::string& csv, const std::string& result_marker,
                  int64_t* recording, int64_t* job) {
  std::unique_ptr<storage::Store> store;
  ASSERT_TRUE(storage::Store::Open(path, storage::StoreOptions(), &store).ok());
  storage::NewRecording r;
  r.data = csv;
  r.device = "SN1";
  r.layout = "pca_averaged";
  r.rows = 1;
  r.job = storage::NewJob{"pca", "SN1", "{}"};
  storage::RecordingInfo info;
  ASSERT_TRUE(store->PutRecording(r, &info, nullptr).ok());
  *recording = info.id;
  storage::JobInfo claimed;
  bool got = false;
  ASSERT_TRUE(store->ClaimJob("test-1", 60000, &claimed, &got).ok());
  ASSERT_TRUE(got);
  *job = claimed.id;
  const json result = {{"method", "pca"},
                       {"usable", true},
                       {"note", result_marker},
                       {"verdict", {{"status", "accepted"}}}};
  Status s = store->CompleteJob(claimed.id, "test-1", result.dump());
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(store->Checkpoint().ok());
}

httplib::Client KeepAlive(const ServerProcess& server) {
  httplib::Client client = server.Client();
  client.set_keep_alive(true);
  return client;
}

json Body(const httplib::Result& res) {
  return res ? json::parse(res->body, nullptr, /*allow_exceptions=*/false) : json();
}

TEST(StorageDamage, ADamagedResultIsNeverServedAndHealthzNamesIt) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  int64_t recording = 0, job = 0;
  MakeDatabase(db, Csv(40), "result-marker-abcdefgh", &recording, &job);
  {
    // Sound: served.
    ServerProcess server(db, {"--workers", "1"});
    ASSERT_GT(server.port(), 0) << server.log();
    httplib::Client client = KeepAlive(server);
    auto res = client.Get("/api/v1/devices/SN1/calibration?method=pca");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200) << res->body;
    EXPECT_EQ(client.Get("/healthz")->status, 200);
  }
  FlipBitOf(db, "result-marker-abcdefgh", 10);
  ServerProcess server(db, {"--workers", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  httplib::Client client = KeepAlive(server);
  for (const std::string& path :
       {std::string("/api/v1/devices/SN1/calibration?method=pca"),
        std::string("/api/v1/devices/SN1/calibration?method=pca&format=csv"),
        std::string("/api/v1/devices/SN1/calibration?job=") + std::to_string(job)}) {
    auto res = client.Get(path.c_str());
    ASSERT_TRUE(res) << path;
    EXPECT_EQ(res->status, 500) << path << ": " << res->body;
    const json body = Body(res);
    EXPECT_EQ(body["error"]["reason"], "storage_damaged") << res->body;
    EXPECT_NE(body["error"]["message"].get<std::string>().find("job " + std::to_string(job)),
              std::string::npos)
        << res->body;
    EXPECT_EQ(res->get_header_value("ETag"), "") << path;
  }
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 503) << health->body;
  const json h = Body(health);
  EXPECT_EQ(h["status"], "damaged") << health->body;
  EXPECT_NE(h["problems"].dump().find("result of job " + std::to_string(job)), std::string::npos)
      << health->body;
}

TEST(StorageDamage, ADamagedRecordingIsNotServedAndAReuploadRepairsIt) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  const std::string csv = Csv(3000);  // ~50 KB
  int64_t recording = 0, job = 0;
  MakeDatabase(db, csv, "result-marker-ijklmnop", &recording, &job);
  FlipBitOf(db, "\np2345,2345,", 3);  // a digit of one row: still a CSV, other bytes
  ServerProcess server(db, {"--workers", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  httplib::Client client = KeepAlive(server);
  const std::string data = "/api/v1/recordings/" + std::to_string(recording) + "/data";
  auto res = client.Get(data.c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 500) << res->body.substr(0, 200);
  EXPECT_EQ(Body(res)["error"]["reason"], "storage_damaged") << res->body.substr(0, 200);
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 503) << health->body;
  EXPECT_NE(health->body.find("recording " + std::to_string(recording) + " is damaged"),
            std::string::npos)
      << health->body;

  // A rerun of the damaged copy fails as damaged: it is never calibrated.
  auto rerun = client.Post(
      "/api/v1/jobs", json{{"recording_id", recording}, {"config", {{"method", "pca"}}}}.dump(),
      "application/json");
  ASSERT_TRUE(rerun);
  ASSERT_EQ(rerun->status, 202) << rerun->body;
  const int64_t rerun_id = Body(rerun)["job"]["id"].get<int64_t>();
  json rerun_job;
  for (int i = 0; i < 500; ++i) {
    rerun_job = testing::GetJob(client, rerun_id);
    if (rerun_job.value("status", "") == "failed" || rerun_job.value("status", "") == "succeeded")
      break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(rerun_job.value("status", ""), "failed") << rerun_job.dump();
  EXPECT_EQ(rerun_job["error"].value("reason", ""), "storage_damaged") << rerun_job.dump();

  // The same bytes again: the stored copy is repaired.
  auto upload = client.Post("/api/v1/recordings?method=pca&device=SN1", csv, "text/csv");
  ASSERT_TRUE(upload);
  ASSERT_TRUE(upload->status == 200 || upload->status == 201) << upload->body;
  EXPECT_EQ(Body(upload)["recording"]["existed"], true) << upload->body;
  res = client.Get(data.c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_TRUE(res->body == csv);
  testing::WaitUntilIdle(client, 10000);
  health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200) << health->body;
}

TEST(StorageDamage, AStructureCheckAtStartFindsDamageThatTheQueueDoesNotSee) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  int64_t recording = 0, job = 0;
  MakeDatabase(db, Csv(3000), "result-marker-qrstuvwx", &recording, &job);
  // The first 4 bytes of the overflow page holding this row point to the next page: nowhere.
  const std::string file = ReadFile(db);
  const size_t at = file.find("\np2345,2345,");
  ASSERT_NE(at, std::string::npos);
  {
    std::fstream f(db, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(at / 4096 * 4096));
    f.write("\x7f\xff\xff\xff", 4);
  }
  ServerProcess server(db, {"--workers", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  httplib::Client client = KeepAlive(server);
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 503) << health->body;
  EXPECT_EQ(Body(health)["status"], "damaged") << health->body;
  EXPECT_NE(health->body.find("quick_check"), std::string::npos) << health->body;
  EXPECT_NE(server.log().find("is damaged (quick_check)"), std::string::npos) << server.log();
  // What is sound is still served.
  auto res = client.Get("/api/v1/devices/SN1/calibration?method=pca");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
}

TEST(StorageDamage, TheScheduledStructureCheckFindsDamageDoneWhileTheServerRuns) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  int64_t recording = 0, job = 0;
  MakeDatabase(db, Csv(3000), "result-marker-yzabcdef", &recording, &job);
  ServerProcess server(db, {"--workers", "1", "--check-seconds", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  httplib::Client client = KeepAlive(server);
  ASSERT_EQ(client.Get("/healthz")->status, 200);
  const std::string file = ReadFile(db);
  const size_t at = file.find("\np2345,2345,");
  ASSERT_NE(at, std::string::npos);
  {
    std::fstream f(db, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(at / 4096 * 4096));
    f.write("\x7f\xff\xff\xff", 4);
  }
  int status = 0;
  std::string body;
  for (int i = 0; i < 250 && status != 503; ++i) {  // the check runs every second
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    auto health = client.Get("/healthz");
    ASSERT_TRUE(health);
    status = health->status;
    body = health->body;
  }
  EXPECT_EQ(status, 503) << body;
  EXPECT_NE(body.find("quick_check"), std::string::npos) << body;
}

TEST(StorageDamage, AFullDatabaseAnswers507DiskFullWithoutSqlAndHealthzSaysSo) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ServerProcess server(db, {"--workers", "1", "--db-max-pages", "80"});
  ASSERT_GT(server.port(), 0) << server.log();
  httplib::Client client = KeepAlive(server);
  int status = 0;
  std::string answer;
  for (int i = 0; i < 60; ++i) {
    std::string csv = Csv(1500);
    csv += "q" + std::to_string(i) + ",1,2,3\n";  // distinct bytes every time
    auto res = client.Post("/api/v1/recordings?method=pca&device=SN1", csv, "text/csv");
    ASSERT_TRUE(res);
    status = res->status;
    answer = res->body;
    if (status != 201 && status != 200) break;
  }
  ASSERT_EQ(status, 507) << answer;
  const json body = json::parse(answer, nullptr, false);
  EXPECT_EQ(body["error"]["reason"], "disk_full") << answer;
  for (const char* sql : {"INSERT", "SELECT", "UPDATE", "VALUES", "`", "?1"}) {
    EXPECT_EQ(answer.find(sql), std::string::npos) << sql << " in " << answer;
  }
  auto health = client.Get("/healthz");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 503) << health->body;
  EXPECT_EQ(Body(health)["status"], "disk_full") << health->body;
}

// Runs `calibd ARGS` (`command`: calibd, maybe behind a prefix) to its end; its exit status and
// what it wrote.
int RunCalibd(const std::string& args, std::string* output,
              const std::string& command = calibd::test_paths::CalibdBinary()) {
  FILE* pipe = ::popen((command + " " + args + " 2>&1").c_str(), "r");
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) output->append(buf, n);
  return ::pclose(pipe);
}

TEST(StartUp, ADbPathThatIsADirectorySaysSo) {
  TempDir dir;
  std::string out;
  const int status = RunCalibd("serve --listen 127.0.0.1:0 --db " + dir.path().string(), &out);
  EXPECT_NE(status, 0) << out;
  EXPECT_NE(out.find("is a directory"), std::string::npos) << out;
  EXPECT_NE(out.find("calibd.db"), std::string::npos) << out;
}

// The file's mode says read-only: calibd run by a user it binds (as root: nobody, by setpriv).
TEST(StartUp, AReadOnlyDbFileSaysSo) {
  TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  {
    std::unique_ptr<storage::Store> store;
    ASSERT_TRUE(storage::Store::Open(db, storage::StoreOptions(), &store).ok());
  }
  ASSERT_EQ(::chmod(db.c_str(), 0444), 0);
  ASSERT_TRUE(unprivileged::OpenFolderToNobody(dir.path().string()));
  std::string as_nobody, why;
  if (!unprivileged::UnprivilegedCommand(db, &as_nobody, &why)) GTEST_SKIP() << why;
  std::string out;
  const int status =
      RunCalibd("serve --listen 127.0.0.1:0 --db " + db, &out, as_nobody + calibd::test_paths::CalibdBinary());
  EXPECT_NE(status, 0) << out;
  EXPECT_NE(out.find("read-only"), std::string::npos) << out;
  EXPECT_EQ(out.find("unable to open database file"), std::string::npos) << out;
}

TEST(StartUp, ATokenWithSpacesAroundItIsTrimmedAndSaid) {
  TempDir dir;
  const std::string token = "0123456789abcdef-token";
  const std::string token_file = (dir.path() / "token").string();
  {
    std::ofstream out(token_file);
    out << "   " << token << " \t\n";
  }
  ServerProcess server((dir.path() / "calibd.db").string(), {"--token-file", token_file});
  ASSERT_GT(server.port(), 0) << server.log();
  EXPECT_NE(server.log().find("whitespace removed from the token"), std::string::npos)
      << server.log();
  httplib::Client client = KeepAlive(server);
  const std::string reason = json{{"reason", "test"}}.dump();
  auto refused = client.Post("/api/v1/jobs/99/cancel", reason, "application/json");
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 401);
  client.set_bearer_token_auth(token);
  auto res = client.Post("/api/v1/jobs/99/cancel", reason, "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 404) << res->body;  // authorized: there is no job 99
}

}  // namespace
}  // namespace calibd::server
