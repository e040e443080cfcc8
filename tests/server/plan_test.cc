// Tests of the plan (SPEC §10, issue #27 item 1; server/plan.h, methods/plan.h, Method::Plan of
// pca and imu): the predicted σ against the σ calibrations of simulated recordings of the same
// protocol report, what planar and single-axis protocols cannot determine, the suggested protocol
// meeting the gate's limits, and the request's errors naming the field.
#include "server/plan.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/imu_simulation.h"
#include "core/pca_simulation.h"
#include "methods/imu/imu_method.h"
#include "methods/imu/imu_plan.h"
#include "methods/plan.h"
#include "server/config.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The paper's a_model as the config's nominal (one row per sensor).
json PcaNominal() {
  const Eigen::MatrixXd a = core::PcaModelSensitivities();
  json rows = json::array();
  for (Eigen::Index i = 0; i < a.cols(); ++i) rows.push_back({a(0, i), a(1, i), a(2, i)});
  return rows;
}

json PcaConfig() {
  return {{"method", "pca"},
          {"nominal", PcaNominal()},
          {"magnitude", 1.0},
          {"noise_std", 0.01},
          {"bias", "estimate"}};
}

// 14 orientations: the 6 faces and the 8 corners of a box.
const std::vector<std::string> kFacesAndCorners = {"+x",     "-x",     "+y",     "-y",     "+z",
                                                   "-z",     "+x+y+z", "+x+y-z", "+x-y+z", "+x-y-z",
                                                   "-x+y+z", "-x+y-z", "-x-y+z", "-x-y-z"};

json Plan(const json& request) {
  json out;
  const Status s = PlanJson(request, json(), &out);
  EXPECT_TRUE(s.ok()) << s.message() << " " << request.dump();
  return out;
}

// The averaged-layout recording of sensors `a` (d×m, true sensitivities) and biases `b` at the
// orientations, with N(0, noise²) per reading; header position,s0,...
std::string PcaRecording(const Eigen::MatrixXd& a, const Eigen::VectorXd& b,
                         const std::vector<Eigen::Vector3d>& u, double noise,
                         core::PcaRandom* rng) {
  std::string csv = "position";
  for (Eigen::Index i = 0; i < a.cols(); ++i) csv += ",s" + std::to_string(i);
  csv += "\n";
  char cell[64];
  for (size_t j = 0; j < u.size(); ++j) {
    csv += "p" + std::to_string(j);
    for (Eigen::Index i = 0; i < a.cols(); ++i) {
      std::snprintf(cell, sizeof cell, ",%.17g", a.col(i).dot(u[j]) + b(i) + noise * rng->Normal());
      csv += cell;
    }
    csv += "\n";
  }
  return csv;
}

std::vector<Eigen::Vector3d> Directions(const std::vector<std::string>& names) {
  std::vector<Eigen::Vector3d> out;
  for (const std::string& n : names) {
    Eigen::Vector3d v;
    EXPECT_TRUE(OrientationFromName(n, &v).ok()) << n;
    out.push_back(v);
  }
  return out;
}

void ExpectWithin(double predicted, double reported, double tolerance, const std::string& what) {
  EXPECT_TRUE(std::isfinite(predicted) && std::isfinite(reported)) << what;
  EXPECT_NEAR(predicted / reported, 1.0, tolerance)
      << what << ": predicted " << predicted << ", reported " << reported;
}

// The plan's σ against the σ reported by calibrations of recordings of the same protocol by
// sensors off the nominal by 1 % (axes) with biases, 5 noise seeds. The CRB at the estimate moves
// with the seed by O(σ/|a|) = O(1 %) and with the sensors' offset from the nominal by O(1 %), so
// 15 % is a wide margin; a plan that ignored the protocol (e.g. σ of a uniform sphere) or the
// noise would be off by far more (the faces-and-corners set vs. 14 random directions differ by
// tens of %, and σ ∝ noise_std).
TEST(PlanTest, PcaSigmaMatchesCalibrationsOfTheProtocol) {
  const json plan = Plan({{"method", "pca"},
                          {"config", PcaConfig()},
                          {"protocol", {{"orientations", kFacesAndCorners}}}});
  ASSERT_TRUE(plan["undetermined"].empty()) << plan.dump(2);
  const json& predicted = plan["uncertainty"]["sensors"];
  ASSERT_EQ(predicted.size(), 12u);
  const std::vector<Eigen::Vector3d> u = Directions(kFacesAndCorners);
  for (uint64_t seed = 1; seed <= 5; ++seed) {
    core::PcaRandom rng(seed);
    const Eigen::MatrixXd a = core::PcaModelSensitivities() + 0.01 * rng.NormalMatrix(3, 12);
    const Eigen::VectorXd b = 0.05 * rng.NormalMatrix(12, 1);
    json result;
    ASSERT_TRUE(Calibrate(PcaRecording(a, b, u, 0.01, &rng), "pca.csv", PcaConfig(), &result).ok());
    const json& reported = result["uncertainty"]["sensors"];
    for (size_t i = 0; i < 12; ++i) {
      for (const char* key : {"scale_std", "axis_std_rad", "bias_std"}) {
        ExpectWithin(predicted[i][key].get<double>(), reported[i][key].get<double>(), 0.15,
                     "seed " + std::to_string(seed) + " sensor " + std::to_string(i) + " " + key);
      }
    }
  }
}

