// The worker pool against a real Store on a temporary SQLite file, running the real methods on
// small simulated recordings: jobs complete, Stop's grace period, Stop(0) releasing a running
// job, a lease taken back cancelling the computation, and the shared numerics executor.
//
// A running job is held at a known point without timing: the array solver's parallel numerics go
// through WorkerPoolOptions::executor, and the test's executor (GatedExecutor) runs every task
// correctly but makes the first call wait until the test opens the gate.
#include "server/worker_pool.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <thread>

#include "core/pca_simulation.h"
#include "core/task_pool.h"
#include "methods/array/array_method.h"
#include "methods/pca/pca_method.h"
#include "server/metrics.h"
#include "storage/db.h"
#include "storage/store.h"
#include "tests/lib/sanitizer.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using storage::testing::FakeClock;
using storage::testing::TempDir;

// Runs every task on the calling thread (the solvers' results do not depend on the thread
// count), counts the calls, and holds the first call until Open() while the gate is closed.
class GatedExecutor {
 public:
  explicit GatedExecutor(bool closed) : open_(!closed) {}

  core::TaskExecutor Fn() {
    return [this](int64_t tasks, const std::function<void(int64_t)>& run) {
      {
        std::unique_lock<std::mutex> lock(mu_);
        ++calls_;
        changed_.notify_all();
        changed_.wait(lock, [this] { return open_; });
      }
      for (int64_t i = 0; i < tasks; ++i) run(i);
    };
  }
  // Waits (at most a minute) until a computation is inside the executor.
  bool WaitEntered() {
    std::unique_lock<std::mutex> lock(mu_);
    return changed_.wait_for(lock, std::chrono::minutes(1), [this] { return calls_ > 0; });
  }
  void Open() {
    std::lock_guard<std::mutex> lock(mu_);
    open_ = true;
    changed_.notify_all();
  }
  int calls() const {
    std::lock_guard<std::mutex> lock(mu_);
    return calls_;
  }

 private:
  mutable std::mutex mu_;
  std::condition_variable changed_;
  bool open_;
  int calls_ = 0;
};

class WorkerPoolTest : public ::testing::Test {
 protected:
  void OpenStore(std::function<int64_t()> now_ms = {}) {
    storage::StoreOptions o;
    o.now_ms = std::move(now_ms);
    ASSERT_TRUE(storage::Store::Open(dir_.File("calibd.db"), o, &store_).ok());
  }
  void SetUp() override { OpenStore(); }

  // A small array recording (N = 1000, 32 triads) and its job.
  int64_t EnqueueArray(uint64_t seed) {
    ArraySimulationFileOptions so;
    so.seed = seed;
    std::string csv;
    json config, truth;
    EXPECT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
    return Enqueue(csv, "array", "array", config);
  }
  // A small pca recording (12 sensors, 100 positions).
  int64_t EnqueuePca(uint64_t seed) {
    core::PcaSimulationOptions so;
    so.seed = seed;
    std::string csv;
    json config, truth;
    EXPECT_TRUE(SimulatePcaFiles(so, &csv, &config, &truth).ok());
    return Enqueue(csv, "pca_averaged", "pca", config);
  }
  int64_t Enqueue(const std::string& csv, const std::string& layout, const std::string& method,
                  const json& config) {
    storage::NewRecording r;
    r.data = csv;
    r.layout = layout;
    r.file_name = method + ".csv";
    r.device = "SN-1";
    r.job = storage::NewJob{method, "", config.dump()};
    storage::RecordingInfo info;
    const Status s = store_->PutRecording(r, &info, nullptr);
    EXPECT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(info.job.has_value());
    return info.job ? info.job->id : 0;
  }

