// Every method's adapter passes the run's StopToken into its core (issue #20): a deadline that
// passes mid-run ends Method::Run well within a second with StatusCode::kStopped and
// Reason::kDeadline and the partial diagnostics in the result (usable false); a token cancelled
// before the start ends it at once with Reason::kCancelled; a token that never asks gives the
// result of a run without one.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "core/array_full_simulation.h"
#include "core/imu_simulation.h"
#include "core/stop_token.h"
#include "formats/recording.h"
#include "methods/array/array_method.h"
#include "methods/imu/imu_method.h"
#include "methods/noise/noise_method.h"
#include "server/config.h"
#include "tests/lib/sanitizer.h"

namespace calibd::server {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

struct Input {
  std::string name;  // for messages: the method and its model
  std::string csv;
  json config;
};

// Parses `in` (not timed: the token's deadline is set after) and calibrates it with `stop`.
Status RunParsed(const Input& in, const core::StopToken* stop, json* result,
                 Clock::time_point* started = nullptr,
                 Clock::duration deadline_after = Clock::duration::zero(),
                 core::StopToken* to_arm = nullptr) {
  RecordingParser parser(in.name + ".csv", /*collect=*/true);
  PrepareParser(in.config, &parser);
  const Status parsed = ParseRecording(in.csv, &parser);
  if (!parsed.ok()) return parsed;
  if (started != nullptr) *started = Clock::now();
  if (to_arm != nullptr) to_arm->SetDeadline(*started + deadline_after);
  return CalibrateParsed(&parser, in.name + ".csv", in.config, result, stop);
}

void ExpectStopsAtDeadline(const Input& in) {
  core::StopToken token;
  json result;
  Clock::time_point start;
  const auto after = std::chrono::milliseconds(40);
  const Status s = RunParsed(in, &token, &result, &start, after, &token);
  const double late = std::chrono::duration<double>(Clock::now() - (start + after)).count();
  EXPECT_EQ(s.code(), StatusCode::kStopped) << in.name << ": " << s.message();
  EXPECT_EQ(s.reason(), Reason::kDeadline) << in.name << ": " << s.message();
  EXPECT_EQ(s.message().rfind(in.config["method"].get<std::string>(), 0), 0u)
      << "the message names the method and its stage: " << s.message();
  // Within a second (the bound); under a sanitizer the unpolled stretches (pca's one SVD
  // call) take up to twice that on a loaded machine (0.55-0.7 s alone, 1.08 s beside other tests).
  EXPECT_LT(late, 1.0 * sanitizer::kTimeBoundScale)
      << in.name << " returned " << late << " s after its deadline";
  // The partial diagnostics of a failure: the method, not usable.
  ASSERT_TRUE(result.is_object()) << in.name;
  EXPECT_EQ(result.value("method", ""), in.config["method"]) << result.dump().substr(0, 300);
  EXPECT_EQ(result.value("usable", true), false) << in.name;
  std::printf("%s: stopped %.3f s after the deadline: %s\n", in.name.c_str(), late,
              s.message().c_str());
}

void ExpectStopsBeforeStart(const Input& in) {
  core::StopToken token;
  token.RequestStop(core::StopReason::kCancelled);
  json result;
  Clock::time_point start;
  const Status s = RunParsed(in, &token, &result, &start);
  const double took = std::chrono::duration<double>(Clock::now() - start).count();
  EXPECT_EQ(s.code(), StatusCode::kStopped) << in.name << ": " << s.message();
  EXPECT_EQ(s.reason(), Reason::kCancelled) << in.name << ": " << s.message();
  EXPECT_LT(took, 0.5) << in.name;
}

void ExpectSilentTokenChangesNothing(const Input& in) {
  core::StopToken silent;
  json a, b;
  const Status sa = RunParsed(in, nullptr, &a);
  const Status sb = RunParsed(in, &silent, &b);
  ASSERT_TRUE(sa.ok()) << in.name << ": " << sa.message();
  ASSERT_TRUE(sb.ok()) << in.name << ": " << sb.message();
  EXPECT_EQ(a, b) << in.name;
}

Input ImuInput(int statics, double rate) {
  core::ImuSimulationOptions sim;
  sim.statics = statics;
  sim.static_duration = 4;
  sim.rotation_duration = 3;
  sim.rate = rate;
  sim.seed = 11;
  Input in{"imu", "", json()};
  json truth;
  EXPECT_TRUE(SimulateImuFiles(sim, &in.csv, &in.config, &truth).ok());
  return in;
}

TEST(MethodStop, ImuAdapterStopsAtItsDeadline) {
  const Input in = ImuInput(40, 1000);  // 280 000 rows
  ExpectStopsAtDeadline(in);
  ExpectStopsBeforeStart(in);
  ExpectSilentTokenChangesNothing(ImuInput(16, 100));
}

Input ArrayInput(bool full, int64_t samples) {
  ArraySimulationFileOptions o;
  o.samples = samples;
  o.seed = 5;
  Input in{full ? "array_full" : "array", "", json()};
  json truth;
  const Status s = full ? SimulateArrayFullFiles(o, &in.csv, &in.config, &truth)
                        : SimulateArrayFiles(o, &in.csv, &in.config, &truth);
  EXPECT_TRUE(s.ok()) << s.message();
  in.config["tolerance"] = 0;  // every iteration runs: long unstopped
  return in;
}

TEST(MethodStop, ArrayAdapterStopsAtItsDeadlineForThePositionsAndTheFullModel) {
  for (bool full : {false, true}) {
    const Input in = ArrayInput(full, 10000);
    ExpectStopsAtDeadline(in);
    ExpectStopsBeforeStart(in);
  }
  ExpectSilentTokenChangesNothing(ArrayInput(false, 500));
}

TEST(MethodStop, NoiseAdapterStopsAtItsDeadline) {
  NoiseSimulationFileOptions o;
  o.rate = 400;
  o.seconds = 1200;  // 480 000 rows, 6 channels
  Input in{"noise", "", json()};
  json truth;
  ASSERT_TRUE(SimulateNoiseFiles(o, &in.csv, &in.config, &truth).ok());
  in.config["taus_per_decade"] = 100;
  ExpectStopsAtDeadline(in);
  ExpectStopsBeforeStart(in);
  in.config.erase("taus_per_decade");
  ExpectSilentTokenChangesNothing(in);
}

// m sensors with random axes at n random orientations of a unit field, averaged layout.
Input PcaInput(int m, int n) {
  std::srand(3);
  Eigen::MatrixXd a = Eigen::MatrixXd::Random(3, m);
  a.colwise().normalize();
  Eigen::MatrixXd v = Eigen::MatrixXd::Random(3, n);
  v.colwise().normalize();
  const Eigen::MatrixXd readings = a.transpose() * v + 1e-3 * Eigen::MatrixXd::Random(m, n);
  Input in{"pca", "position", json{{"method", "pca"}, {"refine", true}, {"bias", "estimate"}}};
  for (int i = 0; i < m; ++i) in.csv += ",s" + std::to_string(i);
  in.csv += "\n";
  char buf[40];
  for (int j = 0; j < n; ++j) {
    in.csv += "p" + std::to_string(j + 1);
    for (int i = 0; i < m; ++i) {
      std::snprintf(buf, sizeof buf, ",%.17g", readings(i, j));
      in.csv += buf;
    }
    in.csv += "\n";
  }
  return in;
}

TEST(MethodStop, PcaAdapterStopsAtItsDeadline) {
  // The closed form's SVD is one Eigen call (not polled; max_flops bounds it): small enough here.
  const Input in = PcaInput(150, 450);
  ExpectStopsAtDeadline(in);
  ExpectStopsBeforeStart(in);
  ExpectSilentTokenChangesNothing(PcaInput(12, 60));
}

}  // namespace
}  // namespace calibd::server
