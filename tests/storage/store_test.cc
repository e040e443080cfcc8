// Store: recordings and every job state transition, legal and illegal — one suite run against
// both backends: an SQLite file and a database in a throw-away PostgreSQL cluster
// (pg_test_cluster.h). Each test gets a fresh file or database.
#include "storage/store.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "storage/sha256.h"
#include "tests/storage/pg_test_cluster.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::FakeClock;
using testing::RandomBytes;
using testing::TempDir;

// The backend under test: "sqlite" or "postgresql".
class StoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "postgresql") {
      auto* cluster = testing::PgTestCluster::Get();
      ASSERT_NE(cluster, nullptr);
      target_ = cluster->NewDatabase();
    } else {
      target_ = dir_.File("calibd.db");
    }
    Reopen();
  }

  void Reopen(StoreOptions options = {}) {
    store_.reset();
    if (!options.now_ms) options.now_ms = clock_.Fn();
    options_ = options;
    Status s = Store::Open(target_, options, &store_);
    ASSERT_TRUE(s.ok()) << s.ToString();
  }

  // Stores `bytes` as a recording and returns its id.
  int64_t Put(const std::string& bytes, const std::string& device = "SN1") {
    NewRecording r;
    r.data = bytes;
    r.device = device;
    r.layout = "pca_averaged";
    r.rows = 3;
    RecordingInfo info;
    bool existed = false;
    Status s = store_->PutRecording(r, &info, &existed);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return info.id;
  }

  int64_t Enqueue(int64_t recording, const std::string& method = "pca",
                  const std::string& device = "") {
    JobInfo job;
    Status s = store_->EnqueueJob(recording, method, device, R"({"dimension":3})", &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job.id;
  }

  JobInfo Claim(const std::string& worker, int64_t lease_ms = 10000) {
    JobInfo job;
    bool claimed = false;
    Status s = store_->ClaimJob(worker, lease_ms, &job, &claimed);
    EXPECT_TRUE(s.ok()) << s.ToString();
    EXPECT_TRUE(claimed);
    return job;
  }

  JobInfo Get(int64_t id) {
    JobInfo job;
    Status s = store_->GetJob(id, &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job;
  }

  TempDir dir_;
  std::string target_;  // the SQLite file or the PostgreSQL URI
  FakeClock clock_;
  StoreOptions options_;
  std::unique_ptr<Store> store_;
};

// ---- recordings ----

TEST_P(StoreTest, PutRecordingStoresBytesAndSummary) {
  const std::string bytes = "position,s1,s2\np1,1,2\np2,3,4\np3,5,6\n";
  NewRecording r;
  r.data = bytes;
  r.device = "SN-7";
  r.layout = "pca_averaged";
  r.rows = 3;
  r.columns_json = R"(["position","s1","s2"])";
  r.sensors_json = R"(["s1","s2"])";
  r.file_name = "lab.csv";
  RecordingInfo info;
  bool existed = true;
  ASSERT_TRUE(store_->PutRecording(r, &info, &existed).ok());
  EXPECT_FALSE(existed);
  EXPECT_GT(info.id, 0);
  EXPECT_EQ(info.sha256, Sha256Hex(bytes));
  EXPECT_EQ(info.bytes, static_cast<int64_t>(bytes.size()));
  EXPECT_EQ(info.rows, 3);
  EXPECT_EQ(info.layout, "pca_averaged");
  EXPECT_EQ(info.device, "SN-7");
  EXPECT_EQ(info.file_name, "lab.csv");
  EXPECT_EQ(info.created_at_ms, clock_.Now());
  EXPECT_EQ(info.created_at, FormatTimestamp(clock_.Now()));
  EXPECT_FALSE(info.job.has_value());
  auto summary = nlohmann::json::parse(info.summary_json);
  EXPECT_EQ(summary["layout"], "pca_averaged");
  EXPECT_EQ(summary["rows"], 3);
  EXPECT_EQ(summary["columns"], nlohmann::json::parse(r.columns_json));
  EXPECT_EQ(summary["sensors"], nlohmann::json::parse(r.sensors_json));

  RecordingInfo again;
  ASSERT_TRUE(store_->GetRecording(info.id, &again).ok());
  EXPECT_EQ(again.sha256, info.sha256);
  EXPECT_EQ(again.summary_json, info.summary_json);
  std::string back;
  ASSERT_TRUE(store_->ReadRecordingBytes(info.id, &back).ok());
  EXPECT_EQ(back, bytes);
}

TEST_P(StoreTest, FormatsTimestampsAsIsoUtcWithMilliseconds) {
  EXPECT_EQ(FormatTimestamp(0), "1970-01-01T00:00:00.000Z");
  EXPECT_EQ(FormatTimestamp(1'790'000'000'123), "2026-09-21T14:13:20.123Z");
  EXPECT_EQ(FormatTimestamp(-1), "1969-12-31T23:59:59.999Z");
}

TEST_P(StoreTest, IdenticalBytesAreStoredOnceAndReturnTheExistingId) {
  const std::string bytes = RandomBytes(10000, 1);
  NewRecording r;
  r.data = bytes;
  r.device = "SN1";
  RecordingInfo first, second;
  bool existed = true;
  ASSERT_TRUE(store_->PutRecording(r, &first, &existed).ok());
  EXPECT_FALSE(existed);
  clock_.Advance(1000);
  r.device = "SN2";  // another device uploading the same bytes still dedupes
  ASSERT_TRUE(store_->PutRecording(r, &second, &existed).ok());
  EXPECT_TRUE(existed);
  EXPECT_EQ(second.id, first.id);
  EXPECT_EQ(second.created_at_ms, first.created_at_ms);  // the stored one
  EXPECT_EQ(second.device, "SN1");
  // Different bytes: a new recording.
  const std::string other = bytes + "x";
  r.data = other;
  RecordingInfo third;
  ASSERT_TRUE(store_->PutRecording(r, &third, &existed).ok());
  EXPECT_FALSE(existed);
  EXPECT_NE(third.id, first.id);
}

TEST_P(StoreTest, DuplicateUploadStillEnqueuesItsJobAgainstTheExistingRecording) {
  NewRecording r;
  r.data = "a,b\n1,2\n";
  r.device = "SN1";
  r.job = NewJob{"pca", "", R"({"magnitude":1})"};
  RecordingInfo first, second;
  bool existed = false;
  ASSERT_TRUE(store_->PutRecording(r, &first, &existed).ok());
  ASSERT_TRUE(first.job.has_value());
  EXPECT_EQ(first.job->status, JobStatus::kQueued);
  EXPECT_EQ(first.job->recording_id, first.id);
  EXPECT_EQ(first.job->device, "SN1");
  EXPECT_EQ(first.job->config_json, R"({"magnitude":1})");
  r.job->device = "SN9";
  ASSERT_TRUE(store_->PutRecording(r, &second, &existed).ok());
  EXPECT_TRUE(existed);
  ASSERT_TRUE(second.job.has_value());
  EXPECT_NE(second.job->id, first.job->id);
  EXPECT_EQ(second.job->recording_id, first.id);
  EXPECT_EQ(second.job->device, "SN9");
  QueueCounts counts;
  ASSERT_TRUE(store_->QueueDepth(&counts).ok());
  EXPECT_EQ(counts.queued, 2);
}

TEST_P(StoreTest, EmptyRecordingRoundTrips) {
  RecordingInfo info;
  NewRecording r;
  r.data = std::string_view();
  ASSERT_TRUE(store_->PutRecording(r, &info, nullptr).ok());
  EXPECT_EQ(info.bytes, 0);
  std::string back = "junk";
  ASSERT_TRUE(store_->ReadRecordingBytes(info.id, &back).ok());
  EXPECT_EQ(back, "");
}

TEST_P(StoreTest, StreamsAStagedFileByteExactInBoundedChunks) {
  // 50 MB from a staged file: the store reads and writes it in 1 MiB chunks (blob API), and
  // reading it back delivers chunks of at most 1 MiB — memory does not depend on the size.
  const size_t size = 50u << 20;
  const std::string staged = dir_.File("upload.tmp");
  Sha256 expected_hash;
  {
    std::ofstream out(staged, std::ios::binary);
    for (size_t off = 0; off < size; off += 1 << 20) {
      std::string chunk = RandomBytes(1 << 20, static_cast<uint32_t>(off >> 20));
      expected_hash.Update(chunk);
      out.write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    }
  }
  const std::string expected_sha = expected_hash.HexDigest();
  NewRecording r;
  r.path = staged;
  r.device = "SN-big";
  RecordingInfo info;
  bool existed = true;
  Status s = store_->PutRecording(r, &info, &existed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_FALSE(existed);
  EXPECT_EQ(info.bytes, static_cast<int64_t>(size));
  EXPECT_EQ(info.sha256, expected_sha);

  Sha256 read_hash;
  size_t total = 0, max_chunk = 0, chunks = 0;
  bool in_order = true;
  s = store_->ReadRecordingData(info.id, [&](std::string_view chunk) {
    // Compare with the generator chunk by chunk (every chunk is exactly 1 MiB here).
    if (chunk != RandomBytes(chunk.size(), static_cast<uint32_t>(total >> 20))) in_order = false;
    read_hash.Update(chunk);
    total += chunk.size();
    max_chunk = std::max(max_chunk, chunk.size());
    ++chunks;
    return true;
  });
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(total, size);
  EXPECT_TRUE(in_order);
  EXPECT_LE(max_chunk, size_t{1} << 20);
  EXPECT_EQ(chunks, 50u);
  EXPECT_EQ(read_hash.HexDigest(), expected_sha);

  // The same file again is recognised after streaming and rolled back: stored once.
  RecordingInfo again;
  s = store_->PutRecording(r, &again, &existed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(existed);
  EXPECT_EQ(again.id, info.id);
  // And with the hash announced, without copying.
  r.sha256 = expected_sha;
  s = store_->PutRecording(r, &again, &existed);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(existed);
  EXPECT_EQ(again.id, info.id);
}

TEST_P(StoreTest, StagedFileWithAWrongAnnouncedHashIsRejectedAndNothingStored) {
  const std::string staged = dir_.File("upload.tmp");
  std::ofstream(staged, std::ios::binary) << "t,a0_x\n1,2\n";
  NewRecording r;
  r.path = staged;
  r.sha256 = std::string(64, '0');
  Status s = store_->PutRecording(r, nullptr, nullptr);
  EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
  EXPECT_NE(s.message().find("sha256"), std::string::npos);
  RecordingInfo info;
  EXPECT_EQ(store_->GetRecording(1, &info).code(), StatusCode::kNotFound);
}

TEST_P(StoreTest, MissingStagedFileIsAnIoErrorNamingIt) {
  NewRecording r;
  r.path = dir_.File("nope.tmp");
  Status s = store_->PutRecording(r, nullptr, nullptr);
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_NE(s.message().find("nope.tmp"), std::string::npos);
}

TEST_P(StoreTest, ReadCanStopEarly) {
  const std::string bytes = RandomBytes(3u << 20, 5);
  int64_t id = Put(bytes);
  int calls = 0;
  ASSERT_TRUE(store_->ReadRecordingData(id, [&](std::string_view) { return ++calls < 2; }).ok());
  EXPECT_EQ(calls, 2);
}

TEST_P(StoreTest, UnknownRecordingIsNotFound) {
  RecordingInfo info;
  std::string bytes;
  EXPECT_EQ(store_->GetRecording(42, &info).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ReadRecordingBytes(42, &bytes).code(), StatusCode::kNotFound);
  JobInfo job;
  EXPECT_EQ(store_->EnqueueJob(42, "pca", "", "{}", &job).code(), StatusCode::kNotFound);
}

TEST_P(StoreTest, BadRecordingArgumentsAreInvalidInputAndStoreNothing) {
  NewRecording r;
  r.data = "x";
  r.columns_json = "not json";
  EXPECT_EQ(store_->PutRecording(r, nullptr, nullptr).code(), StatusCode::kInvalidInput);
  r.columns_json = "[]";
  r.sensors_json = R"({"a":1})";
  EXPECT_EQ(store_->PutRecording(r, nullptr, nullptr).code(), StatusCode::kInvalidInput);
  r.sensors_json = "[]";
  r.job = NewJob{"", "", "{}"};
  EXPECT_EQ(store_->PutRecording(r, nullptr, nullptr).code(), StatusCode::kInvalidInput);
  RecordingInfo info;
  EXPECT_EQ(store_->GetRecording(1, &info).code(), StatusCode::kNotFound);
}

// ---- jobs: the happy path ----

TEST_P(StoreTest, EnqueuedJobIsQueuedWithTheRecordingsDevice) {
  int64_t rec = Put("x", "SN1");
  JobInfo job;
  ASSERT_TRUE(store_->EnqueueJob(rec, "pca", "", "", &job).ok());
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.device, "SN1");
  EXPECT_EQ(job.method, "pca");
  EXPECT_EQ(job.config_json, "{}");
  EXPECT_EQ(job.attempts, 0);
  EXPECT_EQ(job.created_at, FormatTimestamp(clock_.Now()));
  EXPECT_EQ(job.started_at, "");
  EXPECT_EQ(job.finished_at, "");
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(job.result_json, "");
  ASSERT_TRUE(store_->EnqueueJob(rec, "array", "SN2", "{}", &job).ok());
  EXPECT_EQ(job.device, "SN2");
  EXPECT_EQ(store_->EnqueueJob(rec, "", "", "{}", &job).code(), StatusCode::kInvalidInput);
}

TEST_P(StoreTest, ClaimRunsTheOldestJobUnderALease) {
  int64_t rec = Put("x");
  int64_t first = Enqueue(rec), second = Enqueue(rec);
  JobInfo job = Claim("w1", 30000);
  EXPECT_EQ(job.id, first);
  EXPECT_EQ(job.status, JobStatus::kRunning);
  EXPECT_EQ(job.lease_owner, "w1");
  EXPECT_EQ(job.lease_expires_at_ms, clock_.Now() + 30000);
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(job.started_at_ms, clock_.Now());
  EXPECT_EQ(Claim("w2").id, second);
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w3", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);
}

// ---- cancel ----

TEST_P(StoreTest, CancellingAQueuedJobFailsItAtOnceWithWhoAndWhy) {
  const int64_t id = Enqueue(Put("x"));
  clock_.Advance(500);
  JobInfo job;
  JobEvent event;
  ASSERT_TRUE(store_->CancelJob(id, "wrong recording", "token", &job, &event).ok());
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "stopped");
  EXPECT_EQ(job.error_reason, "cancelled");
  EXPECT_EQ(job.error_message, "cancelled by token: wrong recording");
  EXPECT_EQ(job.finished_at_ms, clock_.Now());
  EXPECT_EQ(job.cancel_requested_at_ms, clock_.Now());
  EXPECT_EQ(job.cancel_reason, "wrong recording");
  EXPECT_EQ(job.cancel_actor, "token");
  EXPECT_EQ(event.action, "cancel");
  EXPECT_EQ(event.reason, "wrong recording");
  std::vector<JobEvent> events;
  ASSERT_TRUE(store_->ListJobEvents(id, &events).ok());
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0].action, "cancel");
  EXPECT_EQ(events[0].actor, "token");
  // Nothing left to claim, and a second cancel is a conflict naming the status.
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);
  Status again = store_->CancelJob(id, "again", "token");
  EXPECT_EQ(again.code(), StatusCode::kConflict);
  EXPECT_NE(again.message().find("failed"), std::string::npos) << again.ToString();
}

