// Failure reasons (server/failure_reasons.h): the catalog is complete, every method's failures
// carry their reason and partial diagnostics, offline and through a real server (API JSON and
// the job page).
#include "server/failure_reasons.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/imu_simulation.h"
#include "core/noise.h"
#include "core/pca.h"
#include "core/pca_simulation.h"
#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "methods/pca/pca_method.h"
#include "methods/registry.h"
#include "server/config.h"
#include "tests/lib/test_paths.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;

bool IsSnakeCase(const std::string& s) {
  if (s.empty() || s.front() < 'a' || s.front() > 'z' || s.back() == '_') return false;
  for (char c : s) {
    if (!((c >= 'a' && c <= 'z') || c == '_')) return false;
  }
  return true;
}

TEST(FailureReasons, EveryEntryHasAUniqueSnakeCaseCodeATitleAndAdvice) {
  // Reasons are an open set (generic in base/status.h, a method's own beside its numerics);
  // scripts/check_structure.py checks that every reason defined in product code has an entry.
  std::set<std::string> codes;
  for (const FailureReason& e : AllFailureReasons()) {
    EXPECT_STREQ(e.code, e.reason.code());
    EXPECT_TRUE(IsSnakeCase(e.code)) << e.code;
    EXPECT_GE(std::string(e.title).size(), 5u) << e.code;
    EXPECT_GE(std::string(e.advice).size(), 20u) << e.code;
    EXPECT_TRUE(codes.insert(e.code).second) << "duplicate code " << e.code;
    EXPECT_EQ(FindFailureReason(e.code), &e);
    EXPECT_EQ(&DescribeReason(e.reason), &e);
  }
  EXPECT_EQ(FindFailureReason("no_such_reason"), nullptr);
  EXPECT_STREQ(DescribeReason(Reason::kUnspecified).code, "internal");
  EXPECT_STREQ(DescribeReason(Reason("no_such_reason")).code, "internal");
}

TEST(FailureReasons, EveryMethodsOwnReasonsAreInTheCatalog) {
  size_t own = 0;
  for (const Method* m : AllMethods()) {
    for (const FailureReason& r : m->FailureReasons()) {
      ++own;
      const FailureReason* e = FindFailureReason(r.code);
      ASSERT_NE(e, nullptr) << m->name() << ": " << r.code;
      EXPECT_STREQ(e->title, r.title);
    }
  }
  EXPECT_GT(own, 0u);
  EXPECT_EQ(DescribeReason(core::pca_reason::kNoRankGap).reason, core::pca_reason::kNoRankGap);
  EXPECT_EQ(DescribeReason(core::noise_reason::kNotStationary).reason,
            core::noise_reason::kNotStationary);
}

