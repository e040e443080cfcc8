// Clocks (issue 27): leases and "latest" must not depend on the hosts' clocks agreeing.
//   - A device's latest calibration is the result stored last (results.seq), on both backends,
//     even when the host that stored it has a clock 10 minutes behind; databases written before
//     (SQLite v5, PostgreSQL v3) are numbered in the old order when migrated.
//   - On PostgreSQL, leases, back-offs and enqueue times are measured on the database server's
//     clock: processes whose wall clock is shifted by the clock-skew shim (clock_skew_shim.cc,
//     LD_PRELOAD) neither take live leases nor hand out leases that are already over.
// The skewed processes are this program run again (ClockChild.DISABLED_Act, selected by
// --gtest_also_run_disabled_tests) with the shim preloaded, on the throw-away PostgreSQL cluster
// (pg_test_cluster.h); and `calibd serve` itself (tests/lib/server_process.h).
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "methods/pca/pca_method.h"
#include "storage/db.h"
#include "storage/pg_conn.h"
#include "storage/pg_store.h"
#include "storage/schema.h"
#include "storage/store.h"
#include "tests/lib/server_process.h"
#include "tests/storage/pg_test_cluster.h"
#include "tests/storage/storage_test_util.h"
#include "tests/lib/test_paths.h"

extern char** environ;

