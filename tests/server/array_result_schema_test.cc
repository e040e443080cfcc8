// The typed array result (methods/array/array_result.h) has every key the real adapter writes:
// results of RunArray on simulated recordings (both models, several option combinations, failing
// runs' partial documents) read with FromJson and write back with ToJson to exactly the same JSON.
#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <string>

#include "core/array_simulation.h"
#include "core/pca.h"
#include "formats/recording.h"
#include "methods/acceptance.h"
#include "methods/array/array_method.h"
#include "methods/array/array_result.h"
#include "methods/export_util.h"
#include "methods/pca/pca_method.h"
#include "methods/registry.h"
#include "tests/lib/array_csv.h"
#include "web/method_report.h"
#include "web/pages.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// FromJson(doc) succeeds, and ToJson of what it read is doc exactly.
void ExpectRoundTrip(const json& doc, bool usable, bool full) {
  results::ArrayResult r;
  const Status s = results::FromJson(doc, &r);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(r.envelope.usable, usable);
  EXPECT_EQ(r.full, full);
  EXPECT_EQ(doc["schema_version"], results::kArraySchemaVersion);
  const json back = results::ToJson(r);
  EXPECT_EQ(back, doc) << "adapter: " << doc.dump() << "\nround trip: " << back.dump();
}

// A real pca result (frame nominal) of the same simulated board's static recording.
json PcaOfTheBoard(const ArraySimulationFileOptions& so) {
  std::string csv;
  json config;
  EXPECT_TRUE(SimulateArrayStaticFiles(so, 30, &csv, &config).ok());
  RecordingParser parser("static.csv", true);
  EXPECT_TRUE(ParseRecording(csv, &parser).ok());
  PcaRecording rec;
  EXPECT_TRUE(parser.TakePca(&rec).ok());
  core::PcaOptions options;
  EXPECT_TRUE(ParsePcaConfig(config, &options).ok());
  json result;
  const Status s = RunPca(rec, options, &result);
  EXPECT_TRUE(s.ok()) << s.ToString();
  return result;
}

TEST(ArrayResultSchema, PositionsModelJointSolverRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 5;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["solver"], "joint");
  EXPECT_TRUE(result["diagnostics"]["accelerometer_calibration"].is_null());
  ExpectRoundTrip(result, true, false);
}

TEST(ArrayResultSchema, PositionsModelBcdWithCalibrationAndNoiseJobRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 6;
  so.gyro_unit = "deg/s";
  so.accel_bias = 0.05;
  so.accel_scale_error = 0.01;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  config["solver"] = "bcd";
  config["max_iterations"] = 30;
  config["gyro_noise"] = {{"job", 12}, {"sigma", 0.06 * core::kDegree}};  // resolved reference
  config["accelerometer_calibration"] = {{"job", 7}, {"result", PcaOfTheBoard(so)}};
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  const json& d = result["diagnostics"];
  EXPECT_EQ(d["solver"], "bcd");
  EXPECT_EQ(d["gyro_unit"], "deg/s");
  EXPECT_EQ(d["noise_jobs"]["gyroscope"], 12);
  EXPECT_EQ(d["accelerometer_calibration"]["job"], 7);
  ExpectRoundTrip(result, true, false);
}

TEST(ArrayResultSchema, PositionsModelFailingRunsPartialDocumentRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 2;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_EQ(s.code(), StatusCode::kNotDeterminable) << s.ToString();
  EXPECT_EQ(result["usable"], false);
  EXPECT_FALSE(result.contains("parameters"));
  ExpectRoundTrip(result, false, false);
}

TEST(ArrayResultSchema, FullModelRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 8;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["parameters"]["model"], "full");
  ExpectRoundTrip(result, true, true);
}

TEST(ArrayResultSchema, FullModelWithResidualAwareSigmaInDegreesRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 9;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  // A configured accelerometer noise a tenth of the true one: the residuals exceed it, so the
  // result carries the residual-aware σ (uncertainty.imus[].crb).
  config["accel_noise"] = so.accel_noise / 10;
  config["dynamic_weighting"] = "residual";
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_EQ(result["diagnostics"]["gyro_unit"], "deg/s");
  EXPECT_TRUE(result["diagnostics"]["robust"]["used"].get<bool>()) << result["diagnostics"].dump();
  EXPECT_EQ(result["uncertainty"]["basis"], "sandwich");
  EXPECT_TRUE(result["uncertainty"]["imus"][1].contains("crb"));
  ExpectRoundTrip(result, true, true);
}