  storage::JobInfo Job(int64_t id) {
    storage::JobInfo job;
    EXPECT_TRUE(store_->GetJob(id, &job).ok());
    return job;
  }
  // Polls until the job has `status` (at most two minutes: a liveness bound, not a speed claim).
  storage::JobInfo WaitFor(int64_t id, storage::JobStatus status) {
    storage::JobInfo job;
    for (int i = 0; i < 12000; ++i) {
      job = Job(id);
      if (job.status == status) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return job;
  }
  // Waits (a liveness bound of two minutes, not a speed claim) until the job has failed or is
  // back in the queue after an attempt.
  storage::JobInfo WaitUntilFailedOrRequeued(int64_t id) {
    storage::JobInfo job;
    for (int i = 0; i < 12000; ++i) {
      job = Job(id);
      if (job.status == JobStatus::kFailed ||
          (job.status == JobStatus::kQueued && job.attempts > 0)) {
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return job;
  }
  int Outcomes(const std::string& method, const std::string& outcome) {
    const std::string text = metrics_.Render({}, {});
    const std::string key =
        "calibd_jobs_finished_total{method=\"" + method + "\",outcome=\"" + outcome + "\"} ";
    const size_t at = text.find(key);
    return at == std::string::npos ? 0 : std::stoi(text.substr(at + key.size()));
  }
  WorkerPoolOptions Options(core::TaskExecutor executor = {}) {
    WorkerPoolOptions o;
    o.workers = 1;
    o.lease_ms = 300;  // renewed every 100 ms: a lost lease is noticed at once
    o.poll_ms = 20;
    o.id_prefix = "test:1";
    o.executor = std::move(executor);
    return o;
  }

  TempDir dir_;
  FakeClock clock_;  // used by the tests that open the store with it
  std::unique_ptr<storage::Store> store_;
  Metrics metrics_;
};

TEST_F(WorkerPoolTest, JobsOfEveryQueuedMethodComplete) {
  const int64_t pca = EnqueuePca(3);
  const int64_t array = EnqueueArray(4);
  WorkerPoolOptions o = Options();
  o.workers = 2;
  WorkerPool pool(store_.get(), &metrics_, o);
  pool.Start();
  pool.Notify();
  const storage::JobInfo p = WaitFor(pca, JobStatus::kSucceeded);
  const storage::JobInfo a = WaitFor(array, JobStatus::kSucceeded);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  ASSERT_EQ(p.status, JobStatus::kSucceeded) << p.error_code << ": " << p.error_message;
  ASSERT_EQ(a.status, JobStatus::kSucceeded) << a.error_code << ": " << a.error_message;
  EXPECT_EQ(p.attempts, 1);
  EXPECT_EQ(a.attempts, 1);
  EXPECT_EQ(json::parse(p.result_json)["parameters"]["sensors"].size(), 12u);
  EXPECT_EQ(json::parse(a.result_json)["parameters"]["positions"].size(), 32u);
  EXPECT_EQ(Outcomes("pca", "succeeded"), 1);
  EXPECT_EQ(Outcomes("array", "succeeded"), 1);
  EXPECT_EQ(pool.running_jobs(), 0);
}

TEST_F(WorkerPoolTest, StopWithAGracePeriodLetsTheRunningJobFinish) {
  const int64_t id = EnqueueArray(5);
  GatedExecutor gate(/*closed=*/true);
  WorkerPool pool(store_.get(), &metrics_, Options(gate.Fn()));
  pool.Start();
  pool.Notify();
  ASSERT_TRUE(gate.WaitEntered());
  EXPECT_EQ(pool.running_jobs(), 1);
  EXPECT_EQ(Job(id).status, JobStatus::kRunning);
  StopOutcome outcome = StopOutcome::kAbandoned;
  std::thread stopper([&] { outcome = pool.Stop(std::chrono::minutes(2)); });
  // Stop is now waiting (or about to) while the job is held; let the job go on.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  gate.Open();
  stopper.join();
  EXPECT_EQ(outcome, StopOutcome::kFinished);
  const storage::JobInfo job = Job(id);
  EXPECT_EQ(job.status, JobStatus::kSucceeded) << job.error_code << ": " << job.error_message;
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(Outcomes("array", "succeeded"), 1);
}

// A job computing through Stop's grace period keeps its lease: the renewer outlives the workers.
// (It stopped with them: a job longer than a lease was taken back by another process mid-grace.)
TEST_F(WorkerPoolTest, LeasesAreRenewedThroughStopsGracePeriod) {
  const int64_t id = EnqueueArray(15);
  GatedExecutor gate(/*closed=*/true);
  WorkerPool pool(store_.get(), &metrics_, Options(gate.Fn()));  // lease 300 ms
  pool.Start();
  pool.Notify();
  ASSERT_TRUE(gate.WaitEntered());
  StopOutcome outcome = StopOutcome::kAbandoned;
  std::thread stopper([&] { outcome = pool.Stop(std::chrono::minutes(2)); });
  // Several lease lengths into the grace period, the lease is alive: nothing to recover.
  int64_t recovered = 0;
  for (int i = 0; i < 10; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    ASSERT_TRUE(store_->RecoverExpiredLeases(&recovered).ok());
    EXPECT_EQ(recovered, 0) << "the lease lapsed " << (i + 1) * 150 << " ms into Stop";
  }
  gate.Open();
  stopper.join();
  EXPECT_EQ(outcome, StopOutcome::kFinished);
  const storage::JobInfo job = Job(id);
  EXPECT_EQ(job.status, JobStatus::kSucceeded) << job.error_code << ": " << job.error_message;
  EXPECT_EQ(job.attempts, 1);
}

TEST_F(WorkerPoolTest, StopWithoutGraceReleasesTheRunningJobWithoutCountingTheAttempt) {
  // A whole run of the job first, counting its executor calls: a cancelled run must make fewer.
  const int64_t whole = EnqueueArray(6);
  int full_calls = 0;
  {
    GatedExecutor counter(/*closed=*/false);
    WorkerPool pool(store_.get(), &metrics_, Options(counter.Fn()));
    pool.Start();
    pool.Notify();
    ASSERT_EQ(WaitFor(whole, JobStatus::kSucceeded).status, JobStatus::kSucceeded);
    EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
    full_calls = counter.calls();
  }
  ASSERT_GT(full_calls, 2);

  // The same recording and config again, held in its first executor call.
  const storage::JobInfo first = Job(whole);
  storage::JobInfo queued;
  ASSERT_TRUE(store_->EnqueueJob(first.recording_id, "array", "", first.config_json, &queued).ok());
  const int64_t id = queued.id;
  GatedExecutor gate(/*closed=*/true);
  WorkerPool pool(store_.get(), &metrics_, Options(gate.Fn()));
  pool.Start();
  pool.Notify();
  ASSERT_TRUE(gate.WaitEntered());
  EXPECT_EQ(Job(id).attempts, 1);
  StopOutcome outcome = StopOutcome::kFinished;
  std::thread stopper([&] { outcome = pool.Stop(std::chrono::milliseconds(0)); });
  // Stop(0) asks the computation to stop, but while it still computes (held here) the job keeps
  // its lease: a restarted server must not claim it yet (the 7.8 s bug of issue #20).
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(Job(id).status, JobStatus::kRunning);
  EXPECT_EQ(Job(id).lease_owner, "test:1-0");
  gate.Open();  // the computation stops at its next check; only then is the job released
  stopper.join();
  EXPECT_EQ(outcome, StopOutcome::kReleased);
  const storage::JobInfo job = Job(id);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.attempts, 0) << "a released attempt is not counted";
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(job.result_json, "");
  EXPECT_EQ(Outcomes("array", "released"), 1);
  EXPECT_EQ(Outcomes("array", "succeeded"), 1);  // the whole run only
  EXPECT_LT(gate.calls(), full_calls) << "the stopped computation ran to the end";

  // It runs again, to the same result, after the restart.
  WorkerPool again(store_.get(), &metrics_, Options());
  again.Start();
  again.Notify();
  const storage::JobInfo done = WaitFor(id, JobStatus::kSucceeded);
  EXPECT_EQ(again.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  EXPECT_EQ(done.status, JobStatus::kSucceeded) << done.error_code << ": " << done.error_message;
  EXPECT_EQ(done.attempts, 1);
}

// A computation that does not return within stop_wait_ms of Stop's request is abandoned: its
// job keeps its lease (which lapses), so nobody computes it while this process still might.
TEST_F(WorkerPoolTest, AComputationThatDoesNotStopKeepsItsLease) {
  const int64_t id = EnqueueArray(16);
  GatedExecutor gate(/*closed=*/true);
  WorkerPoolOptions o = Options(gate.Fn());
  o.stop_wait_ms = 300;
  auto pool = std::make_unique<WorkerPool>(store_.get(), &metrics_, o);
  pool->Start();
  pool->Notify();
  ASSERT_TRUE(gate.WaitEntered());
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(pool->Stop(std::chrono::milliseconds(0)), StopOutcome::kAbandoned);
  const double took =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_GE(took, 0.3);
  EXPECT_LT(took, 2.0);
  storage::JobInfo job = Job(id);
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "test:1-0");
  gate.Open();
  pool.reset();  // waits for the abandoned computation, which releases nothing
  job = Job(id);
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "test:1-0");
}

// The job's time limit ends it as failed, reason deadline, never retried.
TEST_F(WorkerPoolTest, AJobPastItsTimeLimitFailsWithReasonDeadline) {
  const int64_t id = EnqueueArray(17);
  GatedExecutor gate(/*closed=*/true);
  WorkerPoolOptions o = Options(gate.Fn());
  o.job_ms = 200;
  WorkerPool pool(store_.get(), &metrics_, o);
  pool.Start();
  pool.Notify();
  // The limit may pass before the solver starts (parsing takes longer than 0.2 s under
  // sanitizers): then the job fails without entering the executor. Otherwise it is held inside
  // the solver past the limit, and must stop at the solver's next check.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::minutes(1);
  while (gate.calls() == 0 && Job(id).status != JobStatus::kFailed &&
         std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (gate.calls() > 0) std::this_thread::sleep_for(std::chrono::milliseconds(300));
  gate.Open();
  const storage::JobInfo job = WaitFor(id, JobStatus::kFailed);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_reason, "deadline");
  EXPECT_EQ(job.error_code, "stopped");
  EXPECT_NE(job.error_message.find("time limit of 0.2 s"), std::string::npos) << job.error_message;
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  EXPECT_EQ(Job(id).status, JobStatus::kFailed);
}

// A full disk: the result does not fit. The job must not stay running until its lease lapses:
// its failure (reason disk_full) is stored in place, or, when not even that fits, it is released.
// (The paths where the failure with diagnostics does not fit, or neither does, are the two
// tests after this one.)
TEST_F(WorkerPoolTest, AJobWhoseResultDoesNotFitOnAFullDiskStillEnds) {
  const int64_t id = EnqueueArray(20);
  store_.reset();
  int64_t pages = 0;
  {
    std::unique_ptr<storage::Db> db;
    ASSERT_TRUE(storage::Db::Open(dir_.File("calibd.db"), storage::Db::Options(), &db).ok());
    ASSERT_TRUE(db->QueryInt("PRAGMA page_count", &pages).ok());
  }
  storage::StoreOptions so;
  so.max_page_count = pages;  // full: rows change in place, nothing new fits
  ASSERT_TRUE(storage::Store::Open(dir_.File("calibd.db"), so, &store_).ok());
  WorkerPool pool(store_.get(), &metrics_, Options());
  pool.Start();
  pool.Notify();
  WaitUntilFailedOrRequeued(id);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  const storage::JobInfo job = Job(id);
  ASSERT_NE(job.status, JobStatus::kRunning) << "the job stayed running";
  if (job.status == JobStatus::kFailed) {
    EXPECT_EQ(job.error_reason, "disk_full") << job.error_message;
    EXPECT_NE(job.error_message.find("disk is full"), std::string::npos) << job.error_message;
    EXPECT_EQ(job.error_message.find("INSERT"), std::string::npos) << job.error_message;
  } else {
    EXPECT_EQ(job.lease_owner, "");  // given back to the queue
  }
}

// A job that fails with partial diagnostics (an array log of 2 samples: too_few_samples), on a
// database filled to its max_page_count, with a trigger (made through a second connection)
// that makes any UPDATE of a job matching `when` insert 200 kB: a genuine SQLITE_FULL (never
// RAISE(), which the store reports as a conflict). Returns the job's id; the store is reopened
// full, backing off 10 minutes after a transient failure.
int64_t EnqueueFailingJobOnAFullDisk(const TempDir& dir, const std::string& when,
                                     std::unique_ptr<storage::Store>* store) {
  int64_t id = 0;
  {
    ArraySimulationFileOptions so;
    so.samples = 2;
    std::string csv;
    json config, truth;
    EXPECT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
    storage::NewRecording r;
    r.data = csv;
    r.layout = "array";
    r.file_name = "short.csv";
    r.job = storage::NewJob{"array", "", config.dump()};
    storage::RecordingInfo info;
    EXPECT_TRUE((*store)->PutRecording(r, &info, nullptr).ok());
    id = info.job ? info.job->id : 0;
  }
  store->reset();
  int64_t pages = 0, free_pages = 0;
  {
    std::unique_ptr<storage::Db> db;
    EXPECT_TRUE(storage::Db::Open(dir.File("calibd.db"), storage::Db::Options(), &db).ok());
    EXPECT_TRUE(db->Exec("CREATE TABLE filler(b BLOB); "
                         "CREATE TRIGGER grow BEFORE UPDATE ON jobs WHEN " +
                         when + " BEGIN INSERT INTO filler VALUES (randomblob(200000)); END")
                    .ok());
    EXPECT_TRUE(db->QueryInt("PRAGMA page_count", &pages).ok());
    EXPECT_TRUE(db->QueryInt("PRAGMA freelist_count", &free_pages).ok());
  }
  EXPECT_LT(free_pages * 4096, 200000) << "the free pages would hold the trigger's blob";
  storage::StoreOptions so;
  so.max_page_count = pages;  // full: rows change in place, nothing new fits
  so.backoff_base_ms = so.backoff_max_ms = 600000;
  EXPECT_TRUE(storage::Store::Open(dir.File("calibd.db"), so, store).ok());
  return id;
}

// The failure with its diagnostics does not fit; the one without them does: the job ends failed
// with its reason and message, and no diagnostics.
TEST_F(WorkerPoolTest, AFailureWhoseDiagnosticsDoNotFitIsStoredWithoutThem) {
  const int64_t id =
      EnqueueFailingJobOnAFullDisk(dir_, "NEW.error_detail_json IS NOT NULL", &store_);
  WorkerPool pool(store_.get(), &metrics_, Options());
  pool.Start();
  pool.Notify();
  const storage::JobInfo job = WaitFor(id, JobStatus::kFailed);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  ASSERT_EQ(job.status, JobStatus::kFailed) << job.error_message;
  EXPECT_EQ(job.error_reason, "too_few_samples") << job.error_message;
  EXPECT_FALSE(job.error_message.empty());
  EXPECT_LE(job.error_message.size(), 200u);
  EXPECT_EQ(job.error_detail_json, "");
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(Outcomes("array", "failed"), 1);
}

// Neither failure fits: the job goes back to the queue, its attempt counted and backing off
// (the shutdown release would uncount it and make it claimable at once: a job whose outcome can
// never be stored would be claimed again and again, forever).
TEST_F(WorkerPoolTest, AJobWhoseFailureCannotBeStoredIsReleasedCountedAndBackingOff) {
  const int64_t id = EnqueueFailingJobOnAFullDisk(dir_, "NEW.error_message IS NOT NULL", &store_);
  const int64_t before = std::chrono::duration_cast<std::chrono::milliseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
  WorkerPool pool(store_.get(), &metrics_, Options());
  pool.Start();
  pool.Notify();
  WaitUntilFailedOrRequeued(id);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  const storage::JobInfo job = Job(id);
  ASSERT_EQ(job.status, JobStatus::kQueued) << job.error_message;
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(job.attempts, 1);
  EXPECT_GE(job.not_before_ms, before + 600000);  // backing off: 10 minutes
  EXPECT_EQ(job.error_message, "");               // what did not fit
  EXPECT_EQ(Outcomes("array", "released"), 1);
  EXPECT_EQ(Outcomes("array", "failed"), 0);
}

// An exception thrown inside a job's computation (here by the numerics executor, where the
// solver's parallel work runs): the job fails with the generic internal error and never shows
// what was thrown (clients read it); the operator's log has it, with the job's id.
TEST_F(WorkerPoolTest, AnExceptionsTextGoesToTheLogNeverIntoTheJob) {
  const int64_t id = EnqueueArray(21);
  const std::string marker = "marker-7f3a: the solver's secret state";
  WorkerPool pool(store_.get(), &metrics_,
                  Options([&](int64_t, const std::function<void(int64_t)>&) {
                    throw std::runtime_error(marker);
                  }));
  ::testing::internal::CaptureStderr();
  pool.Start();
  pool.Notify();
  const storage::JobInfo job = WaitFor(id, JobStatus::kFailed);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_EQ(job.status, JobStatus::kFailed) << job.error_message;
  EXPECT_EQ(job.error_code, "internal");
  EXPECT_NE(job.error_message.find("internal error while calibrating"), std::string::npos)
      << job.error_message;
  EXPECT_EQ(job.error_message.find("marker-7f3a"), std::string::npos) << job.error_message;
  EXPECT_EQ(job.error_detail_json.find("marker-7f3a"), std::string::npos);
  EXPECT_NE(
      log.find("job " + std::to_string(id) + " (array): exception while calibrating: " + marker),
      std::string::npos)
      << log;
}

// A cancel in this process (WorkerPool::Cancel) or through the store from anywhere.
TEST_F(WorkerPoolTest, ACancelledJobFailsWithWhoCancelledItAndWhy) {
  for (const bool local : {true, false}) {
    const int64_t id = EnqueueArray(local ? 18 : 19);
    GatedExecutor gate(/*closed=*/true);
    WorkerPoolOptions o = Options(gate.Fn());
    o.cancel_poll_ms = 20;
    WorkerPool pool(store_.get(), &metrics_, o);
    pool.Start();
    pool.Notify();
    ASSERT_TRUE(gate.WaitEntered());
    ASSERT_TRUE(store_->CancelJob(id, "wrong board", "token").ok());
    if (local) {
      EXPECT_TRUE(pool.Cancel(id));
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));  // a few polls
    }
    EXPECT_FALSE(pool.Cancel(id + 1000));
    gate.Open();
    const storage::JobInfo job = WaitFor(id, JobStatus::kFailed);
    EXPECT_EQ(job.status, JobStatus::kFailed) << (local ? "local" : "through the store");
    EXPECT_EQ(job.error_reason, "cancelled");
    EXPECT_EQ(job.error_message.rfind("cancelled by token: wrong board", 0), 0u)
        << job.error_message;
    EXPECT_EQ(job.attempts, 1);
    EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  }
}