namespace calibd::storage {
namespace {

using testing::FakeClock;
using testing::PgTestCluster;
using testing::TempDir;

constexpr int64_t kTenMinutesMs = 10 * 60 * 1000;
constexpr const char* kAccepted = R"({"verdict":{"status":"accepted"}})";

int64_t SystemNowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct ChildResult {
  int status = -1;  // exit status, or -1 when it did not exit normally
  std::string out, err;
};

// Runs `argv` with the environment of this process plus `env`, and collects its output.
ChildResult RunProcess(const std::vector<std::string>& argv,
                       const std::map<std::string, std::string>& env) {
  ChildResult result;
  int out_pipe[2], err_pipe[2];
  if (pipe(out_pipe) != 0 || pipe(err_pipe) != 0) {
    ADD_FAILURE() << "pipe: " << std::strerror(errno);
    return result;
  }
  std::vector<std::string> env_text;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string kv = *e;
    if (env.count(kv.substr(0, kv.find('='))) == 0) env_text.push_back(kv);
  }
  for (const auto& [k, v] : env) env_text.push_back(k + "=" + v);
  std::vector<char*> envp, args;
  for (auto& kv : env_text) envp.push_back(kv.data());
  envp.push_back(nullptr);
  std::vector<std::string> argv_copy = argv;
  for (auto& a : argv_copy) args.push_back(a.data());
  args.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(out_pipe[1], 1);
    dup2(err_pipe[1], 2);
    close(out_pipe[0]);
    close(err_pipe[0]);
    execve(args[0], args.data(), envp.data());
    _exit(127);
  }
  close(out_pipe[1]);
  close(err_pipe[1]);
  // Both pipes are small (a few lines); read stdout then stderr.
  auto drain = [](int fd, std::string* to) {
    char buf[4096];
    for (ssize_t n; (n = read(fd, buf, sizeof buf)) > 0;) to->append(buf, static_cast<size_t>(n));
    close(fd);
  };
  drain(out_pipe[0], &result.out);
  drain(err_pipe[0], &result.err);
  int status = 0;
  waitpid(pid, &status, 0);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

// The environment that preloads the shim with a skew of `skew_ms`. ASan checks that its runtime
// is the first library loaded; the shim (built without sanitizers) comes first by design.
std::map<std::string, std::string> SkewEnv(const std::string& skew_ms) {
  const char* asan = getenv("ASAN_OPTIONS");
  std::string asan_options = asan != nullptr && *asan != '\0' ? std::string(asan) + ":" : "";
  return {{"LD_PRELOAD", calibd::test_paths::BesideTests("libcalibd_clock_skew_shim.so")},
          {"CALIBD_CLOCK_SKEW_MS", skew_ms},
          {"ASAN_OPTIONS", asan_options + "verify_asan_link_order=0"}};
}

std::string SelfPath() {
  char buf[4096];
  const ssize_t n = readlink("/proc/self/exe", buf, sizeof buf - 1);
  if (n <= 0) return "";
  return std::string(buf, static_cast<size_t>(n));
}

// Runs ClockChild.DISABLED_Act of this program under the shim: `action` on the database `uri`.
// Its answer is the "key=value ..." line after "CHILD ".
std::map<std::string, int64_t> RunSkewedChild(int64_t skew_ms, const std::string& action,
                                              const std::string& uri) {
  auto env = SkewEnv(std::to_string(skew_ms));
  env["CALIBD_CLOCK_CHILD_ACTION"] = action;
  env["CALIBD_CLOCK_CHILD_URI"] = uri;
  ChildResult r = RunProcess({SelfPath(), "--gtest_also_run_disabled_tests",
                              "--gtest_filter=ClockChild.DISABLED_Act", "--gtest_brief=1"},
                             env);
  std::map<std::string, int64_t> answer;
  const size_t at = r.out.find("CHILD ");
  EXPECT_EQ(r.status, 0) << r.out << r.err;
  if (at == std::string::npos) {
    ADD_FAILURE() << "no answer from the child: " << r.out << r.err;
    return answer;
  }
  std::istringstream line(r.out.substr(at + 6, r.out.find('\n', at) - at - 6));
  for (std::string kv; line >> kv;) {
    const size_t eq = kv.find('=');
    answer[kv.substr(0, eq)] = std::stoll(kv.substr(eq + 1));
  }
  return answer;
}

// ---- The shim itself ----

TEST(ClockSkewShim, ShiftsTheWallClockButNotTheMonotonicOne) {
  // `date +%s` asks clock_gettime(CLOCK_REALTIME).
  ChildResult plain = RunProcess({"/bin/date", "+%s"}, {});
  ChildResult behind = RunProcess({"/bin/date", "+%s"}, SkewEnv("-600000"));
  ChildResult ahead = RunProcess({"/bin/date", "+%s"}, SkewEnv("3600000"));
  ASSERT_EQ(plain.status, 0) << plain.err;
  ASSERT_EQ(behind.status, 0) << behind.err;
  ASSERT_EQ(ahead.status, 0) << ahead.err;
  EXPECT_NEAR(std::stoll(behind.out) - std::stoll(plain.out), -600, 3);
  EXPECT_NEAR(std::stoll(ahead.out) - std::stoll(plain.out), 3600, 3);
  // The child reports all three wall clocks and the monotonic one (ClockChild.DISABLED_Act).
  auto times = RunSkewedChild(-kTenMinutesMs, "clocks", "");
  const int64_t now = SystemNowMs();
  EXPECT_NEAR(times["clock_gettime_ms"] - now, -kTenMinutesMs, 3000);
  EXPECT_NEAR(times["gettimeofday_ms"] - now, -kTenMinutesMs, 3000);
  EXPECT_NEAR(times["time_s"] * 1000 - now, -kTenMinutesMs, 4000);
  timespec mono;
  clock_gettime(CLOCK_MONOTONIC, &mono);
  EXPECT_NEAR(times["monotonic_s"], mono.tv_sec, 3);
}

TEST(ClockSkewShim, RefusesASkewThatIsNotWholeMilliseconds) {
  for (const char* bad : {"ten", "-600000ms", "1.5", "99999999999999999999"}) {
    ChildResult r = RunProcess({"/bin/date", "+%s"}, SkewEnv(bad));
    EXPECT_EQ(r.status, 86) << bad << ": " << r.out;
    EXPECT_NE(r.err.find(std::string("CALIBD_CLOCK_SKEW_MS=\"") + bad + "\""), std::string::npos)
        << r.err;
    EXPECT_EQ(r.out, "") << bad;  // it never ran unshifted
  }
}

// The skewed process: this program again, with the shim, doing CALIBD_CLOCK_CHILD_ACTION.
// Disabled: it runs only when a test selects it (RunSkewedChild).
TEST(ClockChild, DISABLED_Act) {
  const char* action_env = getenv("CALIBD_CLOCK_CHILD_ACTION");
  ASSERT_NE(action_env, nullptr) << "run by RunSkewedChild only";
  const std::string action = action_env;
  std::ostringstream answer;
  if (action == "clocks") {
    timespec ts, mono;
    clock_gettime(CLOCK_REALTIME, &ts);
    clock_gettime(CLOCK_MONOTONIC, &mono);
    timeval tv;
    gettimeofday(&tv, nullptr);
    answer << "clock_gettime_ms=" << SystemNowMs()
           << " gettimeofday_ms=" << int64_t{tv.tv_sec} * 1000 + tv.tv_usec / 1000
           << " time_s=" << time(nullptr) << " monotonic_s=" << mono.tv_sec;
  } else {
    std::unique_ptr<Store> store;
    Status s = Store::Open(getenv("CALIBD_CLOCK_CHILD_URI"), {}, &store);  // the default clock
    ASSERT_TRUE(s.ok()) << s.ToString();
    answer << "host_now_ms=" << SystemNowMs();
    if (action == "claim") {  // claims the oldest claimable job for 60 s, as "skewed:1"
      JobInfo job;
      bool claimed = false;
      s = store->ClaimJob("skewed:1", 60000, &job, &claimed);
      ASSERT_TRUE(s.ok()) << s.ToString();
      answer << " claimed=" << claimed << " id=" << job.id
             << " lease_expires_at_ms=" << job.lease_expires_at_ms;
    } else if (action == "take") {  // what a worker's poll does: recover lapsed leases, claim
      int64_t recovered = 0;
      s = store->RecoverExpiredLeases(&recovered);
      ASSERT_TRUE(s.ok()) << s.ToString();
      JobInfo job;
      bool claimed = false;
      s = store->ClaimJob("skewed:2", 60000, &job, &claimed);
      ASSERT_TRUE(s.ok()) << s.ToString();
      answer << " recovered=" << recovered << " claimed=" << claimed;
    } else if (action == "enqueue") {  // a job on recording 1, as an upload does
      JobInfo job;
      s = store->EnqueueJob(1, "pca", "SN-CLOCK", "{}", &job);
      ASSERT_TRUE(s.ok()) << s.ToString();
      answer << " id=" << job.id << " not_before_ms=" << job.not_before_ms
             << " created_at_ms=" << job.created_at_ms;
    } else {
      FAIL() << "unknown CALIBD_CLOCK_CHILD_ACTION " << action;
    }
  }
  std::printf("CHILD %s\n", answer.str().c_str());
}

// ---- "latest" on both backends ----

class LatestClock : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "postgresql") {
      auto* cluster = PgTestCluster::Get();
      ASSERT_NE(cluster, nullptr);
      target_ = cluster->NewDatabase();
    } else {
      target_ = dir_.File("calibd.db");
    }
  }

  std::unique_ptr<Store> Open(FakeClock* clock) {
    StoreOptions o;
    o.now_ms = clock->Fn();
    std::unique_ptr<Store> store;
    Status s = Store::Open(target_, o, &store);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return store;
  }

  // Enqueues a job on recording 1 through `store` (whose clock sets when it is claimable), claims
  // it and completes it with `result`; returns its id.
  static int64_t RunOne(Store* store, const std::string& worker, const std::string& result) {
    JobInfo job;
    Status s = store->EnqueueJob(1, "pca", "", "{}", &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    bool claimed = false;
    s = store->ClaimJob(worker, 10000, &job, &claimed);
    EXPECT_TRUE(s.ok() && claimed) << s.ToString();
    s = store->CompleteJob(job.id, worker, result);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job.id;
  }

  static int64_t Latest(Store* store) {
    JobInfo job;
    Status s = store->LatestResult("SN-CLOCK", "pca", &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job.id;
  }

  TempDir dir_;
  std::string target_;
};

// Host B's clock is 10 minutes behind host A's. B completes a calibration after A: B's is the
// device's calibration (it was stored last), not A's (which has the later clock reading).
TEST_P(LatestClock, TheResultStoredLastIsLatestWhateverTheHostsClocksSay) {
  FakeClock clock_a;
  FakeClock clock_b(clock_a.Now() - kTenMinutesMs);
  auto a = Open(&clock_a);
  auto b = Open(&clock_b);
  ASSERT_TRUE(a && b);
  NewRecording r;
  r.data = "recording";
  r.device = "SN-CLOCK";
  RecordingInfo rec;
  ASSERT_TRUE(a->PutRecording(r, &rec, nullptr).ok());
  ASSERT_EQ(rec.id, 1);

  const int64_t first = RunOne(a.get(), "a:1", kAccepted);
  clock_a.Advance(1000);
  clock_b.Advance(1000);
  const int64_t second = RunOne(b.get(), "b:1", kAccepted);
  EXPECT_EQ(Latest(a.get()), second);
  EXPECT_EQ(Latest(b.get()), second);
  std::vector<DeviceInfo> devices;
  ASSERT_TRUE(a->ListDevices(&devices).ok());
  ASSERT_EQ(devices.size(), 1u);
  ASSERT_EQ(devices[0].latest.size(), 1u);
  EXPECT_EQ(devices[0].latest[0].job_id, second);

  // Revoking it falls back to the one stored before it; accepting it again restores it.
  ASSERT_TRUE(a->RevokeJob(second, "wrong fixture", "test").ok());
  EXPECT_EQ(Latest(a.get()), first);
  ASSERT_TRUE(b->AcceptJob(second, "fixture was right", "test").ok());
  EXPECT_EQ(Latest(a.get()), second);

  // A rejected result stored last is not served; the one before it stays.
  const int64_t third = RunOne(a.get(), "a:2", R"({"verdict":{"status":"rejected"}})");
  EXPECT_EQ(Latest(b.get()), second);
  ASSERT_TRUE(b->AcceptJob(third, "looked at it", "test").ok());
  EXPECT_EQ(Latest(b.get()), third);
}

INSTANTIATE_TEST_SUITE_P(Backends, LatestClock, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& info) { return info.param; });

