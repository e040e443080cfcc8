// PgStore: what only the PostgreSQL backend promises beyond the shared Store contract
// (store_test.cc runs that against both): several stores (as on several hosts) on one database,
// schema versioning under concurrent openers, chunked recordings, LISTEN/NOTIFY, and a server
// that goes away and comes back. Runs against a throw-away cluster (pg_test_cluster.h).
#include "storage/pg_store.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include "storage/pg_conn.h"
#include "storage/pg_store_internal.h"
#include "storage/store.h"
#include "tests/lib/sanitizer.h"
#include "tests/storage/pg_test_cluster.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::FakeClock;
using testing::PgTestCluster;
using testing::RandomBytes;

class PgStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    cluster_ = PgTestCluster::Get();
    ASSERT_NE(cluster_, nullptr);
    uri_ = cluster_->NewDatabase();
  }

  std::unique_ptr<Store> Open(StoreOptions o = {}) {
    if (!o.now_ms) o.now_ms = clock_.Fn();
    std::unique_ptr<Store> store;
    Status s = Store::Open(uri_, o, &store);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return store;
  }

  std::unique_ptr<PgConn> Sql() {
    std::unique_ptr<PgConn> c;
    Status s = PgConn::Connect(uri_, "test", &c);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return c;
  }

  int64_t Put(Store* store, const std::string& bytes, const std::string& device = "SN1") {
    NewRecording r;
    r.data = bytes;
    r.device = device;
    RecordingInfo info;
    Status s = store->PutRecording(r, &info, nullptr);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return info.id;
  }

  PgTestCluster* cluster_ = nullptr;
  std::string uri_;
  FakeClock clock_;
};

// The plan PostgreSQL makes for `sql` with `params` (EXPLAIN's lines, one per line).
std::string Plan(PgConn* c, const std::string& sql, const std::vector<PgParam>& params) {
  PgResult res;
  const std::string explain = "EXPLAIN " + sql;
  Status s = c->Exec(explain.c_str(), params, &res);
  EXPECT_TRUE(s.ok()) << s.ToString();
  std::string plan;
  for (int i = 0; i < res.rows(); ++i) plan += res.Text(i, 0) + "\n";
  return plan;
}

// ?verdict= (ListJobs and CountJobs with a state and no device) reads index results_by_state,
// on a table of 20 000 succeeded jobs (0.1 % revoked) with its statistics (ANALYZE), so the
// planner chooses by the data, no setting forcing it: without the index it would scan every
// succeeded job (the issue measured 0.23 s at 20 000 jobs) for a verdict that few have.
TEST_F(PgStoreTest, AVerdictListingReadsTheIndexOfResultsByTheirStanding) {
  auto store = Open();
  const int64_t rec = Put(store.get(), "x");
  auto c = Sql();
  ASSERT_TRUE(c->ExecScript(("INSERT INTO jobs (recording_id, method, device, status, created_at) "
                             "SELECT " +
                             std::to_string(rec) +
                             ", 'pca', 'SN-' || (g % 50), 'succeeded', g "
                             "FROM generate_series(1, 20000) g; "
                             "INSERT INTO results (job_id, result_json, sha256, created_at, "
                             "verdict, decision) SELECT id, '{}', 'x', 1, CASE WHEN id % 10 = 0 "
                             "THEN 'rejected' ELSE 'accepted' END, CASE WHEN id % 1000 = 0 THEN "
                             "'revoked' END FROM jobs; ANALYZE jobs; ANALYZE results;")
                                .c_str())
                  .ok());
  for (const ServeState state : {ServeState::kRevoked, ServeState::kRejected}) {
    SCOPED_TRACE(Name(state));
    JobFilter filter;
    filter.state = state;
    filter.limit = 50;
    std::vector<PgParam> params;
    std::string plan = Plan(c.get(), pg::ListJobsSql(filter, &params), params);
    EXPECT_NE(plan.find("results_by_state"), std::string::npos) << plan;
    EXPECT_EQ(plan.find("Seq Scan on jobs"), std::string::npos) << plan;
    plan = Plan(c.get(), pg::CountJobsSql(filter, &params), params);
    EXPECT_NE(plan.find("results_by_state"), std::string::npos) << plan;
    // And what they read.
    std::vector<JobInfo> jobs;
    ASSERT_TRUE(store->ListJobs(filter, &jobs).ok());
    ASSERT_EQ(jobs.size(), state == ServeState::kRevoked ? 20u : 50u);
    for (const JobInfo& job : jobs) EXPECT_EQ(job.state, state);
    EXPECT_EQ(jobs[0].id, state == ServeState::kRevoked ? 20000 : 19990);
    int64_t count = 0;
    ASSERT_TRUE(store->CountJobs(filter, &count).ok());
    EXPECT_EQ(count, state == ServeState::kRevoked ? 20 : 1980);
  }
}