TEST_P(StoreTest, CancellingARunningJobLeavesARequestItsHolderSees) {
  const int64_t rec = Put("x");
  const int64_t a = Enqueue(rec), b = Enqueue(rec);
  ASSERT_EQ(Claim("w1").id, a);
  ASSERT_EQ(Claim("w2").id, b);
  std::vector<int64_t> requested = {99};
  ASSERT_TRUE(store_->CancelRequests({a, b}, &requested).ok());
  EXPECT_TRUE(requested.empty());
  JobInfo job;
  ASSERT_TRUE(store_->CancelJob(b, "takes too long", "anonymous", &job).ok());
  EXPECT_EQ(job.status, JobStatus::kRunning);  // its holder stops it
  EXPECT_EQ(job.cancel_reason, "takes too long");
  // A later request keeps the first one's words (and is recorded too).
  ASSERT_TRUE(store_->CancelJob(b, "second thoughts", "token", &job).ok());
  EXPECT_EQ(job.cancel_reason, "takes too long");
  EXPECT_EQ(job.cancel_actor, "anonymous");
  ASSERT_TRUE(store_->CancelRequests({a, b, 12345}, &requested).ok());
  EXPECT_EQ(requested, std::vector<int64_t>({b}));
  ASSERT_TRUE(store_->CancelRequests({}, &requested).ok());
  EXPECT_TRUE(requested.empty());
  // The holder fails it; then it is no longer a request to act on.
  ASSERT_TRUE(
      store_->FailJob(b, "w2", {"stopped", "cancelled", "cancelled by anonymous: x", "{}"}, false)
          .ok());
  ASSERT_TRUE(store_->CancelRequests({a, b}, &requested).ok());
  EXPECT_TRUE(requested.empty());
  EXPECT_EQ(Get(b).error_reason, "cancelled");
}