TEST(PlanTest, PcaPlanarProtocolNamesTheAxisItCannotDetermine) {
  const json plan = Plan(
      {{"method", "pca"},
       {"config", PcaConfig()},
       {"protocol",
        {{"orientations", {"+x", "-x", "+y", "-y", "+x+y", "+x-y", "-x+y", "-x-y", "+x", "+y"}}}}});
  ASSERT_EQ(plan["undetermined"].size(), 1u) << plan.dump(2);
  const json& u = plan["undetermined"][0];
  const std::string parameters = u["parameters"].dump();
  EXPECT_NE(parameters.find("s0.sensitivity[z]"), std::string::npos) << parameters;
  EXPECT_NE(u["missing"].dump().find("no orientation with a component along z"), std::string::npos)
      << u.dump();
  EXPECT_TRUE(plan["uncertainty"].is_null());
}

TEST(PlanTest, PcaSingleAxisProtocolNamesTheOtherAxesAndTheBias) {
  const json plan =
      Plan({{"method", "pca"},
            {"config", PcaConfig()},
            {"protocol",
             {{"orientations", {"+x", "+x", "+x", "+x", "+x", "+x", "+x", "+x", "+x", "+x"}}}}});
  ASSERT_EQ(plan["undetermined"].size(), 1u) << plan.dump(2);
  const std::string text = plan["undetermined"][0].dump();
  EXPECT_NE(text.find("bias"), std::string::npos) << text;
  EXPECT_NE(text.find("sensitivity[y]"), std::string::npos) << text;
  EXPECT_NE(text.find("sensitivity[z]"), std::string::npos) << text;
  EXPECT_NE(text.find("the same component along x"), std::string::npos) << text;
}

// The suggestion meets the limits in force: its predicted σ are within them (checked here
// directly, not only through the flag), and re-planning its orientations gives the same σ.
TEST(PlanTest, PcaSuggestionMeetsTheLimits) {
  json config = PcaConfig();
  config["acceptance"] = {
      {"max_scale_std", 0.006}, {"max_axis_std", 0.006}, {"max_bias_std", 0.006}};
  const json plan = Plan({{"method", "pca"},
                          {"config", config},
                          {"protocol", {{"orientations", {"+x", "+y", "+z"}}}}});
  const json& suggested = plan["suggested"];
  ASSERT_TRUE(suggested["meets_limits"].get<bool>()) << suggested.dump(2);
  EXPECT_TRUE(suggested["unmet"].empty());
  EXPECT_LE(suggested["orientations"].size(), 24u);
  EXPECT_GE(suggested["orientations"].size(), 9u);  // d(d+3)/2 with biases
  for (const json& s : suggested["uncertainty"]["sensors"]) {
    EXPECT_LE(s["scale_std"].get<double>(), 0.006) << s.dump();
    EXPECT_LE(s["axis_std_rad"].get<double>(), 0.006) << s.dump();
    EXPECT_LE(s["bias_std"].get<double>(), 0.006) << s.dump();
  }
  std::vector<std::string> names;
  for (const json& o : suggested["orientations"]) names.push_back(o["name"]);
  const json again =
      Plan({{"method", "pca"}, {"config", config}, {"protocol", {{"orientations", names}}}});
  EXPECT_EQ(again["uncertainty"], suggested["uncertainty"]);
  // Unreachable limits: the cap, and the unmet rules named.
  config["acceptance"] = {{"max_scale_std", 1e-6}};
  const json capped = Plan({{"method", "pca"},
                            {"config", config},
                            {"protocol", {{"orientations", {"+x", "+y", "+z"}}}}});
  EXPECT_FALSE(capped["suggested"]["meets_limits"].get<bool>());
  EXPECT_EQ(capped["suggested"]["orientations"].size(), 24u);
  EXPECT_NE(capped["suggested"]["unmet"].dump().find("scale"), std::string::npos)
      << capped["suggested"].dump(2);
}