TEST_F(PgStoreTest, OpenPicksThePostgresBackendForUrisAndKeywordStrings) {
  EXPECT_TRUE(Store::IsPostgresTarget("postgresql://u@db/calibd"));
  EXPECT_TRUE(Store::IsPostgresTarget("postgres:///calibd?host=/run/postgresql"));
  EXPECT_TRUE(Store::IsPostgresTarget("host=db dbname=calibd"));
  EXPECT_TRUE(Store::IsPostgresTarget("host=/run/postgresql dbname=calibd"));
  EXPECT_TRUE(Store::IsPostgresTarget("service = calibd"));
  EXPECT_FALSE(Store::IsPostgresTarget("data/calibd.db"));
  EXPECT_FALSE(Store::IsPostgresTarget("/var/lib/calibd/calibd.db"));
  EXPECT_FALSE(Store::IsPostgresTarget("./a=b.db"));
  EXPECT_FALSE(Store::IsPostgresTarget("calibd.db"));
  EXPECT_FALSE(Store::IsPostgresTarget("=x"));
  auto store = Open();
  ASSERT_NE(store, nullptr);
  EXPECT_STREQ(store->backend(), "postgresql");
}

TEST_F(PgStoreTest, PasswordsNeverAppearInTheDisplayedTarget) {
  EXPECT_EQ(RedactConnectionTarget("postgresql://calibd:s3cret@db:5432/calibd"),
            "postgresql://calibd:***@db:5432/calibd");
  EXPECT_EQ(RedactConnectionTarget("host=db password=s3cret dbname=calibd"),
            "host=db password=*** dbname=calibd");
  EXPECT_EQ(RedactConnectionTarget("postgresql:///calibd?user=u&password=s3cret&host=/tmp"),
            "postgresql:///calibd?user=u&password=***&host=/tmp");
  EXPECT_EQ(RedactConnectionTarget("postgresql://db/calibd"), "postgresql://db/calibd");
}

TEST_F(PgStoreTest, UnreachableServerIsBusyNamingTheTargetWithoutItsPassword) {
  std::unique_ptr<Store> store;
  Status s = Store::Open(
      "postgresql://u:Xq7-Secret-Zk9@/calibd?host=" + cluster_->dir() + "/nowhere", {}, &store);
  EXPECT_EQ(s.code(), StatusCode::kBusy) << s.ToString();
  EXPECT_NE(s.message().find("cannot connect to PostgreSQL"), std::string::npos) << s.message();
  // A password no random directory name (mkdtemp) can contain, so that its absence means it.
  EXPECT_EQ(s.message().find("Secret"), std::string::npos) << s.message();
}

