// Faults: a full disk (PRAGMA max_page_count as a size limit), read-only files, a locked
// database and a damaged file give clear errors, never a crash, and lose nothing committed.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <thread>
#include <vector>

#include "storage/db.h"
#include "storage/schema.h"
#include "storage/sha256.h"
#include "storage/store.h"
#include "tests/lib/unprivileged.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::RandomBytes;
using testing::TempDir;

int64_t Count(const std::string& path, const char* sql) {
  std::unique_ptr<Db> db;
  EXPECT_TRUE(Db::Open(path, Db::Options(), &db).ok());
  int64_t n = -1;
  Status s = db->QueryInt(sql, &n);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return n;
}

std::string Integrity(Store* store) {
  std::string check;
  Status s = store->IntegrityCheck(&check);
  return s.ok() ? check : s.ToString();
}

class FullDisk : public ::testing::Test {
 protected:
  void OpenWithLimit(int64_t pages) {
    store_.reset();
    StoreOptions o;
    o.max_page_count = pages;
    Status s = Store::Open(path_, o, &store_);
    ASSERT_TRUE(s.ok()) << s.ToString();
  }
  TempDir dir_;
  std::string path_ = dir_.File("full.db");
  std::unique_ptr<Store> store_;
};

TEST_F(FullDisk, UploadsFailWithAClearIoErrorAndCommittedOnesStayIntact) {
  OpenWithLimit(300);  // 300 pages of 4 KiB
  std::vector<std::pair<int64_t, std::string>> stored;
  Status failure;
  std::string rejected;
  for (uint32_t i = 0; i < 1000; ++i) {
    std::string bytes = RandomBytes(20000, i);
    NewRecording r;
    r.data = bytes;
    r.device = "SN1";
    r.job = NewJob{"pca", "", "{}"};
    RecordingInfo info;
    Status s = store_->PutRecording(r, &info, nullptr);
    if (!s.ok()) {
      failure = s;
      rejected = bytes;
      break;
    }
    stored.emplace_back(info.id, bytes);
  }
  ASSERT_FALSE(failure.ok()) << "the limit was never reached";
  EXPECT_EQ(failure.code(), StatusCode::kIoError) << failure.ToString();
  EXPECT_TRUE(failure.IsTransient());
  EXPECT_NE(failure.message().find("database or disk is full"), std::string::npos)
      << failure.message();
  ASSERT_GT(stored.size(), 10u);

  // Nothing committed is lost; the failed upload left nothing behind, not even its job.
  EXPECT_EQ(Integrity(store_.get()), "ok");
  for (const auto& [id, bytes] : stored) {
    std::string back;
    ASSERT_TRUE(store_->ReadRecordingBytes(id, &back).ok());
    ASSERT_EQ(back, bytes);
  }
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM recordings"), static_cast<int64_t>(stored.size()));
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM recording_data"),
            static_cast<int64_t>(stored.size()));
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM jobs"), static_cast<int64_t>(stored.size()));

  // Reads and small state changes still work on a full database.
  JobInfo job;
  bool claimed = false;
  Status s = store_->ClaimJob("w", 1000, &job, &claimed);
  EXPECT_TRUE(s.ok() || s.code() == StatusCode::kIoError) << s.ToString();

  // With room again, the rejected upload goes through.
  OpenWithLimit(0);
  NewRecording r;
  r.data = rejected;
  bool existed = true;
  RecordingInfo info;
  ASSERT_TRUE(store_->PutRecording(r, &info, &existed).ok());
  EXPECT_FALSE(existed);
  EXPECT_EQ(Integrity(store_.get()), "ok");
}

TEST_F(FullDisk, StreamedUploadThatDoesNotFitLeavesNothingHalfWritten) {
  OpenWithLimit(300);
  const std::string staged = dir_.File("big.tmp");
  const std::string big = RandomBytes(3 << 20, 7);
  std::ofstream(staged, std::ios::binary) << big;
  NewRecording r;
  r.path = staged;
  r.job = NewJob{"array", "SN1", "{}"};
  Status s = store_->PutRecording(r, nullptr, nullptr);
  EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
  EXPECT_NE(s.message().find("full"), std::string::npos) << s.message();
  EXPECT_EQ(Integrity(store_.get()), "ok");
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM recordings"), 0);
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM recording_data"), 0);
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM jobs"), 0);
  // A small one still fits.
  const std::string small = "t,a0_x,a0_y,a0_z\n0,1,2,3\n";
  std::ofstream(staged, std::ios::binary | std::ios::trunc) << small;
  RecordingInfo info;
  ASSERT_TRUE(store_->PutRecording(r, &info, nullptr).ok());
  std::string back;
  ASSERT_TRUE(store_->ReadRecordingBytes(info.id, &back).ok());
  EXPECT_EQ(back, small);
}

