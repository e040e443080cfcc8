// Every job ends (issue #20), tested on the real `calibd serve` process: the time limit
// (--job-seconds, config job_seconds), POST /api/v1/jobs/{id}/cancel (in this process and from
// another process on the same database), and SIGTERM: running jobs stopped past the grace period
// and released only once their computation returned, exit within grace + 1 s, a second SIGTERM
// exits at once, and no job is ever computed by two processes.
//
// The long jobs are array jobs (BCD with a huge iteration cap and tolerance 0), whose loops poll
// the job's StopToken; any method that polls works the same.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>
#include <tuple>
#include <utility>

#include "methods/array/array_method.h"
#include "storage/store.h"
#include "tests/lib/sanitizer.h"
#include "tests/lib/server_process.h"
#include "tests/lib/test_paths.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::GetJob;
using testing::ServerProcess;
using Clock = std::chrono::steady_clock;

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

double SecondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

json WaitForStatus(ServerProcess& server, int64_t id, const std::set<std::string>& statuses,
                   int timeout_ms = 120000) {
  auto client = server.Client();
  json job;
  for (int waited = 0; waited < timeout_ms; waited += 10) {
    job = GetJob(client, id);
    if (job.is_object() && statuses.count(job["status"].get<std::string>())) return job;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ADD_FAILURE() << "job " << id << " never reached the expected state: " << job.dump();
  return job;
}

// An array recording with a config whose BCD runs `iterations` sweeps (tolerance 0: no early
// stop); `extra` is merged into the config.
httplib::MultipartFormDataItems ArrayUpload(uint64_t seed, int64_t iterations,
                                            const json& extra = json::object()) {
  ArraySimulationFileOptions sim;
  sim.samples = 1000;
  sim.seed = seed;
  std::string csv;
  json config, truth;
  EXPECT_TRUE(SimulateArrayFiles(sim, &csv, &config, &truth).ok());
  config["solver"] = "bcd";
  config["max_iterations"] = iterations;
  config["tolerance"] = 0;
  config["device"] = "LONG";
  for (auto& [key, value] : extra.items()) config[key] = value;
  return {{"recording", csv, "long.csv", "text/csv"},
          {"config", config.dump(), "", "application/json"}};
}

// A job that runs far longer than any test waits (stopped by the tests).
constexpr int64_t kEndless = 1000000;  // the largest max_iterations

int64_t Upload(ServerProcess& server, const httplib::MultipartFormDataItems& items,
               const httplib::Headers& headers = {}) {
  auto res = server.Client().Post("/api/v1/recordings", headers, items);
  EXPECT_TRUE(res);
  if (!res) return 0;
  EXPECT_EQ(res->status, 201) << res->body;
  if (res->status != 201) return 0;
  return json::parse(res->body)["job"]["id"].get<int64_t>();
}

storage::JobInfo StoredJob(const std::string& db, int64_t id) {
  std::unique_ptr<storage::Store> store;
  EXPECT_TRUE(storage::Store::Open(db, {}, &store).ok());
  storage::JobInfo job;
  if (store) {
    EXPECT_TRUE(store->GetJob(id, &job).ok());
  }
  return job;
}

httplib::Result PostCancel(ServerProcess& server, int64_t id, const std::string& body,
                           const std::string& media = "application/json",
                           const httplib::Headers& headers = {}) {
  return server.Client().Post(("/api/v1/jobs/" + std::to_string(id) + "/cancel").c_str(), headers,
                              body, media.c_str());
}

TEST(StopProcess, AJobPastJobSecondsFailsWithReasonDeadlineAndItsPartialDiagnostics) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ServerProcess server(db, {"--workers", "1", "--job-seconds", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  const int64_t id = Upload(server, ArrayUpload(1, kEndless));
  ASSERT_GT(id, 0);
  json job = WaitForStatus(server, id, {"failed", "succeeded"}, 30000);
  ASSERT_EQ(job["status"], "failed") << job.dump();
  EXPECT_EQ(job["error"]["reason"], "deadline") << job.dump();
  EXPECT_EQ(job["error"]["code"], "stopped");
  EXPECT_NE(job["error"]["message"].get<std::string>().find("time limit of 1 s"), std::string::npos)
      << job.dump();
  // Partial diagnostics: what the method found before it was stopped.
  ASSERT_TRUE(job["error"]["diagnostics"].is_object()) << job.dump();
  EXPECT_EQ(job["error"]["diagnostics"]["usable"], false);
  const storage::JobInfo stored = StoredJob(db, id);
  const int64_t ran_ms = stored.finished_at_ms - stored.started_at_ms;
  EXPECT_GE(ran_ms, 1000);
  EXPECT_LT(ran_ms, 1000 + 2000) << "stopped " << ran_ms - 1000 << " ms after its limit";
  // Never retried: still failed after one attempt a while later.
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  auto client = server.Client();
  job = GetJob(client, id);
  EXPECT_EQ(job["status"], "failed");
  EXPECT_EQ(job["attempts"], 1);
  // The metrics count it as failed with its reason.
  auto metrics = server.Client().Get("/metrics");
  ASSERT_TRUE(metrics);
  EXPECT_NE(metrics->body.find("reason=\"deadline\""), std::string::npos) << metrics->body;
  server.Signal(SIGTERM);
}

// `calibd calibrate --job-seconds`: exit 4 and a message saying the limit was reached; the
// config's job_seconds lowers it; a bad value is bad input (exit 2).
TEST(StopProcess, CalibrateStopsAtItsTimeLimitWithExitCodeFour) {
  testing::TempDir dir;
  const auto items = ArrayUpload(13, kEndless);
  const std::string csv = (dir.path() / "r.csv").string(), cfg = (dir.path() / "c.json").string();
  std::ofstream(csv) << items[0].content;
  std::ofstream(cfg) << items[1].content;
  auto run = [&](const std::string& args, std::string* err) {
    const std::string err_file = (dir.path() / "err.txt").string();
    const std::string cmd = calibd::test_paths::CalibdBinary() + " calibrate " + csv +
                            " --config " + cfg + " " + args + " >/dev/null 2>" + err_file;
    const auto start = Clock::now();
    const int status = std::system(cmd.c_str());
    const double seconds = SecondsSince(start);
    std::ifstream in(err_file);
    err->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    EXPECT_TRUE(WIFEXITED(status));
    return std::make_pair(WEXITSTATUS(status), seconds);
  };
  std::string err;
  auto [code, seconds] = run("--job-seconds 0.5", &err);
  EXPECT_EQ(code, 4) << err;
  EXPECT_LT(seconds, 0.5 + 2.0) << err;
  EXPECT_NE(err.find("the time limit of 0.5 s (--job-seconds) was reached"), std::string::npos)
      << err;
  EXPECT_NE(err.find("reason: deadline"), std::string::npos) << err;
  std::tie(code, seconds) = run("--job-seconds -1", &err);
  EXPECT_EQ(code, 2) << err;  // CLI11 refuses it (exit 2 as for any bad option)
  // The config's job_seconds, lower than the flag.
  json config = json::parse(items[1].content);
  config["job_seconds"] = 0.3;
  std::ofstream(cfg) << config.dump();
  std::tie(code, seconds) = run("--job-seconds 60", &err);
  EXPECT_EQ(code, 4) << err;
  EXPECT_NE(err.find("the time limit of 0.3 s (config job_seconds)"), std::string::npos) << err;
  config["job_seconds"] = "x";
  std::ofstream(cfg) << config.dump();
  std::tie(code, seconds) = run("", &err);
  EXPECT_EQ(code, 2) << err;
  EXPECT_NE(err.find("job_seconds"), std::string::npos) << err;
}

TEST(StopProcess, ConfigJobSecondsMayOnlyLowerTheServersLimit) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ServerProcess server(db, {"--workers", "1", "--job-seconds", "30"});
  ASSERT_GT(server.port(), 0) << server.log();
  // Bad values are refused at upload, naming the key (and the server's limit when too large).
  for (const json& bad : {json(0), json(-1), json("x"), json(31), json(1e12)}) {
    auto res =
        server.Client().Post("/api/v1/recordings", ArrayUpload(7, 10, json{{"job_seconds", bad}}));
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 400) << bad.dump() << ": " << res->body;
    const json body = json::parse(res->body, nullptr, false);
    EXPECT_EQ(body["error"]["field"], "job_seconds") << res->body;
    if (bad == json(31)) {
      EXPECT_NE(res->body.find("at most 30 s"), std::string::npos) << res->body;
    }
  }
  // A lower limit applies: 0.5 s instead of the server's 30 s.
  const int64_t id = Upload(server, ArrayUpload(8, kEndless, json{{"job_seconds", 0.5}}));
  ASSERT_GT(id, 0);
  const json job = WaitForStatus(server, id, {"failed", "succeeded"}, 20000);
  EXPECT_EQ(job["error"]["reason"], "deadline") << job.dump();
  EXPECT_NE(job["error"]["message"].get<std::string>().find("time limit of 0.5 s"),
            std::string::npos)
      << job.dump();
  server.Signal(SIGTERM);
}