// A v5 file (before results.seq): its results are numbered in the order the old rule used
// (finished_at), so its latest calibration stays; then a result stored by a host whose clock is
// behind every stored time becomes the latest.
TEST(LatestClockMigration, SqliteVersion5ResultsAreNumberedByFinishTime) {
  TempDir dir;
  const std::string path = dir.File("v5.db");
  {
    std::unique_ptr<Db> db;
    ASSERT_TRUE(Db::Open(path, Db::Options(), &db).ok());
    ASSERT_TRUE(MigrateSchema(db.get(), 5).ok());
    ASSERT_TRUE(db->Exec("INSERT INTO recordings (id, sha256, bytes, device, layout, rows, "
                         "created_at) VALUES (1, 'h', 3, 'SN-CLOCK', 'pca_averaged', 1, 1000);"
                         "INSERT INTO recording_data VALUES (1, X'616263');"
                         "INSERT INTO jobs (id, recording_id, method, device, status, attempts, "
                         "created_at, finished_at) VALUES "
                         "(1, 1, 'pca', 'SN-CLOCK', 'succeeded', 1, 1100, 3000),"
                         "(2, 1, 'pca', 'SN-CLOCK', 'succeeded', 1, 1100, 2000);"
                         "INSERT INTO results (job_id, result_json, sha256, created_at) VALUES "
                         "(1, '{}', 'a', 3000), (2, '{}', 'b', 2000);"
                         "INSERT INTO device_calibrations VALUES ('SN-CLOCK', 'pca', 1, 3000);")
                    .ok());
  }
  FakeClock behind(500);  // earlier than anything stored
  StoreOptions o;
  o.now_ms = behind.Fn();
  std::unique_ptr<Store> store;
  Status s = Store::Open(path, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  JobInfo job;
  ASSERT_TRUE(store->LatestResult("SN-CLOCK", "pca", &job).ok());
  EXPECT_EQ(job.id, 1);
  ASSERT_TRUE(store->RevokeJob(1, "check the fallback", "test").ok());
  ASSERT_TRUE(store->LatestResult("SN-CLOCK", "pca", &job).ok());
  EXPECT_EQ(job.id, 2);
  ASSERT_TRUE(store->AcceptJob(1, "it was fine", "test").ok());
  ASSERT_TRUE(store->EnqueueJob(1, "pca", "", "{}", &job).ok());
  bool claimed = false;
  ASSERT_TRUE(store->ClaimJob("w", 1000, &job, &claimed).ok() && claimed);
  ASSERT_TRUE(store->CompleteJob(job.id, "w", kAccepted).ok());
  const int64_t newest = job.id;
  ASSERT_TRUE(store->LatestResult("SN-CLOCK", "pca", &job).ok());
  EXPECT_EQ(job.id, newest);
  store.reset();
  std::unique_ptr<Db> db;
  ASSERT_TRUE(Db::Open(path, Db::Options(), &db).ok());
  Stmt st;
  ASSERT_TRUE(db->PrepareUncached("SELECT group_concat(job_id, ',') FROM "
                                  "(SELECT job_id FROM results ORDER BY seq)",
                                  &st)
                  .ok());
  bool row = false;
  ASSERT_TRUE(st.Step(&row).ok() && row);
  EXPECT_EQ(st.ColumnText(0), "2,1," + std::to_string(newest));
  // Two results cannot share a place in the order.
  EXPECT_FALSE(db->Exec("UPDATE results SET seq = 1 WHERE job_id = 1").ok());
}

// ---- PostgreSQL: the database's clock ----

class PgClock : public ::testing::Test {
 protected:
  void SetUp() override {
    cluster_ = PgTestCluster::Get();
    ASSERT_NE(cluster_, nullptr);
    uri_ = cluster_->NewDatabase();
    Status s = Store::Open(uri_, {}, &store_);  // the default clock: the database's
    ASSERT_TRUE(s.ok()) << s.ToString();
    NewRecording r;
    r.data = "recording";
    r.device = "SN-CLOCK";
    RecordingInfo rec;
    s = store_->PutRecording(r, &rec, nullptr);
    ASSERT_TRUE(s.ok()) << s.ToString();
    ASSERT_EQ(rec.id, 1);
  }

  JobInfo Get(int64_t id) {
    JobInfo job;
    Status s = store_->GetJob(id, &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job;
  }

  PgTestCluster* cluster_ = nullptr;
  std::string uri_;
  std::unique_ptr<Store> store_;
};

// A host 10 minutes behind claims a job for 60 s: its lease ends 60 s from now on the database's
// clock, so a correct host does not take it back (before: it had lapsed 9 minutes ago).
TEST_F(PgClock, ALeaseTakenByAHostBehindLastsItsFullTerm) {
  JobInfo job;
  ASSERT_TRUE(store_->EnqueueJob(1, "pca", "", "{}", &job).ok());
  auto child = RunSkewedChild(-kTenMinutesMs, "claim", uri_);
  const int64_t now = SystemNowMs();
  EXPECT_NEAR(child["host_now_ms"] - now, -kTenMinutesMs, 5000);  // the shim was in effect
  ASSERT_EQ(child["claimed"], 1);
  EXPECT_EQ(child["id"], job.id);
  EXPECT_NEAR(child["lease_expires_at_ms"], now + 60000, 5000);
  int64_t recovered = -1;
  ASSERT_TRUE(store_->RecoverExpiredLeases(&recovered).ok());
  EXPECT_EQ(recovered, 0);
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("correct:1", 60000, &job, &claimed).ok());
  EXPECT_FALSE(claimed);
  job = Get(child["id"]);
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "skewed:1");
  EXPECT_EQ(job.attempts, 1);
}

