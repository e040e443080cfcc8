// Tests of static detection (core/static_detection.h) on simulated logs with known statics:
// no initial static needed, slow drift, a bump, gaps, saturation, bad input.
#include "core/static_detection.h"

#include <gtest/gtest.h>

#include <Eigen/LU>
#include <cmath>
#include <vector>

#include "core/imu_simulation.h"

namespace calibd::core {
namespace {

std::vector<TriadSeries> Triads(const ImuSimulation& sim) {
  return {TriadSeries{"a0", TriadKind::kAccelerometer, &sim.accel},
          TriadSeries{"g0", TriadKind::kGyroscope, &sim.gyro}};
}

// Every detected interval lies inside one true static, and every true static is found once.
void ExpectMatchesTruth(const StaticDetection& d, const ImuSimulation& sim,
                        const StaticDetectionOptions& o) {
  ASSERT_EQ(d.intervals.size(), sim.statics.size());
  for (size_t j = 0; j < sim.statics.size(); ++j) {
    const StaticInterval& iv = d.intervals[j];
    EXPECT_GE(iv.first, sim.statics[j].first) << "interval " << j << " starts in motion";
    EXPECT_LE(iv.last, sim.statics[j].second) << "interval " << j << " ends in motion";
    // Trimmed by about half a window at each end (a little more without noise: rounding in the
    // windows that reach into the motion), never by two windows.
    const double true_len = sim.t(sim.statics[j].second) - sim.t(sim.statics[j].first);
    EXPECT_GT(iv.end - iv.start, true_len - 2 * o.static_window) << "interval " << j;
    EXPECT_EQ(iv.samples, iv.last - iv.first + 1);
  }
}

ImuSimulationOptions Log() {
  ImuSimulationOptions so;
  so.statics = 10;
  so.static_duration = 4;
  so.rotation_duration = 2;
  so.seed = 3;
  return so;
}

TEST(StaticDetection, FindsEveryStaticInsideTheTrueOne) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  StaticDetectionOptions o;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  ExpectMatchesTruth(d, sim, o);
  EXPECT_EQ(d.window_samples, 101);
  EXPECT_NEAR(d.sample_period, 0.01, 1e-12);
  EXPECT_TRUE(d.gaps.empty());
  EXPECT_EQ(d.saturated_samples, 0);
  // The floor is the noise: the spread of white noise of σ per axis is σ√3.
  EXPECT_NEAR(d.noise_floor_si[0], 0.01 * std::sqrt(3.0), 0.2 * 0.01 * std::sqrt(3.0));
  EXPECT_NEAR(d.noise_floor_si[1], 0.002 * std::sqrt(3.0), 0.2 * 0.002 * std::sqrt(3.0));
  EXPECT_DOUBLE_EQ(d.threshold[0], 3 * d.noise_floor[0]);
  // Interval statistics: the mean is the true reading, the std the noise.
  const Eigen::Matrix3d ma_inv = sim.accel_truth.matrix.inverse();
  for (size_t j = 0; j < d.intervals.size(); ++j) {
    const Eigen::Vector3d f = sim.orientations[j].transpose() * Eigen::Vector3d(0, 0, 9.80665);
    const Eigen::Vector3d expected = ma_inv * f + sim.accel_truth.bias;
    const double se = 0.01 / std::sqrt(static_cast<double>(d.intervals[j].samples));
    EXPECT_LT((d.intervals[j].mean[0] - expected).cwiseAbs().maxCoeff(), 5 * se);
    EXPECT_NEAR(d.intervals[j].std[0].mean(), 0.01, 0.002);
  }
}

TEST(StaticDetection, ExactStaticsWithoutNoise) {
  ImuSimulationOptions so = Log();
  so.accel_noise = so.gyro_noise = 0;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  StaticDetectionOptions o;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  ExpectMatchesTruth(d, sim, o);
}

TEST(StaticDetection, NeedsNoInitialStaticWhenTheLogStartsMoving) {
  ImuSimulationOptions so = Log();
  so.initial_motion = 5;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  ASSERT_GT(sim.statics[0].first, 400);  // the log starts with 5 s of rotation
  StaticDetectionOptions o;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  ExpectMatchesTruth(d, sim, o);
}

TEST(StaticDetection, SlowBiasDriftDoesNotHideStatics) {
  ImuSimulationOptions so = Log();
  so.gyro_bias_drift = 2e-4;   // rad/s per s: 0.02 rad/s over the log, 10 × the noise
  so.accel_bias_drift = 1e-3;  // m/s² per s
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  StaticDetectionOptions o;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  ExpectMatchesTruth(d, sim, o);
}

TEST(StaticDetection, ABumpSplitsOrTrimsAStaticButNeverJoinsMotion) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  // A tap of 50 ms in the middle of static 4: 0.5 m/s² and 0.1 rad/s.
  const auto [first, last] = sim.statics[4];
  const int64_t mid = (first + last) / 2;
  for (int64_t i = mid; i < mid + 5; ++i) {
    sim.accel(i, 0) += 0.5;
    sim.gyro(i, 2) += 0.1;
  }
  StaticDetectionOptions o;
  o.min_static = 0.5;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  int in_static4 = 0;
  for (const StaticInterval& iv : d.intervals) {
    EXPECT_FALSE(iv.first <= mid + 4 && iv.last >= mid) << "an interval contains the bump";
    EXPECT_FALSE(iv.first <= mid && iv.last >= mid + 4);
    bool inside = false;
    for (const auto& [a, b] : sim.statics) inside = inside || (iv.first >= a && iv.last <= b);
    EXPECT_TRUE(inside) << "interval " << iv.start << ".." << iv.end << " contains motion";
    if (iv.first >= first && iv.last <= last) ++in_static4;
  }
  EXPECT_EQ(in_static4, 2);  // split in two
  EXPECT_EQ(d.intervals.size(), sim.statics.size() + 1);
}