TEST_P(StoreTest, ACancelledRunningJobIsNeverQueuedAgain) {
  const int64_t rec = Put("x");
  const int64_t released = Enqueue(rec), lapsed = Enqueue(rec), transient = Enqueue(rec);
  ASSERT_EQ(Claim("w1", 1000).id, released);
  ASSERT_EQ(Claim("w2", 1000).id, lapsed);
  ASSERT_EQ(Claim("w3", 60000).id, transient);
  for (int64_t id : {released, lapsed, transient}) {
    ASSERT_TRUE(store_->CancelJob(id, "stop it", "token").ok());
  }
  // Released at shutdown: it ends as cancelled instead of going back to the queue.
  ASSERT_TRUE(store_->ReleaseJob(released, "w1", ReleaseKind::kShutdown).ok());
  JobInfo job = Get(released);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_reason, "cancelled");
  EXPECT_EQ(job.error_message, "cancelled by token: stop it");
  // Its holder died: when the lease lapses it fails as cancelled (not lease_expired, not queued).
  clock_.Advance(2000);
  int64_t recovered = 0;
  ASSERT_TRUE(store_->RecoverExpiredLeases(&recovered).ok());
  EXPECT_EQ(recovered, 1);
  job = Get(lapsed);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "stopped");
  EXPECT_EQ(job.error_reason, "cancelled");
  EXPECT_NE(job.error_message.find("cancelled by token: stop it"), std::string::npos);
  // A transient failure of a cancelled job is final.
  ASSERT_TRUE(store_->FailJob(transient, "w3", {"io_error", "", "disk", ""}, true).ok());
  EXPECT_EQ(Get(transient).status, JobStatus::kFailed);
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w4", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);
}

