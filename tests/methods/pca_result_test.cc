// The typed pca result (methods/pca/pca_result.h): round trip, the path of the first problem,
// schema versions and failed runs' partial documents.
#include "methods/pca/pca_result.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>

namespace calibd::results {
namespace {

using nlohmann::json;

PcaResult HandBuilt() {
  PcaResult r;
  r.envelope.method = "pca";
  r.envelope.model = "r_i = a_i^T v + b_i";
  r.envelope.warnings = {"one warning"};
  PcaParameters p;
  p.dimension = 2;
  p.magnitude = 9.80665;
  p.magnitude_known = true;
  p.frame = PcaFrame::kNominal;
  p.bias = PcaBias::kEstimate;
  p.sensors = {{"s0", {1.5, 0.25}, 1.52, {0.98, 0.16}, 0.01},
               {"s1", {-0.5, 2.0}, 2.06, {-0.24, 0.97}, -0.02}};
  r.parameters = p;
  PcaUncertainty u;
  u.sensors = {{"s0", 1e-4, 2e-3, 5e-5, PcaSensorStd::Bound{5e-5, 1e-3, 2.5e-5}},
               {"s1", kPcaNaN, 3e-3, 0.0, std::nullopt}};
  u.basis = "chi2_scaled";
  u.chi2_per_dof = 4.0;
  u.noise_std = 0.001;
  r.uncertainty = u;
  PcaDiagnostics& g = r.diagnostics;
  g.usable = true;
  g.singular_values = {10, 5, 0.01};
  g.rank_gap = 500;
  g.positions = 7;
  g.min_positions = 5;
  g.g_eigenvalues = {0.2, 0.5};
  g.residual_rms = {0.001, 0.0012};
  g.magnitude_error = {0.1, -0.1, kPcaNaN};
  g.degrees_of_freedom = 3;
  PcaCoverage& c = g.coverage.emplace();
  c.verdict = PcaCoverageVerdict::kPoor;
  c.scatter_eigenvalues = {0.1, 0.9};
  c.scatter_min = 0.2;
  c.design_min = 0.04;
  c.positions_per_direction = {{"+x", 3}, {"-x", 0}, {"+x+y", 4}};
  c.advice = "add positions with the -x axis up";
  g.noise_std = 0.001;
  g.noise_std_given = true;
  g.noise_std_estimated = 0.0011;
  g.cost_closed_form = 2e-5;
  g.cost = 1.9e-5;
  g.refined = true;
  g.refine_iterations = 4;
  g.reflection = true;
  g.position_labels = std::vector<std::string>{"p1", "p2", "p3"};
  g.removed_bias = std::vector<double>{0.5, kPcaNaN};
  return r;
}

TEST(PcaResult, HandBuiltRoundTripsExactly) {
  const PcaResult r = HandBuilt();
  const json j = ToJson(r);
  EXPECT_EQ(j["schema_version"], kPcaSchemaVersion);
  EXPECT_EQ(j["parameters"]["frame"], "nominal");
  EXPECT_EQ(j["parameters"]["bias"], "estimate");
  EXPECT_TRUE(j["uncertainty"]["sensors"][1]["scale_std"].is_null());  // NaN written as null
  EXPECT_TRUE(j["diagnostics"]["removed_bias"][1].is_null());
  EXPECT_EQ(j["diagnostics"]["coverage"]["positions_per_direction"]["+x+y"], 4);
  PcaResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  ASSERT_TRUE(back.parameters.has_value());
  EXPECT_EQ(back.parameters->frame, PcaFrame::kNominal);
  EXPECT_EQ(back.parameters->sensors[1].sensitivity, (std::vector<double>{-0.5, 2.0}));
  EXPECT_TRUE(std::isnan(back.uncertainty->sensors[1].scale_std));
  ASSERT_TRUE(back.diagnostics.coverage.has_value());
  EXPECT_EQ(back.diagnostics.coverage->verdict, PcaCoverageVerdict::kPoor);
  EXPECT_EQ(back.diagnostics.refine_iterations, 4);
  EXPECT_EQ(*back.diagnostics.position_labels, (std::vector<std::string>{"p1", "p2", "p3"}));
  EXPECT_EQ(ToJson(back), j);
}

TEST(PcaResult, OptionalDiagnosticsAreAbsentWhenUnset) {
  PcaResult r = HandBuilt();
  r.diagnostics.position_labels.reset();
  r.diagnostics.removed_bias.reset();
  const json j = ToJson(r);
  EXPECT_FALSE(j["diagnostics"].contains("position_labels"));
  EXPECT_FALSE(j["diagnostics"].contains("removed_bias"));
  EXPECT_FALSE(j["diagnostics"].contains("reason"));
  PcaResult back;
  ASSERT_TRUE(FromJson(j, &back).ok());
  EXPECT_FALSE(back.diagnostics.removed_bias.has_value());
  EXPECT_EQ(ToJson(back), j);
}

Status ReadModified(const std::function<void(json*)>& change) {
  json j = ToJson(HandBuilt());
  change(&j);
  PcaResult out;
  return FromJson(j, &out);
}

TEST(PcaResult, WrongTypeNamesThePath) {
  const Status s = ReadModified([](json* j) { (*j)["parameters"]["sensors"][1]["scale"] = "big"; });
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "parameters.sensors[1].scale");
  EXPECT_NE(s.message().find("pca result: parameters.sensors[1].scale"), std::string::npos)
      << s.message();
}

TEST(PcaResult, MissingSpecKeyNamesThePath) {
  const Status s = ReadModified([](json* j) { (*j)["diagnostics"].erase("magnitude_error"); });
  EXPECT_EQ(s.field(), "diagnostics.magnitude_error") << s.message();
  const Status t =
      ReadModified([](json* j) { (*j)["uncertainty"]["sensors"][0].erase("bias_std"); });
  EXPECT_EQ(t.field(), "uncertainty.sensors[0].bias_std") << t.message();
}

// Results stored by an earlier calibd lack the keys added since: they keep the struct's defaults.
TEST(PcaResult, AbsentExtensionsKeepTheirDefaults) {
  json j = ToJson(HandBuilt());
  j["parameters"].erase("bias");
  j["uncertainty"].erase("noise_std");
  j["uncertainty"].erase("basis");  // before the σ convention: the CRB only
  j["uncertainty"].erase("chi2_per_dof");
  j["uncertainty"]["sensors"][0].erase("crb");
  for (const char* key :
       {"usable", "degrees_of_freedom", "coverage", "noise_std", "noise_std_given",
        "noise_std_estimated", "cost_closed_form", "cost", "refined", "refine_iterations",
        "reflection", "position_labels", "removed_bias"}) {
    j["diagnostics"].erase(key);
  }
  PcaResult out;
  const Status s = FromJson(j, &out);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(out.parameters->bias, PcaBias::kNone);
  EXPECT_EQ(out.parameters->sensors[1].bias, -0.02);  // the SPEC keys are read
  EXPECT_TRUE(std::isnan(out.uncertainty->noise_std));
  EXPECT_EQ(out.uncertainty->basis, kPcaBasisCrbOnly);
  EXPECT_TRUE(std::isnan(out.uncertainty->chi2_per_dof));
  EXPECT_FALSE(out.uncertainty->sensors[0].crb.has_value());
  const PcaDiagnostics& g = out.diagnostics;
  EXPECT_TRUE(g.usable) << "absent: the envelope's usable";
  EXPECT_EQ(g.degrees_of_freedom, -1);
  EXPECT_FALSE(g.coverage.has_value());
  EXPECT_TRUE(std::isnan(g.noise_std));
  EXPECT_FALSE(g.noise_std_given);
  EXPECT_TRUE(std::isnan(g.noise_std_estimated));
  EXPECT_TRUE(std::isnan(g.cost_closed_form));
  EXPECT_TRUE(std::isnan(g.cost));
  EXPECT_FALSE(g.refined);
  EXPECT_EQ(g.refine_iterations, 0);
  EXPECT_FALSE(g.reflection);
  EXPECT_FALSE(g.position_labels.has_value());
  EXPECT_EQ(g.positions, 7);
  EXPECT_EQ(g.rank_gap, 500);
  // A coverage object of an earlier shape: its absent members keep their defaults too.
  json k = ToJson(HandBuilt());
  k["diagnostics"]["coverage"] = {{"verdict", "good"}};
  ASSERT_TRUE(FromJson(k, &out).ok()) << FromJson(k, &out).message();
  ASSERT_TRUE(out.diagnostics.coverage.has_value());
  EXPECT_EQ(out.diagnostics.coverage->verdict, PcaCoverageVerdict::kGood);
  EXPECT_TRUE(std::isnan(out.diagnostics.coverage->design_min));
  EXPECT_TRUE(out.diagnostics.coverage->positions_per_direction.empty());
}

TEST(PcaResult, PresentExtensionOfTheWrongTypeIsRefusedNamingThePath) {
  Status s = ReadModified([](json* j) { (*j)["diagnostics"]["coverage"]["design_min"] = "x"; });
  EXPECT_EQ(s.field(), "diagnostics.coverage.design_min") << s.message();
  s = ReadModified([](json* j) { (*j)["parameters"]["bias"] = "guess"; });
  EXPECT_EQ(s.field(), "parameters.bias") << s.message();
  s = ReadModified([](json* j) { (*j)["diagnostics"]["refined"] = 1; });
  EXPECT_EQ(s.field(), "diagnostics.refined") << s.message();
}

TEST(PcaResult, UnknownFrameIsRefusedNamingTheValues) {
  const Status s = ReadModified([](json* j) { (*j)["parameters"]["frame"] = "body"; });
  EXPECT_EQ(s.field(), "parameters.frame");
  EXPECT_NE(s.message().find("\"canonical\" or \"nominal\", found \"body\""), std::string::npos)
      << s.message();
}

TEST(PcaResult, SensitivityOfTheWrongDimensionIsRefused) {
  const Status s = ReadModified([](json* j) {
    (*j)["parameters"]["sensors"][0]["axis"] = {1.0, 0.0, 0.0};
  });
  EXPECT_EQ(s.field(), "parameters.sensors[0].axis") << s.message();
}

TEST(PcaResult, UncertaintyOutOfStepWithTheSensorsIsRefused) {
  const Status s = ReadModified([](json* j) { (*j)["uncertainty"]["sensors"].erase(1); });
  EXPECT_EQ(s.field(), "uncertainty.sensors") << s.message();
  const Status t = ReadModified([](json* j) { (*j)["uncertainty"]["sensors"][1]["name"] = "s9"; });
  EXPECT_EQ(t.field(), "uncertainty.sensors[1].name") << t.message();
}

TEST(PcaResult, UsableResultWithoutParametersIsRefused) {
  const Status s = ReadModified([](json* j) { j->erase("parameters"); });
  EXPECT_EQ(s.field(), "parameters") << s.message();
}

TEST(PcaResult, AnotherMethodsResultIsRefused) {
  const Status s = ReadModified([](json* j) { (*j)["method"] = "array"; });
  EXPECT_EQ(s.field(), "method") << s.message();
}

TEST(PcaResult, AbsentSchemaVersionReadsAsOne) {
  json j = ToJson(HandBuilt());
  j.erase("schema_version");
  PcaResult out;
  ASSERT_TRUE(FromJson(j, &out).ok());
  EXPECT_EQ(out.envelope.schema_version, 1);
}

TEST(PcaResult, NewerSchemaVersionIsRefusedNamingIt) {
  const Status s = ReadModified([](json* j) { (*j)["schema_version"] = kPcaSchemaVersion + 1; });
  EXPECT_EQ(s.field(), "schema_version");
  EXPECT_NE(s.message().find("version " + std::to_string(kPcaSchemaVersion + 1)), std::string::npos)
      << s.message();
}

TEST(PcaResult, PartialDocumentReadsWithoutParameters) {
  PcaResult r = HandBuilt();
  r.envelope.usable = false;
  r.envelope.model.clear();
  r.parameters.reset();
  r.uncertainty.reset();
  r.diagnostics.usable = false;
  r.diagnostics.rank_gap = kPcaNaN;
  r.diagnostics.coverage = PcaCoverage();
  const json j = ToJson(r);
  EXPECT_EQ(j["usable"], false);
  EXPECT_FALSE(j.contains("parameters"));
  EXPECT_FALSE(j.contains("model"));
  EXPECT_EQ(j["diagnostics"]["coverage"]["verdict"], "unknown");
  PcaResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_FALSE(back.envelope.usable);
  EXPECT_FALSE(back.parameters.has_value());
  EXPECT_FALSE(back.uncertainty.has_value());
  EXPECT_EQ(back.diagnostics.positions, 7);
  EXPECT_EQ(ToJson(back), j);
}

// Parameters in a not-usable document are not estimates: they are not read, so no consumer (the
// gate, the exports, the pca -> array chain) can take them for a calibration.
TEST(PcaResult, ParametersOfAPartialDocumentAreNotRead) {
  json j = ToJson(HandBuilt());
  j["usable"] = false;
  PcaResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_FALSE(back.parameters.has_value());
  EXPECT_FALSE(back.uncertainty.has_value());
  EXPECT_FALSE(ToJson(back).contains("parameters"));
}

json PartialDocument() {
  PcaResult r = HandBuilt();
  r.envelope.usable = false;
  r.envelope.model.clear();
  r.parameters.reset();
  r.uncertainty.reset();
  r.diagnostics.usable = false;
  return ToJson(r);
}

// The worker leaves out the largest members over the size cap (and wrote null for them before):
// a partial document's diagnostics may lack any member, even SPEC's, or be absent altogether.
TEST(PcaResult, PartialDocumentWithoutAnyDiagnosticsMemberReads) {
  const json document = PartialDocument();  // outlives the loop (items() of a temporary dangles)
  for (const auto& [key, value] : document["diagnostics"].items()) {
    json absent = PartialDocument();
    absent["diagnostics"].erase(key);
    json null = PartialDocument();
    null["diagnostics"][key] = nullptr;
    for (const json& j : {absent, null}) {
      PcaResult out;
      const Status s = FromJson(j, &out);
      EXPECT_TRUE(s.ok()) << key << ": " << s.message();
      EXPECT_FALSE(out.diagnostics.usable) << key;
    }
  }
  json empty = PartialDocument();
  empty["diagnostics"] = json::object();
  json none = PartialDocument();
  none.erase("diagnostics");
  for (const json& j : {empty, none}) {
    PcaResult out;
    const Status s = FromJson(j, &out);
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_FALSE(out.diagnostics.usable);
    EXPECT_EQ(out.diagnostics.positions, -1);
    EXPECT_TRUE(out.diagnostics.singular_values.empty());
    EXPECT_TRUE(std::isnan(out.diagnostics.rank_gap));
    EXPECT_FALSE(out.diagnostics.coverage.has_value());
  }
  // What is present must still be of its type.
  json wrong = PartialDocument();
  wrong["diagnostics"]["positions"] = "seven";
  PcaResult out;
  EXPECT_EQ(FromJson(wrong, &out).field(), "diagnostics.positions");
}

TEST(PcaResult, NonObjectIsRefused) {
  PcaResult out;
  const Status s = FromJson(json::array(), &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("expected an object, found an array"), std::string::npos)
      << s.message();
}

TEST(PcaResult, EnumNamesParseBack) {
  for (PcaFrame f : {PcaFrame::kCanonical, PcaFrame::kNominal}) {
    PcaFrame back = PcaFrame::kCanonical;
    EXPECT_TRUE(Parse(Name(f), &back));
    EXPECT_EQ(back, f);
  }
  for (PcaCoverageVerdict v :
       {PcaCoverageVerdict::kUnknown, PcaCoverageVerdict::kGood, PcaCoverageVerdict::kPoor}) {
    PcaCoverageVerdict back = PcaCoverageVerdict::kUnknown;
    EXPECT_TRUE(Parse(Name(v), &back));
    EXPECT_EQ(back, v);
  }
  PcaBias b = PcaBias::kNone;
  EXPECT_TRUE(Parse("estimate", &b));
  EXPECT_EQ(b, PcaBias::kEstimate);
  EXPECT_FALSE(Parse("Estimate", &b));
}

}  // namespace
}  // namespace calibd::results