TEST_F(FullDisk, OneUploadOverflowingDoesNotFailTheSmallWritesBatchedWithIt) {
  // Group commit puts concurrent calls in one transaction. When one of them fills the disk,
  // SQLite may roll back the whole transaction; the others must be re-run, not failed or lost.
  OpenWithLimit(400);
  NewRecording seed;
  seed.data = "x";
  RecordingInfo rec;
  ASSERT_TRUE(store_->PutRecording(seed, &rec, nullptr).ok());
  const std::string big = RandomBytes(4 << 20, 3);
  for (int round = 0; round < 5; ++round) {
    std::atomic<int> small_failures{0};
    std::atomic<bool> go{false};
    std::vector<std::thread> threads;
    Status big_status;
    threads.emplace_back([&] {
      while (!go) std::this_thread::yield();
      NewRecording r;
      r.data = big;
      big_status = store_->PutRecording(r, nullptr, nullptr);
    });
    for (int t = 0; t < 6; ++t) {
      threads.emplace_back([&] {
        while (!go) std::this_thread::yield();
        for (int i = 0; i < 5; ++i) {
          JobInfo job;
          Status s = store_->EnqueueJob(rec.id, "pca", "", "{}", &job);
          if (!s.ok()) {
            ADD_FAILURE() << s.ToString();
            ++small_failures;
          }
        }
      });
    }
    go = true;
    for (auto& t : threads) t.join();
    EXPECT_EQ(big_status.code(), StatusCode::kIoError) << big_status.ToString();
    EXPECT_EQ(small_failures.load(), 0);
  }
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM jobs"), 5 * 6 * 5);
  EXPECT_EQ(Count(path_, "SELECT COUNT(*) FROM recordings"), 1);
  EXPECT_EQ(Integrity(store_.get()), "ok");
}

// ---- read-only ----

class ReadOnly : public ::testing::Test {
 protected:
  void SetUp() override {
    std::unique_ptr<Store> store;
    ASSERT_TRUE(Store::Open(path_, StoreOptions(), &store).ok());
    NewRecording r;
    r.data = bytes_;
    r.device = "SN1";
    r.job = NewJob{"pca", "", "{}"};
    RecordingInfo info;
    ASSERT_TRUE(store->PutRecording(r, &info, nullptr).ok());
    recording_ = info.id;
    job_ = info.job->id;
  }
  void ExpectWritesRefused(Store* store) {
    NewRecording r;
    r.data = "other bytes";
    Status s = store->PutRecording(r, nullptr, nullptr);
    EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
    EXPECT_NE(s.message().find("readonly"), std::string::npos) << s.message();
    JobInfo job;
    s = store->EnqueueJob(recording_, "pca", "", "{}", &job);
    EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
    bool claimed = true;
    s = store->ClaimJob("w", 1000, &job, &claimed);
    EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
    EXPECT_FALSE(claimed);
  }
  void ExpectNothingChanged() {
    std::unique_ptr<Store> store;
    ASSERT_TRUE(Store::Open(path_, StoreOptions(), &store).ok());
    std::string back;
    ASSERT_TRUE(store->ReadRecordingBytes(recording_, &back).ok());
    EXPECT_EQ(back, bytes_);
    JobInfo job;
    ASSERT_TRUE(store->GetJob(job_, &job).ok());
    EXPECT_EQ(job.status, JobStatus::kQueued);
    int64_t n = 0;
    ASSERT_TRUE(store->CountJobs(JobFilter(), &n).ok());
    EXPECT_EQ(n, 1);
    EXPECT_EQ(Integrity(store.get()), "ok");
  }
  TempDir dir_;
  std::string path_ = dir_.File("ro.db");
  std::string bytes_ = RandomBytes(5000, 11);
  int64_t recording_ = 0, job_ = 0;
};

TEST_F(ReadOnly, ReadOnlyStoreServesReadsAndRefusesWritesClearly) {
  StoreOptions o;
  o.read_only = true;
  std::unique_ptr<Store> store;
  Status s = Store::Open(path_, o, &store);
  ASSERT_TRUE(s.ok()) << s.ToString();
  std::string back;
  ASSERT_TRUE(store->ReadRecordingBytes(recording_, &back).ok());
  EXPECT_EQ(back, bytes_);
  std::vector<JobInfo> jobs;
  ASSERT_TRUE(store->ListJobs(JobFilter(), &jobs).ok());
  EXPECT_EQ(jobs.size(), 1u);
  ExpectWritesRefused(store.get());
  store.reset();
  ExpectNothingChanged();
}

// The file's mode says read-only: opened by a user it binds (as root: nobody, in a child).
TEST_F(ReadOnly, WriteProtectedFileRefusesWritesClearly) {
  ASSERT_EQ(chmod(path_.c_str(), 0444), 0);
  ASSERT_TRUE(unprivileged::OpenFolderToNobody(dir_.path()));
  const int outcome = unprivileged::RunUnprivileged(path_, [&] {
    ASSERT_NE(geteuid(), 0u);  // permissions bind this user
    std::unique_ptr<Store> store;
    Status s = Store::Open(path_, StoreOptions(), &store);
    if (s.ok()) {
      ExpectWritesRefused(store.get());
    } else {
      EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
    }
  });
  ASSERT_EQ(chmod(path_.c_str(), 0644), 0);
  if (outcome == unprivileged::kUnprivilegedUnavailable) {
    GTEST_SKIP() << "running as root, and a child cannot become nobody and read " << path_;
  }
  EXPECT_EQ(outcome, 0) << "the checks failed as " << (geteuid() == 0 ? "nobody" : "this user");
  ExpectNothingChanged();
}