TEST_F(PgStoreTest, ManyProcessesOpeningAFreshDatabaseAtOnceMigrateItOnce) {
  constexpr int kOpeners = 8;
  std::vector<std::thread> threads;
  std::atomic<int> ok{0};
  for (int i = 0; i < kOpeners; ++i) {
    threads.emplace_back([&] {
      std::unique_ptr<Store> store;
      Status s = Store::Open(uri_, {}, &store);
      if (s.ok())
        ++ok;
      else
        ADD_FAILURE() << s.ToString();
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(ok.load(), kOpeners);
  auto c = Sql();
  int64_t version = 0;
  ASSERT_TRUE(PgSchemaVersion(c.get(), &version).ok());
  EXPECT_EQ(version, kPgSchemaVersion);
  PgResult rows;
  ASSERT_TRUE(c->Exec("SELECT COUNT(*) FROM calibd_schema", {}, &rows).ok());
  EXPECT_EQ(rows.Int(0, 0), 1);
}

// Version 1 -> 2 (failure reasons): a failed job written by version 1 keeps its code and
// message and has no reason; new failures keep reason and partial diagnostics.
TEST_F(PgStoreTest, Version1FailuresMigrateAndNewOnesKeepTheirReason) {
  {
    auto store = Open();
    const int64_t rec = Put(store.get(), "abc");
    JobInfo job;
    ASSERT_TRUE(store->EnqueueJob(rec, "pca", "", "{}", &job).ok());
  }
  // The database as version 1 left it: without the v2 columns, the job failed.
  auto c = Sql();
  ASSERT_TRUE(c->ExecScript("DROP INDEX results_by_state; DROP INDEX devices_by_serial_bytes;"
                            "ALTER TABLE recordings DROP COLUMN log_json;"
                            "ALTER TABLE jobs DROP COLUMN error_reason;"
                            "ALTER TABLE jobs DROP COLUMN error_detail_json;"
                            "ALTER TABLE jobs DROP COLUMN cancel_requested_at;"
                            "ALTER TABLE jobs DROP COLUMN cancel_reason;"
                            "ALTER TABLE jobs DROP COLUMN cancel_actor;"
                            "ALTER TABLE results DROP COLUMN seq;"
                            "ALTER TABLE job_events DROP CONSTRAINT job_events_action_check;"
                            "ALTER TABLE job_events ADD CONSTRAINT job_events_action_check "
                            "CHECK (action IN ('revoke', 'accept'));"
                            "UPDATE jobs SET status = 'failed', finished_at = 5, "
                            "error_code = 'not_determinable', error_message = 'too few';"
                            "UPDATE calibd_schema SET version = 1")
                  .ok());
  auto store = Open();
  ASSERT_NE(store, nullptr);
  int64_t version = 0;
  ASSERT_TRUE(PgSchemaVersion(c.get(), &version).ok());
  EXPECT_EQ(version, kPgSchemaVersion);
  JobInfo job;
  ASSERT_TRUE(store->GetJob(1, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "not_determinable");
  EXPECT_EQ(job.error_message, "too few");
  EXPECT_EQ(job.error_reason, "");
  EXPECT_EQ(job.error_detail_json, "");
  ASSERT_TRUE(store->EnqueueJob(1, "pca", "", "{}", &job).ok());
  bool claimed = false;
  ASSERT_TRUE(store->ClaimJob("w", 1000, &job, &claimed).ok());
  ASSERT_TRUE(claimed);
  ASSERT_TRUE(
      store->FailJob(job.id, "w", {"not_determinable", "no_rank_gap", "m", "{\"a\":1}"}, false)
          .ok());
  ASSERT_TRUE(store->GetJob(job.id, &job).ok());
  EXPECT_EQ(job.error_reason, "no_rank_gap");
  EXPECT_EQ(job.error_detail_json, "{\"a\":1}");
}

TEST_F(PgStoreTest, Version2JobsAndEventsMigrateAndJobsCanBeCancelled) {
  int64_t running = 0;
  {
    auto store = Open();
    const int64_t rec = Put(store.get(), "abc");
    JobInfo job;
    ASSERT_TRUE(store->EnqueueJob(rec, "pca", "", "{}", &job).ok());
    running = job.id;
    bool claimed = false;
    ASSERT_TRUE(store->ClaimJob("w", 60000, &job, &claimed).ok());
    ASSERT_TRUE(claimed);
  }
  // The database as version 2 left it: no cancel columns, events only revoke/accept.
  auto c = Sql();
  ASSERT_TRUE(c->ExecScript("DROP INDEX results_by_state; DROP INDEX devices_by_serial_bytes;"
                            "ALTER TABLE recordings DROP COLUMN log_json;"
                            "ALTER TABLE jobs DROP COLUMN cancel_requested_at;"
                            "ALTER TABLE jobs DROP COLUMN cancel_reason;"
                            "ALTER TABLE jobs DROP COLUMN cancel_actor;"
                            "ALTER TABLE results DROP COLUMN seq;"
                            "ALTER TABLE job_events DROP CONSTRAINT job_events_action_check;"
                            "ALTER TABLE job_events ADD CONSTRAINT job_events_action_check "
                            "CHECK (action IN ('revoke', 'accept'));"
                            "UPDATE calibd_schema SET version = 2")
                  .ok());
  EXPECT_FALSE(c->ExecScript("INSERT INTO job_events (job_id, action, reason, actor, created_at) "
                             "VALUES (1, 'cancel', 'x', 'token', 1)")
                   .ok());
  auto store = Open();
  ASSERT_NE(store, nullptr);
  int64_t version = 0;
  ASSERT_TRUE(PgSchemaVersion(c.get(), &version).ok());
  EXPECT_EQ(version, kPgSchemaVersion);
  JobInfo job;
  ASSERT_TRUE(store->GetJob(running, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.cancel_requested_at_ms, 0);
  ASSERT_TRUE(store->CancelJob(running, "migrated", "token", &job).ok());
  EXPECT_EQ(job.cancel_reason, "migrated");
  std::vector<int64_t> requested;
  ASSERT_TRUE(store->CancelRequests({running}, &requested).ok());
  EXPECT_EQ(requested, std::vector<int64_t>({running}));
  std::vector<JobEvent> events;
  ASSERT_TRUE(store->ListJobEvents(running, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].action, "cancel");
}

TEST_F(PgStoreTest, RefusesADatabaseWithANewerSchema) {
  ASSERT_NE(Open(), nullptr);
  auto c = Sql();
  ASSERT_TRUE(c->ExecScript("UPDATE calibd_schema SET version = 99").ok());
  std::unique_ptr<Store> store;
  Status s = Store::Open(uri_, {}, &store);
  EXPECT_EQ(s.code(), StatusCode::kConflict) << s.ToString();
  EXPECT_NE(s.message().find("newer than this calibd supports"), std::string::npos);
}

TEST_F(PgStoreTest, ReadOnlyStoreReadsButRefusesWrites) {
  auto rw = Open();
  int64_t rec = Put(rw.get(), "abc");
  StoreOptions o;
  o.read_only = true;
  auto ro = Open(o);
  ASSERT_NE(ro, nullptr);
  std::string back;
  ASSERT_TRUE(ro->ReadRecordingBytes(rec, &back).ok());
  EXPECT_EQ(back, "abc");
  JobInfo job;
  EXPECT_EQ(ro->EnqueueJob(rec, "pca", "", "{}", &job).code(), StatusCode::kIoError);
  StoreOptions quota;
  quota.max_page_count = 10;
  std::unique_ptr<Store> refused;
  EXPECT_EQ(Store::Open(uri_, quota, &refused).code(), StatusCode::kInvalidInput);
}

TEST_F(PgStoreTest, RecordingsAreStoredInChunksOfAtMostOneMebibyte) {
  auto store = Open();
  const std::string bytes = RandomBytes((5u << 20) + 123, 7);
  int64_t rec = Put(store.get(), bytes);
  auto c = Sql();
  PgResult r;
  ASSERT_TRUE(c->Exec("SELECT COUNT(*), MAX(length(data)), SUM(length(data)) FROM "
                      "recording_chunks WHERE recording_id = $1",
                      {PgInt(rec)}, &r)
                  .ok());
  EXPECT_EQ(r.Int(0, 0), 6);
  EXPECT_EQ(r.Int(0, 1), 1 << 20);
  EXPECT_EQ(r.Int(0, 2), static_cast<int64_t>(bytes.size()));
  std::string back;
  ASSERT_TRUE(store->ReadRecordingBytes(rec, &back).ok());
  EXPECT_TRUE(back == bytes);
  std::string check;
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
  // A lost chunk is reported, not silently served short.
  ASSERT_TRUE(
      c->Exec("DELETE FROM recording_chunks WHERE recording_id = $1 AND seq = 3", {PgInt(rec)})
          .ok());
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_NE(check, "ok");
  EXPECT_EQ(store->ReadRecordingBytes(rec, &back).code(), StatusCode::kCorruption);
}

TEST_F(PgStoreTest, IdenticalUploadsOnSeveralHostsAtOnceAreStoredOnce) {
  constexpr int kHosts = 4;
  std::vector<std::unique_ptr<Store>> hosts;
  for (int i = 0; i < kHosts; ++i) hosts.push_back(Open());
  const std::string bytes = RandomBytes(3u << 20, 11);
  std::vector<int64_t> ids(kHosts);
  std::vector<int> existed(kHosts);
  std::vector<std::thread> threads;
  for (int i = 0; i < kHosts; ++i) {
    threads.emplace_back([&, i] {
      NewRecording r;
      r.data = bytes;
      r.job = NewJob{"pca", "SN" + std::to_string(i), "{}"};
      RecordingInfo info;
      bool dup = false;
      Status s = hosts[i]->PutRecording(r, &info, &dup);
      EXPECT_TRUE(s.ok()) << s.ToString();
      ids[i] = info.id;
      existed[i] = dup;
    });
  }
  for (auto& t : threads) t.join();
  for (int i = 1; i < kHosts; ++i) EXPECT_EQ(ids[i], ids[0]);
  int fresh = 0;
  for (int e : existed) fresh += e ? 0 : 1;
  EXPECT_EQ(fresh, 1);
  int64_t jobs = 0;
  ASSERT_TRUE(hosts[0]->CountJobs(JobFilter(), &jobs).ok());
  EXPECT_EQ(jobs, kHosts);  // every upload's job, all against the one recording
}

TEST_F(PgStoreTest, HostsClaimingConcurrentlyNeverGetTheSameJob) {
  constexpr int kHosts = 3, kThreads = 3;
  const int kJobs = sanitizer::kSanitizer ? 60 : 150;
  auto setup = Open();
  int64_t rec = Put(setup.get(), "x");
  for (int i = 0; i < kJobs; ++i) {
    JobInfo job;
    ASSERT_TRUE(setup->EnqueueJob(rec, "pca", "", "{}", &job).ok());
  }
  std::vector<std::unique_ptr<Store>> hosts;
  for (int i = 0; i < kHosts; ++i) hosts.push_back(Open());
  std::mutex mu;
  std::multiset<int64_t> done;
  std::vector<std::thread> threads;
  for (int h = 0; h < kHosts; ++h) {
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, h, t] {
        const std::string me = "h" + std::to_string(h) + "-" + std::to_string(t);
        for (;;) {
          JobInfo job;
          bool claimed = false;
          Status s = hosts[h]->ClaimJob(me, 60000, &job, &claimed);
          if (!s.ok()) {
            ADD_FAILURE() << s.ToString();
            return;
          }
          if (!claimed) return;
          s = hosts[h]->CompleteJob(job.id, me, "{\"by\":\"" + me + "\"}");
          EXPECT_TRUE(s.ok()) << s.ToString();
          std::lock_guard<std::mutex> lock(mu);
          done.insert(job.id);
        }
      });
    }
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(static_cast<int>(done.size()), kJobs);
  EXPECT_EQ(static_cast<int>(std::set<int64_t>(done.begin(), done.end()).size()), kJobs);
  auto c = Sql();
  PgResult r;
  ASSERT_TRUE(c->Exec("SELECT COUNT(*) FROM results", {}, &r).ok());
  EXPECT_EQ(r.Int(0, 0), kJobs);
}

TEST_F(PgStoreTest, TwoHostsRacingOnAnExpiredLeaseStoreOneResult) {
  auto a = Open();
  auto b = Open();
  int64_t rec = Put(a.get(), "race");
  JobInfo job;
  ASSERT_TRUE(a->EnqueueJob(rec, "pca", "SN1", "{}", &job).ok());
  JobInfo claimed_a, claimed_b;
  bool got = false;
  ASSERT_TRUE(a->ClaimJob("hostA-1", 1000, &claimed_a, &got).ok() && got);
  clock_.Advance(1500);  // host A hangs past its lease
  ASSERT_TRUE(b->ClaimJob("hostB-1", 1000, &claimed_b, &got).ok() && got);
  EXPECT_EQ(claimed_b.id, job.id);
  EXPECT_EQ(claimed_b.attempts, 2);
  // Both finish at the same moment with different results: only the holder's is stored.
  Status sa, sb;
  std::thread ta([&] { sa = a->CompleteJob(job.id, "hostA-1", "{\"by\":\"A\"}"); });
  std::thread tb([&] { sb = b->CompleteJob(job.id, "hostB-1", "{\"by\":\"B\"}"); });
  ta.join();
  tb.join();
  EXPECT_EQ(sa.code(), StatusCode::kConflict) << sa.ToString();
  EXPECT_TRUE(sb.ok()) << sb.ToString();
  JobInfo final_job;
  ASSERT_TRUE(a->GetJob(job.id, &final_job).ok());
  EXPECT_EQ(final_job.result_json, "{\"by\":\"B\"}");
  // B again with its result: idempotent; A with B's result: also OK (the identical result).
  EXPECT_TRUE(b->CompleteJob(job.id, "hostB-1", "{\"by\":\"B\"}").ok());
  EXPECT_TRUE(a->CompleteJob(job.id, "hostA-1", "{\"by\":\"B\"}").ok());
}

TEST_F(PgStoreTest, ListenerHearsJobsEnqueuedByAnotherHost) {
  auto worker_host = Open();
  auto upload_host = Open();
  std::mutex mu;
  std::condition_variable cv;
  int heard = 0;
  ASSERT_TRUE(worker_host->SetJobListener([&] {
    std::lock_guard<std::mutex> lock(mu);
    ++heard;
    cv.notify_all();
  }));
  // The listener announces itself once when connected (jobs may predate it); wait for that.
  {
    std::unique_lock<std::mutex> lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(30), [&] { return heard >= 1; }));
    heard = 0;
  }
  int64_t rec = Put(upload_host.get(), "notify");
  {
    std::unique_lock<std::mutex> lock(mu);
    EXPECT_EQ(heard, 0);  // an upload without a job wakes nobody
  }
  JobInfo job;
  ASSERT_TRUE(upload_host->EnqueueJob(rec, "pca", "", "{}", &job).ok());
  std::unique_lock<std::mutex> lock(mu);
  EXPECT_TRUE(cv.wait_for(lock, std::chrono::seconds(30), [&] { return heard >= 1; }));
  lock.unlock();
  worker_host->SetJobListener(nullptr);
}

// Stops and restarts the cluster.
TEST_F(PgStoreTest, ServerRestartedWhileTheStoreWasIdleIsInvisibleToItsNextCalls) {
  auto store = Open();
  int64_t rec = Put(store.get(), "before the restart");
  RecordingInfo info;
  ASSERT_TRUE(store->GetRecording(rec, &info).ok());  // idle pooled connections now
  ASSERT_TRUE(cluster_->Stop());
  ASSERT_TRUE(cluster_->Start());
  Status s = store->GetRecording(rec, &info);  // a read: runs again on a fresh connection
  EXPECT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(cluster_->Stop());
  ASSERT_TRUE(cluster_->Start());
  JobInfo job;
  s = store->EnqueueJob(rec, "pca", "", "{}", &job);  // a write whose BEGIN found it dead
  EXPECT_TRUE(s.ok()) << s.ToString();
}

// Last in this file: it stops and restarts the cluster.
TEST_F(PgStoreTest, ServerGoingAwayIsBusyAndTheStoreReconnectsByItself) {
  auto store = Open();
  int64_t rec = Put(store.get(), "before the outage");
  ASSERT_TRUE(cluster_->Stop());
  JobInfo job;
  Status s = store->EnqueueJob(rec, "pca", "", "{}", &job);
  EXPECT_EQ(s.code(), StatusCode::kBusy) << s.ToString();
  EXPECT_EQ(store->Ping().code(), StatusCode::kBusy);
  RecordingInfo info;
  s = store->GetRecording(rec, &info);
  EXPECT_EQ(s.code(), StatusCode::kBusy) << s.ToString();
  EXPECT_NE(s.message().find("PostgreSQL"), std::string::npos) << s.message();
  EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.message();  // one line
  ASSERT_TRUE(cluster_->Start());
  EXPECT_TRUE(store->Ping().ok());
  ASSERT_TRUE(store->EnqueueJob(rec, "pca", "", "{}", &job).ok());
  std::string back;
  ASSERT_TRUE(store->ReadRecordingBytes(rec, &back).ok());
  EXPECT_EQ(back, "before the outage");
  int64_t n = 0;
  ASSERT_TRUE(store->CountJobs(JobFilter(), &n).ok());
  EXPECT_EQ(n, 1);  // the refused enqueue left nothing behind
}

TEST_F(PgStoreTest, AChangedChunkIsFoundWhenReadAndARepeatedUploadRepairsIt) {
  auto store = Open();
  const std::string bytes = RandomBytes((2u << 20) + 77, 11);
  const int64_t rec = Put(store.get(), bytes);
  auto c = Sql();
  // One byte of the second chunk changed (a bad copy, a bad disk): the size is right, the hash
  // is not.
  ASSERT_TRUE(c->Exec("UPDATE recording_chunks SET data = set_byte(data, 1000, "
                      "(get_byte(data, 1000) # 1)) WHERE recording_id = $1 AND seq = 1",
                      {PgInt(rec)})
                  .ok());
  std::string back;
  Status s = store->ReadRecordingBytes(rec, &back);
  EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
  EXPECT_NE(s.message().find("recording " + std::to_string(rec) + " is damaged"), std::string::npos)
      << s.message();
  NewRecording again;
  again.data = bytes;
  RecordingInfo info;
  bool existed = false;
  s = store->PutRecording(again, &info, &existed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(existed);
  EXPECT_EQ(info.id, rec);
  s = store->ReadRecordingBytes(rec, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(back == bytes);
}

}  // namespace
}  // namespace calibd::storage