TEST(FailureReasons, TheReadmeDocumentsEveryCode) {
  std::ifstream in(calibd::test_paths::SourceDir() + "/README.md");
  ASSERT_TRUE(in);
  const std::string readme((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t section = readme.find("### Failure reasons");
  ASSERT_NE(section, std::string::npos);
  const std::string text = readme.substr(section, readme.find("\n## ", section) - section);
  for (const FailureReason& r : AllFailureReasons()) {
    EXPECT_NE(text.find(std::string("`") + r.code + "`"), std::string::npos)
        << r.code << " is not in README's Failure reasons";
  }
}

TEST(FailureReasons, AStatusWithoutAReasonGetsOneFromItsCode) {
  EXPECT_EQ(ReasonOf(Status::InvalidInput("x")), Reason::kInvalidRecording);
  EXPECT_EQ(ReasonOf(Status::NotDeterminable("x")), Reason::kNotDeterminable);
  EXPECT_EQ(ReasonOf(Status::IoError("x")), Reason::kStorageError);
  EXPECT_EQ(ReasonOf(Status::Internal("x")), Reason::kInternal);
  EXPECT_EQ(ReasonOf(Status::NotDeterminable(Reason::kTooFewPositions, "x")),
            Reason::kTooFewPositions);
  // Failures stored before reasons were: from their error code.
  EXPECT_STREQ(StoredFailureReason("", "lease_expired").code, "lease_expired");
  EXPECT_STREQ(StoredFailureReason("", "not_determinable").code, "not_determinable");
  EXPECT_STREQ(StoredFailureReason("too_few_statics", "not_determinable").code, "too_few_statics");
  EXPECT_STREQ(StoredFailureReason("from_a_newer_calibd", "invalid_input").code,
               "invalid_recording");
}

TEST(PartialDiagnostics, OverTheCapTheLargestAreLeftOutAndNamed) {
  json result = {
      {"method", "noise"},
      {"usable", false},
      {"diagnostics",
       {{"rate", 100}, {"allan", std::string(5000, 'x')}, {"channels", std::string(2000, 'y')}}}};
  EXPECT_EQ(PartialDiagnosticsText(result, 1 << 20), result.dump());
  const std::string text = PartialDiagnosticsText(result, 3000);
  ASSERT_LE(text.size(), 3000u);
  const json kept = json::parse(text);
  EXPECT_EQ(kept["diagnostics"]["rate"], 100);
  EXPECT_FALSE(kept["diagnostics"].contains("allan"));
  EXPECT_EQ(kept["diagnostics"]["channels"], std::string(2000, 'y'));
  EXPECT_EQ(kept["trimmed"]["dropped"], json::array({"allan"}));
  EXPECT_EQ(kept["trimmed"]["bytes"], result.dump().size());
  // Not even that: only the method, usable and the note are kept.
  const json bare = json::parse(PartialDiagnosticsText(result, 10));
  EXPECT_EQ(bare["method"], "noise");
  EXPECT_FALSE(bare.contains("diagnostics"));
  EXPECT_TRUE(bare.contains("trimmed"));
  EXPECT_EQ(PartialDiagnosticsText(json(), 100), "");
  EXPECT_EQ(PartialDiagnosticsText(json::object(), 100), "");
}

// A complete result whose storing failed (the store busy, retries exhausted) or whose gate threw
// is not "before the failure": the failed job keeps no diagnostics rather than a usable result
// with parameters and an accepted verdict.
TEST(PartialDiagnostics, OnlyARunsOwnNotUsableDocumentIsKept) {
  json complete = {{"method", "pca"},
                   {"usable", true},
                   {"parameters", {{"sensors", json::array()}}},
                   {"verdict", {{"status", "accepted"}}}};
  EXPECT_EQ(PartialDiagnosticsText(complete, 1 << 20), "");
  complete.erase("usable");
  EXPECT_EQ(PartialDiagnosticsText(complete, 1 << 20), "");
  complete["usable"] = "false";
  EXPECT_EQ(PartialDiagnosticsText(complete, 1 << 20), "");
  const json partial = {{"method", "pca"}, {"usable", false}, {"diagnostics", json::object()}};
  EXPECT_EQ(PartialDiagnosticsText(partial, 1 << 20), partial.dump());
}

// ----- One failing recording per method.

struct Failing {
  std::string csv;
  json config;
};

// pca: positions whose field lies in one plane: the readings (rounded to 6 decimals, so not
// exactly of rank 2) show no gap between singular values 3 and 4.
Failing CoplanarPca() {
  const core::PcaSimulationOptions options;
  Failing f;
  std::string unused_csv;
  json truth;
  EXPECT_TRUE(SimulatePcaFiles(options, &unused_csv, &f.config, &truth).ok());
  const core::PcaSimulation sim = core::SimulatePca(options);
  Eigen::MatrixXd v = sim.v;
  v.row(2).setZero();
  const Eigen::MatrixXd m = sim.a_true.transpose() * v;
  f.csv = "position";
  for (const std::string& name : sim.sensor_names) f.csv += "," + name;
  f.csv += "\n";
  for (Eigen::Index j = 0; j < m.cols(); ++j) {
    f.csv += "p" + std::to_string(j + 1);
    for (Eigen::Index i = 0; i < m.rows(); ++i) f.csv += "," + std::to_string(m(i, j));
    f.csv += "\n";
  }
  return f;
}

// imu: 5 statics where at least 9 are needed.
Failing FewStaticsImu() {
  core::ImuSimulationOptions sim;
  sim.statics = 5;
  Failing f;
  json truth;
  EXPECT_TRUE(SimulateImuFiles(sim, &f.csv, &f.config, &truth).ok());
  return f;
}

// noise: a minute at rest at 100 Hz whose a0_x jumps by 1 m/s² halfway.
Failing MovedNoise() {
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 60;
  Failing f;
  json truth;
  EXPECT_TRUE(SimulateNoiseFiles(sim, &f.csv, &f.config, &truth).ok());
  // Rewrite the data rows: the column after t (a0_x) gets +1 from the middle on.
  std::string out;
  size_t pos = 0, row = 0;
  const size_t rows = static_cast<size_t>(sim.rate * sim.seconds);
  while (pos < f.csv.size()) {
    size_t end = f.csv.find('\n', pos);
    if (end == std::string::npos) end = f.csv.size();
    std::string line = f.csv.substr(pos, end - pos);
    pos = end + 1;
    if (!line.empty() && line[0] != '#' && line[0] != 't') {
      if (row++ >= rows / 2) {
        const size_t c1 = line.find(','), c2 = line.find(',', c1 + 1);
        const double a = std::stod(line.substr(c1 + 1, c2 - c1 - 1)) + 1.0;
        line = line.substr(0, c1 + 1) + std::to_string(a) + line.substr(c2);
      }
    }
    out += line + "\n";
  }
  f.csv = out;
  return f;
}

// array: only 2 samples where 3 are needed.
Failing TwoSampleArray() {
  ArraySimulationFileOptions sim;
  sim.samples = 2;
  Failing f;
  json truth;
  EXPECT_TRUE(SimulateArrayFiles(sim, &f.csv, &f.config, &truth).ok());
  return f;
}

struct Case {
  const char* name;
  Failing (*make)();
  const char* reason;
  // A key of the partial diagnostics (a JSON pointer into the result) that must be there.
  const char* partial_key;
  // A fragment the failed job page shows from the method's partial report.
  const char* page_fragment;
};

const Case kCases[] = {
    {"pca", &CoplanarPca, "no_rank_gap", "/diagnostics/singular_values", "plot-singular-values"},
    {"imu", &FewStaticsImu, "too_few_statics", "/diagnostics/imus/0/coverage/verdict",
     "plot-imu-statics-found"},
    {"noise", &MovedNoise, "not_stationary", "/diagnostics/channels/0/status",
     "table-noise-channels"},
    {"array", &TwoSampleArray, "too_few_samples", "/diagnostics/samples", "partial-array"},
};

TEST(FailureReasons, EveryMethodsFailureCarriesItsReasonAndPartialDiagnostics) {
  for (const Case& c : kCases) {
    SCOPED_TRACE(c.name);
    const Failing f = c.make();
    json result;
    const Status s = Calibrate(f.csv, "recording.csv", f.config, &result);
    ASSERT_FALSE(s.ok());
    EXPECT_STREQ(DescribeReason(ReasonOf(s)).code, c.reason) << s.ToString();
    EXPECT_EQ(result.value("method", ""), c.name) << result.dump();
    EXPECT_EQ(result.value("usable", true), false);
    EXPECT_TRUE(result.contains(json::json_pointer(c.partial_key))) << result.dump();
    EXPECT_FALSE(result.contains("parameters")) << "a failed run has no parameters";
    if (std::string(c.name) == "pca") {
      // The config has a nominal: the coverage, seen through it, names the missing directions.
      EXPECT_EQ(result["diagnostics"]["coverage"]["verdict"], "poor") << result.dump();
      EXPECT_NE(result["diagnostics"]["coverage"]["advice"].get<std::string>().find("z"),
                std::string::npos);
    }
  }
}

// More failures driven offline, each with the reason its site names.
TEST(FailureReasons, DrivenFailuresCarryTheReasonOfTheirSite) {
  const json pca = {{"method", "pca"}};
  std::string few_positions = "position,s1,s2,s3\n";
  for (int j = 0; j < 4; ++j) few_positions += "p" + std::to_string(j) + ",1,0.5,0.25\n";
  std::string zeros = "position,s1,s2,s3,s4\n";
  for (int j = 0; j < 12; ++j) zeros += "p" + std::to_string(j) + ",0,0,0,0\n";
  std::string short_noise = "t,a0_x,a0_y,a0_z\n";
  for (int i = 0; i < 100; ++i) short_noise += std::to_string(i * 0.01) + ",0.1,0.2,9.8\n";
  NoiseSimulationFileOptions sim;
  sim.rate = 100;
  sim.seconds = 60;
  std::string unused_csv;
  json noise, truth;
  ASSERT_TRUE(SimulateNoiseFiles(sim, &unused_csv, &noise, &truth).ok());
  // imu: every rotation between the 12 statics exceeds the gyroscope's range (0.2 rad/s).
  core::ImuSimulationOptions imu_sim;
  imu_sim.statics = 12;
  std::string fast_rotations;
  json imu;
  ASSERT_TRUE(SimulateImuFiles(imu_sim, &fast_rotations, &imu, &truth).ok());
  imu["gyro_saturation"] = 0.2;
  const struct {
    std::string csv;
    json config;
    const char* reason;
  } cases[] = {
      {few_positions, pca, "too_few_positions"},
      {"position,s1,s2\np1,1,0\np2,0,1\np3,1,1\np4,1,2\np5,2,1\np6,3,1\np7,1,3\n", pca,
       "too_few_sensors"},
      {zeros, pca, "no_signal"},
      {few_positions, {{"method", "pca"}, {"colour", "red"}}, "invalid_config"},
      {"position,s1,s2,s3\np1,1,0\n", pca, "recording_unreadable"},
      {short_noise, noise, "log_too_short"},
      {fast_rotations, imu, "too_few_rotations"},
  };
  for (const auto& c : cases) {
    json result;
    const Status s = Calibrate(c.csv, "recording.csv", c.config, &result);
    ASSERT_FALSE(s.ok()) << c.reason;
    EXPECT_STREQ(DescribeReason(ReasonOf(s)).code, c.reason) << s.ToString();
  }
}

// array with model full, cut short: the first 199 rows hold too few statics; the first 1999
// have them but too little rotation. The partial result says what the model found.
TEST(FailureReasons, TheFullArrayModelCutShortFailsWithItsReasonAndPartialDiagnostics) {
  ArraySimulationFileOptions sim;
  sim.samples = 400;
  sim.seed = 3;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulateArrayFullFiles(sim, &csv, &config, &truth).ok());
  auto head = [&](int lines) {
    size_t at = 0;
    for (int i = 0; i < lines && at != std::string::npos; ++i) at = csv.find('\n', at + 1);
    return csv.substr(0, at + 1);
  };
  for (const auto& [lines, reason] : std::vector<std::pair<int, std::string>>{
           {200, "too_few_statics"}, {2000, "weak_excitation"}}) {
    json result;
    const Status s = Calibrate(head(lines), "full.csv", config, &result);
    ASSERT_FALSE(s.ok()) << lines;
    EXPECT_EQ(DescribeReason(ReasonOf(s)).code, reason) << s.ToString();
    EXPECT_EQ(result["diagnostics"]["model"], "full") << result.dump();
    EXPECT_EQ(result["usable"], false);
    EXPECT_TRUE(result["diagnostics"].contains("static_samples"));
  }
}

TEST(FailureReasons, AFailedUploadShowsReasonAdviceAndPartialDiagnosticsInTheApiAndOnThePage) {
  testing::TestServer server;
  ASSERT_EQ(server.error(), "");
  // The OpenAPI document lists every reason code.
  auto openapi = server.Client().Get("/api/v1/openapi.json");
  ASSERT_TRUE(openapi);
  const json doc = json::parse(openapi->body);
  const json& schema = doc["components"]["schemas"]["JobFailure"];
  EXPECT_EQ(schema["properties"]["reason"]["enum"].size(), AllFailureReasons().size());
  for (const FailureReason& r : AllFailureReasons()) {
    EXPECT_NE(schema.dump().find(std::string("\"") + r.code + "\""), std::string::npos) << r.code;
  }
  for (const Case& c : kCases) {
    SCOPED_TRACE(c.name);
    const Failing f = c.make();
    const json job = server.UploadAndWait(f.csv, f.config);
    ASSERT_EQ(job.value("status", ""), "failed") << job.dump();
    const json& error = job["error"];
    const FailureReason* reason = FindFailureReason(c.reason);
    ASSERT_NE(reason, nullptr);
    EXPECT_EQ(error["code"], "not_determinable");
    EXPECT_EQ(error["reason"], c.reason);
    EXPECT_EQ(error["title"], reason->title);
    EXPECT_EQ(error["advice"], reason->advice);
    EXPECT_FALSE(error["message"].get<std::string>().empty());
    ASSERT_TRUE(error["diagnostics"].is_object()) << error.dump();
    EXPECT_EQ(error["diagnostics"]["usable"], false);
    EXPECT_TRUE(error["diagnostics"].contains(json::json_pointer(c.partial_key)))
        << error["diagnostics"].dump();
    // Lists carry the reason but not the diagnostics.
    auto list = server.Client().Get("/api/v1/jobs?status=failed&limit=50");
    ASSERT_TRUE(list);
    bool listed = false;
    const json jobs = json::parse(list->body);
    for (const json& j : jobs["jobs"]) {
      if (j["id"] != job["id"]) continue;
      listed = true;
      EXPECT_EQ(j["error"]["reason"], c.reason);
      EXPECT_TRUE(j["error"]["diagnostics"].is_null());
    }
    EXPECT_TRUE(listed);
    // The page: title, message, advice once, and the method's partial report.
    auto page = server.Client().Get(("/jobs/" + job["id"].dump()).c_str());
    ASSERT_TRUE(page);
    ASSERT_EQ(page->status, 200);
    const std::string& html = page->body;
    EXPECT_NE(html.find(reason->title), std::string::npos);
    EXPECT_NE(html.find(c.reason), std::string::npos);
    EXPECT_NE(html.find("failure-advice"), std::string::npos);
    EXPECT_NE(html.find("id=\"partial\""), std::string::npos);
    EXPECT_NE(html.find(c.page_fragment), std::string::npos) << html;
    EXPECT_NE(html.find("id=\"diagnostics\""), std::string::npos);
    // The failure is counted by its reason.
    auto metrics = server.Client().Get("/api/v1/metrics");
    ASSERT_TRUE(metrics);
    EXPECT_NE(metrics->body.find(std::string("calibd_job_failures_total{method=\"") + c.name +
                                 "\",reason=\"" + c.reason + "\"} 1"),
              std::string::npos)
        << metrics->body;
    // Title, message and advice are each said once (the partial diagnostics do not repeat the
    // message; the beginnings are compared, free of characters the page escapes).
    const std::string message = error["message"].get<std::string>().substr(0, 30);
    const std::string advice = std::string(reason->advice).substr(0, 30);
    for (const std::string& once : {std::string(reason->title), message, advice}) {
      const size_t at = html.find(once);
      ASSERT_NE(at, std::string::npos) << once;
      EXPECT_EQ(html.find(once, at + 1), std::string::npos) << once << " is said twice";
    }
  }
}

TEST(FailureReasons, CalibrateOnTheCommandLinePrintsTheReasonAndItsAdvice) {
  testing::TempDir dir;
  const Failing f = FewStaticsImu();
  const std::string csv = (dir.path() / "imu.csv").string();
  const std::string config = (dir.path() / "config.json").string();
  std::ofstream(csv) << f.csv;
  std::ofstream(config) << f.config.dump();
  FILE* pipe = ::popen((calibd::test_paths::CalibdBinary() + " calibrate " + csv + " --config " +
                        config + " 2>&1 >/dev/null")
                           .c_str(),
                       "r");
  ASSERT_NE(pipe, nullptr);
  std::string err;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, pipe)) > 0) err.append(buf, n);
  const int status = ::pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3) << err;  // not determinable
  const FailureReason* reason = FindFailureReason("too_few_statics");
  ASSERT_NE(reason, nullptr);
  EXPECT_NE(err.find("found 5 static intervals"), std::string::npos) << err;
  EXPECT_NE(err.find(std::string("calibd: reason: too_few_statics (") + reason->title + ")"),
            std::string::npos)
      << err;
  EXPECT_NE(err.find(std::string("calibd: advice: ") + reason->advice), std::string::npos) << err;
}

}  // namespace
}  // namespace calibd::server