TEST(StopProcess, CancelEndsARunningJobWithinASecondAndAQueuedOneAtOnce) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ServerProcess server(db, {"--workers", "1"});
  ASSERT_GT(server.port(), 0) << server.log();
  const int64_t running = Upload(server, ArrayUpload(2, kEndless));
  const int64_t queued = Upload(server, ArrayUpload(3, kEndless));
  ASSERT_GT(queued, 0);
  WaitForStatus(server, running, {"running"}, 30000);

  // Bad requests change nothing.
  auto res = PostCancel(server, queued, "not json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  res = PostCancel(server, queued, "{}");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  EXPECT_NE(res->body.find("'reason' is required"), std::string::npos) << res->body;
  res = PostCancel(server, queued, R"({"reason": "  "})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  res = PostCancel(server, queued, R"({"reason": 5})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  res = PostCancel(server, queued, R"({"reason": "x", "force": true})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  res = PostCancel(server, queued, "reason=x", "text/plain");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 415) << res->body;
  res = PostCancel(server, 987654, R"({"reason": "x"})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 404) << res->body;
  res = server.Client().Get(("/api/v1/jobs/" + std::to_string(queued) + "/cancel").c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 405);
  auto client = server.Client();
  EXPECT_EQ(GetJob(client, queued)["status"], "queued");

  // The queued job fails at once.
  res = PostCancel(server, queued, R"({"reason": "uploaded twice"})");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200) << res->body;
  json body = json::parse(res->body);
  EXPECT_EQ(body["job"]["status"], "failed");
  EXPECT_EQ(body["job"]["error"]["reason"], "cancelled");
  EXPECT_EQ(body["job"]["event"]["action"], "cancel");

  // The running one ends within a second.
  const int64_t asked_ms = NowMs();
  res = PostCancel(server, running, R"({"reason": "wrong board"})");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  json job = WaitForStatus(server, running, {"failed", "succeeded"}, 10000);
  ASSERT_EQ(job["status"], "failed") << job.dump();
  EXPECT_EQ(job["error"]["reason"], "cancelled");
  EXPECT_NE(job["error"]["message"].get<std::string>().find("cancelled by anonymous: wrong board"),
            std::string::npos)
      << job.dump();
  EXPECT_TRUE(job["error"]["diagnostics"].is_object()) << job.dump();
  ASSERT_EQ(job["events"].size(), 1u) << job.dump();
  EXPECT_EQ(job["events"][0]["action"], "cancel");
  EXPECT_EQ(job["events"][0]["reason"], "wrong board");
  const storage::JobInfo stored = StoredJob(db, running);
  EXPECT_LT(stored.finished_at_ms - asked_ms, 1000) << server.log();
  EXPECT_EQ(stored.attempts, 1);

  // Finished jobs: 409 naming the status.
  res = PostCancel(server, running, R"({"reason": "again"})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 409) << res->body;
  EXPECT_NE(res->body.find("failed"), std::string::npos) << res->body;
  server.Signal(SIGTERM);
}

TEST(StopProcess, ACancelThroughAnotherProcessOnTheDatabaseStopsTheJobWhereItRuns) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ServerProcess worker(db, {"--workers", "1"});
  ASSERT_GT(worker.port(), 0) << worker.log();
  const int64_t id = Upload(worker, ArrayUpload(4, kEndless));
  WaitForStatus(worker, id, {"running"}, 30000);
  ServerProcess other(db, {"--workers", "1"});
  ASSERT_GT(other.port(), 0) << other.log();
  const int64_t asked_ms = NowMs();
  auto res = PostCancel(other, id, R"({"reason": "from the other host"})");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  const json job = WaitForStatus(worker, id, {"failed", "succeeded"}, 10000);
  EXPECT_EQ(job["error"]["reason"], "cancelled") << job.dump();
  const storage::JobInfo stored = StoredJob(db, id);
  EXPECT_LT(stored.finished_at_ms - asked_ms, 1000) << worker.log();
  other.Signal(SIGTERM);
  worker.Signal(SIGTERM);
}

TEST(StopProcess, WithATokenCancelNeedsItInTheHeaderOrTheJobPagesForm) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  const std::string token = "0123456789abcdef-stop";
  const std::string token_file = (dir.path() / "token").string();
  std::ofstream(token_file) << token << "\n";
  ServerProcess server(db, {"--workers", "1", "--token-file", token_file});
  ASSERT_GT(server.port(), 0) << server.log();
  const httplib::Headers auth = {{"Authorization", "Bearer " + token}};
  const int64_t running = Upload(server, ArrayUpload(5, kEndless), auth);
  const int64_t queued = Upload(server, ArrayUpload(6, kEndless), auth);
  ASSERT_GT(queued, 0);
  WaitForStatus(server, running, {"running"}, 30000);

  // The running job's page: its elapsed time and a Cancel form asking for the token.
  auto page = server.Client().Get(("/jobs/" + std::to_string(running)).c_str());
  ASSERT_TRUE(page);
  EXPECT_NE(page->body.find("class=\"elapsed\""), std::string::npos) << page->body;
  EXPECT_NE(page->body.find("action=\"/api/v1/jobs/" + std::to_string(running) + "/cancel\""),
            std::string::npos);
  EXPECT_NE(page->body.find("name=\"token\""), std::string::npos);

  auto res = PostCancel(server, queued, R"({"reason": "x"})");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 401) << res->body;
  res = PostCancel(server, queued, R"({"reason": "x"})", "application/json",
                   {{"Authorization", "Bearer wrong-token-0000000"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 401) << res->body;
  res = PostCancel(server, queued, "reason=x&token=wrong-token-0000000",
                   "application/x-www-form-urlencoded");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 401) << res->body;
  res = PostCancel(server, queued, "reason=x", "application/x-www-form-urlencoded");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 401) << res->body;
  res = PostCancel(server, queued, "reason=&token=" + token, "application/x-www-form-urlencoded");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 400) << res->body;
  auto client = server.Client();
  EXPECT_EQ(GetJob(client, queued)["status"], "queued");

  // A form another site's page made the browser post is refused, token or not.
  res = PostCancel(server, queued, "reason=x&token=" + token, "application/x-www-form-urlencoded",
                   {{"Origin", "http://evil.example"}});
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 403) << res->body;
  EXPECT_EQ(GetJob(client, queued)["status"], "queued");

  // The form with the token: 303 back to the job page; the header works too.
  res = PostCancel(server, queued, "reason=not+needed&token=" + token,
                   "application/x-www-form-urlencoded");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 303) << res->body;
  EXPECT_EQ(res->get_header_value("Location"), "/jobs/" + std::to_string(queued));
  json job = GetJob(client, queued);
  EXPECT_EQ(job["status"], "failed");
  EXPECT_EQ(job["error"]["message"], "cancelled by token: not needed");
  res = PostCancel(server, running, R"({"reason": "done"})", "application/json", auth);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 202) << res->body;
  job = WaitForStatus(server, running, {"failed"}, 10000);
  EXPECT_EQ(job["error"]["reason"], "cancelled");
  server.Signal(SIGTERM);
}