TEST_F(ReadOnly, ReadOnlyOpenOfAFileThatNeedsAMigrationIsAClearError) {
  const std::string old_path = dir_.File("v1.db");
  {
    std::unique_ptr<Db> db;
    ASSERT_TRUE(Db::Open(old_path, Db::Options(), &db).ok());
    ASSERT_TRUE(MigrateSchema(db.get(), 1).ok());
  }
  StoreOptions o;
  o.read_only = true;
  std::unique_ptr<Store> store;
  Status s = Store::Open(old_path, o, &store);
  EXPECT_EQ(s.code(), StatusCode::kIoError);
  EXPECT_NE(s.message().find("schema version 1"), std::string::npos) << s.message();
}

TEST_F(ReadOnly, ReadOnlyOpenOfAMissingFileIsAnIoError) {
  StoreOptions o;
  o.read_only = true;
  std::unique_ptr<Store> store;
  Status s = Store::Open(dir_.File("missing.db"), o, &store);
  EXPECT_EQ(s.code(), StatusCode::kIoError) << s.ToString();
}

// ---- locked and damaged ----

TEST(Locked, WriteLockHeldPastTheBusyTimeoutIsATransientBusyError) {
  TempDir dir;
  const std::string path = dir.File("busy.db");
  StoreOptions o;
  o.busy_timeout_ms = 100;
  std::unique_ptr<Store> store;
  ASSERT_TRUE(Store::Open(path, o, &store).ok());
  NewRecording r;
  r.data = "x";
  RecordingInfo rec;
  ASSERT_TRUE(store->PutRecording(r, &rec, nullptr).ok());

  std::unique_ptr<Db> other;  // e.g. another process in a long transaction
  ASSERT_TRUE(Db::Open(path, Db::Options(), &other).ok());
  ASSERT_TRUE(other->Exec("BEGIN IMMEDIATE").ok());
  JobInfo job;
  Status s = store->EnqueueJob(rec.id, "pca", "", "{}", &job);
  EXPECT_EQ(s.code(), StatusCode::kBusy) << s.ToString();
  EXPECT_TRUE(s.IsTransient());
  EXPECT_NE(s.message().find("locked"), std::string::npos) << s.message();
  RecordingInfo info;
  EXPECT_TRUE(store->GetRecording(rec.id, &info).ok());  // reads still work (WAL)
  ASSERT_TRUE(other->Exec("COMMIT").ok());
  EXPECT_TRUE(store->EnqueueJob(rec.id, "pca", "", "{}", &job).ok());
}

TEST(Damaged, CorruptedPagesAreReportedAsCorruptionNotACrash) {
  TempDir dir;
  const std::string path = dir.File("bad.db");
  std::vector<int64_t> ids;
  {
    std::unique_ptr<Store> store;
    ASSERT_TRUE(Store::Open(path, StoreOptions(), &store).ok());
    for (uint32_t i = 0; i < 20; ++i) {
      NewRecording r;
      const std::string bytes = RandomBytes(10000, i);
      r.data = bytes;
      r.job = NewJob{"pca", "SN1", "{}"};
      RecordingInfo info;
      ASSERT_TRUE(store->PutRecording(r, &info, nullptr).ok());
      ids.push_back(info.id);
    }
    ASSERT_TRUE(store->Checkpoint().ok());
  }
  {
    // Overwrite pages 2..12 (the tables' root pages), keeping page 1 (header and schema).
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(4096);
    const std::string garbage(11 * 4096, '\xab');
    f.write(garbage.data(), static_cast<std::streamsize>(garbage.size()));
  }
  std::unique_ptr<Store> store;
  Status s = Store::Open(path, StoreOptions(), &store);
  if (!s.ok()) {
    EXPECT_EQ(s.code(), StatusCode::kCorruption) << s.ToString();
    return;
  }
  std::string check;
  s = store->IntegrityCheck(&check);
  EXPECT_TRUE(!s.ok() || check != "ok") << check;
  int corrupt = 0;
  for (int64_t id : ids) {
    std::string bytes;
    RecordingInfo info;
    Status a = store->ReadRecordingBytes(id, &bytes);
    Status b = store->GetRecording(id, &info);
    for (const Status& st : {a, b}) {
      if (st.code() == StatusCode::kCorruption) {
        ++corrupt;
        EXPECT_NE(st.message().find("malformed"), std::string::npos) << st.message();
      }
    }
  }
  JobInfo job;
  Status c = store->GetJob(1, &job);
  if (c.code() == StatusCode::kCorruption) ++corrupt;
  EXPECT_GT(corrupt, 0);
}

}  // namespace
}  // namespace calibd::storage
