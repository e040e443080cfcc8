// Crash safety: a child process uploads recordings (acknowledging each one only after the call
// returned, like the server's 201) and runs jobs, and is killed with SIGKILL at random moments,
// 55 times. After every kill the file must pass PRAGMA integrity_check, every acknowledged upload
// must be there byte-exact with its job, and every stored result must be the right one; after a
// final recovery run every job has succeeded, with exactly one result each.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <thread>

#include "storage/db.h"
#include "storage/sha256.h"
#include "storage/store.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::RandomBytes;
using testing::TempDir;

constexpr int kKills = 55;

std::string UploadBytes(uint64_t seed) {
  const size_t size = 100 + (seed * 7919) % 20000;
  return RandomBytes(size, static_cast<uint32_t>(seed));
}

// What the fake calibration returns: a function of the input only (SPEC §6: deterministic).
std::string ExpectedResult(const std::string& recording_sha, const std::string& config_json) {
  return "{\"recording\":\"" + recording_sha + "\",\"config\":" + config_json + "}";
}

void AppendLine(int fd, const std::string& line) {
  // One write() per line: a kill leaves at most one incomplete last line.
  ssize_t unused = ::write(fd, line.data(), line.size());
  (void)unused;
}

// The child: uploads on this thread, runs jobs on another, until killed.
[[noreturn]] void RunChild(const TempDir& dir, int round) {
  StoreOptions o;
  o.max_attempts = 1000;  // kills must not exhaust a job's attempts in this test
  o.busy_timeout_ms = 10000;
  std::unique_ptr<Store> store;
  if (!Store::Open(dir.File("crash.db"), o, &store).ok()) _exit(3);
  const int ack_fd = ::open(dir.File("acks.txt").c_str(), O_WRONLY | O_APPEND | O_CREAT, 0644);
  const int err_fd = ::open(dir.File("errors.txt").c_str(), O_WRONLY | O_APPEND | O_CREAT, 0644);
  if (ack_fd < 0 || err_fd < 0) _exit(4);
  if (!store->RecoverExpiredLeases(nullptr).ok()) _exit(5);

  std::thread worker([&] {
    const std::string me = "child-" + std::to_string(round);
    for (;;) {
      JobInfo job;
      bool claimed = false;
      Status s = store->ClaimJob(me, 300, &job, &claimed);
      if (!s.ok() || !claimed) {
        usleep(2000);
        continue;
      }
      RecordingInfo rec;
      std::string bytes;
      if (!store->GetRecording(job.recording_id, &rec).ok() ||
          !store->ReadRecordingBytes(job.recording_id, &bytes).ok() ||
          Sha256Hex(bytes) != rec.sha256) {
        AppendLine(err_fd, "recording " + std::to_string(job.recording_id) + " unreadable\n");
        continue;
      }
      (void)store->RenewLease(job.id, me, 300);
      s = store->CompleteJob(job.id, me, ExpectedResult(rec.sha256, job.config_json));
      if (!s.ok() && s.code() != StatusCode::kConflict) {
        AppendLine(err_fd, "complete " + std::to_string(job.id) + ": " + s.ToString() + "\n");
      }
    }
  });

  for (uint64_t i = 0;; ++i) {
    // Every 7th upload repeats an earlier recording (dedupe), every 5th goes through a staged
    // file (the streaming path with its savepoint).
    const uint64_t seed =
        (i % 7 == 6) ? uint64_t(round) * 1000000 + i / 2 : uint64_t(round) * 1000000 + i;
    const std::string bytes = UploadBytes(seed);
    NewRecording r;
    std::string staged;
    if (i % 5 == 4) {
      staged = dir.File("staged-" + std::to_string(round) + "-" + std::to_string(i));
      std::ofstream(staged, std::ios::binary) << bytes;
      r.path = staged;
    } else {
      r.data = bytes;
    }
    r.device = "SN" + std::to_string(i % 3);
    r.job = NewJob{"pca", "", "{\"seed\":" + std::to_string(seed) + "}"};
    RecordingInfo info;
    Status s = store->PutRecording(r, &info, nullptr);
    if (!staged.empty()) ::unlink(staged.c_str());
    if (!s.ok()) {
      AppendLine(err_fd, "upload: " + s.ToString() + "\n");
      continue;
    }
    // Acknowledged only now, after the commit — like the server's 201.
    std::ostringstream line;
    line << seed << " " << info.id << " " << info.job->id << " " << info.sha256 << "\n";
    AppendLine(ack_fd, line.str());
  }
}

