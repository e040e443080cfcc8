// `calibd serve` as a child process, for the tests of the real binary
// (tests/server/process_test.cc, tests/server/pg_process_test.cc): started with fork/exec on a free
// loopback port
// (--listen 127.0.0.1:0, --no-access-log), its stderr collected to learn the port and to show in
// failure messages, killed with SIGKILL when the object goes unless a test signalled it before.
// The binary is the one the build made (test_paths.h).
#ifndef CALIBD_TESTS_LIB_SERVER_PROCESS_H_
#define CALIBD_TESTS_LIB_SERVER_PROCESS_H_

#include <httplib.h>
#include <sys/types.h>

#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

namespace calibd::server::testing {

class ServerProcess {
 public:
  // Starts `calibd serve --db DB --listen 127.0.0.1:0 --no-access-log EXTRA...` and waits up to
  // 30 s for its "listening on" line; port() is 0 when it never came (see log()). `tmpdir`, when
  // not empty, becomes the child's TMPDIR (where a PostgreSQL calibd stages uploads). `env` is
  // set in the child's environment (e.g. LD_PRELOAD of the clock-skew shim, tests/storage/
  // clock_test.cc).
  explicit ServerProcess(const std::string& db, std::vector<std::string> extra = {},
                         const std::string& tmpdir = "",
                         const std::map<std::string, std::string>& env = {});
  ~ServerProcess();
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  int port() const { return port_; }
  // Sends `sig` and waits for the process to end; returns its wait status.
  int Signal(int sig);
  // Sends `sig` without waiting.
  void Send(int sig);
  // Everything the process wrote to stderr so far.
  std::string log();
  // A client of its port: 30 s read timeout, 5 s connection timeout.
  httplib::Client Client() const;

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  bool exited_ = false;
  std::mutex mu_;
  std::string log_;
  std::thread reader_;
};

// GET /api/v1/jobs/{id}: the job, or null when the answer is not 200.
nlohmann::json GetJob(httplib::Client& client, int64_t id);

// Polls /healthz every 20 ms until no job is queued or running, for at most `timeout_ms`; returns
// the last health answer (null when none was 200).
nlohmann::json WaitUntilIdle(httplib::Client& client, int timeout_ms);

}  // namespace calibd::server::testing

#endif  // CALIBD_TESTS_LIB_SERVER_PROCESS_H_