// A host 10 minutes ahead polls for work while a correct host holds a 60 s lease: it takes
// nothing (before: every live lease looked lapsed to it, and the job ran twice).
TEST_F(PgClock, AHostAheadDoesNotTakeLiveLeases) {
  JobInfo job;
  ASSERT_TRUE(store_->EnqueueJob(1, "pca", "", "{}", &job).ok());
  bool claimed = false;
  ASSERT_TRUE(store_->ClaimJob("correct:1", 60000, &job, &claimed).ok() && claimed);
  EXPECT_NEAR(job.lease_expires_at_ms, SystemNowMs() + 60000, 5000);
  auto child = RunSkewedChild(kTenMinutesMs, "take", uri_);
  EXPECT_NEAR(child["host_now_ms"] - SystemNowMs(), kTenMinutesMs, 5000);
  EXPECT_EQ(child["recovered"], 0);
  EXPECT_EQ(child["claimed"], 0);
  job = Get(job.id);
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "correct:1");
  // The holder renews and completes it as usual.
  ASSERT_TRUE(store_->RenewLease(job.id, "correct:1", 60000).ok());
  ASSERT_TRUE(store_->CompleteJob(job.id, "correct:1", kAccepted).ok());
}

// A job enqueued through a host 10 minutes ahead is claimable at once by the others (before: its
// not_before lay 10 minutes in their future), and its times are the database's.
TEST_F(PgClock, AJobEnqueuedByAHostAheadIsClaimableAtOnce) {
  auto child = RunSkewedChild(kTenMinutesMs, "enqueue", uri_);
  ASSERT_GT(child["id"], 0);
  EXPECT_NEAR(child["not_before_ms"], SystemNowMs(), 5000);
  EXPECT_NEAR(child["created_at_ms"], SystemNowMs(), 5000);
  JobInfo job;
  bool claimed = false;
  ASSERT_TRUE(store_->ClaimJob("correct:1", 60000, &job, &claimed).ok());
  ASSERT_TRUE(claimed);
  EXPECT_EQ(job.id, child["id"]);
}

