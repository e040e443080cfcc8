// Real `calibd serve` processes on one PostgreSQL database (serve --db postgresql://...): several
// hosts sharing the queue under kill -9, and a database that goes away and comes back. The
// database is a throw-away cluster this program starts (tests/storage/pg_test_cluster.h); the
// servers are the built binary, started with fork/exec on free ports (tests/lib/server_process.h),
// each with the test's temporary folder as its TMPDIR, where a PostgreSQL calibd stages uploads.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <thread>

#include "methods/array/array_method.h"
#include "methods/pca/pca_method.h"
#include "storage/pg_conn.h"
#include "storage/store.h"
#include "tests/lib/sanitizer.h"
#include "tests/lib/server_process.h"
#include "tests/server/http_test_util.h"
#include "tests/storage/pg_test_cluster.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using storage::testing::PgTestCluster;
using testing::ServerProcess;
using testing::WaitUntilIdle;

httplib::MultipartFormDataItems PcaUpload(uint64_t seed, std::string* csv_out) {
  core::PcaSimulationOptions sim;
  sim.seed = seed;
  sim.positions = 30;
  std::string csv;
  json config, truth;
  EXPECT_TRUE(SimulatePcaFiles(sim, &csv, &config, &truth).ok());
  config["device"] = "PG-" + std::to_string(seed % 3);
  if (csv_out != nullptr) *csv_out = csv;
  return {{"recording", csv, "r.csv", "text/csv"},
          {"config", config.dump(), "", "application/json"}};
}

class PgServe : public ::testing::Test {
 protected:
  void SetUp() override {
    cluster_ = PgTestCluster::Get();
    ASSERT_NE(cluster_, nullptr);
    uri_ = cluster_->NewDatabase();
  }
  PgTestCluster* cluster_ = nullptr;
  std::string uri_;
  testing::TempDir tmp_;  // the servers' TMPDIR
};

TEST_F(PgServe, DatabaseGoneGivesServiceUnavailableAndCalibdReconnectsByItself) {
  ServerProcess server(uri_, {"--workers", "1"}, tmp_.path().string());
  ASSERT_GT(server.port(), 0) << server.log();
  auto client = server.Client();
  std::string first_csv;
  auto res = client.Post("/api/v1/recordings", PcaUpload(1, &first_csv));
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  const int64_t first = json::parse(res->body)["recording"]["id"];
  res = client.Get("/healthz");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 200);
  EXPECT_EQ(json::parse(res->body)["backend"], "postgresql");
  EXPECT_EQ(json::parse(res->body)["database"], "reachable");

  ASSERT_TRUE(cluster_->Stop());
  res = client.Get(("/api/v1/recordings/" + std::to_string(first)).c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 503) << res->body;
  EXPECT_EQ(res->get_header_value("Retry-After"), "1");
  json error = json::parse(res->body);
  EXPECT_EQ(error["error"]["code"], "busy") << res->body;
  EXPECT_NE(error["error"]["message"].get<std::string>().find("PostgreSQL"), std::string::npos)
      << res->body;
  res = client.Post("/api/v1/recordings", PcaUpload(2, nullptr));
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 503) << res->body;  // not acknowledged: the client sends it again
  res = client.Get("/healthz");
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 503);
  EXPECT_EQ(json::parse(res->body)["status"], "unavailable");
  res = client.Get("/metrics");
  ASSERT_TRUE(res);
  EXPECT_NE(res->body.find("calibd_database_up{backend=\"postgresql\"} 0"), std::string::npos);

  ASSERT_TRUE(cluster_->Start());
  res = client.Get(("/api/v1/recordings/" + std::to_string(first) + "/data").c_str());
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200) << res->body;
  EXPECT_EQ(res->body, first_csv);
  res = client.Post("/api/v1/recordings", PcaUpload(2, nullptr));
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 201) << res->body;
  res = client.Get("/metrics");
  ASSERT_TRUE(res);
  EXPECT_NE(res->body.find("calibd_database_up{backend=\"postgresql\"} 1"), std::string::npos);
  EXPECT_EQ(server.Signal(SIGTERM), 0) << server.log();
}

// A cancel sent to one host stops the job where another host computes it, within a second (its
// worker pool reads the cancel requests of its running jobs every 250 ms).
TEST_F(PgServe, ACancelThroughOneHostStopsTheJobOnAnotherWithinASecond) {
  testing::TempDir other_tmp;  // another TMPDIR: another host as far as calibd can tell
  ServerProcess computing(uri_, {"--workers", "1"}, tmp_.path().string());
  ASSERT_GT(computing.port(), 0) << computing.log();
  ArraySimulationFileOptions sim;
  sim.samples = 1000;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFiles(sim, &csv, &config, &truth).ok());
  config["solver"] = "bcd";
  config["max_iterations"] = 1000000;  // far longer than the test
  config["tolerance"] = 0;
  auto client = computing.Client();
  auto res = client.Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", csv, "long.csv", "text/csv"},
                                      {"config", config.dump(), "", "application/json"}});
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  const int64_t id = json::parse(res->body)["job"]["id"];
  const std::string path = "/api/v1/jobs/" + std::to_string(id);
  json job = json::object();
  for (int i = 0; i < 3000 && !(job.is_object() && job.value("status", "") == "running"); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    job = testing::GetJob(client, id);
  }
  ASSERT_EQ(job["status"], "running") << job.dump();
  ServerProcess other(uri_, {"--workers", "1"}, other_tmp.path().string());
  ASSERT_GT(other.port(), 0) << other.log();
  const auto asked = std::chrono::steady_clock::now();
  res = other.Client().Post((path + "/cancel").c_str(), R"({"reason": "from another host"})",
                            "application/json");
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 202) << res->body;
  for (int i = 0; i < 500 && job["status"] == "running"; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    job = testing::GetJob(client, id);
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - asked).count();
  EXPECT_EQ(job["status"], "failed") << job.dump();
  EXPECT_EQ(job["error"]["reason"], "cancelled") << job.dump();
  EXPECT_NE(job["error"]["message"].get<std::string>().find("from another host"),
            std::string::npos);
  EXPECT_LT(seconds, 1.0) << computing.log();
  EXPECT_EQ(other.Signal(SIGTERM), 0) << other.log();
  EXPECT_EQ(computing.Signal(SIGTERM), 0) << computing.log();
}