struct Ack {
  uint64_t seed;
  int64_t recording_id, job_id;
  std::string sha;
};

std::vector<Ack> ReadAcks(const TempDir& dir) {
  std::ifstream in(dir.File("acks.txt"));
  std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<Ack> acks;
  size_t start = 0;
  for (size_t nl; (nl = content.find('\n', start)) != std::string::npos; start = nl + 1) {
    std::istringstream line(content.substr(start, nl - start));
    Ack a;
    if (line >> a.seed >> a.recording_id >> a.job_id >> a.sha) acks.push_back(a);
  }
  return acks;
}

// Every succeeded job's result is the deterministic one; exactly one result per succeeded job.
void ExpectResultsConsistent(Store* store, const std::string& path) {
  std::map<int64_t, std::string> sha_of_recording;
  JobFilter f;
  f.limit = 500;
  f.include_results = true;
  for (;;) {
    std::vector<JobInfo> page;
    ASSERT_TRUE(store->ListJobs(f, &page).ok());
    if (page.empty()) break;
    for (const JobInfo& job : page) {
      if (job.status != JobStatus::kSucceeded) continue;
      auto it = sha_of_recording.find(job.recording_id);
      if (it == sha_of_recording.end()) {
        RecordingInfo rec;
        ASSERT_TRUE(store->GetRecording(job.recording_id, &rec).ok());
        it = sha_of_recording.emplace(job.recording_id, rec.sha256).first;
      }
      ASSERT_EQ(job.result_json, ExpectedResult(it->second, job.config_json)) << job.id;
      ASSERT_EQ(job.result_sha256, Sha256Hex(job.result_json)) << job.id;
    }
    f.before = page.back().id;
  }
  std::unique_ptr<Db> db;
  ASSERT_TRUE(Db::Open(path, Db::Options(), &db).ok());
  int64_t results = -1, succeeded = -2, orphans = -1;
  ASSERT_TRUE(db->QueryInt("SELECT COUNT(*) FROM results", &results).ok());
  ASSERT_TRUE(
      db->QueryInt("SELECT COUNT(*) FROM jobs WHERE status = 'succeeded'", &succeeded).ok());
  ASSERT_TRUE(db->QueryInt("SELECT COUNT(*) FROM results r JOIN jobs j ON j.id = r.job_id "
                           "WHERE j.status <> 'succeeded'",
                           &orphans)
                  .ok());
  EXPECT_EQ(results, succeeded);
  EXPECT_EQ(orphans, 0);
  int64_t half_written = -1;  // a recording row without its bytes, or with the wrong size
  ASSERT_TRUE(db->QueryInt("SELECT COUNT(*) FROM recordings r LEFT JOIN recording_data d "
                           "ON d.recording_id = r.id WHERE d.data IS NULL OR "
                           "length(d.data) <> r.bytes OR r.sha256 = ''",
                           &half_written)
                  .ok());
  EXPECT_EQ(half_written, 0);
}

