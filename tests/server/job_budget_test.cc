// The memory budget per job (server/job_budget.h) through a real server: a job that would not
// fit is refused at once with 422 and the reason, before anything is stored or computed; the
// same recording fits a larger budget; a job queued under a larger budget is failed by the
// worker with the same reason instead of running.
#include "server/job_budget.h"

#include <gtest/gtest.h>

#include <string>

#include "methods/array/array_method.h"
#include "methods/registry.h"
#include "storage/store.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::TestServer;

struct ArrayUpload {
  std::string csv;
  json config;
};

// The paper's 32-IMU array with 400 samples: 400 rows x 193 columns.
ArrayUpload SmallArray() {
  ArraySimulationFileOptions o;
  o.samples = 400;
  o.seed = 5;
  ArrayUpload u;
  json truth;
  EXPECT_TRUE(SimulateArrayFiles(o, &u.csv, &u.config, &truth).ok());
  return u;
}

httplib::Result Upload(const TestServer& server, const ArrayUpload& u, bool with_method) {
  json config = u.config;
  if (!with_method) config = json::object();
  config["device"] = "BUDGET-1";
  return server.Client().Post(
      "/api/v1/recordings",
      httplib::MultipartFormDataItems{{"recording", u.csv, "r.csv", "text/csv"},
                                      {"config", config.dump(), "", "application/json"}});
}

TEST(JobBudget, EstimateGrowsWithTheRecordingAndTheMethodsPeak) {
  const Method& array = *FindMethod("array");
  const json config = {{"method", "array"}};
  const int64_t small = EstimateJobBytes(array, {1000, 193}, config);
  const int64_t large = EstimateJobBytes(array, {100000, 193}, config);
  // Linear in the values beyond the fixed allowance, at the method's bytes per value.
  EXPECT_NEAR(static_cast<double>(large - small),
              (100000.0 - 1000.0) * 193 * array.PeakBytesPerValue(config), 1.0);
  EXPECT_GE(array.PeakBytesPerValue(config), 8.0);  // at least the parser's doubles
  EXPECT_TRUE(CheckJobBudget(array, {100000, 193}, config, 0).ok());  // no budget
  EXPECT_TRUE(CheckJobBudget(array, {100000, 193}, config, large).ok());
  const Status s = CheckJobBudget(array, {100000, 193}, config, large - 1);
  EXPECT_EQ(s.code(), StatusCode::kNotDeterminable);
  EXPECT_EQ(s.field(), "job_memory");
  EXPECT_NE(s.message().find("100000 rows x 193 columns"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("--job-memory-bytes"), std::string::npos) << s.message();
}

TEST(JobBudget, ATwoHourNoiseLogFitsTheSmallestDefaultBudget) {
  // The noise job holds its samples as float (4 B), t as double and one channel's cumulative sum
  // (double): (6 · 4 + 8 + 8) / 7 bytes per value of a 6-channel log with t, plus what the
  // server holds anyway (bench/README.md measures 127 MiB for 2 h at 400 Hz, 6.6 B a value).
  const Method& noise = *FindMethod("noise");
  const json config = {{"method", "noise"}};
  EXPECT_GE(noise.PeakBytesPerValue(config), (6.0 * 4 + 8 + 8) / 7);
  EXPECT_LE(noise.PeakBytesPerValue(config), 8.0);  // the whole server: not the values as doubles
  const RecordingShape two_hours{7200 * 400, 7};
  EXPECT_TRUE(CheckJobBudget(noise, two_hours, config, 256 << 20).ok());
  EXPECT_EQ(CheckJobBudget(noise, two_hours, config, 128 << 20).code(),
            StatusCode::kNotDeterminable);
}

TEST(JobBudget, DefaultSharesHalfTheMemoryAmongTheWorkersWithinBounds) {
  const int64_t one = DefaultJobMemoryBytes(1);
  const int64_t many = DefaultJobMemoryBytes(1000);
  EXPECT_GE(one, int64_t{256} << 20);
  EXPECT_LE(one, int64_t{8} << 30);
  EXPECT_EQ(many, int64_t{256} << 20);  // the floor: no machine here has 500 GiB
  EXPECT_GE(one, DefaultJobMemoryBytes(2));
}

TEST(JobBudget, AnUploadWhoseJobWouldNotFitIsRefused422AndNothingIsStored) {
  ServeOptions options;
  options.job_memory_bytes = 20 << 20;  // 20 MiB: the fixed 16 MiB leaves ~4 MiB for values
  TestServer server(options);
  ASSERT_TRUE(server.error().empty()) << server.error();
  const ArrayUpload u = SmallArray();  // 400 x 193 x 24 B = 1.9 MB: fits
  auto fits = Upload(server, u, true);
  ASSERT_TRUE(fits);
  ASSERT_EQ(fits->status, 201) << fits->body;

  ArraySimulationFileOptions o;
  o.samples = 1200;  // 1200 x 193 x 24 B = 5.6 MB beyond the allowance: too large
  o.seed = 6;
  ArrayUpload big;
  json truth;
  ASSERT_TRUE(SimulateArrayFiles(o, &big.csv, &big.config, &truth).ok());
  auto refused = Upload(server, big, true);
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 422) << refused->body;
  const json error = json::parse(refused->body)["error"];
  EXPECT_EQ(error["field"], "job_memory");
  EXPECT_NE(error["message"].get<std::string>().find("1200 rows"), std::string::npos);
  // The refusal carries its failure reason and the catalog's advice (README "Failure reasons").
  EXPECT_EQ(error["reason"], "over_memory_budget");
  EXPECT_FALSE(error.value("advice", "").empty());
  // Nothing of the refused upload was kept: the same bytes uploaded without a method (no job,
  // nothing to budget) are new to the store.
  auto stored_only = Upload(server, big, false);
  ASSERT_TRUE(stored_only);
  ASSERT_EQ(stored_only->status, 201) << stored_only->body;
  const json recording = json::parse(stored_only->body)["recording"];
  EXPECT_EQ(recording["existed"], false);
  const int64_t id = recording["id"].get<int64_t>();
  // Rerunning the stored recording with a method is refused the same way.
  auto rerun = server.Client().Post("/api/v1/jobs",
                                    json{{"recording_id", id}, {"config", big.config}}.dump(),
                                    "application/json");
  ASSERT_TRUE(rerun);
  EXPECT_EQ(rerun->status, 422) << rerun->body;
  EXPECT_EQ(json::parse(rerun->body)["error"]["field"], "job_memory");
}