// Three hosts on one database, uploads spread over them, one killed -9 every second or so and
// restarted: every acknowledged upload is there byte-exact, every job succeeds, exactly one
// result per job. (bench/pg_hosts_soak.sh runs the one-minute version.)
TEST_F(PgServe, ThreeHostsUnderKillNineLoseNothingAndRunEveryJobOnce) {
  constexpr int kHosts = 3;
  const int kKills = sanitizer::kSanitizer ? 4 : 8;
  std::vector<std::unique_ptr<ServerProcess>> hosts(kHosts);
  std::vector<std::mutex> host_mu(kHosts);
  for (int h = 0; h < kHosts; ++h) {
    hosts[h] = std::make_unique<ServerProcess>(uri_, std::vector<std::string>{"--workers", "2"},
                                               tmp_.path().string());
    ASSERT_GT(hosts[h]->port(), 0) << hosts[h]->log();
  }
  std::mutex mu;
  std::map<int64_t, std::string> acknowledged;  // recording id -> bytes
  std::set<int64_t> jobs;
  std::atomic<bool> stop{false};
  std::atomic<uint64_t> seed{1000};
  std::vector<std::thread> uploaders;
  for (int u = 0; u < kHosts; ++u) {
    uploaders.emplace_back([&, u] {
      for (int round = u; !stop; ++round) {
        const int h = round % kHosts;
        int port;
        {
          std::lock_guard<std::mutex> lock(host_mu[h]);
          port = hosts[h]->port();
        }
        httplib::Client client("127.0.0.1", port);
        client.set_read_timeout(30, 0);
        client.set_connection_timeout(2, 0);
        std::string csv;
        auto res = client.Post("/api/v1/recordings", PcaUpload(seed++, &csv));
        if (res && res->status == 201) {
          json body = json::parse(res->body);
          std::lock_guard<std::mutex> lock(mu);
          acknowledged[body["recording"]["id"]] = csv;
          jobs.insert(body["job"]["id"].get<int64_t>());
        }
      }
    });
  }
  std::mt19937_64 rng(20261124);
  for (int k = 0; k < kKills; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(700 + rng() % 800));
    const int h = k % kHosts;
    auto fresh = std::make_unique<ServerProcess>(uri_, std::vector<std::string>{"--workers", "2"},
                                                 tmp_.path().string());
    ASSERT_GT(fresh->port(), 0) << fresh->log();
    std::unique_ptr<ServerProcess> old;
    {
      std::lock_guard<std::mutex> lock(host_mu[h]);
      old = std::move(hosts[h]);
      hosts[h] = std::move(fresh);  // new uploads go to the restarted host
    }
    old->Signal(SIGKILL);
  }
  stop = true;
  for (auto& t : uploaders) t.join();
  ASSERT_GT(acknowledged.size(), static_cast<size_t>(kKills));

  auto client = hosts[0]->Client();
  for (const auto& [id, bytes] : acknowledged) {
    auto res = client.Get(("/api/v1/recordings/" + std::to_string(id) + "/data").c_str());
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << "recording " << id << " lost";
    EXPECT_EQ(res->body, bytes) << "recording " << id << " differs";
  }
  // Drain: jobs of killed hosts are taken back by the restarted host of the same machine.
  const json health = WaitUntilIdle(client, 60000);
  EXPECT_EQ(health["queued"], 0) << health.dump();
  EXPECT_EQ(health["running"], 0) << health.dump();
  for (int64_t id : jobs) {
    auto res = client.Get(("/api/v1/jobs/" + std::to_string(id)).c_str());
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200);
    EXPECT_EQ(json::parse(res->body)["status"], "succeeded") << res->body;
  }
  for (auto& h : hosts) EXPECT_EQ(h->Signal(SIGTERM), 0) << h->log();

  // In the database: every job succeeded, with exactly one result each, every recording sound.
  std::unique_ptr<storage::PgConn> sql;
  ASSERT_TRUE(storage::PgConn::Connect(uri_, "test", &sql).ok());
  storage::PgResult r;
  ASSERT_TRUE(sql->Exec("SELECT COUNT(*), COUNT(*) FILTER (WHERE status = 'succeeded'), "
                        "(SELECT COUNT(*) FROM results), "
                        "(SELECT COUNT(DISTINCT job_id) FROM results) FROM jobs",
                        {}, &r)
                  .ok());
  EXPECT_GE(r.Int(0, 0), static_cast<int64_t>(jobs.size()));
  EXPECT_EQ(r.Int(0, 1), r.Int(0, 0));  // every job, acknowledged or not, succeeded
  EXPECT_EQ(r.Int(0, 2), r.Int(0, 0));  // one result per job
  EXPECT_EQ(r.Int(0, 3), r.Int(0, 0));
  std::unique_ptr<storage::Store> store;
  ASSERT_TRUE(storage::Store::Open(uri_, {}, &store).ok());
  std::string integrity;
  ASSERT_TRUE(store->IntegrityCheck(&integrity).ok());
  EXPECT_EQ(integrity, "ok");
}

}  // namespace
}  // namespace calibd::server