json ImuConfig() { return {{"method", "imu"}, {"accel_noise", 0.02}, {"gyro_noise", 0.003}}; }

// 12 orientations: the 6 faces and 6 edge diagonals, 2 s statics at 100 Hz, 1.5 s rotations.
json ImuProtocol() {
  return {{"orientations",
           {"+z", "+x", "-z", "-x", "+y", "-y", "+x+y", "+y+z", "-x+z", "-y-z", "+x-z", "-x-y"}},
          {"static_duration", 2.0},
          {"rate", 100.0},
          {"rotation_duration", 1.5}};
}

// The imu plan's σ against what the imu method reports for simulated logs of the same protocol
// by IMUs with 1 % scale errors, misalignment and biases (core/imu_simulation.h defaults), 4
// seeds: the primary σ and the CRB of every reported quantity within 15 %.
TEST(PlanTest, ImuSigmaMatchesCalibrationsOfTheProtocol) {
  const json plan = Plan({{"method", "imu"}, {"config", ImuConfig()}, {"protocol", ImuProtocol()}});
  ASSERT_TRUE(plan["undetermined"].empty()) << plan.dump(2);
  const json& predicted = plan["uncertainty"];
  ASSERT_TRUE(predicted.is_object()) << plan.dump(2);
  PlanProtocol protocol;
  ASSERT_TRUE(ParsePlanProtocol(ImuProtocol(), &protocol).ok());
  for (uint64_t seed = 11; seed <= 14; ++seed) {
    core::ImuSimulationOptions sim;
    sim.statics = static_cast<int>(protocol.orientations.size());
    sim.orientations = ProtocolRotations(protocol.orientations);
    sim.static_duration = 2;
    sim.rotation_duration = 1.5;
    sim.rate = 100;
    sim.accel_noise = 0.02;
    sim.gyro_noise = 0.003;
    sim.seed = seed;
    std::string csv;
    json sim_config, truth, result;
    ASSERT_TRUE(SimulateImuFiles(sim, &csv, &sim_config, &truth).ok());
    ASSERT_TRUE(Calibrate(csv, "imu.csv", ImuConfig(), &result).ok());
    const json& reported = result["uncertainty"];
    for (const char* triad : {"accelerometer", "gyroscope"}) {
      for (const char* key : {"bias_std", "scale_std"}) {
        for (int k = 0; k < 3; ++k) {
          const std::string what = "seed " + std::to_string(seed) + " " + triad + "." + key + "[" +
                                   std::to_string(k) + "]";
          ExpectWithin(predicted["imus"][0][triad][key][k].get<double>(),
                       reported["imus"][0][triad][key][k].get<double>(), 0.15, what);
          ExpectWithin(predicted["imus"][0]["crb"][triad][key][k].get<double>(),
                       reported["imus"][0]["crb"][triad][key][k].get<double>(), 0.15,
                       what + " (crb)");
        }
      }
    }
  }
}

TEST(PlanTest, ImuPlanarProtocolNamesWhatItMisses) {
  json protocol = ImuProtocol();
  protocol["orientations"] = {"+x",   "+y",   "-x", "-y", "+x+y", "-x+y",
                              "-x-y", "+x-y", "+x", "+y", "-x",   "-y"};
  const json plan = Plan({{"method", "imu"}, {"config", ImuConfig()}, {"protocol", protocol}});
  ASSERT_EQ(plan["undetermined"].size(), 1u) << plan.dump(2);
  EXPECT_NE(plan["undetermined"][0].dump().find("no orientation with a component along z"),
            std::string::npos)
      << plan.dump(2);
  EXPECT_TRUE(plan["uncertainty"].is_null());
}