TEST(ArrayResultSchema, FullModelFailingRunsPartialDocumentRoundTrips) {
  ArraySimulationFileOptions so;
  so.samples = 100;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  config["min_static"] = 100;  // s: no static of 1.5 s qualifies
  const Status s = RunArray(testing::ArrayRecordingFromCsv(csv), config, &result);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(result["usable"], false) << result.dump();
  EXPECT_EQ(result["diagnostics"]["model"], "full");
  ExpectRoundTrip(result, false, true);
}

// The exports read the result typed: the real adapter's result exports, a damaged one is an
// internal error naming the path of the problem.
TEST(ArrayResultSchema, ExportsReadTheTypedResultAndNameWhatDoesNotRead) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 5;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &result).ok());
  std::string out;
  ASSERT_TRUE(ArrayResultToCsv(result, &out).ok());
  EXPECT_EQ(out.substr(0, out.find('\n')),
            "name,x,y,z,offset_x,offset_y,offset_z,std_x,std_y,std_z");
  EXPECT_EQ(std::count(out.begin(), out.end(), '\n'), 33);  // header and 32 triads
  result["parameters"]["positions"][4]["offset"] = {1, 2};
  Status s = ArrayResultToCsv(result, &out);
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("parameters.positions[4].offset"), std::string::npos) << s.message();
  s = ArrayResultToHeader(result, {1, "D", "array", "2026-01-01T00:00:00Z"}, &out);
  EXPECT_EQ(s.code(), StatusCode::kConflict);
  EXPECT_NE(s.message().find("parameters.positions[4].offset"), std::string::npos) << s.message();
}

// ---- Results stored by an earlier calibd: only the SPEC's keys ----

// The paths SPEC requires of an array result ("[]": every element of an array): the envelope
// (§4), parameters, uncertainty and the diagnostics "at least" list of §4 (positions model), and
// for `model: full` §7's parameters.imus / uncertainty.imus (as for imu, plus position /
// position_std, the Cramér–Rao bound under crb with the same keys), its diagnostics.gauge,
// and the §4 diagnostics it has (solver, iterations, converged, cost, samples_dropped).
const std::set<std::string>& SpecPaths(bool full) {
  static const std::set<std::string> common = {"method",
                                               "model",
                                               "verdict.status",
                                               "verdict.reasons",
                                               "warnings",
                                               "parameters.reference",
                                               "diagnostics.solver",
                                               "diagnostics.iterations",
                                               "diagnostics.converged",
                                               "diagnostics.cost",
                                               "diagnostics.samples_dropped"};
  static const std::set<std::string> positions = [] {
    std::set<std::string> p = common;
    p.insert({"parameters.positions[].name", "parameters.positions[].position",
              "parameters.positions[].offset", "uncertainty.positions[].name",
              "uncertainty.positions[].std", "diagnostics.samples",
              "diagnostics.residual_rms.accelerometer", "diagnostics.residual_rms.gyroscope",
              "diagnostics.noise_estimate.accelerometer", "diagnostics.noise_estimate.gyroscope",
              "diagnostics.excitation.min_eigenvalue", "diagnostics.excitation.verdict"});
    return p;
  }();
  static const std::set<std::string> full_model = [] {
    std::set<std::string> p = common;
    p.insert({"parameters.imus[].name", "parameters.imus[].position", "uncertainty.imus[].name",
              "uncertainty.imus[].position_std", "uncertainty.imus[].crb.position_std",
              "diagnostics.gauge.scale"});
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const std::string s = sensor;
      for (const char* key : {"bias", "scale", "misalignment", "matrix"})
        p.insert("parameters.imus[]." + s + "." + key);
      for (const char* key : {"bias_std", "scale_std", "misalignment_std"}) {
        p.insert("uncertainty.imus[]." + s + "." + key);
        p.insert("uncertainty.imus[].crb." + s + "." + key);
      }
    }
    return p;
  }();
  return full ? full_model : positions;
}