// An injected clock (StoreOptions::now_ms) is still the clock, on PostgreSQL too: the tests of
// lease expiry and back-off (store_test.cc) rely on it.
TEST_F(PgClock, AnInjectedClockIsUsedInsteadOfTheDatabases) {
  FakeClock clock(1'000'000);  // 1970: far from the database's clock
  StoreOptions o;
  o.now_ms = clock.Fn();
  std::unique_ptr<Store> store;
  ASSERT_TRUE(Store::Open(uri_, o, &store).ok());
  JobInfo job;
  ASSERT_TRUE(store->EnqueueJob(1, "pca", "", "{}", &job).ok());
  EXPECT_EQ(job.created_at_ms, 1'000'000);
  bool claimed = false;
  ASSERT_TRUE(store->ClaimJob("w", 5000, &job, &claimed).ok() && claimed);
  EXPECT_EQ(job.lease_expires_at_ms, 1'005'000);
}

// A database at PostgreSQL schema v3 (before results.seq): numbered by finish time when migrated,
// and the sequence continues after them.
TEST_F(PgClock, Version3ResultsAreNumberedByFinishTimeAndTheSequenceContinues) {
  for (int i = 0; i < 2; ++i) {
    JobInfo job;
    ASSERT_TRUE(store_->EnqueueJob(1, "pca", "", "{}", &job).ok());
    bool claimed = false;
    ASSERT_TRUE(store_->ClaimJob("w", 60000, &job, &claimed).ok() && claimed);
    ASSERT_TRUE(store_->CompleteJob(job.id, "w", kAccepted).ok());
  }
  std::unique_ptr<PgConn> c;
  ASSERT_TRUE(PgConn::Connect(uri_, "test", &c).ok());
  // As v3 left it: no seq (nor v5's indexes, nor v6's log_json); job 1 finished after job 2 by
  // the hosts' clocks.
  ASSERT_TRUE(c->ExecScript("DROP INDEX results_by_state; DROP INDEX devices_by_serial_bytes;"
                            "ALTER TABLE recordings DROP COLUMN log_json;"
                            "ALTER TABLE results DROP COLUMN seq;"
                            "UPDATE jobs SET finished_at = 3000 WHERE id = 1;"
                            "UPDATE jobs SET finished_at = 2000 WHERE id = 2;"
                            "UPDATE device_calibrations SET job_id = 1;"
                            "UPDATE calibd_schema SET version = 3")
                  .ok());
  store_.reset();
  ASSERT_TRUE(Store::Open(uri_, {}, &store_).ok());
  int64_t version = 0;
  ASSERT_TRUE(PgSchemaVersion(c.get(), &version).ok());
  EXPECT_EQ(version, kPgSchemaVersion);
  JobInfo job;
  ASSERT_TRUE(store_->LatestResult("SN-CLOCK", "pca", &job).ok());
  EXPECT_EQ(job.id, 1);
  ASSERT_TRUE(store_->EnqueueJob(1, "pca", "", "{}", &job).ok());
  bool claimed = false;
  ASSERT_TRUE(store_->ClaimJob("w", 60000, &job, &claimed).ok() && claimed);
  ASSERT_TRUE(store_->CompleteJob(job.id, "w", kAccepted).ok());
  PgResult res;
  ASSERT_TRUE(
      c->Exec("SELECT string_agg(job_id::text, ',' ORDER BY seq) FROM results", {}, &res).ok());
  EXPECT_EQ(res.Text(0, 0), "2,1," + std::to_string(job.id));
  const int64_t newest = job.id;
  ASSERT_TRUE(store_->LatestResult("SN-CLOCK", "pca", &job).ok());
  EXPECT_EQ(job.id, newest);
}