// The linearised accelerometer information of ImuDesign against the method, through ratios in
// which the noise scale cancels: per axis, bias σ / (g × relative scale σ). For each of two
// protocols the design's ratio is within 20 % of the method's (the block-diagonal information
// leaves out the coupling through the gravity directions that the joint fit has, which
// determines the bias 6-16 % better here), and how the ratio changes from one protocol to the
// other (what ranks candidates) within 10 %, while the change itself is over 25 %: a criterion
// blind to the protocol, or with a wrong feature (|a| linear in u, a missing T_a term), fails.
TEST(PlanTest, ImuDesignInformationPredictsTheMethodsSigmaRatios) {
  const std::vector<std::vector<std::string>> protocols = {
      ImuProtocol()["orientations"].get<std::vector<std::string>>(),
      {"+z", "+x", "-z", "-x", "+y", "-y", "+x+y+z", "-x-y+z", "+x-y-z", "-x+y-z"}};
  std::vector<Eigen::Vector3d> design(2), method(2);
  for (size_t p = 0; p < 2; ++p) {
    const std::vector<std::string>& names = protocols[p];
    json protocol = ImuProtocol();
    protocol["orientations"] = names;
    const json plan = Plan({{"method", "imu"}, {"config", ImuConfig()}, {"protocol", protocol}});
    ASSERT_TRUE(plan["uncertainty"].is_object()) << plan.dump(2);
    const json& accel = plan["uncertainty"]["imus"][0]["crb"]["accelerometer"];
    const Eigen::Matrix<double, 9, 9> cov = ImuDesign(Directions(names)).accel.inverse();
    for (int k = 0; k < 3; ++k) {
      // d|a| = -u·db + g u_k² dK_k/K_k: bias σ (m/s²) over g × relative scale σ.
      design[p](k) = std::sqrt(cov(k, k) / cov(3 + k, 3 + k));
      method[p](k) =
          accel["bias_std"][k].get<double>() / (9.80665 * accel["scale_std"][k].get<double>());
      ExpectWithin(design[p](k), method[p](k), 0.20,
                   std::to_string(names.size()) + " orientations, axis " + std::to_string(k));
    }
  }
  for (int k = 0; k < 3; ++k) {
    const double change = method[1](k) / method[0](k);
    EXPECT_GT(change, 1.25) << "axis " << k << ": the protocols do not tell criteria apart";
    ExpectWithin(design[1](k) / design[0](k), change, 0.10,
                 "change between the protocols, axis " + std::to_string(k));
  }
}

// The design's first orientations: the greedy sequence starts flat, never repeats the current
// orientation (a repeat is one longer static), by 9 positions has every body axis up and down
// within 45° (the method's coverage rule, which the sequence keeps room for), and each position
// increases the criterion.
TEST(PlanTest, ImuGreedySequenceCoversTheSphere) {
  const std::vector<const PlanCandidate*> seq = ImuGreedySequence(12);
  ASSERT_EQ(seq.size(), 12u);
  EXPECT_EQ(seq[0]->name, "+z");
  for (size_t j = 1; j < seq.size(); ++j) EXPECT_NE(seq[j], seq[j - 1]) << j;
  for (int axis = 0; axis < 3; ++axis) {
    for (const double sign : {1.0, -1.0}) {
      double best = -1;
      for (size_t j = 0; j < 9; ++j) best = std::max(best, sign * seq[j]->direction(axis));
      EXPECT_GE(best, std::cos(M_PI / 4) - 1e-9) << "axis " << axis << " sign " << sign;
    }
  }
  // Each added position increases the criterion (the information only grows).
  std::vector<Eigen::Vector3d> up;
  double last = -INFINITY;
  for (const PlanCandidate* c : seq) {
    up.push_back(c->direction);
    const double value = ImuDesignCriterion(ImuDesign(up));
    EXPECT_GT(value, last);
    last = value;
  }
}

json ImuSuggestConfig() { return {{"method", "imu"}, {"accel_noise", 0.05}, {"gyro_noise", 0.01}}; }

// The imu σ limit of this test: between the plan's σ of the greedy sequence's first 14 and 15
// positions (the largest relative scale σ of either triad), so the suggestion must stop at 15.
// The σ of one prefix is the plan's answer for that prefix typed as a protocol (PlanJson, not
// SuggestImu's own trials).
double LargestScaleStd(const json& uncertainty) {
  double worst = 0;
  for (const char* triad : {"accelerometer", "gyroscope"}) {
    for (int k = 0; k < 3; ++k) {
      worst = std::max(worst, uncertainty["imus"][0][triad]["scale_std"][k].get<double>());
    }
  }
  return worst;
}

