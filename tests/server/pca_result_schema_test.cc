// The typed pca result (results/pca_result.h) holds every key the real adapter (RunPca) writes:
// ToJson(FromJson(j)) == j for results of simulated recordings under several option combinations
// and for a failed run's partial document.
#include <gtest/gtest.h>

#include <string>

#include "core/pca_simulation.h"
#include "results/pca_result.h"
#include "server/acceptance.h"
#include "server/pca_method.h"
#include "server/recording.h"

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

TEST(PcaResultSchema, ExportsOfAResultThatDoesNotReadAreInternalNamingThePath) {
  json j = UsableResult();
  j["parameters"]["frame"] = "canonical */ int frame; /*";
  std::string out;
  const Status csv = PcaResultToCsv(j, &out);
  EXPECT_EQ(csv.code(), StatusCode::kInternal);
  EXPECT_NE(csv.message().find("pca result: parameters.frame: expected \"canonical\" or "
                               "\"nominal\""),
            std::string::npos)
      << csv.message();
  const Status h = PcaResultToHeader(j, {1, "SN-1", "pca", "2026-01-01T00:00:00Z"}, &out);
  EXPECT_EQ(h.code(), StatusCode::kInternal);
  EXPECT_NE(h.message().find("parameters.frame"), std::string::npos) << h.message();
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

}  // namespace
}  // namespace calibd::server