// ---- calibd serve processes ----

// A PCA recording of device SN-CLOCK for POST /api/v1/recordings.
httplib::MultipartFormDataItems PcaUpload(uint64_t seed) {
  core::PcaSimulationOptions sim;
  sim.seed = seed;
  sim.positions = 30;
  std::string csv;
  nlohmann::json config, truth;
  EXPECT_TRUE(server::SimulatePcaFiles(sim, &csv, &config, &truth).ok());
  config["device"] = "SN-CLOCK";
  return {{"recording", csv, "r.csv", "text/csv"},
          {"config", config.dump(), "", "application/json"}};
}

// Uploads through `server`, waits for its job and returns the job's id (0 on failure).
int64_t CalibrateThrough(server::testing::ServerProcess* server, uint64_t seed) {
  auto client = server->Client();
  auto res = client.Post("/api/v1/recordings", PcaUpload(seed));
  if (!res || res->status != 201) {
    ADD_FAILURE() << (res ? res->body : "no answer") << server->log();
    return 0;
  }
  const int64_t id = nlohmann::json::parse(res->body)["job"]["id"];
  server::testing::WaitUntilIdle(client, 30000);
  nlohmann::json job = server::testing::GetJob(client, id);
  EXPECT_EQ(job["status"], "succeeded") << job.dump() << server->log();
  return id;
}