// A cancel answered "stopping it" wins over a run that finished meanwhile (its holder had not
// seen the request yet): the completion is refused (kConflict), nothing is stored, and the job
// ends as cancelled, so a cancelled calibration never becomes a device's calibration.
TEST_P(StoreTest, ACancelledRunningJobIsNotCompletedByItsLateResult) {
  const int64_t rec = Put("x");
  const int64_t id = Enqueue(rec, "pca", "SN-CANCEL");
  ASSERT_EQ(Claim("w1").id, id);
  ASSERT_TRUE(store_->CancelJob(id, "wrong board", "token").ok());
  const Status s =
      store_->CompleteJob(id, "w1", R"({"verdict": {"status": "accepted", "reasons": []}})");
  EXPECT_EQ(s.code(), StatusCode::kConflict) << s.ToString();
  EXPECT_NE(s.message().find("cancelled by token: wrong board"), std::string::npos) << s.message();
  const JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_reason, "cancelled");
  EXPECT_TRUE(job.result_json.empty());
  JobInfo latest;
  EXPECT_EQ(store_->LatestResult(job.device, "pca", &latest).code(), StatusCode::kNotFound);
}

TEST_P(StoreTest, CancelNeedsAReasonAndAnUnfinishedJob) {
  const int64_t rec = Put("x");
  const int64_t id = Enqueue(rec);
  Status s = store_->CancelJob(id, "", "token");
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "reason");
  EXPECT_EQ(Get(id).status, JobStatus::kQueued);  // nothing changed
  EXPECT_EQ(store_->CancelJob(424242, "why", "token").code(), StatusCode::kNotFound);
  ASSERT_EQ(Claim("w").id, id);
  ASSERT_TRUE(store_->CompleteJob(id, "w", R"({"ok":true})").ok());
  s = store_->CancelJob(id, "too late", "token");
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("succeeded"), std::string::npos) << s.ToString();
  std::vector<JobEvent> events;
  ASSERT_TRUE(store_->ListJobEvents(id, &events).ok());
  EXPECT_TRUE(events.empty());
}

TEST_P(StoreTest, CompleteStoresResultWithHashAndUpdatesTheDevice) {
  int64_t rec = Put("x", "SN1");
  int64_t id = Enqueue(rec);
  Claim("w1");
  clock_.Advance(1500);
  const std::string result = R"({"method":"pca","parameters":{}})";
  ASSERT_TRUE(store_->CompleteJob(id, "w1", result).ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kSucceeded);
  EXPECT_EQ(job.result_json, result);
  EXPECT_EQ(job.result_sha256, Sha256Hex(result));
  EXPECT_EQ(job.finished_at_ms, clock_.Now());
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(job.lease_expires_at, "");

  JobInfo latest;
  ASSERT_TRUE(store_->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, id);
  EXPECT_EQ(latest.result_json, result);
  EXPECT_EQ(latest.result_sha256, Sha256Hex(result));
  EXPECT_EQ(store_->LatestResult("SN1", "array", &latest).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->LatestResult("SN2", "pca", &latest).code(), StatusCode::kNotFound);

  std::vector<DeviceInfo> devices;
  ASSERT_TRUE(store_->ListDevices(&devices).ok());
  ASSERT_EQ(devices.size(), 1u);
  EXPECT_EQ(devices[0].serial, "SN1");
  ASSERT_EQ(devices[0].latest.size(), 1u);
  EXPECT_EQ(devices[0].latest[0].method, "pca");
  EXPECT_EQ(devices[0].latest[0].job_id, id);
  EXPECT_EQ(devices[0].latest[0].calibrated_at, job.finished_at);
}

TEST_P(StoreTest, LatestResultIsTheLastToFinishPerMethod) {
  int64_t rec = Put("x", "SN1");
  int64_t a = Enqueue(rec, "pca"), b = Enqueue(rec, "pca"), c = Enqueue(rec, "array");
  Claim("w");
  Claim("w");
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(b, "w", R"({"r":"b"})").ok());
  clock_.Advance(10);
  ASSERT_TRUE(store_->CompleteJob(a, "w", R"({"r":"a"})").ok());  // finished last: latest
  ASSERT_TRUE(store_->CompleteJob(c, "w", R"({"r":"c"})").ok());
  JobInfo latest;
  ASSERT_TRUE(store_->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, a);
  ASSERT_TRUE(store_->LatestResult("SN1", "array", &latest).ok());
  EXPECT_EQ(latest.id, c);
  std::vector<DeviceInfo> devices;
  ASSERT_TRUE(store_->ListDevices(&devices).ok());
  ASSERT_EQ(devices.size(), 1u);
  ASSERT_EQ(devices[0].latest.size(), 2u);
  EXPECT_EQ(devices[0].latest[0].method, "array");
  EXPECT_EQ(devices[0].latest[1].method, "pca");
}

TEST_P(StoreTest, CompletingTwiceWithTheSameResultStoresOneResult) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(store_->CompleteJob(id, "w1", "{\"v\":1}").ok());
  clock_.Advance(5000);
  EXPECT_TRUE(store_->CompleteJob(id, "w1", "{\"v\":1}").ok());
  EXPECT_TRUE(store_->CompleteJob(id, "w2", "{\"v\":1}").ok());  // a rerun elsewhere, same answer
  JobInfo job = Get(id);
  EXPECT_EQ(job.finished_at_ms, clock_.Now() - 5000);  // unchanged
  EXPECT_EQ(store_->CompleteJob(id, "w1", "{\"v\":2}").code(), StatusCode::kConflict);
  EXPECT_EQ(Get(id).result_json, "{\"v\":1}");
}