TEST(JobBudget, AJobQueuedUnderALargerBudgetIsFailedByTheWorkerWithTheReason) {
  testing::TempDir dir;
  const std::string db = (dir.path() / "calibd.db").string();
  ArraySimulationFileOptions o;
  o.samples = 1200;
  o.seed = 6;
  ArrayUpload big;
  json truth;
  ASSERT_TRUE(SimulateArrayFiles(o, &big.csv, &big.config, &truth).ok());
  int64_t job_id = 0;
  {
    // Queued by a server without a budget problem, which is stopped before its worker runs it.
    std::unique_ptr<storage::Store> store;
    ASSERT_TRUE(storage::Store::Open(db, {}, &store).ok());
    storage::NewRecording rec;
    rec.data = big.csv;
    rec.layout = "array";
    rec.rows = 1200;
    json columns = json::array();
    for (int i = 0; i < 193; ++i) columns.push_back("c" + std::to_string(i));
    rec.columns_json = columns.dump();
    rec.device = "BUDGET-2";
    rec.job = storage::NewJob{"array", "BUDGET-2", big.config.dump()};
    storage::RecordingInfo info;
    ASSERT_TRUE(store->PutRecording(rec, &info, nullptr).ok());
    ASSERT_TRUE(info.job.has_value());
    job_id = info.job->id;
  }
  ServeOptions options;
  options.job_memory_bytes = 20 << 20;
  TestServer server(options, db);
  ASSERT_TRUE(server.error().empty()) << server.error();
  const json job = server.WaitForJob(job_id);
  EXPECT_EQ(job["status"], "failed");
  EXPECT_NE(job["error"]["message"].get<std::string>().find("per-job memory budget"),
            std::string::npos)
      << job.dump();
  EXPECT_EQ(job["error"]["reason"], "over_memory_budget");
  EXPECT_TRUE(job["error"]["diagnostics"].is_null());  // refused before any numerics
  EXPECT_EQ(job["attempts"], 1);  // not retried: the same budget would refuse it again
}

}  // namespace
}  // namespace calibd::server
