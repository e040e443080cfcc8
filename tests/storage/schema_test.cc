// Schema migrations: from an empty file, from every earlier version (with data), forward only.
#include "storage/schema.h"

#include <gtest/gtest.h>

#include <thread>
#include <vector>

#include "storage/sha256.h"
#include "storage/store.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::TempDir;

std::unique_ptr<Db> OpenDb(const std::string& path) {
  std::unique_ptr<Db> db;
  Status s = Db::Open(path, Db::Options(), &db);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return db;
}

int64_t Version(Db* db) {
  int64_t v = -1;
  EXPECT_TRUE(SchemaVersion(db, &v).ok());
  return v;
}

// The schema as text (tables, indexes), for comparing two files.
std::string SchemaDump(Db* db) {
  Stmt st;
  EXPECT_TRUE(db->PrepareUncached(
                    "SELECT type || ' ' || name || ': ' || COALESCE(sql, '') FROM sqlite_schema "
                    "ORDER BY type, name",
                    &st)
                  .ok());
  std::string out;
  for (bool row = true;;) {
    EXPECT_TRUE(st.Step(&row).ok());
    if (!row) break;
    out += st.ColumnText(0) + "\n";
  }
  return out;
}

TEST(Schema, MigratesAnEmptyFileToTheLatestVersion) {
  TempDir dir;
  auto db = OpenDb(dir.File("a.db"));
  EXPECT_EQ(Version(db.get()), 0);
  ASSERT_TRUE(MigrateSchema(db.get()).ok());
  EXPECT_EQ(Version(db.get()), kSchemaVersion);
  std::string schema = SchemaDump(db.get());
  for (const char* table :
       {"table recordings", "table recording_data", "table jobs", "table results", "table devices",
        "table device_calibrations", "index jobs_by_status", "index jobs_by_lease"}) {
    EXPECT_NE(schema.find(table), std::string::npos) << table << "\n" << schema;
  }
  // Migrating again is a no-op.
  ASSERT_TRUE(MigrateSchema(db.get()).ok());
  EXPECT_EQ(SchemaDump(db.get()), schema);
}

TEST(Schema, EveryEarlierVersionMigratesToTheSameSchemaAsAFreshFile) {
  TempDir dir;
  auto fresh = OpenDb(dir.File("fresh.db"));
  ASSERT_TRUE(MigrateSchema(fresh.get()).ok());
  const std::string expected = SchemaDump(fresh.get());
  for (int from = 0; from < kSchemaVersion; ++from) {
    auto db = OpenDb(dir.File("from" + std::to_string(from) + ".db"));
    ASSERT_TRUE(MigrateSchema(db.get(), from).ok());
    EXPECT_EQ(Version(db.get()), from);
    db.reset();
    // Open as the server would: through Store, which migrates at open.
    std::unique_ptr<Store> store;
    Status s = Store::Open(dir.File("from" + std::to_string(from) + ".db"), StoreOptions(), &store);
    ASSERT_TRUE(s.ok()) << "from v" << from << ": " << s.ToString();
    store.reset();
    db = OpenDb(dir.File("from" + std::to_string(from) + ".db"));
    EXPECT_EQ(Version(db.get()), kSchemaVersion);
    EXPECT_EQ(SchemaDump(db.get()), expected) << "from v" << from;
  }
}