class CalibdClock : public LatestClock {};

// The issue's report, with real calibd processes on one database: host A (right clock)
// calibrates the device, then host B (10 minutes behind, through the shim) calibrates it again.
// Every host serves B's calibration (before: A's stayed latest, B's was never served).
TEST_P(CalibdClock, ANewerCalibrationFromAHostBehindIsServedByEveryHost) {
  TempDir tmp_a, tmp_b;  // each host its own TMPDIR (uploads are staged there)
  auto a = std::make_unique<server::testing::ServerProcess>(
      target_, std::vector<std::string>{"--workers", "1"}, tmp_a.path());
  ASSERT_GT(a->port(), 0) << a->log();
  const int64_t first = CalibrateThrough(a.get(), 1);
  ASSERT_GT(first, 0);
  EXPECT_EQ(a->Signal(SIGTERM), 0) << a->log();  // only B computes the next one
  server::testing::ServerProcess b(target_, {"--workers", "1"}, tmp_b.path(),
                                   SkewEnv(std::to_string(-kTenMinutesMs)));
  ASSERT_GT(b.port(), 0) << b.log();
  const int64_t second = CalibrateThrough(&b, 2);
  ASSERT_GT(second, first);
  {
    // The shim was in effect: on SQLite B stored its own (10 minutes behind) times; on PostgreSQL
    // every time is the database's, so B's job was created after A's finished.
    auto client = b.Client();
    const std::string a_finished = server::testing::GetJob(client, first)["finished_at"];
    const std::string b_created = server::testing::GetJob(client, second)["created_at"];
    if (GetParam() == "sqlite") {
      EXPECT_LT(b_created, a_finished);
    } else {
      EXPECT_GT(b_created, a_finished);
    }
  }
  a = std::make_unique<server::testing::ServerProcess>(
      target_, std::vector<std::string>{"--workers", "1"}, tmp_a.path());
  ASSERT_GT(a->port(), 0) << a->log();
  for (auto* host : {a.get(), &b}) {
    auto res = host->Client().Get("/api/v1/devices/SN-CLOCK/calibration?method=pca");
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << res->body;
    EXPECT_EQ(res->get_header_value("X-Calibd-Job"), std::to_string(second)) << res->body;
  }
  EXPECT_EQ(b.Signal(SIGTERM), 0) << b.log();
}

INSTANTIATE_TEST_SUITE_P(Backends, CalibdClock, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& info) { return info.param; });

}  // namespace
}  // namespace calibd::storage
