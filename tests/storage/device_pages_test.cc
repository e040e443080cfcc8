// Lists that stay bounded (issue #27): ListDevices a page at a time (limit + the last serial as
// cursor, byte order of the serials on both backends), and ?verdict= listing from the index of
// results by their standing. Run on both backends: an SQLite file and a database in a throw-away
// PostgreSQL cluster (pg_test_cluster.h).
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <string>
#include <vector>

#include "storage/sqlite_store_internal.h"
#include "storage/store.h"
#include "tests/storage/pg_test_cluster.h"
#include "tests/storage/storage_test_util.h"

namespace calibd::storage {
namespace {

using testing::FakeClock;
using testing::TempDir;

class DevicePagesTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "postgresql") {
      auto* cluster = testing::PgTestCluster::Get();
      ASSERT_NE(cluster, nullptr);
      target_ = cluster->NewDatabase();
    } else {
      target_ = dir_.File("calibd.db");
    }
    StoreOptions options;
    options.now_ms = clock_.Fn();
    Status s = Store::Open(target_, options, &store_);
    ASSERT_TRUE(s.ok()) << s.ToString();
  }

  // A recording of `device` (distinct bytes each time) and its id.
  int64_t Put(const std::string& device) {
    const std::string data = "recording " + std::to_string(++puts_);  // r.data only views it
    NewRecording r;
    r.data = data;
    r.device = device;
    r.layout = "pca_averaged";
    r.rows = 3;
    RecordingInfo info;
    bool existed = false;
    Status s = store_->PutRecording(r, &info, &existed);
    EXPECT_TRUE(s.ok()) << s.ToString();
    return info.id;
  }

  // A succeeded pca job of `device` whose result the gate judged `verdict`.
  int64_t Succeeded(const std::string& device, const std::string& verdict) {
    JobInfo job;
    Status s = store_->EnqueueJob(Put(device), "pca", device, "{}", &job);
    EXPECT_TRUE(s.ok()) << s.ToString();
    JobInfo claimed;
    bool got = false;
    EXPECT_TRUE(store_->ClaimJob("w", 10000, &claimed, &got).ok());
    EXPECT_TRUE(got);
    EXPECT_EQ(claimed.id, job.id);
    clock_.Advance(1);
    s = store_->CompleteJob(
        job.id, "w",
        R"({"n":)" + std::to_string(job.id) + R"(,"verdict":{"status":")" + verdict + R"("}})");
    EXPECT_TRUE(s.ok()) << s.ToString();
    return job.id;
  }

  TempDir dir_;
  std::string target_;
  FakeClock clock_;
  std::unique_ptr<Store> store_;
  int puts_ = 0;
};

TEST_P(DevicePagesTest, PagesFollowTheLastSerialInByteOrderAndEndShort) {
  // Byte order: uppercase before lowercase, "SN-10" before "SN-2", UTF-8 after ASCII.
  const std::vector<std::string> serials = {"SN-2",
                                            "sn-1",
                                            "SN-10",
                                            "\xC3\x89"
                                            "CLAIR",
                                            "A",
                                            "SN-1"};
  for (const auto& s : serials) Put(s);
  const int64_t job = Succeeded("SN-10", "accepted");
  const std::vector<std::string> expected = {"A",
                                             "SN-1",
                                             "SN-10",
                                             "SN-2",
                                             "sn-1",
                                             "\xC3\x89"
                                             "CLAIR"};  // as bytes: C3 > 's'
  std::vector<std::string> got;
  DeviceFilter filter;
  filter.limit = 4;
  std::vector<DeviceInfo> page;
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  ASSERT_EQ(page.size(), 4u);
  for (const auto& d : page) got.push_back(d.serial);
  // The page carries each device's latest calibrations.
  ASSERT_EQ(page[2].serial, "SN-10");  // A, SN-1, SN-10, SN-2
  ASSERT_EQ(page[2].latest.size(), 1u);
  EXPECT_EQ(page[2].latest[0].job_id, job);
  filter.after = page.back().serial;
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  ASSERT_EQ(page.size(), 2u);  // shorter than the limit: the last page
  for (const auto& d : page) got.push_back(d.serial);
  EXPECT_EQ(got, expected);
  filter.after = page.back().serial;
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  EXPECT_TRUE(page.empty());
  // One device by its exact serial (no case folding), and every device page after page.
  DeviceFilter one;
  one.serial = "sn-1";
  ASSERT_TRUE(store_->ListDevices(one, &page).ok());
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].serial, "sn-1");
  one.serial = "SN-3";
  ASSERT_TRUE(store_->ListDevices(one, &page).ok());
  EXPECT_TRUE(page.empty());
  std::vector<DeviceInfo> all;
  ASSERT_TRUE(store_->ListDevices(&all).ok());
  ASSERT_EQ(all.size(), expected.size());
  EXPECT_EQ(all.back().serial, expected.back());
  // `from`: the cursor itself included (a range that starts at a prefix), or not there.
  filter = DeviceFilter();
  filter.after = "SN-1";
  filter.from = true;
  filter.limit = 2;
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  ASSERT_EQ(page.size(), 2u);
  EXPECT_EQ(page[0].serial, "SN-1");
  EXPECT_EQ(page[1].serial, "SN-10");
  filter.after = "SN-0";  // not a serial: from the next one
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  ASSERT_EQ(page.size(), 2u);
  EXPECT_EQ(page[0].serial, "SN-1");
  filter.from = false;
  filter.after = "SN-1";
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  ASSERT_EQ(page.size(), 2u);
  EXPECT_EQ(page[0].serial, "SN-10");
  // Limits are clamped: 0 is the default 100, 5000 is 1000.
  filter = DeviceFilter();
  filter.limit = 0;
  ASSERT_TRUE(store_->ListDevices(filter, &page).ok());
  EXPECT_EQ(page.size(), expected.size());
}

