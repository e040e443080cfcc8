#include "tests/lib/server_process.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>

#include "tests/lib/test_paths.h"

namespace calibd::server::testing {

using nlohmann::json;

ServerProcess::ServerProcess(const std::string& db, std::vector<std::string> extra,
                             const std::string& tmpdir,
                             const std::map<std::string, std::string>& env) {
  const std::string binary = calibd::test_paths::CalibdBinary();  // not in the child: it may lock
  int fds[2];
  if (pipe(fds) != 0) return;
  pid_ = fork();
  if (pid_ == 0) {
    dup2(fds[1], 2);
    close(fds[0]);
    close(fds[1]);
    if (!tmpdir.empty()) setenv("TMPDIR", tmpdir.c_str(), 1);
    for (const auto& [name, value] : env) setenv(name.c_str(), value.c_str(), 1);
    std::vector<std::string> args = {binary,     "serve",       "--db",           db,
                                     "--listen", "127.0.0.1:0", "--no-access-log"};
    args.insert(args.end(), extra.begin(), extra.end());
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execv(binary.c_str(), argv.data());
    _exit(127);
  }
  close(fds[1]);
  if (pid_ < 0) {
    close(fds[0]);
    return;
  }
  reader_ = std::thread([this, fd = fds[0]] {
    char buf[4096];
    ssize_t n;
    while ((n = read(fd, buf, sizeof buf)) > 0) {
      std::lock_guard<std::mutex> lock(mu_);
      log_.append(buf, static_cast<size_t>(n));
    }
    close(fd);
  });
  for (int i = 0; i < 3000 && port_ == 0; ++i) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      const size_t at = log_.find("listening on http://127.0.0.1:");
      if (at != std::string::npos) port_ = std::atoi(log_.c_str() + at + 30);
    }
    if (port_ == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

ServerProcess::~ServerProcess() {
  if (pid_ > 0 && !exited_) Signal(SIGKILL);
  if (reader_.joinable()) reader_.join();
}

int ServerProcess::Signal(int sig) {
  kill(pid_, sig);
  int status = 0;
  waitpid(pid_, &status, 0);
  exited_ = true;
  return status;
}

void ServerProcess::Send(int sig) { kill(pid_, sig); }

std::string ServerProcess::log() {
  std::lock_guard<std::mutex> lock(mu_);
  return log_;
}

httplib::Client ServerProcess::Client() const {
  httplib::Client c("127.0.0.1", port_);
  c.set_read_timeout(30, 0);
  c.set_connection_timeout(5, 0);
  return c;
}

json GetJob(httplib::Client& client, int64_t id) {
  auto res = client.Get(("/api/v1/jobs/" + std::to_string(id)).c_str());
  if (!res || res->status != 200) return json();
  return json::parse(res->body);
}

json WaitUntilIdle(httplib::Client& client, int timeout_ms) {
  json health;
  for (int waited = 0; waited < timeout_ms; waited += 20) {
    auto res = client.Get("/healthz");
    if (res && res->status == 200) {
      health = json::parse(res->body);
      if (health["queued"] == 0 && health["running"] == 0) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return health;
}

}  // namespace calibd::server::testing