TEST_P(StoreTest, ListJobsIsNewestFirstWithFiltersAndStableCursor) {
  int64_t r1 = Put("1", "SN1"), r2 = Put("2", "SN2");
  std::vector<int64_t> ids;
  for (int i = 0; i < 7; ++i) {
    ids.push_back(Enqueue(i % 2 ? r1 : r2, i % 3 ? "pca" : "array"));
  }
  std::vector<JobInfo> page;
  JobFilter f;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 7u);
  for (size_t i = 0; i < page.size(); ++i) EXPECT_EQ(page[i].id, ids[6 - i]);

  f.limit = 3;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 3u);
  EXPECT_EQ(page[0].id, ids[6]);
  Enqueue(r1);  // a new job does not shift the next page
  f.before = page.back().id;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 3u);
  EXPECT_EQ(page[0].id, ids[3]);
  EXPECT_EQ(page[2].id, ids[1]);

  JobFilter by_device;
  by_device.device = "SN1";
  ASSERT_TRUE(store_->ListJobs(by_device, &page).ok());
  EXPECT_EQ(page.size(), 4u);  // ids 1,3,5 + the new one
  for (const auto& j : page) EXPECT_EQ(j.device, "SN1");
  JobFilter by_method;
  by_method.method = "array";
  by_method.device = "SN2";
  ASSERT_TRUE(store_->ListJobs(by_method, &page).ok());
  ASSERT_EQ(page.size(), 2u);  // i = 0, 6
  int64_t n = 0;
  ASSERT_TRUE(store_->CountJobs(by_method, &n).ok());
  EXPECT_EQ(n, 2);

  Claim("w");
  JobFilter by_status;
  by_status.status = JobStatus::kRunning;
  ASSERT_TRUE(store_->ListJobs(by_status, &page).ok());
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].id, ids[0]);

  JobFilter big;
  big.limit = 100000;  // clamped to 500, not an error
  ASSERT_TRUE(store_->ListJobs(big, &page).ok());
  EXPECT_EQ(page.size(), 8u);
}

TEST_P(StoreTest, ListJobsIncludesResultsOnlyWhenAsked) {
  int64_t id = Enqueue(Put("x"));
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(id, "w", "{\"ok\":true}").ok());
  std::vector<JobInfo> page;
  JobFilter f;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].result_json, "");
  EXPECT_EQ(page[0].result_sha256, Sha256Hex("{\"ok\":true}"));
  f.include_results = true;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  EXPECT_EQ(page[0].result_json, "{\"ok\":true}");
}

TEST_P(StoreTest, QueueDepthCountsEveryState) {
  int64_t rec = Put("x");
  for (int i = 0; i < 5; ++i) Enqueue(rec);
  JobInfo a = Claim("w"), b = Claim("w"), c = Claim("w");
  ASSERT_TRUE(store_->CompleteJob(a.id, "w", "{}").ok());
  ASSERT_TRUE(store_->FailJob(b.id, "w", {"singular", "", "rank gap too small", ""}, false).ok());
  QueueCounts q;
  ASSERT_TRUE(store_->QueueDepth(&q).ok());
  EXPECT_EQ(q.queued, 2);
  EXPECT_EQ(q.running, 1);
  EXPECT_EQ(q.succeeded, 1);
  EXPECT_EQ(q.failed, 1);
  (void)c;
}

// ---- leases ----

TEST_P(StoreTest, ExpiredLeaseIsTakenBackByTheNextClaim) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1", 1000);
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w2", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);  // lease still valid
  clock_.Advance(1000);
  JobInfo job = Claim("w2", 1000);
  EXPECT_EQ(job.id, id);
  EXPECT_EQ(job.lease_owner, "w2");
  EXPECT_EQ(job.attempts, 2);
}

TEST_P(StoreTest, RenewedLeaseIsNotTakenBack) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1", 1000);
  clock_.Advance(900);
  ASSERT_TRUE(store_->RenewLease(id, "w1", 1000).ok());
  EXPECT_EQ(Get(id).lease_expires_at_ms, clock_.Now() + 1000);
  clock_.Advance(900);
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w2", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);
  ASSERT_TRUE(store_->CompleteJob(id, "w1", "{}").ok());
}

TEST_P(StoreTest, HolderMayRenewALapsedLeaseNobodyTookBack) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1", 1000);
  clock_.Advance(5000);
  EXPECT_TRUE(store_->RenewLease(id, "w1", 1000).ok());
  EXPECT_TRUE(store_->CompleteJob(id, "w1", "{}").ok());
}

TEST_P(StoreTest, RenewingALeaseTakenByAnotherWorkerIsAConflict) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1", 1000);
  clock_.Advance(1001);
  EXPECT_EQ(Claim("w2", 1000).id, id);
  Status s = store_->RenewLease(id, "w1", 1000);
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("leased by w2"), std::string::npos) << s.message();
  // ... and so is completing, failing or releasing it.
  EXPECT_EQ(store_->CompleteJob(id, "w1", "{}").code(), StatusCode::kConflict);
  EXPECT_EQ(store_->FailJob(id, "w1", {"x", "", "y", ""}, true).code(), StatusCode::kConflict);
  EXPECT_EQ(store_->ReleaseJob(id, "w1", ReleaseKind::kShutdown).code(), StatusCode::kConflict);
  EXPECT_EQ(Get(id).lease_owner, "w2");
  EXPECT_TRUE(store_->CompleteJob(id, "w2", "{}").ok());
}

TEST_P(StoreTest, RecoverExpiredLeasesRequeuesOnlyLapsedJobs) {
  int64_t rec = Put("x");
  int64_t a = Enqueue(rec), b = Enqueue(rec);
  Claim("w1", 1000);
  Claim("w2", 60000);
  clock_.Advance(2000);
  int64_t n = -1;
  ASSERT_TRUE(store_->RecoverExpiredLeases(&n).ok());
  EXPECT_EQ(n, 1);
  JobInfo ja = Get(a);
  EXPECT_EQ(ja.status, JobStatus::kQueued);
  EXPECT_EQ(ja.error_code, "lease_expired");
  EXPECT_EQ(ja.lease_owner, "");
  EXPECT_EQ(ja.started_at, "");
  EXPECT_EQ(Get(b).status, JobStatus::kRunning);
  // The recovered job is claimable at once, and success clears the old error.
  JobInfo again = Claim("w3");
  EXPECT_EQ(again.id, a);
  ASSERT_TRUE(store_->CompleteJob(a, "w3", "{}").ok());
  EXPECT_EQ(Get(a).error_code, "");
}

