// The typed pca result (methods/pca/pca_result.h) holds every key the real adapter (RunPca) writes:
// ToJson(FromJson(j)) == j for results of simulated recordings under several option combinations
// and for a failed run's partial document.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "core/pca_simulation.h"
#include "formats/recording.h"
#include "methods/acceptance.h"
#include "methods/exports.h"
#include "methods/pca/pca_method.h"
#include "methods/pca/pca_result.h"
#include "methods/registry.h"
#include "web/method_report.h"
#include "web/pages.h"

namespace calibd::server {
namespace {

using nlohmann::json;

PcaRecording Recording(const core::PcaSimulation& sim) {
  PcaRecording rec;
  rec.sensor_names = sim.sensor_names;
  rec.readings = sim.m;
  for (Eigen::Index j = 0; j < sim.m.cols(); ++j)
    rec.position_labels.push_back("p" + std::to_string(j + 1));
  return rec;
}

// Runs the adapter; the document must read and be written back unchanged.
json ExpectRoundTrip(const PcaRecording& rec, const core::PcaOptions& o, bool expect_ok,
                     results::PcaResult* typed) {
  json j;
  const Status s = RunPca(rec, o, &j);
  EXPECT_EQ(s.ok(), expect_ok) << s.message();
  const Status read = results::FromJson(j, typed);
  EXPECT_TRUE(read.ok()) << read.message();
  EXPECT_EQ(results::ToJson(*typed), j)
      << "written: " << results::ToJson(*typed).dump() << "\nadapter: " << j.dump();
  // The typed overload gives the same document.
  results::PcaResult direct;
  EXPECT_EQ(RunPca(rec, o, &direct).ok(), expect_ok);
  EXPECT_EQ(results::ToJson(direct), j);
  return j;
}

TEST(PcaResultSchema, CanonicalFrameUnknownMagnitudeRoundTrips) {
  core::PcaSimulationOptions so;
  so.positions = 30;
  const core::PcaSimulation sim = core::SimulatePca(so);
  results::PcaResult t;
  const json j = ExpectRoundTrip(Recording(sim), core::PcaOptions(), true, &t);
  ASSERT_TRUE(t.parameters.has_value());
  EXPECT_EQ(t.parameters->frame, results::PcaFrame::kCanonical);
  EXPECT_FALSE(t.parameters->magnitude_known);
  EXPECT_EQ(t.parameters->bias, results::PcaBias::kNone);
  EXPECT_EQ(t.parameters->sensors.size(), 12u);
  EXPECT_EQ(j["schema_version"], results::kPcaSchemaVersion);
}

TEST(PcaResultSchema, NominalFrameKnownMagnitudeWithBiasEstimationRoundTrips) {
  core::PcaSimulationOptions so;
  so.positions = 40;
  so.magnitude = 9.80665;
  so.bias_std = 0.05;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulatePcaFiles(so, &csv, &config, &truth).ok());
  RecordingParser parser("sim.csv", true);
  ASSERT_TRUE(ParseRecording(csv, &parser).ok());
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  core::PcaOptions o;
  ASSERT_TRUE(ParsePcaConfig(config, &o).ok());
  ASSERT_EQ(o.bias, core::BiasModel::kEstimate);
  results::PcaResult t;
  ExpectRoundTrip(rec, o, true, &t);
  ASSERT_TRUE(t.parameters.has_value());
  EXPECT_EQ(t.parameters->frame, results::PcaFrame::kNominal);
  EXPECT_TRUE(t.parameters->magnitude_known);
  EXPECT_EQ(t.parameters->bias, results::PcaBias::kEstimate);
  EXPECT_EQ(t.diagnostics.position_labels->size(), 40u);
}

TEST(PcaResultSchema, RefinedWithGivenNoiseAndRawLogRoundTrips) {
  core::PcaSimulationOptions so;
  so.positions = 25;
  const core::PcaSimulation sim = core::SimulatePca(so);
  PcaRecording rec = Recording(sim);
  // A raw log: the static means (b' per position) are reported as removed biases.
  rec.raw = true;
  rec.static_means = Eigen::MatrixXd::Constant(sim.m.rows(), sim.m.cols(), 0.25);
  for (Eigen::Index j = 0; j < sim.m.cols(); ++j) rec.static_means.col(j).array() += 0.001 * j;
  core::PcaOptions o;
  o.magnitude = 1.0;
  o.nominal = sim.a_model;
  o.refine = true;
  o.noise_std = so.noise_std;
  results::PcaResult t;
  ExpectRoundTrip(rec, o, true, &t);
  EXPECT_TRUE(t.diagnostics.refined);
  EXPECT_TRUE(t.diagnostics.noise_std_given);
  ASSERT_TRUE(t.diagnostics.removed_bias.has_value());
  EXPECT_EQ(t.diagnostics.removed_bias->size(), 12u);
  EXPECT_EQ(t.parameters->frame, results::PcaFrame::kNominal);
}

TEST(PcaResultSchema, FailedRunsPartialDocumentRoundTrips) {
  // Coplanar orientations: the fit fails; the partial diagnostics are kept.
  const core::PcaSimulation sim = core::SimulatePca(core::PcaSimulationOptions());
  Eigen::MatrixXd v = sim.v;
  v.row(2).setZero();
  PcaRecording rec = Recording(sim);
  rec.readings = sim.a_true.transpose() * v;
  results::PcaResult t;
  const json j = ExpectRoundTrip(rec, core::PcaOptions(), false, &t);
  EXPECT_FALSE(t.envelope.usable);
  EXPECT_FALSE(t.parameters.has_value());
  EXPECT_FALSE(j.contains("parameters"));
  EXPECT_FALSE(j.contains("model"));
  EXPECT_FALSE(j["diagnostics"].contains("reason"));
  EXPECT_FALSE(t.diagnostics.usable);
  EXPECT_EQ(t.diagnostics.positions, 100);
}

TEST(PcaResultSchema, TooFewPositionsWithNominalKeepsTheCoverageInThePartialDocument) {
  core::PcaSimulationOptions so;
  so.positions = 4;  // below d(d+1)/2 = 6
  const core::PcaSimulation sim = core::SimulatePca(so);
  core::PcaOptions o;
  o.nominal = sim.a_model;
  results::PcaResult t;
  const json j = ExpectRoundTrip(Recording(sim), o, false, &t);
  EXPECT_FALSE(t.envelope.usable);
  EXPECT_EQ(t.diagnostics.min_positions, 6);
  ASSERT_TRUE(t.diagnostics.coverage.has_value());
  EXPECT_NE(t.diagnostics.coverage->verdict, results::PcaCoverageVerdict::kUnknown) << j.dump();
}

// A real usable result of 30 random orientations (canonical frame).
json UsableResult() {
  core::PcaSimulationOptions so;
  so.positions = 30;
  json j;
  EXPECT_TRUE(RunPca(Recording(core::SimulatePca(so)), core::PcaOptions(), &j).ok());
  return j;
}

// A stored result this calibd cannot read is a conflict (409) with the reader's message, not an
// opaque 500: e.g. one written by a newer calibd sharing the database.
TEST(PcaResultSchema, ExportsOfAResultThatDoesNotReadAreAConflictNamingThePath) {
  json j = UsableResult();
  j["parameters"]["frame"] = "canonical */ int frame; /*";
  std::string out;
  const Status csv = PcaResultToCsv(j, &out);
  EXPECT_EQ(csv.code(), StatusCode::kConflict);
  EXPECT_NE(csv.message().find("pca result: parameters.frame: expected \"canonical\" or "
                               "\"nominal\""),
            std::string::npos)
      << csv.message();
  const Status h = PcaResultToHeader(j, {1, "SN-1", "pca", "2026-01-01T00:00:00Z"}, &out);
  EXPECT_EQ(h.code(), StatusCode::kConflict);
  EXPECT_NE(h.message().find("parameters.frame"), std::string::npos) << h.message();
  json newer = UsableResult();
  newer["schema_version"] = 2;
  const Status v = PcaResultToCsv(newer, &out);
  EXPECT_EQ(v.code(), StatusCode::kConflict);
  EXPECT_NE(v.message().find("schema_version: version 2 is newer than this calibd reads (up to 1)"),
            std::string::npos)
      << v.message();
  // The same result unchanged exports.
  EXPECT_TRUE(PcaResultToCsv(UsableResult(), &out).ok());
}

TEST(PcaResultSchema, ExportOfAFailedRunsPartialDocumentIsInternal) {
  const core::PcaSimulation sim = core::SimulatePca(core::PcaSimulationOptions());
  Eigen::MatrixXd v = sim.v;
  v.row(2).setZero();
  PcaRecording rec = Recording(sim);
  rec.readings = sim.a_true.transpose() * v;
  json partial;
  ASSERT_FALSE(RunPca(rec, core::PcaOptions(), &partial).ok());
  std::string out;
  const Status s = PcaResultToCsv(partial, &out);
  EXPECT_EQ(s.code(), StatusCode::kInternal);
  EXPECT_NE(s.message().find("no parameters"), std::string::npos) << s.message();
  // And the gate does not judge it.
  Verdict verdict;
  JudgePca(partial, json{{"method", "pca"}}, AcceptanceLimits(), &verdict);
  ASSERT_EQ(verdict.reasons().size(), 1u);
  EXPECT_NE(verdict.reasons()[0].find("cannot be judged: it is a failed run's partial"),
            std::string::npos)
      << verdict.reasons()[0];
}

TEST(PcaResultSchema, JudgeRejectsAResultThatDoesNotReadNamingThePath) {
  json j = UsableResult();
  j["uncertainty"]["sensors"][2]["axis_std_rad"] = "small";
  Verdict verdict;
  JudgePca(j, json{{"method", "pca"}}, AcceptanceLimits(), &verdict);
  ASSERT_EQ(verdict.reasons().size(), 1u);
  EXPECT_EQ(verdict.reasons()[0],
            "the result cannot be judged: pca result: uncertainty.sensors[2].axis_std_rad: "
            "expected a number, found a string");
  // Unchanged, with no limits, it is accepted.
  Verdict good;
  JudgePca(UsableResult(), json{{"method", "pca"}}, AcceptanceLimits(), &good);
  EXPECT_TRUE(good.accepted());
}

// ---- Results stored by an earlier calibd: only the keys SPEC requires ----

// The paths SPEC §4 requires of a pca result (the common envelope, "pca parameters",
// "uncertainty.sensors", the diagnostics "at least" list); "[]" stands for every element.
const std::set<std::string>& SpecPaths() {
  static const std::set<std::string> paths = {"method",
                                              "model",
                                              "verdict.status",
                                              "verdict.reasons",
                                              "warnings",
                                              "parameters.dimension",
                                              "parameters.magnitude",
                                              "parameters.magnitude_known",
                                              "parameters.frame",
                                              "parameters.sensors[].name",
                                              "parameters.sensors[].sensitivity",
                                              "parameters.sensors[].scale",
                                              "parameters.sensors[].axis",
                                              "parameters.sensors[].bias",
                                              "uncertainty.sensors[].name",
                                              "uncertainty.sensors[].scale_std",
                                              "uncertainty.sensors[].axis_std_rad",
                                              "uncertainty.sensors[].bias_std",
                                              "diagnostics.singular_values",
                                              "diagnostics.rank_gap",
                                              "diagnostics.positions",
                                              "diagnostics.min_positions",
                                              "diagnostics.g_eigenvalues",
                                              "diagnostics.residual_rms",
                                              "diagnostics.magnitude_error"};
  return paths;
}

// Removes, recursively, every member of `j` (at `path`) that is not a SPEC path nor on the way to
// one; the names removed go to `removed`.
void KeepSpecKeys(json* j, const std::string& path, std::set<std::string>* removed) {
  if (j->is_array()) {
    for (json& e : *j) KeepSpecKeys(&e, path + "[]", removed);
    return;
  }
  if (!j->is_object()) return;
  for (auto it = j->begin(); it != j->end();) {
    const std::string p = path.empty() ? it.key() : path + "." + it.key();
    bool keep = SpecPaths().count(p) > 0;
    bool inner = false;
    for (const std::string& s : SpecPaths()) {
      if (s.rfind(p + ".", 0) == 0 || s.rfind(p + "[].", 0) == 0) inner = true;
    }
    if (!keep && !inner) {
      removed->insert(p);
      it = j->erase(it);
      continue;
    }
    if (inner) KeepSpecKeys(&it.value(), p, removed);
    ++it;
  }
}

// A usable result as the server stores it (judged with the built-in limits), and the same with
// only SPEC's keys.
struct Stored {
  json full, spec_only;
  std::set<std::string> removed;
};
Stored StoredResult(const PcaRecording& rec, const core::PcaOptions& o, const json& config) {
  Stored s;
  EXPECT_TRUE(RunPca(rec, o, &s.full).ok());
  Verdict verdict;
  const AcceptanceLimits limits = EffectiveAcceptance("pca", json(), config);
  JudgePca(s.full, config, limits, &verdict);
  s.full["verdict"] = verdict.ToJson(limits);
  s.spec_only = s.full;
  KeepSpecKeys(&s.spec_only, "", &s.removed);
  return s;
}

// Judge, the exports and the web report on a result of an earlier calibd.
void ExpectReadsExportsAndRenders(const Stored& s, const json& config) {
  results::PcaResult typed;
  const Status read = results::FromJson(s.spec_only, &typed);
  ASSERT_TRUE(read.ok()) << read.message();
  EXPECT_EQ(typed.envelope.schema_version, 1);
  // The exports (csv and h, the method's formats) use only SPEC's keys: the same bytes.
  std::string csv, csv_full;
  ASSERT_TRUE(ResultToCsv(s.spec_only, &csv).ok()) << ResultToCsv(s.spec_only, &csv).message();
  ASSERT_TRUE(ResultToCsv(s.full, &csv_full).ok());
  EXPECT_EQ(csv, csv_full);
  const ExportContext context{4, "SN-7", "pca", "2026-01-01T00:00:00Z"};
  std::string h, h_full;
  const Status hs = ResultToHeader(s.spec_only, context, &h);
  ASSERT_TRUE(hs.ok()) << hs.message();
  ASSERT_TRUE(ResultToHeader(s.full, context, &h_full).ok());
  EXPECT_EQ(h, h_full);
  // Judge: a verdict, not "cannot be judged".
  Verdict verdict;
  JudgePca(s.spec_only, config, EffectiveAcceptance("pca", json(), config), &verdict);
  for (const std::string& reason : verdict.reasons()) {
    EXPECT_EQ(reason.find("cannot be judged"), std::string::npos) << reason;
  }
  // The web report: parameters and plots, no "not available"; key figures.
  const web::MethodReport* report = web::FindMethodReport("pca");
  ASSERT_NE(report, nullptr);
  web::JobView view;
  view.job.id = 4;
  view.job.device = "SN-7";
  view.job.method = "pca";
  view.job.status = JobStatus::kSucceeded;
  view.job.created_at = view.job.finished_at = "2026-01-01T00:00:00Z";
  view.job.result = s.spec_only;
  view.config = config;
  const std::string section = report->Section(view);
  EXPECT_EQ(section.find("not available"), std::string::npos) << section;
  EXPECT_NE(section.find("table-pca-parameters"), std::string::npos);
  EXPECT_NE(section.find("plot-singular-values"), std::string::npos);
  EXPECT_EQ(section.find("nan<"), std::string::npos);
  EXPECT_EQ(section.find("NaN"), std::string::npos);
  const std::string figures = report->KeyFigures(s.spec_only);
  EXPECT_EQ(figures, report->KeyFigures(s.full));
  EXPECT_NE(figures.find("gap"), std::string::npos) << figures;
  const std::string page = web::RenderJobPage(view);
  EXPECT_EQ(page.find("not available"), std::string::npos);
  // The device page's drift between an earlier calibd's result and a current one.
  web::DeviceView device;
  device.serial = "SN-7";
  view.job.state = ServeState::kAccepted;  // (also by an operator's accept, were it rejected)
  device.jobs = {view.job, view.job};
  device.jobs[1].id = 5;
  device.jobs[1].created_at = device.jobs[1].finished_at = "2026-02-01T00:00:00Z";
  device.jobs[1].result = s.full;
  const std::string drift = web::RenderDevicePage(device);
  EXPECT_NE(drift.find("table-drift-pca"), std::string::npos);
  EXPECT_EQ(drift.find("not available"), std::string::npos);
}

TEST(PcaResultCompat, AResultWithOnlyTheSpecsKeysStillReadsExportsAndRenders) {
  core::PcaSimulationOptions so;
  so.positions = 30;
  const json config = {{"method", "pca"}};
  const Stored s = StoredResult(Recording(core::SimulatePca(so)), core::PcaOptions(), config);
  // The extensions were there and are gone (the test strips what it means to).
  for (const char* p :
       {"schema_version", "verdict.limits", "parameters.bias", "uncertainty.noise_std",
        "diagnostics.coverage", "diagnostics.usable", "diagnostics.degrees_of_freedom",
        "diagnostics.cost", "diagnostics.position_labels"}) {
    EXPECT_EQ(s.removed.count(p), 1u) << p;
  }
  EXPECT_EQ(s.full["verdict"]["status"], "accepted") << s.full["verdict"].dump();
  ExpectReadsExportsAndRenders(s, config);
  // Nothing the gate judged needed an extension: the same verdict.
  Verdict verdict;
  JudgePca(s.spec_only, config, EffectiveAcceptance("pca", json(), config), &verdict);
  EXPECT_TRUE(verdict.accepted()) << verdict.reasons()[0];
}

TEST(PcaResultCompat, ANominalFrameBiasEstimateResultWithOnlyTheSpecsKeysStillWorks) {
  core::PcaSimulationOptions so;
  so.positions = 40;
  so.magnitude = 9.80665;
  so.bias_std = 0.05;
  std::string csv;
  json config, truth;
  ASSERT_TRUE(SimulatePcaFiles(so, &csv, &config, &truth).ok());
  RecordingParser parser("sim.csv", true);
  ASSERT_TRUE(ParseRecording(csv, &parser).ok());
  PcaRecording rec;
  ASSERT_TRUE(parser.TakePca(&rec).ok());
  core::PcaOptions o;
  ASSERT_TRUE(ParsePcaConfig(config, &o).ok());
  o.refine = true;
  const Stored s = StoredResult(rec, o, config);
  ASSERT_EQ(s.full["parameters"]["frame"], "nominal");
  ExpectReadsExportsAndRenders(s, config);
}

// A failed run's partial document: its diagnostics may lack any member, or all of them.
TEST(PcaResultCompat, PartialDocumentsWithDiagnosticsStrippedStillReadAndRender) {
  core::PcaSimulationOptions so;
  so.positions = 4;  // below d(d+1)/2 = 6
  const core::PcaSimulation sim = core::SimulatePca(so);
  core::PcaOptions o;
  o.nominal = sim.a_model;
  json partial;
  ASSERT_FALSE(RunPca(Recording(sim), o, &partial).ok());
  ASSERT_FALSE(partial["diagnostics"].empty());
  std::vector<json> documents;
  json empty = partial;
  empty["diagnostics"] = json::object();
  documents.push_back(empty);
  json none = partial;
  none.erase("diagnostics");
  documents.push_back(none);
  for (const auto& [key, value] : partial["diagnostics"].items()) {
    json one = partial;
    one["diagnostics"].erase(key);
    documents.push_back(one);
  }
  const web::MethodReport* report = web::FindMethodReport("pca");
  ASSERT_NE(report, nullptr);
  for (const json& j : documents) {
    results::PcaResult typed;
    const Status read = results::FromJson(j, &typed);
    EXPECT_TRUE(read.ok()) << read.message() << "\n" << j.dump();
    EXPECT_FALSE(typed.diagnostics.usable);
    web::JobView view;
    view.job.method = "pca";
    view.job.status = JobStatus::kFailed;
    view.job.error_detail = j;
    const std::string shown = report->Partial(view);
    EXPECT_EQ(shown.find("not available"), std::string::npos) << shown;
    EXPECT_NE(shown.find("positions n"), std::string::npos) << shown;
  }
  // Without the diagnostics: the counts are unknown ("—"), not -1.
  web::JobView view;
  view.job.error_detail = empty;
  EXPECT_EQ(report->Partial(view).find("-1"), std::string::npos) << report->Partial(view);
}

}  // namespace
}  // namespace calibd::server