json PrefixProtocol(int k) {
  json protocol = ImuProtocol();
  protocol["orientations"] = json::array();
  const std::vector<const PlanCandidate*> seq = ImuGreedySequence(k);
  for (const PlanCandidate* c : seq) protocol["orientations"].push_back(c->name);
  return protocol;
}

// The suggested imu protocol meets the limits on simulated recordings: with a max_scale_std
// between the plan's σ of 14 and 15 positions of the sequence (other σ limits off), the
// suggestion has 15 positions and says 14 fail; 8 simulated recordings of the suggestion (IMUs
// with 1 % scale errors, misalignment, biases; seeds 21-28), calibrated by the imu method, all
// pass the gate's limit, and 8 recordings of the 14 positions all report a largest scale σ above
// the tightened limit the design says 14 positions miss. The limit sits at least 5 % from either
// prediction (asserted), and the σ of one recording moves by about 1 % with the seed
// (ImuSigmaMatchesCalibrationsOfTheProtocol), so a wrong prediction or stopping point fails.
TEST(PlanTest, ImuSuggestionMeetsTheLimitsOnSimulatedRecordings) {
  const ImuSuggestOptions options;
  auto plan_sigma = [&](int k) {
    const json plan =
        Plan({{"method", "imu"}, {"config", ImuSuggestConfig()}, {"protocol", PrefixProtocol(k)}});
    return LargestScaleStd(plan["uncertainty"]);
  };
  const double sigma14 = plan_sigma(14), sigma15 = plan_sigma(15);
  ASSERT_GT(sigma14, 1.12 * sigma15) << "the test's limit needs a step between 14 and 15";
  const double tightened = std::sqrt(sigma14 * sigma15);  // the margined limit
  const double limit = tightened / (1 - options.margin);
  json config = ImuSuggestConfig();
  config["acceptance"] = {{"max_scale_std", limit},
                          {"max_axis_std", nullptr},
                          {"max_accel_bias_std", nullptr},
                          {"max_gyro_bias_std", nullptr}};
  const json plan = Plan({{"method", "imu"}, {"config", config}, {"protocol", PrefixProtocol(3)}});
  const json& suggested = plan["suggested"];
  ASSERT_TRUE(suggested["meets_limits"].get<bool>()) << suggested.dump(2);
  ASSERT_EQ(suggested["orientations"].size(), 15u) << suggested.dump(2);
  EXPECT_EQ(suggested["fewer"]["positions"], 14) << suggested.dump(2);
  EXPECT_NE(suggested["fewer"]["unmet"].dump().find("scale"), std::string::npos);
  EXPECT_LE(suggested["predictions"].get<int>(), 5);  // 1 + ⌈log2(24 − 8)⌉
  const AcceptanceLimits limits = EffectiveAcceptance("imu", json(), config);
  for (const int k : {15, 14}) {
    json protocol = PrefixProtocol(k);
    PlanProtocol parsed;
    ASSERT_TRUE(ParsePlanProtocol(protocol, &parsed).ok());
    int accepted = 0, above_tightened = 0;
    for (uint64_t seed = 21; seed <= 28; ++seed) {
      core::ImuSimulationOptions sim;
      sim.statics = k;
      sim.orientations = ProtocolRotations(parsed.orientations);
      sim.static_duration = parsed.static_duration;
      sim.rotation_duration = parsed.rotation_duration;
      sim.rate = parsed.rate;
      sim.accel_noise = 0.05;
      sim.gyro_noise = 0.01;
      sim.seed = seed;
      std::string csv;
      json sim_config, truth, result;
      ASSERT_TRUE(SimulateImuFiles(sim, &csv, &sim_config, &truth).ok());
      ASSERT_TRUE(Calibrate(csv, "imu.csv", config, &result).ok());
      Verdict verdict;
      ImuMethod().Judge(result, config, limits, &verdict);
      accepted += verdict.accepted() ? 1 : 0;
      above_tightened += LargestScaleStd(result["uncertainty"]) > tightened ? 1 : 0;
      if (k == 15) {
        EXPECT_TRUE(verdict.accepted()) << "seed " << seed << " " << verdict.ToJson(limits).dump();
      }
    }
    if (k == 15) {
      EXPECT_EQ(accepted, 8);
    } else {
      EXPECT_EQ(above_tightened, 8);
    }
  }
}

