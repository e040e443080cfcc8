// methods/noise/noise_result.h: the typed noise result round-trips and reads back what the adapter
// writes; problems are named by their path.
#include "methods/noise/noise_result.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace calibd::results {
namespace {

using nlohmann::json;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

NoiseResult HandBuilt() {
  NoiseResult r;
  r.envelope.method = "noise";
  r.envelope.model = "the Allan variance model";
  r.envelope.warnings = {"a0_z: random walk not visible"};
  r.channels = {{"a0_x", "m/s^2", 2e-3, 1e-4, 12.5, 1e-4},
                {"g0_x", "rad/s", 2e-4, kNaN, kNaN, kNaN}};
  r.channel_stds.resize(2);  // as an earlier calibd wrote them: no basis, no crb
  r.channel_stds[0].name = "a0_x";
  r.channel_stds[0].white_noise_std = 1e-5;
  r.channel_stds[0].bias_instability_std = 2e-6;
  r.channel_stds[0].random_walk_std = 3e-6;
  r.channel_stds[1].name = "g0_x";
  r.channel_stds[1].white_noise_std = 2e-6;
  NoiseDiagnostics& d = r.diagnostics;
  d.rate = 100;
  d.samples = 180000;
  d.duration = 1799.99;
  d.jitter = 0.001;
  d.stationary = true;
  d.taus_per_decade = 10;
  d.confidence = 0.683;
  d.channels = {{"a0_x", "ok", "", 12, 0.9, 0.01}, {"g0_x", "ok", "", 11, kNaN, -0.002}};
  d.allan = {{"a0_x", {0.01, 0.02}, {0.02, 0.014}, {0.019, 0.013}, {0.021, 0.015}, {0.02, 0.014}},
             {"g0_x", {0.01}, {kNaN}, {0.001}, {0.003}, {0.002}}};
  d.units = NoiseUnits{"m/s^2", "rad/s"};
  return r;
}

TEST(NoiseResult, HandBuiltResultRoundTripsThroughJson) {
  const json j = ToJson(HandBuilt());
  EXPECT_EQ(j["schema_version"], kNoiseSchemaVersion);
  EXPECT_TRUE(j["parameters"]["channels"][1]["bias_instability"].is_null());
  NoiseResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_EQ(ToJson(back), j);
  ASSERT_EQ(back.channels.size(), 2u);
  EXPECT_EQ(back.channels[0].white_noise, 2e-3);
  EXPECT_TRUE(std::isnan(back.channels[1].random_walk));
  EXPECT_EQ(back.channel_stds[0].random_walk_std, 3e-6);
  EXPECT_EQ(back.diagnostics.samples, 180000);
  EXPECT_EQ(back.diagnostics.taus_per_decade, 10);
  ASSERT_TRUE(back.diagnostics.units.has_value());
  EXPECT_EQ(back.diagnostics.units->gyro_unit, "rad/s");
  EXPECT_EQ(back.diagnostics.allan[0].tau, (std::vector<double>{0.01, 0.02}));
}

TEST(NoiseResult, AWrongTypeIsNamedByItsPath) {
  json j = ToJson(HandBuilt());
  j["parameters"]["channels"][1]["white_noise"] = "2e-4";
  NoiseResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_EQ(s.field(), "parameters.channels[1].white_noise");
  EXPECT_NE(s.message().find("noise result: parameters.channels[1].white_noise: expected a number"),
            std::string::npos)
      << s.message();
}

TEST(NoiseResult, AMissingKeyIsNamedByItsPath) {
  json j = ToJson(HandBuilt());
  j["diagnostics"]["allan"][0].erase("adev_upper");
  NoiseResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "diagnostics.allan[0].adev_upper");
  EXPECT_NE(s.message().find("missing"), std::string::npos) << s.message();
}

TEST(NoiseResult, UncertaintiesOfAnotherCountAreRefused) {
  json j = ToJson(HandBuilt());
  j["uncertainty"]["channels"].erase(1);
  NoiseResult r;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "uncertainty.channels");
  EXPECT_NE(s.message().find("2 channels in parameters but 1"), std::string::npos) << s.message();
}

