// A real calibd server on a free loopback port with a temporary database, for integration tests.
#ifndef CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_
#define CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "server/http_util.h"
#include "server/service.h"

namespace calibd::server::testing {

// A temporary directory removed (recursively) on destruction.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "calibd-test-XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// The in-process server: Service on 127.0.0.1:0, served by a background thread.
class TestServer {
 public:
  explicit TestServer(ServeOptions options = {}, const std::string& db_path = {}) {
    options.db_path = db_path.empty() ? (dir_.path() / "calibd.db").string() : db_path;
    options.listen = "127.0.0.1:0";
    if (options.workers == 0) options.workers = 2;
    options.access_log = false;
    options_ = options;
    Status s = Service::Create(options, &service_);
    if (!s.ok()) {
      error_ = s.ToString();
      return;
    }
    s = service_->Bind();
    if (!s.ok()) {
      error_ = s.ToString();
      return;
    }
    thread_ = std::thread([this] { service_->Run(); });
    // Ready when /healthz answers.
    for (int i = 0; i < 200; ++i) {
      auto res = Client().Get("/healthz");
      if (res && res->status == 200) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    error_ = "server did not become ready";
  }
  ~TestServer() { Stop(); }

  void Stop() {
    if (service_) service_->Shutdown();
    if (thread_.joinable()) thread_.join();
    service_.reset();
  }

  const std::string& error() const { return error_; }
  int port() const { return service_ ? service_->port() : 0; }
  const std::filesystem::path& dir() const { return dir_.path(); }
  const ServeOptions& options() const { return options_; }

  httplib::Client Client() const {
    httplib::Client client("127.0.0.1", port());
    client.set_read_timeout(60, 0);
    client.set_write_timeout(60, 0);
    return client;
  }

  // Polls GET /api/v1/jobs/{id} until the job is succeeded or failed (or 120 s passed).
  nlohmann::json WaitForJob(int64_t id) const {
    auto client = Client();
    nlohmann::json job;
    for (int i = 0; i < 2400; ++i) {
      auto res = client.Get(("/api/v1/jobs/" + std::to_string(id)).c_str());
      if (res && res->status == 200) {
        job = nlohmann::json::parse(res->body);
        if (job["status"] == "succeeded" || job["status"] == "failed") return job;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "job " << id << " did not finish: " << job.dump();
    return job;
  }

 private:
  TempDir dir_;
  ServeOptions options_;
  std::unique_ptr<Service> service_;
  std::thread thread_;
  std::string error_;
};

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_