TEST(Crash, KilledWriterLosesNoAcknowledgedUploadAndEveryJobSucceedsAfterRecovery) {
  TempDir dir;
  const std::string path = dir.File("crash.db");
  std::mt19937 rng(20261122);
  std::uniform_int_distribution<int> delay_ms(5, 120);
  size_t verified_bytes = 0;  // acks whose bytes were regenerated and compared
  std::map<int64_t, std::string> acked_sha;

  for (int round = 0; round < kKills; ++round) {
    pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) RunChild(dir, round);
    usleep(static_cast<useconds_t>(delay_ms(rng)) * 1000);
    ASSERT_EQ(kill(pid, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status))
        << "child exited on its own with " << WEXITSTATUS(status) << " in round " << round;

    SCOPED_TRACE("after kill " + std::to_string(round + 1));
    std::unique_ptr<Store> store;
    Status s = Store::Open(path, StoreOptions(), &store);
    ASSERT_TRUE(s.ok()) << s.ToString();
    std::string check;
    ASSERT_TRUE(store->IntegrityCheck(&check).ok());
    ASSERT_EQ(check, "ok");
    const std::vector<Ack> acks = ReadAcks(dir);
    for (size_t i = 0; i < acks.size(); ++i) {
      const Ack& a = acks[i];
      std::string bytes;
      s = store->ReadRecordingBytes(a.recording_id, &bytes);
      ASSERT_TRUE(s.ok()) << "acknowledged recording " << a.recording_id << ": " << s.ToString();
      ASSERT_EQ(Sha256Hex(bytes), a.sha) << "recording " << a.recording_id;
      if (i >= verified_bytes) {  // new since the last kill: compare byte by byte as well
        ASSERT_EQ(bytes, UploadBytes(a.seed)) << "recording " << a.recording_id;
      }
      auto it = acked_sha.emplace(a.recording_id, a.sha).first;
      ASSERT_EQ(it->second, a.sha) << "one id acknowledged for two contents";
      JobInfo job;
      s = store->GetJob(a.job_id, &job);
      ASSERT_TRUE(s.ok()) << "acknowledged job " << a.job_id << ": " << s.ToString();
      ASSERT_EQ(job.recording_id, a.recording_id);
    }
    verified_bytes = acks.size();
    ExpectResultsConsistent(store.get(), path);
  }

  std::ifstream errors(dir.File("errors.txt"));
  std::string error_text((std::istreambuf_iterator<char>(errors)),
                         std::istreambuf_iterator<char>());
  EXPECT_EQ(error_text, "") << "the child reported errors";
  EXPECT_GT(acked_sha.size(), 100u) << "too few uploads to mean anything";

  // Final recovery run, an hour later: every lease has lapsed.
  StoreOptions later;
  later.now_ms = [] {
    return std::chrono::duration_cast<std::chrono::milliseconds>(
               std::chrono::system_clock::now().time_since_epoch())
               .count() +
           3'600'000;
  };
  later.max_attempts = 1000;
  std::unique_ptr<Store> store;
  ASSERT_TRUE(Store::Open(path, later, &store).ok());
  int64_t recovered = 0;
  ASSERT_TRUE(store->RecoverExpiredLeases(&recovered).ok());
  for (;;) {
    JobInfo job;
    bool claimed = false;
    ASSERT_TRUE(store->ClaimJob("recovery", 60000, &job, &claimed).ok());
    if (!claimed) break;
    RecordingInfo rec;
    ASSERT_TRUE(store->GetRecording(job.recording_id, &rec).ok());
    ASSERT_TRUE(
        store->CompleteJob(job.id, "recovery", ExpectedResult(rec.sha256, job.config_json)).ok());
  }
  QueueCounts q;
  ASSERT_TRUE(store->QueueDepth(&q).ok());
  EXPECT_EQ(q.queued, 0);
  EXPECT_EQ(q.running, 0);
  EXPECT_EQ(q.failed, 0);
  EXPECT_GE(q.succeeded, static_cast<int64_t>(ReadAcks(dir).size()));
  ExpectResultsConsistent(store.get(), path);
  std::string check;
  ASSERT_TRUE(store->IntegrityCheck(&check).ok());
  EXPECT_EQ(check, "ok");
  std::cout << "[ crash    ] " << kKills << " kills, " << ReadAcks(dir).size()
            << " acknowledged uploads, " << q.succeeded << " jobs succeeded, " << recovered
            << " leases recovered at the end\n";
}

}  // namespace
}  // namespace calibd::storage