// How many BCD sweeps take at least about `seconds` here: the fastest of two short probe jobs
// (other load only slows a probe down; a probe slowed by it and a job run after the load ended
// made the job end before the signal, 1 run in 2 beside a heavy test).
int64_t IterationsFor(const std::string& db_dir, double seconds) {
  ServerProcess server(db_dir + "/probe.db", {"--workers", "1"});
  if (server.port() == 0) return 0;
  const int64_t iterations = 200;
  double per_iteration = std::numeric_limits<double>::infinity();
  for (int probe = 0; probe < 2; ++probe) {
    const int64_t id = Upload(server, ArrayUpload(11 + probe, iterations));
    WaitForStatus(server, id, {"succeeded", "failed"}, 120000);
    const storage::JobInfo job = StoredJob(db_dir + "/probe.db", id);
    per_iteration =
        std::min(per_iteration,
                 std::max<double>(job.finished_at_ms - job.started_at_ms, 1) / 1e3 / iterations);
  }
  server.Signal(SIGTERM);
  return std::max<int64_t>(iterations, static_cast<int64_t>(seconds / per_iteration));
}

TEST(StopProcess, SigtermPastTheGraceStopsTheJobExitsWithinOneSecondAndTheRestartCompletesIt) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  // A job of about 8 s: longer than the grace period, short enough to complete after restart.
  const int64_t iterations = IterationsFor(dir.path().string(), 8);
  ASSERT_GT(iterations, 0);
  int64_t id = 0;
  int64_t stopped_ms = 0;
  {
    // No parsed-columns cache: the job computes at the signal (see ASecondSigtermExitsAtOnce).
    ServerProcess server(db,
                         {"--workers", "1", "--grace-seconds", "2", "--column-cache-bytes", "0"});
    ASSERT_GT(server.port(), 0) << server.log();
    id = Upload(server, ArrayUpload(9, iterations));
    WaitForStatus(server, id, {"running"}, 30000);
    const auto signalled = Clock::now();
    const int status = server.Signal(SIGTERM);
    const double took = SecondsSince(signalled);
    stopped_ms = NowMs();
    EXPECT_TRUE(WIFEXITED(status)) << server.log();
    EXPECT_LT(took, 3.0) << server.log();
    EXPECT_GE(took, 2.0) << server.log();  // the grace period was given
    EXPECT_NE(server.log().find("released job " + std::to_string(id) + " after its computation"),
              std::string::npos)
        << server.log();
  }
  storage::JobInfo job = StoredJob(db, id);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.attempts, 0);  // a release does not count
  EXPECT_EQ(job.lease_owner, "");
  ServerProcess again(db, {"--workers", "1"});
  ASSERT_GT(again.port(), 0) << again.log();
  const json done = WaitForStatus(again, id, {"succeeded", "failed"}, 180000);
  EXPECT_EQ(done["status"], "succeeded") << done.dump();
  job = StoredJob(db, id);
  EXPECT_EQ(job.attempts, 1);
  EXPECT_GE(job.started_at_ms, stopped_ms);  // claimed only after the old process had stopped
  again.Signal(SIGTERM);
}