TEST_P(StoreTest, LeaseExpiringOnTheLastAttemptFailsTheJob) {
  StoreOptions o;
  o.max_attempts = 2;
  Reopen(o);
  int64_t id = Enqueue(Put("x"));
  Claim("w1", 100);
  clock_.Advance(100);
  Claim("w2", 100);  // attempt 2
  clock_.Advance(100);
  int64_t n = 0;
  ASSERT_TRUE(store_->RecoverExpiredLeases(&n).ok());
  EXPECT_EQ(n, 1);
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "lease_expired");
  EXPECT_NE(job.error_message.find("giving up"), std::string::npos);
  EXPECT_EQ(job.finished_at_ms, clock_.Now());
}

TEST_P(StoreTest, ClaimRejectsBadArguments) {
  JobInfo job;
  bool claimed;
  EXPECT_EQ(store_->ClaimJob("", 1000, &job, &claimed).code(), StatusCode::kInvalidInput);
  EXPECT_EQ(store_->ClaimJob("w", 0, &job, &claimed).code(), StatusCode::kInvalidInput);
}

// ---- failures and retries ----

TEST_P(StoreTest, TransientFailureRequeuesWithExponentialBackoff) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(store_->FailJob(id, "w1", {"io_error", "", "disk hiccup", ""}, true).ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(job.error_code, "io_error");
  EXPECT_EQ(job.error_message, "disk hiccup");
  EXPECT_EQ(job.not_before_ms, clock_.Now() + 1000);
  EXPECT_EQ(job.lease_owner, "");
  JobInfo none;
  bool claimed = true;
  clock_.Advance(999);
  ASSERT_TRUE(store_->ClaimJob("w2", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);  // backing off
  clock_.Advance(1);
  EXPECT_EQ(Claim("w2").id, id);
  ASSERT_TRUE(store_->FailJob(id, "w2", {"busy", "", "locked", ""}, true).ok());
  EXPECT_EQ(Get(id).not_before_ms, clock_.Now() + 2000);  // doubled
}

TEST_P(StoreTest, BackoffIsCappedAtTheMaximum) {
  StoreOptions o;
  o.max_attempts = 20;
  o.backoff_base_ms = 1000;
  o.backoff_max_ms = 5000;
  Reopen(o);
  int64_t id = Enqueue(Put("x"));
  for (int i = 0; i < 6; ++i) {
    clock_.Advance(10000);
    Claim("w");
    ASSERT_TRUE(store_->FailJob(id, "w", {"io", "", "again", ""}, true).ok());
  }
  EXPECT_EQ(Get(id).not_before_ms, clock_.Now() + 5000);
}

TEST_P(StoreTest, TransientFailuresStopAtMaxAttempts) {
  StoreOptions o;
  o.max_attempts = 3;
  Reopen(o);
  int64_t id = Enqueue(Put("x"));
  for (int attempt = 1; attempt <= 3; ++attempt) {
    clock_.Advance(1'000'000);
    JobInfo job = Claim("w");
    EXPECT_EQ(job.attempts, attempt);
    ASSERT_TRUE(store_->FailJob(id, "w", {"io_error", "", "disk", ""}, true).ok());
  }
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.attempts, 3);
  EXPECT_EQ(job.error_code, "io_error");
  EXPECT_NE(job.error_message.find("gave up after 3 attempts"), std::string::npos);
  clock_.Advance(1'000'000);
  JobInfo none;
  bool claimed = true;
  ASSERT_TRUE(store_->ClaimJob("w", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);
}

TEST_P(StoreTest, PermanentFailureFailsAtOnceWithTheReason) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(
      store_->FailJob(id, "w1", {"not_determinable", "", "g is not positive definite", ""}, false)
          .ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(job.error_code, "not_determinable");
  EXPECT_EQ(job.error_message, "g is not positive definite");
  EXPECT_EQ(job.finished_at_ms, clock_.Now());
  EXPECT_EQ(job.result_json, "");
}

TEST_P(StoreTest, AFailureKeepsItsReasonAndPartialDiagnostics) {
  const int64_t id = Enqueue(Put("x"));
  Claim("w1");
  const std::string detail = R"({"method":"pca","usable":false,"diagnostics":{"positions":4}})";
  ASSERT_TRUE(
      store_
          ->FailJob(id, "w1",
                    {"not_determinable", "too_few_positions", "4 positions recorded", detail},
                    false)
          .ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_code, "not_determinable");
  EXPECT_EQ(job.error_reason, "too_few_positions");
  EXPECT_EQ(job.error_message, "4 positions recorded");
  EXPECT_EQ(job.error_detail_json, detail);
  // Lists carry the reason; the diagnostics only with include_results.
  JobFilter f;
  std::vector<JobInfo> page;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].error_reason, "too_few_positions");
  EXPECT_EQ(page[0].error_detail_json, "");
  f.include_results = true;
  ASSERT_TRUE(store_->ListJobs(f, &page).ok());
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].error_detail_json, detail);
}

TEST_P(StoreTest, ARetriedFailureLeavesNoStaleReasonOnSuccessOrLeaseExpiry) {
  const int64_t a = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(
      store_->FailJob(a, "w1", {"io_error", "storage_error", "disk", "{\"x\":1}"}, true).ok());
  JobInfo job = Get(a);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.error_reason, "storage_error");
  EXPECT_EQ(job.error_detail_json, "{\"x\":1}");
  clock_.Advance(1'000'000);
  Claim("w2", 1000);
  clock_.Advance(2000);
  int64_t n = 0;
  ASSERT_TRUE(store_->RecoverExpiredLeases(&n).ok());
  job = Get(a);
  EXPECT_EQ(job.error_code, "lease_expired");
  EXPECT_EQ(job.error_reason, "");
  EXPECT_EQ(job.error_detail_json, "");
  Claim("w3");
  ASSERT_TRUE(store_->FailJob(a, "w3", {"io_error", "storage_error", "disk", "{}"}, true).ok());
  clock_.Advance(1'000'000);
  Claim("w4");
  ASSERT_TRUE(store_->CompleteJob(a, "w4", "{}").ok());
  job = Get(a);
  EXPECT_EQ(job.error_code, "");
  EXPECT_EQ(job.error_reason, "");
  EXPECT_EQ(job.error_detail_json, "");
}