TEST(NoiseResult, AbsentSchemaVersionReadsAsOneAndANewerOneIsRefused) {
  json j = ToJson(HandBuilt());
  j.erase("schema_version");
  NoiseResult r;
  ASSERT_TRUE(FromJson(j, &r).ok());
  EXPECT_EQ(r.envelope.schema_version, 1);
  j["schema_version"] = kNoiseSchemaVersion + 1;
  const Status s = FromJson(j, &r);
  EXPECT_EQ(s.field(), "schema_version");
  EXPECT_NE(s.message().find("newer"), std::string::npos) << s.message();
}

TEST(NoiseResult, AnotherMethodsResultIsRefused) {
  json j = ToJson(HandBuilt());
  j["method"] = "imu";
  NoiseResult r;
  EXPECT_EQ(FromJson(j, &r).field(), "method");
}

TEST(NoiseResult, PartialDocumentReadsWithoutParameters) {
  NoiseResult partial = HandBuilt();
  partial.envelope.usable = false;
  partial.envelope.model.clear();
  partial.diagnostics.stationary = false;
  partial.diagnostics.channels[1].status = "not_stationary";
  partial.diagnostics.channels[1].reason = "g0_x moved";
  const json j = ToJson(partial);
  EXPECT_FALSE(j.contains("parameters"));
  EXPECT_FALSE(j.contains("uncertainty"));
  EXPECT_FALSE(j.contains("model"));
  EXPECT_EQ(j["usable"], false);
  NoiseResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_FALSE(back.envelope.usable);
  EXPECT_TRUE(back.channels.empty());
  EXPECT_EQ(back.diagnostics.channels[1].reason, "g0_x moved");
  EXPECT_EQ(ToJson(back), j);
}

// A partial document the server trimmed to fit the store (largest diagnostics left out and
// listed under "trimmed", or cut to the bare envelope) still reads and writes back.
TEST(NoiseResult, TrimmedPartialDocumentsRead) {
  NoiseResult partial = HandBuilt();
  partial.envelope.usable = false;
  partial.envelope.model.clear();
  json j = ToJson(partial);
  j["diagnostics"].erase("allan");
  j["diagnostics"].erase("channels");
  j["trimmed"] = {{"bytes", 5000000}, {"dropped", {"allan", "channels"}}, {"note", "left out"}};
  NoiseResult back;
  Status s = FromJson(j, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(back.diagnostics.allan.empty());
  EXPECT_EQ(back.diagnostics.samples, 180000);
  EXPECT_EQ(back.dropped, (std::vector<std::string>{"allan", "channels"}));
  EXPECT_EQ(ToJson(back), j);
  // Trimmed by an earlier calibd, which set the dropped members to null.
  json legacy = j;
  legacy["diagnostics"]["allan"] = nullptr;
  legacy["diagnostics"]["channels"] = nullptr;
  ASSERT_TRUE(FromJson(legacy, &back).ok());
  EXPECT_TRUE(back.diagnostics.channels.empty());
  // A null that the note does not list is still an error.
  j["diagnostics"]["samples"] = nullptr;
  EXPECT_EQ(FromJson(j, &back).field(), "diagnostics.samples");
  // Cut to the bare envelope.
  const json bare = {
      {"method", "noise"},
      {"usable", false},
      {"trimmed", {{"bytes", 9000000}, {"dropped", {"diagnostics"}}, {"note", "x"}}}};
  s = FromJson(bare, &back);
  ASSERT_TRUE(s.ok()) << s.ToString();
  EXPECT_TRUE(back.diagnostics.channels.empty());
}

TEST(NoiseResult, ADocumentThatIsNotAnObjectIsRefused) {
  NoiseResult r;
  const Status s = FromJson(json::array(), &r);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("expected an object"), std::string::npos) << s.message();
}