TEST(StopProcess, NoJobIsComputedByTwoProcessesAcrossSigtermAndKillAndRestart) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  // Two processes on one database; the one computing the job is stopped (SIGTERM, grace 0)
  // while the other polls for work: the other may claim the job only after the first released
  // it, which it does only once its computation has returned.
  ServerProcess first(db, {"--workers", "1", "--grace-seconds", "0"});
  ASSERT_GT(first.port(), 0) << first.log();
  const int64_t id = Upload(first, ArrayUpload(10, kEndless));
  WaitForStatus(first, id, {"running"}, 30000);
  ServerProcess second(db, {"--workers", "1"});
  ASSERT_GT(second.port(), 0) << second.log();
  ASSERT_EQ(StoredJob(db, id).lease_owner.empty(), false);
  const std::string first_owner = StoredJob(db, id).lease_owner;
  const auto signalled = Clock::now();
  const int64_t signalled_ms = NowMs();
  first.Signal(SIGTERM);
  EXPECT_LT(SecondsSince(signalled), 1.5) << first.log();
  const std::string log = first.log();
  const size_t released = log.find("released job " + std::to_string(id) + " after its computation");
  ASSERT_NE(released, std::string::npos) << log;
  // The second process takes it over (its own worker id) once the first released it. The release
  // comes after the computation returned and before the first process exits, so the claim may
  // precede the exit the test observes (by the exit's own time): the bound is the signal, before
  // which the first one's lease was live and the job running on it.
  json job = WaitForStatus(second, id, {"running"}, 10000);
  storage::JobInfo stored = StoredJob(db, id);
  EXPECT_NE(stored.lease_owner, first_owner);
  EXPECT_GE(stored.started_at_ms, signalled_ms);
  EXPECT_EQ(stored.attempts, 1);
  // kill -9 of the second one: a third process on the same host takes the job back at once and
  // runs it; the killed one computes nothing any more.
  second.Signal(SIGKILL);
  ServerProcess third(db, {"--workers", "1"});
  ASSERT_GT(third.port(), 0) << third.log();
  job = WaitForStatus(third, id, {"running"}, 10000);
  stored = StoredJob(db, id);
  EXPECT_EQ(stored.attempts, 2);
  auto client = third.Client();
  auto res = client.Post(("/api/v1/jobs/" + std::to_string(id) + "/cancel").c_str(),
                         R"({"reason": "end of test"})", "application/json");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 202) << res->body;
  WaitForStatus(third, id, {"failed"}, 10000);
  third.Signal(SIGTERM);
}