// Removes from `j` (at `path`) every member that is neither a SPEC path nor on the way to one.
void StripToSpec(json* j, const std::string& path, const std::set<std::string>& spec) {
  if (j->is_array()) {
    for (json& e : *j) StripToSpec(&e, path + "[]", spec);
    return;
  }
  if (!j->is_object()) return;
  for (auto it = j->begin(); it != j->end();) {
    const std::string member = path.empty() ? it.key() : path + "." + it.key();
    bool keep = spec.count(member) > 0, descend = false;
    for (const std::string& p : spec) {
      if (p.compare(0, member.size() + 1, member + ".") == 0 ||
          p.compare(0, member.size() + 2, member + "[]") == 0)
        keep = descend = true;
    }
    if (!keep) {
      it = j->erase(it);
      continue;
    }
    if (descend && !spec.count(member)) StripToSpec(&it.value(), member, spec);
    ++it;
  }
}

bool Contains(const std::string& text, const std::string& needle) {
  return text.find(needle) != std::string::npos;
}

// `result` (the adapter's, of `config`) stripped to SPEC's keys reads, exports, is judged and
// renders.
void ExpectSpecOnlyResultServes(json result, const json& config) {
  const bool full = result["diagnostics"].contains("model");
  StripToSpec(&result, "", SpecPaths(full));
  ASSERT_FALSE(result.contains("schema_version"));
  ASSERT_FALSE(result["diagnostics"].contains("model")) << "model is not SPEC's";
  results::ArrayResult typed;
  const Status read = results::FromJson(result, &typed);
  ASSERT_TRUE(read.ok()) << read.message() << "\n" << result.dump();
  EXPECT_EQ(typed.full, full);

  std::string out;
  Status s = ArrayResultToCsv(result, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_FALSE(Contains(out, "nan")) << out;
  if (full) {  // the offsets are not SPEC's for model full: left empty, never 0
    EXPECT_TRUE(Contains(out.substr(out.find('\n')), ",,,")) << out;
  }
  // The C header: every value it writes is SPEC's (for model full the offsets from the nominal
  // are not, and are left out with a comment).
  s = ArrayResultToHeader(result, {1, "D", "array", "2026-01-01T00:00:00Z"}, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(Contains(out, "POSITION"));
  EXPECT_EQ(Contains(out, "OFFSET is not written"), full) << out;
  if (full) {
    EXPECT_TRUE(Contains(out, "ARRAY_ACCEL_MATRIX[")) << out;
  }

  Verdict verdict;
  JudgeArray(result, config, EffectiveAcceptance("array", json(), config), &verdict);
  for (const std::string& reason : verdict.reasons())
    EXPECT_FALSE(Contains(reason, "cannot be judged")) << reason;

  const web::MethodReport* report = web::FindMethodReport("array");
  ASSERT_NE(report, nullptr);
  web::JobView view;
  view.job.id = 3;
  view.job.device = "D";
  view.job.method = "array";
  view.job.status = JobStatus::kSucceeded;
  view.job.result = result;
  view.config = config;
  const std::string section = report->Section(view);
  EXPECT_FALSE(Contains(section, "not available")) << section;
  EXPECT_FALSE(Contains(section, "nan")) << section;
  EXPECT_TRUE(Contains(section, "table-array-parameters"));
  // The offsets (for model full not SPEC's) against the config's geometry, not a dash.
  EXPECT_FALSE(Contains(section, "<dt>RMS offset from nominal</dt><dd>\xE2\x80\x93")) << section;
  if (full) {
    EXPECT_TRUE(Contains(section, "table-array-full-accelerometer"));
  }
  EXPECT_NE(report->KeyFigures(result), "");
}

TEST(ArrayResultSchema, PositionsResultWithOnlyTheSpecsKeysStillReadsExportsAndRenders) {
  ArraySimulationFileOptions so;
  so.samples = 300;
  so.seed = 6;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  config["gyro_noise"] = {{"job", 12}, {"sigma", 0.06 * core::kDegree}};
  config["accelerometer_calibration"] = {{"job", 7}, {"result", PcaOfTheBoard(so)}};
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &result).ok());
  ExpectSpecOnlyResultServes(result, config);
}

