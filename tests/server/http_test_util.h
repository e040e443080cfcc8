// A real calibd server on a free loopback port with a temporary database, for integration tests.
#ifndef CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_
#define CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
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

// Files of uploads being staged under a server's database folder (the per-process lock files of
// server/instance.h are not uploads).
inline int StagedUploads(const std::filesystem::path& db_dir) {
  int n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::recursive_directory_iterator(db_dir / "staging", ec)) {
    if (e.is_regular_file() && e.path().extension() != ".lock") ++n;
  }
  return n;
}

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

  // Uploads `csv` with its `config` as multipart/form-data (as `curl -F recording=@... -F
  // config=@...`), then waits for the upload's job: the finished job's JSON (status succeeded or
  // failed). When the upload is not answered 201 with a job, a test failure naming the answer and
  // a null JSON.
  nlohmann::json UploadAndWait(const std::string& csv, const nlohmann::json& config,
                               const std::string& file_name = "recording.csv") const {
    auto res = Client().Post(
        "/api/v1/recordings",
        httplib::MultipartFormDataItems{{"recording", csv, file_name, "text/csv"},
                                        {"config", config.dump(), "", "application/json"}});
    if (!res || res->status != 201) {
      ADD_FAILURE() << "upload not accepted: "
                    << (res ? std::to_string(res->status) + " " + res->body : "no answer");
      return nullptr;
    }
    const nlohmann::json body = nlohmann::json::parse(res->body, nullptr, false);
    if (!body.is_object() || !body.contains("job") || !body["job"].contains("id")) {
      ADD_FAILURE() << "the upload's answer has no job: " << res->body;
      return nullptr;
    }
    return WaitForJob(body["job"]["id"].get<int64_t>());
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

// A raw TCP connection to the server.
class RawConnection {
 public:
  explicit RawConnection(int port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(static_cast<uint16_t>(port));
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (connect(fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
      close(fd_);
      fd_ = -1;
    }
    timeval tv{10, 0};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    setsockopt(fd_, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
  }
  ~RawConnection() {
    if (fd_ >= 0) close(fd_);
  }
  bool ok() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  // True when the server has closed the connection: a read sees the end within `timeout_ms`
  // (after any bytes still in flight, which are returned in *rest).
  bool ClosedByPeer(int timeout_ms, std::string* rest = nullptr) {
    char buf[8192];
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeout_ms);
    while (std::chrono::steady_clock::now() < end) {
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, 50) <= 0) continue;
      const ssize_t n = recv(fd_, buf, sizeof buf, MSG_DONTWAIT);
      if (n == 0) return true;
      if (n < 0) return errno == ECONNRESET;
      if (rest != nullptr) rest->append(buf, static_cast<size_t>(n));
    }
    return false;
  }
  // Sends all of `data`; false when the server closed the connection meanwhile.
  bool Send(const std::string& data) {
    size_t sent = 0;
    while (sent < data.size()) {
      const ssize_t n = send(fd_, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return false;
      sent += static_cast<size_t>(n);
    }
    return true;
  }
  // Reads one response (headers and Content-Length body), or until the peer closes, `limit`
  // bytes or the timeout; returns what came.
  std::string Receive(size_t limit = 1 << 20) {
    std::string out;
    char buf[8192];
    while (out.size() < limit) {
      const size_t end = out.find("\r\n\r\n");
      if (end != std::string::npos) {
        const size_t at = out.find("Content-Length: ");
        if (at != std::string::npos && at < end &&
            out.size() >= end + 4 + std::stoul(out.substr(at + 16))) {
          break;
        }
      }
      const ssize_t n = recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) break;
      out.append(buf, static_cast<size_t>(n));
    }
    return out;
  }

 private:
  int fd_ = -1;
};

// The status code of a raw HTTP answer, or 0 if the connection was closed without one.
inline int StatusOf(const std::string& response) {
  if (response.rfind("HTTP/1.1 ", 0) != 0) return 0;
  return std::atoi(response.c_str() + 9);
}

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_SERVER_HTTP_TEST_UTIL_H_