TEST_P(StoreTest, ReleaseRequeuesWithoutCountingTheAttempt) {
  int64_t id = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(store_->ReleaseJob(id, "w1", ReleaseKind::kShutdown).ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.attempts, 0);
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(Claim("w2").id, id);  // claimable at once
}

// Released because its outcome could not be stored (full disk): unlike the shutdown release
// the attempt counts and the job backs off as after a transient failure; past max_attempts it
// stays queued (failing it is the write that did not fit), and its next storable failure ends it.
TEST_P(StoreTest, AReleaseAfterAStoreFailureCountsTheAttemptAndBacksOff) {
  StoreOptions o;
  o.max_attempts = 2;
  Reopen(o);
  int64_t id = Enqueue(Put("x"));
  Claim("w1");
  ASSERT_TRUE(store_->ReleaseJob(id, "w1", ReleaseKind::kShutdown).ok());
  JobInfo job = Get(id);
  EXPECT_EQ(job.attempts, 0);
  EXPECT_EQ(job.not_before_ms, clock_.Now());
  EXPECT_EQ(Claim("w2").attempts, 1);  // at once
  ASSERT_TRUE(store_->ReleaseJob(id, "w2", ReleaseKind::kStoreFailed).ok());
  job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kQueued);
  EXPECT_EQ(job.attempts, 1);
  EXPECT_EQ(job.lease_owner, "");
  EXPECT_EQ(job.error_code, "");  // nothing written about a failure it could not store
  EXPECT_EQ(job.not_before_ms, clock_.Now() + 1000);
  JobInfo none;
  bool claimed = true;
  clock_.Advance(999);
  ASSERT_TRUE(store_->ClaimJob("w3", 1000, &none, &claimed).ok());
  EXPECT_FALSE(claimed);  // backing off
  clock_.Advance(1);
  EXPECT_EQ(Claim("w3").attempts, 2);
  ASSERT_TRUE(store_->ReleaseJob(id, "w3", ReleaseKind::kStoreFailed).ok());
  job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kQueued);  // out of attempts, yet nothing could be stored
  EXPECT_EQ(job.attempts, 2);
  EXPECT_EQ(job.not_before_ms, clock_.Now() + 2000);  // doubled
  clock_.Advance(2000);
  EXPECT_EQ(Claim("w4").attempts, 3);
  ASSERT_TRUE(store_->FailJob(id, "w4", {"io_error", "disk_full", "full", ""}, true).ok());
  job = Get(id);
  EXPECT_EQ(job.status, JobStatus::kFailed);
  EXPECT_EQ(job.error_message, "gave up after 3 attempts: full");
}

// ---- illegal transitions ----

TEST_P(StoreTest, CompletingAJobOneDoesNotLeaseIsAConflict) {
  int64_t id = Enqueue(Put("x"));
  Status s = store_->CompleteJob(id, "w1", "{}");  // still queued
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("queued"), std::string::npos);
  Claim("w1");
  s = store_->CompleteJob(id, "w2", "{}");
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("leased by w1"), std::string::npos);
  EXPECT_EQ(Get(id).status, JobStatus::kRunning);
}

TEST_P(StoreTest, FailingOrReleasingAFinishedJobIsAConflict) {
  int64_t rec = Put("x");
  int64_t ok = Enqueue(rec), bad = Enqueue(rec);
  Claim("w");
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(ok, "w", "{}").ok());
  ASSERT_TRUE(store_->FailJob(bad, "w", {"bad", "", "bad input", ""}, false).ok());
  EXPECT_EQ(store_->FailJob(ok, "w", {"x", "", "y", ""}, false).code(), StatusCode::kConflict);
  EXPECT_EQ(store_->FailJob(ok, "w", {"x", "", "y", ""}, true).code(), StatusCode::kConflict);
  EXPECT_EQ(store_->ReleaseJob(ok, "w", ReleaseKind::kStoreFailed).code(), StatusCode::kConflict);
  EXPECT_EQ(store_->RenewLease(ok, "w", 1000).code(), StatusCode::kConflict);
  EXPECT_EQ(store_->CompleteJob(bad, "w", "{}").code(), StatusCode::kConflict);
  EXPECT_EQ(store_->FailJob(bad, "w", {"x", "", "y", ""}, true).code(), StatusCode::kConflict);
  EXPECT_EQ(Get(ok).status, JobStatus::kSucceeded);
  EXPECT_EQ(Get(bad).status, JobStatus::kFailed);
  EXPECT_EQ(Get(bad).error_code, "bad");
}

TEST_P(StoreTest, OperationsOnUnknownJobsAreNotFound) {
  JobInfo job;
  EXPECT_EQ(store_->GetJob(99, &job).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->RenewLease(99, "w", 1000).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->CompleteJob(99, "w", "{}").code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->FailJob(99, "w", {"x", "", "y", ""}, false).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->ReleaseJob(99, "w", ReleaseKind::kStoreFailed).code(), StatusCode::kNotFound);
}

TEST_P(StoreTest, EmptyResultIsInvalid) {
  int64_t id = Enqueue(Put("x"));
  Claim("w");
  EXPECT_EQ(store_->CompleteJob(id, "w", "").code(), StatusCode::kInvalidInput);
  EXPECT_EQ(Get(id).status, JobStatus::kRunning);
}

// ---- devices and persistence ----

TEST_P(StoreTest, DevicesAreRememberedFromUploadsAndJobs) {
  Put("a", "SN-B");
  int64_t rec = Put("b", "");
  Enqueue(rec, "pca", "SN-A");
  std::vector<DeviceInfo> devices;
  ASSERT_TRUE(store_->ListDevices(&devices).ok());
  ASSERT_EQ(devices.size(), 2u);
  EXPECT_EQ(devices[0].serial, "SN-A");
  EXPECT_EQ(devices[1].serial, "SN-B");
  EXPECT_TRUE(devices[0].latest.empty());
  EXPECT_EQ(devices[0].first_seen_ms, clock_.Now());
}