// The lease is taken back (as another process does when it believes this one dead, or after the
// lease expired) and another worker claims the job: the running computation is cancelled, stores
// nothing, and the new holder keeps the job.
void ExpectTakenBackJobIsCancelled(storage::Store* store, Metrics* metrics, int64_t id,
                                   const std::function<void()>& take_back) {
  GatedExecutor gate(/*closed=*/true);
  WorkerPoolOptions o;
  o.workers = 1;
  o.lease_ms = 300;
  o.poll_ms = 20;
  o.id_prefix = "test:1";
  o.executor = gate.Fn();
  WorkerPool pool(store, metrics, o);
  pool.Start();
  pool.Notify();
  ASSERT_TRUE(gate.WaitEntered());
  take_back();
  storage::JobInfo other;
  bool claimed = false;
  ASSERT_TRUE(store->ClaimJob("other:2-0", 600000, &other, &claimed).ok());
  ASSERT_TRUE(claimed);
  ASSERT_EQ(other.id, id);
  // The renewer (every 100 ms) finds the lease gone and cancels the run; keep the computation
  // held long enough for that (a liveness allowance, scaled for the sanitizers).
  std::this_thread::sleep_for(
      std::chrono::milliseconds(static_cast<int>(1500 * sanitizer::kTimeBoundScale)));
  gate.Open();
  // The pool's worker is free again (it ends the cancelled run) and nothing was stored.
  for (int i = 0; i < 12000 && pool.running_jobs() > 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(pool.running_jobs(), 0);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  storage::JobInfo job;
  ASSERT_TRUE(store->GetJob(id, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "other:2-0");
  EXPECT_EQ(job.result_json, "");
  const std::string text = metrics->Render({}, {});
  // Cancelled, not computed to the end and refused at CompleteJob ("released").
  EXPECT_NE(text.find("calibd_jobs_finished_total{method=\"array\",outcome=\"cancelled\"} 1"),
            std::string::npos)
      << text;
  EXPECT_EQ(text.find("outcome=\"released\""), std::string::npos) << text;
}

TEST_F(WorkerPoolTest, LeaseTakenBackFromADeadOwnerCancelsTheRunningComputation) {
  const int64_t id = EnqueueArray(7);
  ExpectTakenBackJobIsCancelled(store_.get(), &metrics_, id, [&] {
    int64_t taken_back = 0;
    ASSERT_TRUE(store_->ExpireLeasesOf("test:1-", &taken_back).ok());
    EXPECT_EQ(taken_back, 1);
  });
}

TEST_F(WorkerPoolTest, ExpiredLeaseRecoveredElsewhereCancelsTheRunningComputation) {
  store_.reset();
  OpenStore(clock_.Fn());
  const int64_t id = EnqueueArray(8);
  ExpectTakenBackJobIsCancelled(store_.get(), &metrics_, id, [&] {
    // The lease (300 ms, renewed from the fake clock) lapses when the clock jumps a minute; the
    // renewer may renew it from the new time in between, so jump until one recovery takes it.
    int64_t recovered = 0;
    for (int i = 0; i < 100 && recovered == 0; ++i) {
      clock_.Advance(60000);
      ASSERT_TRUE(store_->RecoverExpiredLeases(&recovered).ok());
    }
    EXPECT_EQ(recovered, 1);
  });
}

TEST_F(WorkerPoolTest, SharedExecutorIsUsedAndGivesTheIdenticalResult) {
  const int64_t own = EnqueueArray(9);
  {
    WorkerPool pool(store_.get(), &metrics_, Options());
    pool.Start();
    pool.Notify();
    ASSERT_EQ(WaitFor(own, JobStatus::kSucceeded).status, JobStatus::kSucceeded);
    EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  }
  // The same recording and config again (a second job on the stored recording).
  storage::JobInfo first = Job(own);
  storage::JobInfo second;
  ASSERT_TRUE(store_->EnqueueJob(first.recording_id, "array", "", first.config_json, &second).ok());
  core::TaskPool numerics(2);
  std::atomic<int> calls{0};
  const core::TaskExecutor pooled = numerics.Executor();
  WorkerPool pool(store_.get(), &metrics_,
                  Options([&](int64_t tasks, const std::function<void(int64_t)>& run) {
                    ++calls;
                    pooled(tasks, run);
                  }));
  pool.Start();
  pool.Notify();
  const storage::JobInfo shared = WaitFor(second.id, JobStatus::kSucceeded);
  EXPECT_EQ(pool.Stop(std::chrono::seconds(60)), StopOutcome::kFinished);
  ASSERT_EQ(shared.status, JobStatus::kSucceeded)
      << shared.error_code << ": " << shared.error_message;
  EXPECT_GT(calls.load(), 0) << "the job did not use the shared executor";
  json a = json::parse(first.result_json), b = json::parse(shared.result_json);
  EXPECT_EQ(a["parameters"], b["parameters"]);
  EXPECT_EQ(a["uncertainty"], b["uncertainty"]);
  EXPECT_EQ(a["diagnostics"]["iterations"], b["diagnostics"]["iterations"]);
}

}  // namespace
}  // namespace calibd::server