TEST(StaticDetection, ReportsGapsAndNeverBridgesThem) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  // Drop 30 samples (0.3 s) in the middle of static 2.
  const int64_t cut = (sim.statics[2].first + sim.statics[2].second) / 2;
  const int64_t n = sim.t.size(), drop = 30;
  ImuSimulation g = sim;
  g.t.resize(n - drop);
  g.accel.resize(n - drop, 3);
  g.gyro.resize(n - drop, 3);
  g.t << sim.t.head(cut), sim.t.tail(n - cut - drop);
  g.accel << sim.accel.topRows(cut), sim.accel.bottomRows(n - cut - drop);
  g.gyro << sim.gyro.topRows(cut), sim.gyro.bottomRows(n - cut - drop);
  StaticDetectionOptions o;
  o.min_static = 0.5;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(g.t, Triads(g), o, &d).ok());
  ASSERT_EQ(d.gaps.size(), 1u);
  EXPECT_EQ(d.gaps[0].index, cut);
  EXPECT_NEAR(d.gaps[0].end - d.gaps[0].start, 0.31, 1e-9);
  for (const StaticInterval& iv : d.intervals) {
    EXPECT_FALSE(iv.first < cut && iv.last >= cut) << "an interval bridges the gap";
  }
  EXPECT_EQ(d.intervals.size(), sim.statics.size() + 1);
}

TEST(StaticDetection, DropsAndCountsSaturatedSamples) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  const int64_t mid = (sim.statics[5].first + sim.statics[5].second) / 2;
  for (int64_t i = mid; i < mid + 3; ++i) sim.gyro(i, 1) = 100;  // clipped at the limit
  std::vector<TriadSeries> triads = Triads(sim);
  triads[1].saturation_high = 100;
  triads[1].saturation_low = -100;
  StaticDetectionOptions o;
  o.min_static = 0.5;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, triads, o, &d).ok());
  EXPECT_EQ(d.saturated_samples, 3);
  EXPECT_EQ(d.saturated_per_triad[1], 3);
  EXPECT_EQ(d.saturated_per_triad[0], 0);
  for (const StaticInterval& iv : d.intervals) {
    EXPECT_FALSE(iv.first <= mid + 2 && iv.last >= mid) << "a saturated sample is in a static";
  }
}

TEST(StaticDetection, ThresholdOverrideAndMultipliers) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  StaticDetector det;
  StaticDetectionOptions o;
  ASSERT_TRUE(det.Init(sim.t, Triads(sim), o).ok());
  const StaticDetection d2 = det.Detect(2.0), d8 = det.Detect(8.0);
  EXPECT_DOUBLE_EQ(d8.threshold[1], 4 * d2.threshold[1]);
  EXPECT_GE(d8.static_samples, d2.static_samples);  // a higher threshold keeps more samples
  // A tiny absolute override leaves no static; a generous one for both kinds finds them all.
  o.gyro_threshold = 1e-9;
  ASSERT_TRUE(det.Init(sim.t, Triads(sim), o).ok());
  EXPECT_TRUE(det.Detect().intervals.empty());
  o.gyro_threshold = 0.02;
  o.accel_threshold = 0.1;
  ASSERT_TRUE(det.Init(sim.t, Triads(sim), o).ok());
  const StaticDetection d = det.Detect();
  EXPECT_TRUE(d.threshold_overridden[0] && d.threshold_overridden[1]);
  EXPECT_EQ(d.threshold[1], 0.02);
  ExpectMatchesTruth(d, sim, o);
}

TEST(StaticDetection, RejectsBadInputNamingIt) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  StaticDetection d;
  StaticDetectionOptions o;
  Eigen::VectorXd t = sim.t;
  t(100) = t(99);
  Status s = DetectStatics(t, Triads(sim), o, &d);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("strictly increasing: sample 100"), std::string::npos) << s.message();
  Eigen::MatrixX3d bad = sim.accel;
  bad(7, 2) = std::nan("");
  s = DetectStatics(sim.t, {TriadSeries{"a0", TriadKind::kAccelerometer, &bad}}, o, &d);
  EXPECT_NE(s.message().find("reading z at sample 7"), std::string::npos) << s.message();
  Eigen::MatrixX3d shorter = sim.accel.topRows(10);
  s = DetectStatics(sim.t, {TriadSeries{"a0", TriadKind::kAccelerometer, &shorter}}, o, &d);
  EXPECT_NE(s.message().find("has 10 samples"), std::string::npos) << s.message();
  o.static_window = -1;
  s = DetectStatics(sim.t, Triads(sim), o, &d);
  EXPECT_NE(s.message().find("static_window"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::core