TEST(ArrayResultSchema, FullModelResultWithOnlyTheSpecsKeysStillReadsExportsAndRenders) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 9;
  so.gyro_unit = "deg/s";
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  config["accel_noise"] = so.accel_noise / 10;  // the residual-aware σ too (robust)
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &result).ok());
  ASSERT_EQ(result["uncertainty"]["basis"], "sandwich");
  ExpectSpecOnlyResultServes(result, config);
}

// The gate judges the offsets of a full-model result stored without parameters.positions (an
// extension) against the config's geometry: the same triads are too far as in the whole result.
TEST(ArrayResultSchema, GateJudgesTheOffsetsOfAFullResultWithoutPositionsAgainstTheGeometry) {
  ArraySimulationFileOptions so;
  so.samples = 400;
  so.seed = 8;
  std::string csv;
  json config, truth, result;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  ASSERT_TRUE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &result).ok());
  config["acceptance"] = {{"max_offset", 1e-9}};  // m: every free triad is farther
  const AcceptanceLimits limits = EffectiveAcceptance("array", json(), config);
  auto far_reason = [&](const json& doc) {
    Verdict verdict;
    JudgeArray(doc, config, limits, &verdict);
    for (const std::string& reason : verdict.reasons())
      if (Contains(reason, "from its nominal position")) return reason;
    return std::string();
  };
  const std::string whole = far_reason(result);
  ASSERT_NE(whole, "");
  json stripped = result;
  stripped["parameters"].erase("positions");
  stripped["uncertainty"].erase("positions");
  EXPECT_EQ(far_reason(stripped), whole);
}

// A failed run's partial document: every diagnostics member may be missing (the worker leaves
// out the largest over the size cap, or the whole object).
void ExpectPartialReadsAndRenders(const json& partial) {
  results::ArrayResult typed;
  const Status read = results::FromJson(partial, &typed);
  ASSERT_TRUE(read.ok()) << read.message() << "\n" << partial.dump();
  EXPECT_FALSE(typed.envelope.usable);
  web::JobView view;
  view.job.id = 4;
  view.job.method = "array";
  view.job.status = JobStatus::kFailed;
  view.job.error_detail = partial;
  const std::string html = web::FindMethodReport("array")->Partial(view);
  EXPECT_FALSE(Contains(html, "not available")) << html;
  EXPECT_TRUE(Contains(html, "partial-array")) << html;
}

TEST(ArrayResultSchema, PartialDocumentsWithDiagnosticsLeftOutStillRead) {
  ArraySimulationFileOptions so;
  so.samples = 2;
  std::string csv;
  json config, truth, positions, full;
  ASSERT_TRUE(SimulateArrayFiles(so, &csv, &config, &truth).ok());
  ASSERT_FALSE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &positions).ok());
  so.samples = 100;
  ASSERT_TRUE(SimulateArrayFullFiles(so, &csv, &config, &truth).ok());
  config["min_static"] = 100;
  ASSERT_FALSE(RunArray(testing::ArrayRecordingFromCsv(csv), config, &full).ok());
  for (const json& doc : {positions, full}) {
    ASSERT_EQ(doc["usable"], false);
    json empty = doc;
    empty["diagnostics"] = json::object();
    ExpectPartialReadsAndRenders(empty);
    json bare = {
        {"method", "array"}, {"usable", false}, {"trimmed", {{"dropped", {"diagnostics"}}}}};
    ExpectPartialReadsAndRenders(bare);
    for (const auto& item : doc["diagnostics"].items()) {
      json one = doc;
      one["diagnostics"].erase(item.key());
      SCOPED_TRACE(item.key());
      ExpectPartialReadsAndRenders(one);
    }
  }
  // Without samples the page shows a dash, not 0.
  json lacking = positions;
  lacking["diagnostics"].erase("samples");
  web::JobView view;
  view.job.error_detail = lacking;
  const std::string html = web::FindMethodReport("array")->Partial(view);
  EXPECT_TRUE(Contains(html, "<dt>usable samples</dt><dd>\xE2\x80\x93 (")) << html;
}

}  // namespace
}  // namespace calibd::server