TEST(Schema, Version1DataIsCarriedOverAndUsable) {
  TempDir dir;
  const std::string path = dir.File("v1.db");
  const std::string result = R"({"method":"pca","parameters":{"dimension":3}})";
  {
    auto db = OpenDb(path);
    ASSERT_TRUE(MigrateSchema(db.get(), 1).ok());
    // What calibd with schema v1 would have written.
    Stmt st;
    ASSERT_TRUE(
        db->PrepareUncached(
              "INSERT INTO recordings (id, sha256, bytes, device, layout, rows, created_at) "
              "VALUES (1, ?1, 3, 'SN1', 'pca_averaged', 1, 1000)",
              &st)
            .ok());
    st.BindText(1, Sha256Hex("abc"));
    ASSERT_TRUE(st.Run().ok());
    ASSERT_TRUE(db->Exec("INSERT INTO recording_data VALUES (1, X'616263')").ok());
    Stmt job;
    ASSERT_TRUE(db->PrepareUncached(
                      "INSERT INTO jobs (id, recording_id, method, device, config_json, status, "
                      "attempts, created_at, started_at, finished_at, result_json) VALUES "
                      "(1, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 2000, 2100, 2500, ?1),"
                      "(2, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 2200, 2300, 2400, '{\"old\":1}'),"
                      "(3, 1, 'array', 'SN2', '{}', 'queued', 0, 3000, NULL, NULL, NULL),"
                      "(4, 1, 'pca', 'SN1', '{}', 'failed', 1, 3100, 3200, 3300, NULL)",
                      &job)
                    .ok());
    job.BindText(1, result);
    ASSERT_TRUE(job.Run().ok());
  }
  std::unique_ptr<Store> store;
  StoreOptions o;
  o.now_ms = [] { return int64_t{10000}; };
  Status s = Store::Open(path, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();

  std::string bytes;
  ASSERT_TRUE(store->ReadRecordingBytes(1, &bytes).ok());
  EXPECT_EQ(bytes, "abc");
  JobInfo job;
  ASSERT_TRUE(store->GetJob(1, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kSucceeded);
  EXPECT_EQ(job.result_json, result);
  EXPECT_EQ(job.result_sha256, Sha256Hex(result));  // hashed during the migration
  // Latest calibration: job 1 finished last (2500 > 2400) although job 2 was created later.
  JobInfo latest;
  ASSERT_TRUE(store->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, 1);
  std::vector<DeviceInfo> devices;
  ASSERT_TRUE(store->ListDevices(&devices).ok());
  ASSERT_EQ(devices.size(), 2u);
  EXPECT_EQ(devices[0].serial, "SN1");
  EXPECT_EQ(devices[0].first_seen_ms, 1000);
  EXPECT_EQ(devices[1].serial, "SN2");
  EXPECT_TRUE(devices[1].latest.empty());
  // The queued v1 job runs normally.
  bool claimed = false;
  ASSERT_TRUE(store->ClaimJob("w", 1000, &job, &claimed).ok());
  ASSERT_TRUE(claimed);
  EXPECT_EQ(job.id, 3);
  ASSERT_TRUE(store->CompleteJob(3, "w", "{}").ok());
  ASSERT_TRUE(store->LatestResult("SN2", "array", &latest).ok());
  EXPECT_EQ(latest.id, 3);
  std::string check;
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
}

TEST(Schema, Version2ResultsGetTheirVerdictAndTheLatestBecomesTheLatestAccepted) {
  TempDir dir;
  const std::string path = dir.File("v2.db");
  const std::string rejected =
      R"({"method":"pca","verdict":{"status":"rejected","reasons":["x"]}})";
  {
    auto db = OpenDb(path);
    ASSERT_TRUE(MigrateSchema(db.get(), 2).ok());
    ASSERT_TRUE(db->Exec("INSERT INTO recordings (id, sha256, bytes, device, layout, rows, "
                         "created_at) VALUES (1, 'h', 3, 'SN1', 'pca_averaged', 1, 1000);"
                         "INSERT INTO recording_data VALUES (1, X'616263');"
                         "INSERT INTO devices VALUES ('SN1', 1000);")
                    .ok());
    // What calibd with schema v2 wrote: results without a verdict (job 1), one with a rejected
    // verdict (job 2, the newest) and one whose JSON is damaged (job 3); v2 made job 2 the latest.
    ASSERT_TRUE(db->Exec("INSERT INTO jobs (id, recording_id, method, device, config_json, status, "
                         "attempts, created_at, finished_at) VALUES "
                         "(1, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 1100, 2000),"
                         "(2, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 1200, 3000),"
                         "(3, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 1300, 2500);"
                         "INSERT INTO results VALUES (1, '{\"method\":\"pca\"}', 'a', 2000),"
                         "(3, '{not json', 'c', 2500);"
                         "INSERT INTO device_calibrations VALUES ('SN1', 'pca', 2, 3000);")
                    .ok());
    Stmt st;
    ASSERT_TRUE(db->PrepareUncached("INSERT INTO results VALUES (2, ?1, 'b', 3000)", &st).ok());
    st.BindText(1, rejected);
    ASSERT_TRUE(st.Run().ok());
  }
  std::unique_ptr<Store> store;
  StoreOptions o;
  o.now_ms = [] { return int64_t{10000}; };
  Status s = Store::Open(path, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  JobInfo job;
  ASSERT_TRUE(store->GetJob(1, &job).ok());
  EXPECT_EQ(job.verdict,
            GateVerdict::kAccepted);  // no verdict: results before the gate count as accepted
  EXPECT_EQ(job.state, ServeState::kAccepted);
  ASSERT_TRUE(store->GetJob(2, &job).ok());
  EXPECT_EQ(job.verdict, GateVerdict::kRejected);
  EXPECT_EQ(job.result_json, rejected);
  ASSERT_TRUE(store->GetJob(3, &job).ok());
  EXPECT_EQ(job.verdict, GateVerdict::kAccepted);  // unreadable JSON: no verdict in it
  // The latest served is job 3 (finished 2500), not the rejected job 2 (3000).
  JobInfo latest;
  ASSERT_TRUE(store->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, 3);
  // Revoking it falls back to job 1; accepting job 2 serves it; the events are kept in order.
  ASSERT_TRUE(store->RevokeJob(3, "wrong fixture", "anonymous").ok());
  ASSERT_TRUE(store->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, 1);
  EXPECT_EQ(store->RevokeJob(3, "again", "anonymous").code(), StatusCode::kConflict);
  EXPECT_EQ(store->RevokeJob(2, "not served", "anonymous").code(), StatusCode::kConflict);
  EXPECT_EQ(store->AcceptJob(1, "fine", "anonymous").code(), StatusCode::kConflict);
  EXPECT_EQ(store->AcceptJob(2, "", "anonymous").code(), StatusCode::kInvalidInput);
  ASSERT_TRUE(store->AcceptJob(2, "checked by hand", "token").ok());
  ASSERT_TRUE(store->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, 2);
  std::vector<JobEvent> events;
  ASSERT_TRUE(store->ListJobEvents(3, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].action, "revoke");
  EXPECT_EQ(events[0].reason, "wrong fixture");
  EXPECT_EQ(events[0].created_at_ms, 10000);
  EXPECT_EQ(store->ListJobEvents(99, &events).code(), StatusCode::kNotFound);
  // Filters by state.
  JobFilter filter;
  filter.state = ServeState::kRevoked;
  std::vector<JobInfo> jobs;
  ASSERT_TRUE(store->ListJobs(filter, &jobs).ok());
  ASSERT_EQ(jobs.size(), 1u);
  EXPECT_EQ(jobs[0].id, 3);
  int64_t count = 0;
  filter.state = ServeState::kAccepted;
  ASSERT_TRUE(store->CountJobs(filter, &count).ok());
  EXPECT_EQ(count, 2);
  std::string check;
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
}

TEST(Schema, Version3FailuresKeepTheirCodeAndMessageWithoutAReason) {
  TempDir dir;
  const std::string path = dir.File("v3.db");
  {
    auto db = OpenDb(path);
    ASSERT_TRUE(MigrateSchema(db.get(), 3).ok());
    // What calibd with schema v3 wrote: a failed job with its code and message only.
    ASSERT_TRUE(db->Exec("INSERT INTO recordings (id, sha256, bytes, device, layout, rows, "
                         "created_at) VALUES (1, 'h', 3, 'SN1', 'pca_averaged', 1, 1000);"
                         "INSERT INTO recording_data VALUES (1, X'616263');"
                         "INSERT INTO jobs (id, recording_id, method, device, config_json, "
                         "status, attempts, created_at, finished_at, error_code, error_message) "
                         "VALUES (1, 1, 'pca', 'SN1', '{}', 'failed', 1, 1100, 2000, "
                         "'not_determinable', '4 positions recorded');")
                    .ok());
  }
  std::unique_ptr<Store> store;
  StoreOptions o;
  o.now_ms = [] { return int64_t{10000}; };
  Status s = Store::Open(path, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  {
    auto db = OpenDb(path);
    EXPECT_EQ(Version(db.get()), kSchemaVersion);
  }
  JobInfo job;
  ASSERT_TRUE(store->GetJob(1, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "not_determinable");
  EXPECT_EQ(job.error_message, "4 positions recorded");
  EXPECT_EQ(job.error_reason, "");
  EXPECT_EQ(job.error_detail_json, "");
  // New failures on the migrated file keep both.
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

TEST(Schema, Version4EventsAndJobsAreCarriedOverAndJobsCanBeCancelled) {
  TempDir dir;
  const std::string path = dir.File("v4.db");
  {
    auto db = OpenDb(path);
    ASSERT_TRUE(MigrateSchema(db.get(), 4).ok());
    // What calibd with schema v4 wrote: a succeeded job revoked by a person, a running job.
    ASSERT_TRUE(db->Exec("INSERT INTO recordings (id, sha256, bytes, device, layout, rows, "
                         "created_at) VALUES (1, 'h', 3, 'SN1', 'pca_averaged', 1, 1000);"
                         "INSERT INTO recording_data VALUES (1, X'616263');"
                         "INSERT INTO jobs (id, recording_id, method, device, config_json, "
                         "status, attempts, created_at, finished_at) "
                         "VALUES (1, 1, 'pca', 'SN1', '{}', 'succeeded', 1, 1100, 2000);"
                         "INSERT INTO results (job_id, result_json, sha256, created_at, verdict, "
                         "decision) VALUES (1, '{}', 's', 2000, 'accepted', 'revoked');"
                         "INSERT INTO job_events (id, job_id, action, reason, actor, created_at) "
                         "VALUES (7, 1, 'revoke', 'bad fixture', 'token', 3000);"
                         "INSERT INTO jobs (id, recording_id, method, device, config_json, "
                         "status, attempts, lease_owner, lease_expires_at, created_at, "
                         "started_at) VALUES (2, 1, 'pca', 'SN1', '{}', 'running', 1, 'w', "
                         "999999, 1100, 1200);")
                    .ok());
    // v4 refuses the action 'cancel'.
    EXPECT_FALSE(db->Exec("INSERT INTO job_events (job_id, action, reason, actor, created_at) "
                          "VALUES (1, 'cancel', 'x', 'token', 1)")
                     .ok());
  }
  std::unique_ptr<Store> store;
  StoreOptions o;
  o.now_ms = [] { return int64_t{10000}; };
  Status s = Store::Open(path, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  std::vector<JobEvent> events;
  ASSERT_TRUE(store->ListJobEvents(1, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].id, 7);
  EXPECT_EQ(events[0].action, "revoke");
  EXPECT_EQ(events[0].reason, "bad fixture");
  JobInfo job;
  ASSERT_TRUE(store->GetJob(2, &job).ok());
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.cancel_requested_at_ms, 0);
  EXPECT_EQ(job.cancel_reason, "");
  ASSERT_TRUE(store->CancelJob(2, "migrated", "token", &job).ok());
  EXPECT_EQ(job.cancel_requested_at_ms, 10000);
  std::vector<int64_t> requested;
  ASSERT_TRUE(store->CancelRequests({1, 2}, &requested).ok());
  EXPECT_EQ(requested, std::vector<int64_t>({2}));
  ASSERT_TRUE(store->ListJobEvents(2, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].action, "cancel");
}

TEST(Schema, NewerSchemaThanThisBuildIsRefused) {
  TempDir dir;
  {
    auto db = OpenDb(dir.File("a.db"));
    ASSERT_TRUE(db->Exec("PRAGMA user_version = 99").ok());
  }
  std::unique_ptr<Store> store;
  Status s = Store::Open(dir.File("a.db"), StoreOptions(), &store);
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("newer"), std::string::npos) << s.message();
}

TEST(Schema, ConcurrentOpenersMigrateOnce) {
  TempDir dir;
  std::vector<std::thread> threads;
  std::vector<Status> results(4);
  for (int i = 0; i < 4; ++i) {
    threads.emplace_back([&, i] {
      std::unique_ptr<Store> store;
      results[i] = Store::Open(dir.File("a.db"), StoreOptions(), &store);
    });
  }
  for (auto& t : threads) t.join();
  for (const Status& s : results) EXPECT_TRUE(s.ok()) << s.ToString();
  auto db = OpenDb(dir.File("a.db"));
  EXPECT_EQ(Version(db.get()), kSchemaVersion);
}

}  // namespace
}  // namespace calibd::storage