// Members beyond SPEC's keys (our extensions) may be absent, as in a result of an earlier calibd:
// they keep their defaults; SPEC's keys stay required.
TEST(NoiseResult, AbsentExtensionsKeepTheirDefaults) {
  json j = ToJson(HandBuilt());
  for (const char* key :
       {"duration", "jitter", "stationary", "taus_per_decade", "confidence", "channels", "units"}) {
    j["diagnostics"].erase(key);
  }
  j["diagnostics"]["allan"][0].erase("fitted_adev");
  NoiseResult r;
  ASSERT_TRUE(FromJson(j, &r).ok()) << FromJson(j, &r).ToString();
  EXPECT_TRUE(std::isnan(r.diagnostics.duration));
  EXPECT_TRUE(std::isnan(r.diagnostics.confidence));
  EXPECT_TRUE(r.diagnostics.stationary);
  EXPECT_EQ(r.diagnostics.taus_per_decade, 0);
  EXPECT_TRUE(r.diagnostics.channels.empty());
  EXPECT_FALSE(r.diagnostics.units.has_value());
  EXPECT_TRUE(r.diagnostics.allan[0].fitted_adev.empty());
  EXPECT_FALSE(r.diagnostics.allan[0].adev.empty());
  // SPEC's keys are still required.
  j["diagnostics"].erase("samples");
  EXPECT_EQ(FromJson(j, &r).field(), "diagnostics.samples");
}

// The σ convention (issue 28): basis, χ²/dof and the model's σ round-trip; a result stored
// before it (no basis, no crb) reads as "crb_only"; an unknown basis is named by its path.
TEST(NoiseResult, SigmaBasisRoundTripsAndAnEarlierResultReadsAsCrbOnly) {
  NoiseResult r = HandBuilt();
  r.basis = "chi2_scaled";
  r.chi2_per_dof = 19.6;
  r.channel_stds[0].basis = "chi2_scaled";
  r.channel_stds[0].chi2_per_dof = 19.6;
  r.channel_stds[0].crb = NoiseTermStds{1e-5 / 4.4, 2e-6 / 4.4, 3e-6 / 4.4};
  r.channel_stds[1].basis = "crb";
  r.channel_stds[1].chi2_per_dof = 0.9;
  r.channel_stds[1].crb = NoiseTermStds{2e-6, kNaN, kNaN};
  json j = ToJson(r);
  EXPECT_EQ(j["uncertainty"]["basis"], "chi2_scaled");
  EXPECT_EQ(j["uncertainty"]["channels"][0]["crb"]["white_noise_std"], 1e-5 / 4.4);
  EXPECT_TRUE(j["uncertainty"]["channels"][1]["crb"]["random_walk_std"].is_null());
  NoiseResult back;
  ASSERT_TRUE(FromJson(j, &back).ok()) << FromJson(j, &back).message();
  EXPECT_EQ(ToJson(back), j);
  EXPECT_EQ(back.basis, "chi2_scaled");
  EXPECT_EQ(back.chi2_per_dof, 19.6);
  ASSERT_TRUE(back.channel_stds[0].crb.has_value());
  EXPECT_EQ(back.channel_stds[0].crb->bias_instability_std, 2e-6 / 4.4);
  EXPECT_EQ(back.channel_stds[1].basis, "crb");

  // An earlier calibd's result: the σ keys only.
  const json earlier = ToJson(HandBuilt());
  EXPECT_FALSE(earlier["uncertainty"].contains("basis"));
  EXPECT_FALSE(earlier["uncertainty"]["channels"][0].contains("crb"));
  ASSERT_TRUE(FromJson(earlier, &back).ok());
  EXPECT_EQ(back.basis, kNoiseBasisCrbOnly);
  EXPECT_TRUE(std::isnan(back.chi2_per_dof));
  EXPECT_EQ(back.channel_stds[0].basis, kNoiseBasisCrbOnly);
  EXPECT_FALSE(back.channel_stds[0].crb.has_value());
  EXPECT_EQ(back.channel_stds[0].white_noise_std, 1e-5);

  j["uncertainty"]["channels"][1]["basis"] = "sandwich";
  const Status s = FromJson(j, &back);
  EXPECT_EQ(s.field(), "uncertainty.channels[1].basis") << s.ToString();
  j["uncertainty"]["channels"][1]["basis"] = "crb";
  j["uncertainty"]["channels"][0]["crb"]["random_walk_std"] = "3e-6";
  EXPECT_EQ(FromJson(j, &back).field(), "uncertainty.channels[0].crb.random_walk_std");
}

}  // namespace
}  // namespace calibd::results