// Limits no protocol of the cap meets: the cap's orientations, meets_limits false, the rule named,
// one prediction; a protocol whose 9 positions are over max_samples: none simulated, said so.
TEST(PlanTest, ImuSuggestionNamesWhatItCannotMeet) {
  json config = ImuSuggestConfig();
  config["acceptance"] = {{"max_scale_std", 1e-7}};
  const json plan = Plan({{"method", "imu"}, {"config", config}, {"protocol", PrefixProtocol(12)}});
  const json& suggested = plan["suggested"];
  EXPECT_FALSE(suggested["meets_limits"].get<bool>());
  EXPECT_EQ(suggested["orientations"].size(), 24u);
  EXPECT_EQ(suggested["predictions"], 1);
  EXPECT_NE(suggested["unmet"].dump().find("scale"), std::string::npos) << suggested.dump(2);
  EXPECT_TRUE(suggested["fewer"].is_null());

  PlanProtocol protocol;
  ASSERT_TRUE(ParsePlanProtocol(PrefixProtocol(12), &protocol).ok());
  ImuSuggestOptions options;
  options.max_samples = 8 * protocol.rate * (protocol.static_duration + protocol.rotation_duration);
  const json small =
      SuggestImu(config, protocol, EffectiveAcceptance("imu", json(), config), options);
  EXPECT_FALSE(small["meets_limits"].get<bool>());
  EXPECT_EQ(small["predictions"], 0);
  EXPECT_NE(small["unmet"].dump().find("max_samples"), std::string::npos) << small.dump(2);

  std::string error;
  options = ImuSuggestOptions();
  EXPECT_TRUE(options.IsValid(&error));
  options.max_positions = 8;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("max_positions"), std::string::npos);
  options = ImuSuggestOptions();
  options.margin = 1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("margin"), std::string::npos);
}

Status PlanStatus(const json& request) {
  json out;
  return PlanJson(request, json(), &out);
}

TEST(PlanTest, ErrorsNameTheField) {
  const json protocol = {{"orientations", {"+x", "+y", "+z"}}};
  EXPECT_EQ(PlanStatus({{"method", "noise"}, {"protocol", protocol}}).field(), "method");
  EXPECT_EQ(PlanStatus({{"method", "nope"}, {"protocol", protocol}}).field(), "method");
  EXPECT_EQ(PlanStatus({{"method", "pca"},
                        {"config", PcaConfig()},
                        {"protocol", {{"orientations", {"+x", "+w"}}}}})
                .field(),
            "protocol.orientations[1]");
  EXPECT_EQ(PlanStatus({{"method", "pca"},
                        {"config", PcaConfig()},
                        {"protocol", {{"orientations", {"+x", json::array({0, 0, 0})}}}}})
                .field(),
            "protocol.orientations[1]");
  EXPECT_EQ(PlanStatus({{"method", "pca"},
                        {"config", PcaConfig()},
                        {"protocol", {{"orientations", protocol["orientations"]}, {"rate", -1}}}})
                .field(),
            "protocol.rate");
  json many = json::array();
  for (int i = 0; i < 1001; ++i) many.push_back("+x");
  EXPECT_EQ(
      PlanStatus(
          {{"method", "pca"}, {"config", PcaConfig()}, {"protocol", {{"orientations", many}}}})
          .field(),
      "protocol.orientations");
  json no_noise = PcaConfig();
  no_noise.erase("noise_std");
  EXPECT_EQ(PlanStatus({{"method", "pca"}, {"config", no_noise}, {"protocol", protocol}}).field(),
            "config.noise_std");
  EXPECT_EQ(
      PlanStatus({{"method", "imu"}, {"config", {{"accel_noise", 0.01}}}, {"protocol", protocol}})
          .field(),
      "config.gyro_noise");
  EXPECT_EQ(PlanStatus({{"method", "pca"}, {"config", {{"refine", "x"}}}, {"protocol", protocol}})
                .field(),
            "config.refine");
}

TEST(PlanTest, CandidatesAreTheTwentySixDirections) {
  const auto& c = PlanCandidates();
  ASSERT_EQ(c.size(), 26u);
  for (size_t i = 0; i < c.size(); ++i) {
    EXPECT_NEAR(c[i].direction.norm(), 1.0, 1e-12);
    for (size_t j = 0; j < i; ++j) EXPECT_NE(c[i].name, c[j].name);
  }
}

}  // namespace
}  // namespace calibd::server
