// A throw-away PostgreSQL cluster for the tests of the PostgreSQL storage backend.
//
// PgTestCluster::Get() starts it on first use (once per test program): initdb into a fresh
// mkdtemp folder (as the `postgres` system user when running as root: initdb refuses root),
// fsync off, listening only on a Unix socket in that folder (no TCP port, so parallel test
// programs never collide), pg_ctl start. NewDatabase() creates an empty database per test.
// The cluster is stopped and its folder removed when the program exits normally (a gtest
// Environment) and, should the program crash or be killed, by a watchdog child that notices its
// parent is gone. The binaries come from $CALIBD_PG_BIN, else /usr/lib/postgresql/15/bin;
// they are installed by scripts/setup.sh, so a missing binary is a failure, never a skip. When
// run as root, $TMPDIR (default /tmp) must be reachable by the postgres user (/tmp is).
#ifndef CALIBD_TESTS_STORAGE_PG_TEST_CLUSTER_H_
#define CALIBD_TESTS_STORAGE_PG_TEST_CLUSTER_H_

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/prctl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>

#include "storage/pg_conn.h"

namespace calibd::storage::testing {

class PgTestCluster {
 public:
  // The running cluster (started on first call). Fails the calling test when it cannot start.
  static PgTestCluster* Get() {
    static PgTestCluster* cluster = [] {
      auto* c = new PgTestCluster();
      c->StartOnce();
      ::testing::AddGlobalTestEnvironment(new Env(c));  // stops it after the last test
      return c;
    }();
    if (!cluster->error_.empty()) {
      ADD_FAILURE() << "cannot start the test PostgreSQL cluster: " << cluster->error_;
      return nullptr;
    }
    return cluster;
  }

  // A new empty database; returns its libpq URI ("postgresql:///tN?host=<dir>&user=postgres").
  std::string NewDatabase() {
    const std::string name = "t" + std::to_string(++databases_) + "_" + std::to_string(getpid());
    std::unique_ptr<PgConn> conn;
    Status s = PgConn::Connect(Uri("postgres"), "test cluster", &conn);
    if (s.ok()) s = conn->ExecScript(("CREATE DATABASE " + name).c_str());
    if (!s.ok()) ADD_FAILURE() << "CREATE DATABASE " << name << ": " << s.ToString();
    return Uri(name);
  }

  std::string Uri(const std::string& db) const {
    return "postgresql:///" + db + "?host=" + dir_ + "&user=postgres";
  }
  const std::string& dir() const { return dir_; }

  // Stops the server (fast shutdown: clients are disconnected) / starts it again, for tests of a
  // database that goes away. True on success.
  bool Stop() { return Run(Ctl("stop -m fast")); }
  bool Start() { return Run(Ctl(StartArgs())); }

 private:
  struct Env : ::testing::Environment {
    explicit Env(PgTestCluster* c) : cluster(c) {}
    void TearDown() override { cluster->Destroy(); }
    PgTestCluster* cluster;
  };

  static std::string BinDir() {
    const char* env = getenv("CALIBD_PG_BIN");
    return env != nullptr && *env != '\0' ? env : "/usr/lib/postgresql/15/bin";
  }
  // As the postgres user when root (initdb and postgres refuse to run as root).
  std::string As() const { return geteuid() == 0 ? "runuser -u postgres -- " : ""; }
  std::string Ctl(const std::string& args) const {
    return As() + BinDir() + "/pg_ctl -D " + dir_ + "/data -l " + dir_ + "/log -w -t 60 " + args;
  }
  std::string StartArgs() const {
    return "-o \"-k " + dir_ +
           " -c listen_addresses='' -c fsync=off -c full_page_writes=off"
           " -c synchronous_commit=off -c max_connections=200 -c shared_buffers=32MB\" start";
  }
  static bool Run(const std::string& cmd) {
    const std::string quiet = cmd + " >/dev/null 2>&1";
    return std::system(quiet.c_str()) == 0;
  }

  void StartOnce() {
    const char* base = getenv("TMPDIR");
    std::string templ = std::string(base != nullptr ? base : "/tmp") + "/calibd-pg-XXXXXX";
    if (mkdtemp(templ.data()) == nullptr) {
      error_ = "mkdtemp failed";
      return;
    }
    dir_ = templ;
    if (!std::filesystem::exists(BinDir() + "/initdb")) {
      error_ = BinDir() + "/initdb not found (scripts/setup.sh installs postgresql-15)";
      return;
    }
    if (geteuid() == 0 && !Run("chown postgres: " + dir_)) {
      error_ = "cannot chown " + dir_ + " to the postgres user";
      return;
    }
    StartWatchdog();
    if (!Run(As() + BinDir() + "/initdb -D " + dir_ +
             "/data -U postgres --auth=trust --no-sync --locale=C -E UTF8")) {
      error_ = "initdb failed in " + dir_;
      return;
    }
    if (!Start()) {
      error_ = "pg_ctl start failed (see " + dir_ + "/log)";
      return;
    }
  }

  // A child that waits until this process is gone (the pipe's write end closes with it), then
  // stops the cluster and removes its folder: no server is left behind by a crashed test.
  void StartWatchdog() {
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return;
    const std::string stop = Ctl("stop -m immediate") + " >/dev/null 2>&1; rm -rf " + dir_;
    pid_t pid = fork();
    if (pid == 0) {
      close(fds[1]);
      setsid();  // not killed with the test's process group by a Ctrl-C before cleaning up
      char byte;
      while (read(fds[0], &byte, 1) < 0 && errno == EINTR) {
      }
      execl("/bin/sh", "sh", "-c", stop.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
    close(fds[0]);
    watchdog_fd_ = fds[1];  // kept open for the life of this process
  }

  void Destroy() {
    if (dir_.empty()) return;
    Run(Ctl("stop -m immediate"));
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string dir_;
  std::string error_;
  std::atomic<int> databases_{0};
  int watchdog_fd_ = -1;
};

}  // namespace calibd::storage::testing

#endif  // CALIBD_TESTS_STORAGE_PG_TEST_CLUSTER_H_