TEST_P(DevicePagesTest, VerdictListingReadsTheMatchingResultsNewestFirst) {
  std::vector<int64_t> revoked, rejected;
  for (int i = 0; i < 12; ++i) {
    const int64_t id =
        Succeeded("SN-" + std::to_string(i % 3), i % 4 == 0 ? "rejected" : "accepted");
    if (i % 4 == 0) rejected.push_back(id);
    if (i % 5 == 1) {
      ASSERT_TRUE(store_->RevokeJob(id, "bad fixture", "test").ok());
      revoked.push_back(id);
    }
  }
  JobFilter filter;
  filter.state = ServeState::kRevoked;
  filter.limit = 2;
  std::vector<int64_t> got;
  for (int pages = 0; pages < 5; ++pages) {
    std::vector<JobInfo> jobs;
    ASSERT_TRUE(store_->ListJobs(filter, &jobs).ok());
    for (const auto& j : jobs) {
      EXPECT_EQ(j.state, ServeState::kRevoked);
      got.push_back(j.id);
    }
    if (static_cast<int>(jobs.size()) < filter.limit) break;
    filter.before = jobs.back().id;
  }
  EXPECT_EQ(got, std::vector<int64_t>(revoked.rbegin(), revoked.rend()));
  int64_t count = 0;
  filter.before = 0;
  ASSERT_TRUE(store_->CountJobs(filter, &count).ok());
  EXPECT_EQ(count, static_cast<int64_t>(revoked.size()));
  filter.state = ServeState::kRejected;
  ASSERT_TRUE(store_->CountJobs(filter, &count).ok());
  EXPECT_EQ(count, static_cast<int64_t>(rejected.size()));
  // With a device too: only that device's.
  filter.device = "SN-0";
  filter.limit = 50;
  std::vector<JobInfo> jobs;
  ASSERT_TRUE(store_->ListJobs(filter, &jobs).ok());
  for (const auto& j : jobs) EXPECT_EQ(j.device, "SN-0");
  EXPECT_FALSE(jobs.empty());
  if (GetParam() != "sqlite") return;
  // SQLite: the verdict listing (the statements the store prepares) searches index
  // results_by_state, not every succeeded job. (PostgreSQL: pg_store_test.cc, on enough rows for
  // its planner to choose by the data.)
  store_.reset();
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open_v2(target_.c_str(), &db, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  auto plan = [&](const std::string& sql) {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db, ("EXPLAIN QUERY PLAN " + sql).c_str(), -1, &st, nullptr),
              SQLITE_OK)
        << sql;
    std::string text;
    while (sqlite3_step(st) == SQLITE_ROW) {
      text += reinterpret_cast<const char*>(sqlite3_column_text(st, 3));
      text += "\n";
    }
    sqlite3_finalize(st);
    return text;
  };
  JobFilter by_state;
  by_state.state = ServeState::kRevoked;
  by_state.include_results = true;
  for (const int64_t before : {int64_t{0}, int64_t{7}}) {
    by_state.before = before;
    const std::string list = plan(sqlite::ListJobsSql(by_state));
    EXPECT_NE(list.find("results_by_state"), std::string::npos) << list;
    EXPECT_EQ(list.find("TEMP B-TREE"), std::string::npos) << list;  // in order, no sort
  }
  const std::string counting = plan(sqlite::CountJobsSql(by_state));
  EXPECT_NE(counting.find("results_by_state"), std::string::npos) << counting;
  sqlite3_close(db);
}

INSTANTIATE_TEST_SUITE_P(Backends, DevicePagesTest, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           return info.param;
                         });

}  // namespace
}  // namespace calibd::storage