TEST_P(StoreTest, EverythingSurvivesReopening) {
  const std::string bytes = RandomBytes(100000, 9);
  int64_t rec = Put(bytes, "SN1");
  int64_t id = Enqueue(rec);
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(id, "w", "{\"r\":1}").ok());
  Reopen();
  std::string back;
  ASSERT_TRUE(store_->ReadRecordingBytes(rec, &back).ok());
  EXPECT_EQ(back, bytes);
  EXPECT_EQ(Get(id).result_json, "{\"r\":1}");
  std::string check;
  ASSERT_TRUE(store_->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
  EXPECT_TRUE(store_->Checkpoint().ok());
}

TEST(SqliteStoreTest, OpenCreatesTheParentFolder) {
  TempDir dir_;
  std::unique_ptr<Store> store;
  StoreOptions o;
  Status s = Store::Open(dir_.File("data/sub/calibd.db"), o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(std::filesystem::exists(dir_.File("data/sub/calibd.db")));
}

TEST_P(StoreTest, StoreIsUsableFromManyThreadsAtOnce) {
  int64_t rec = Put("x");
  std::vector<std::thread> threads;
  std::atomic<int> errors{0};
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 20; ++i) {
        JobInfo job;
        if (!store_->EnqueueJob(rec, "pca", "SN" + std::to_string(t), "{}", &job).ok()) ++errors;
        std::vector<JobInfo> page;
        if (!store_->ListJobs(JobFilter(), &page).ok()) ++errors;
        RecordingInfo info;
        if (!store_->GetRecording(rec, &info).ok()) ++errors;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(errors.load(), 0);
  int64_t n = 0;
  ASSERT_TRUE(store_->CountJobs(JobFilter(), &n).ok());
  EXPECT_EQ(n, 160);
}

TEST_P(StoreTest, RejectedResultIsNotServedUntilAcceptedAndRevokingFallsBack) {
  int64_t rec = Put("decisions");
  int64_t first = Enqueue(rec, "pca", "SN1");
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(first, "w", R"({"verdict":{"status":"accepted"}})").ok());
  clock_.Advance(1000);
  int64_t second = Enqueue(rec, "pca", "SN1");
  Claim("w");
  ASSERT_TRUE(store_->CompleteJob(second, "w", R"({"verdict":{"status":"rejected"}})").ok());
  EXPECT_EQ(Get(second).state, ServeState::kRejected);
  JobInfo latest;
  ASSERT_TRUE(store_->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, first);  // the rejected one is not served

  EXPECT_EQ(store_->RevokeJob(second, "not served", "anonymous").code(), StatusCode::kConflict);
  EXPECT_EQ(store_->AcceptJob(first, "fine", "anonymous").code(), StatusCode::kConflict);
  EXPECT_EQ(store_->AcceptJob(second, "", "anonymous").code(), StatusCode::kInvalidInput);
  JobEvent event;
  ASSERT_TRUE(store_->AcceptJob(second, "checked by hand", "token", &event).ok());
  EXPECT_EQ(event.job_id, second);
  EXPECT_EQ(event.action, "accept");
  ASSERT_TRUE(store_->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, second);

  ASSERT_TRUE(store_->RevokeJob(second, "wrong fixture", "token").ok());
  EXPECT_EQ(store_->RevokeJob(second, "again", "token").code(), StatusCode::kConflict);
  ASSERT_TRUE(store_->LatestResult("SN1", "pca", &latest).ok());
  EXPECT_EQ(latest.id, first);  // falls back to the previous served one
  std::vector<JobEvent> events;
  ASSERT_TRUE(store_->ListJobEvents(second, &events).ok());
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[0].action, "accept");
  EXPECT_EQ(events[1].action, "revoke");
  EXPECT_EQ(events[1].reason, "wrong fixture");
  JobFilter revoked;
  revoked.state = ServeState::kRevoked;
  int64_t n = 0;
  ASSERT_TRUE(store_->CountJobs(revoked, &n).ok());
  EXPECT_EQ(n, 1);
  ASSERT_TRUE(store_->RevokeJob(first, "also wrong", "token").ok());
  EXPECT_EQ(store_->LatestResult("SN1", "pca", &latest).code(), StatusCode::kNotFound);
}

TEST_P(StoreTest, ExpireLeasesOfTakesBackOnlyTheDeadProcesssJobsAtOnce) {
  int64_t rec = Put("reap");
  int64_t dead_job = Enqueue(rec);
  int64_t live_job = Enqueue(rec);
  EXPECT_EQ(Claim("host:1:5-0", 30000).id, dead_job);
  EXPECT_EQ(Claim("host:1:50-0", 30000).id, live_job);  // shares a prefix, but not "host:1:5-"
  EXPECT_EQ(store_->ExpireLeasesOf("", nullptr).code(), StatusCode::kInvalidInput);
  int64_t taken_back = -1;
  ASSERT_TRUE(store_->ExpireLeasesOf("host:1:5-", &taken_back).ok());
  EXPECT_EQ(taken_back, 1);
  EXPECT_EQ(Get(dead_job).status, JobStatus::kQueued);  // at once, not after the 30 s lease
  EXPECT_EQ(Get(dead_job).error_code, "lease_expired");
  EXPECT_EQ(Get(live_job).status, JobStatus::kRunning);
  EXPECT_EQ(Claim("host:2:7-0").id, dead_job);
  ASSERT_TRUE(store_->ExpireLeasesOf("host:1:5-", &taken_back).ok());
  EXPECT_EQ(taken_back, 0);
}

TEST_P(StoreTest, PingAnswersAndTheBackendIsNamed) {
  EXPECT_TRUE(store_->Ping().ok());
  EXPECT_EQ(std::string(store_->backend()), GetParam());
}

INSTANTIATE_TEST_SUITE_P(Backends, StoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           return info.param;
                         });

}  // namespace
}  // namespace calibd::storage