TEST(StopProcess, ASecondSigtermExitsAtOnce) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  // No parsed-columns cache: a job waiting for the upload's background build at the signal is
  // sent back to the queue at once (by design, ColumnCacheTest.AJobWaitingForABuild...), and
  // this test is about a job whose computation runs (that race failed 1 CI run under ASan).
  ServerProcess server(db,
                       {"--workers", "1", "--grace-seconds", "120", "--column-cache-bytes", "0"});
  ASSERT_GT(server.port(), 0) << server.log();
  const int64_t id = Upload(server, ArrayUpload(12, kEndless));
  WaitForStatus(server, id, {"running"}, 30000);
  server.Send(SIGTERM);
  // The second signal only once the first was taken (its log line), whatever the machine's load.
  for (int i = 0; i < 1000 && server.log().find("shutting down") == std::string::npos; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_NE(server.log().find("shutting down"), std::string::npos) << server.log();
  const auto again = Clock::now();
  const int status = server.Signal(SIGTERM);
  // At once: against the 120 s grace the first signal gave (3 s: a loaded machine's exit).
  EXPECT_LT(SecondsSince(again), 3.0) << server.log();
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 128 + SIGTERM) << server.log();
  EXPECT_NE(server.log().find("second signal"), std::string::npos) << server.log();
  // Its job keeps its lease (nobody else computes it meanwhile); a restart on this host takes it
  // back at once (the process is gone) and cancelling it ends it.
  EXPECT_EQ(StoredJob(db, id).status, JobStatus::kRunning);
  ServerProcess restarted(db, {"--workers", "1"});
  ASSERT_GT(restarted.port(), 0) << restarted.log();
  WaitForStatus(restarted, id, {"running"}, 10000);
  auto client = restarted.Client();
  auto res = client.Post(("/api/v1/jobs/" + std::to_string(id) + "/cancel").c_str(),
                         R"({"reason": "end of test"})", "application/json");
  ASSERT_TRUE(res);
  WaitForStatus(restarted, id, {"failed"}, 10000);
  restarted.Signal(SIGTERM);
}

}  // namespace
}  // namespace calibd::server
