// Tests of static detection (core/static_detection.h) on simulated logs with known statics:
// no initial static needed, slow drift, a bump, gaps, saturation, bad input.
#include "core/static_detection.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <vector>

#include "core/array_simulation.h"
#include "core/imu_simulation.h"

namespace calibd::core {
namespace {

std::vector<TriadSeries> Triads(const ImuSimulation& sim) {
  return {TriadSeries{"a0", TriadKind::kAccelerometer, &sim.accel},
          TriadSeries{"g0", TriadKind::kGyroscope, &sim.gyro}};
}

// How far a grown interval may reach past a true static: the growth stops on the smooth end of a
// rotation (1 - cos rate profile) once the mean of the added samples leaves the noise. Measured
// over the logs of these tests: at most 0.14 s (the end of a slow 5 s rotation at 100 Hz); 11
// samples at 200 Hz. kEdgeSeconds bounds it, kEdge in samples at the 100 Hz of Log().
constexpr double kEdgeSeconds = 0.15;
constexpr int64_t kEdge = 15;

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
    // The extent: the whole static, within kEdge samples.
    EXPECT_LE(std::abs(iv.extent_first - sim.statics[j].first), kEdge) << "interval " << j;
    EXPECT_LE(std::abs(iv.extent_last - sim.statics[j].second), kEdge) << "interval " << j;
    EXPECT_LE(iv.extent_first, iv.first);
    EXPECT_GE(iv.extent_last, iv.last);
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

// A log with a long hand-twisted dynamic phase and few statics: SimulateImu's 10 statics of 3 s
// (joined by 2 s rotations), plus a dynamic phase before or after them whose length sets the
// static fraction of the log. The dynamic phase turns the board with a random, never resting
// angular rate (two sinusoids of 0.5-2 rad/s and 0.2-1.5 Hz per axis, faded in over 1 s), the
// accelerometer reading gravity in the turning body frame; the noise as in the statics.
struct MixedLog {
  ImuSimulation sim;  // t, accel, gyro of the whole log; statics: the true static samples
};

MixedLog SimulateMixedLog(double static_fraction, bool dynamic_first, uint64_t seed) {
  MixedLog log;
  ImuSimulationOptions so;
  so.statics = 10;
  so.static_duration = 3;
  so.rotation_duration = 2;
  so.rate = 50;
  so.seed = seed;
  ImuSimulation base;
  EXPECT_TRUE(SimulateImu(so, &base).ok());
  const int64_t nb = base.t.size();
  const double total = so.statics * so.static_duration / static_fraction;
  const int64_t nd =
      std::max<int64_t>(0, std::llround((total - static_cast<double>(nb) / so.rate) * so.rate));
  GaussianRng rng(seed * 7919 + 13);
  Eigen::MatrixX3d da(nd, 3), dg(nd, 3);
  double amp[3][2], freq[3][2], phase[3][2];
  for (int a = 0; a < 3; ++a)
    for (int c = 0; c < 2; ++c) {
      amp[a][c] = 0.5 + 1.5 * rng.Uniform();
      freq[a][c] = 0.2 + 1.3 * rng.Uniform();
      phase[a][c] = 2 * M_PI * rng.Uniform();
    }
  // Start from the orientation at the junction (the first or last static's gravity direction).
  Eigen::Vector3d f = (dynamic_first ? base.accel.row(0) : base.accel.row(nb - 1)).transpose();
  f *= so.gravity / f.norm();
  const double dt = 1 / so.rate;
  for (int64_t n = 0; n < nd; ++n) {
    const double tt = static_cast<double>(n) * dt;
    const double fade = std::min(1.0, tt);
    Eigen::Vector3d w;
    for (int a = 0; a < 3; ++a)
      w(a) = fade * (amp[a][0] * std::sin(2 * M_PI * freq[a][0] * tt + phase[a][0]) +
                     amp[a][1] * std::sin(2 * M_PI * freq[a][1] * tt + phase[a][1]));
    f -= dt * w.cross(f);  // gravity fixed in the world: df/dt = -omega x f
    f *= so.gravity / f.norm();
    for (int a = 0; a < 3; ++a) {
      da(n, a) = f(a) + so.accel_noise * rng.Normal();
      dg(n, a) = w(a) + so.gyro_noise * rng.Normal();
    }
  }
  ImuSimulation& out = log.sim;
  const int64_t n = nb + nd;
  out.t = Eigen::VectorXd::LinSpaced(n, 0, static_cast<double>(n - 1) * dt);
  out.accel.resize(n, 3);
  out.gyro.resize(n, 3);
  const int64_t b0 = dynamic_first ? nd : 0, d0 = dynamic_first ? 0 : nb;
  out.accel.middleRows(b0, nb) = base.accel;
  out.gyro.middleRows(b0, nb) = base.gyro;
  out.accel.middleRows(d0, nd) = da;
  out.gyro.middleRows(d0, nd) = dg;
  for (const auto& st : base.statics) out.statics.push_back({st.first + b0, st.second + b0});
  return log;
}

// Over many logs (fixed seeds) with 3 %, 5 % and 50 % of the time static, the dynamic phase
// first or last: every static is found (one interval inside it) and no motion is ever called
// static, and the floor is the statics' noise (the spread of white noise of sigma per axis is
// sigma sqrt(3)). Zero failures in 16 logs x 10 statics per fraction bounds the miss rate below
// 3/160 (95 %).
TEST(StaticDetection, FindsEveryStaticAndNoMotionWhenOnlyAFewPercentOfTheLogIsStatic) {
  StaticDetectionOptions o;
  for (double fraction : {0.03, 0.05, 0.5}) {
    int missed = 0, motion = 0, intervals = 0, floors_off = 0;
    const int trials = 16;
    for (int trial = 0; trial < trials; ++trial) {
      const MixedLog log = SimulateMixedLog(fraction, trial % 2 == 0, 100 + trial);
      const ImuSimulation& sim = log.sim;
      StaticDetection d;
      ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
      const double static_samples = static_cast<double>(10 * 150);
      EXPECT_NEAR(static_samples / static_cast<double>(sim.t.size()), fraction, 0.1 * fraction);
      std::vector<int> found(sim.statics.size(), 0);
      for (const StaticInterval& iv : d.intervals) {
        ++intervals;
        bool inside = false;
        for (size_t j = 0; j < sim.statics.size(); ++j) {
          if (iv.first >= sim.statics[j].first && iv.last <= sim.statics[j].second) {
            inside = true;
            ++found[j];
          }
        }
        if (!inside) ++motion;
      }
      for (int f : found) missed += f == 1 ? 0 : 1;
      if (std::abs(d.noise_floor_si[0] / (0.01 * std::sqrt(3.0)) - 1) > 0.2 ||
          std::abs(d.noise_floor_si[1] / (0.002 * std::sqrt(3.0)) - 1) > 0.2)
        ++floors_off;
    }
    EXPECT_EQ(missed, 0) << "fraction " << fraction << ": statics not found exactly once";
    EXPECT_EQ(motion, 0) << "fraction " << fraction << ": intervals reaching into motion";
    EXPECT_EQ(floors_off, 0) << "fraction " << fraction << ": noise floor off by > 20 %";
    EXPECT_EQ(intervals, trials * 10) << "fraction " << fraction;
  }
}

// A static of L >= min_static is found (issue #20): 2 s statics with the default 1 s window and
// 1 s minimum, at 62.5 Hz and other rates, noise-free and noisy, with their full length (each run
// of quiet windows grown back out by the half-window).
TEST(StaticDetection, TwoSecondStaticsAreFoundWithTheirBounds) {
  for (double rate : {62.5, 50.0, 100.0, 200.0}) {
    for (double noise : {0.0, 1.0}) {
      for (uint64_t seed = 1; seed <= 4; ++seed) {
        SCOPED_TRACE("rate " + std::to_string(rate) + " noise " + std::to_string(noise) + " seed " +
                     std::to_string(seed));
        ImuSimulationOptions so;
        so.rate = rate;
        so.statics = 12;
        so.static_duration = 2;
        so.rotation_duration = 2;
        so.seed = seed;
        so.accel_noise *= noise;
        so.gyro_noise *= noise;
        ImuSimulation sim;
        ASSERT_TRUE(SimulateImu(so, &sim).ok());
        StaticDetectionOptions o;
        StaticDetection d;
        ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
        ASSERT_EQ(d.intervals.size(), sim.statics.size());
        for (size_t j = 0; j < sim.statics.size(); ++j) {
          const StaticInterval& iv = d.intervals[j];
          const auto [first, last] = sim.statics[j];
          // The extent: noise-free, the exact static (the rotation's first sample, at rest, may
          // join); noisy, within kEdgeSeconds of it.
          const int64_t edge =
              noise == 0 ? 1 : static_cast<int64_t>(std::ceil(kEdgeSeconds * rate));
          EXPECT_LE(std::abs(iv.extent_first - first), edge)
              << "static " << j << ": first " << iv.extent_first - first << ", last "
              << iv.extent_last - last;
          EXPECT_LE(std::abs(iv.extent_last - last), edge)
              << "static " << j << ": first " << iv.extent_first - first << ", last "
              << iv.extent_last - last;
          // The samples used: inside the static, half a window from each end.
          EXPECT_GE(iv.first, first);
          EXPECT_LE(iv.last, last);
          EXPECT_GT(iv.samples, 0);
          EXPECT_GE(iv.extent_end - iv.extent_start, o.min_static);
        }
        EXPECT_TRUE(d.short_stretches.empty());
      }
    }
  }
}

// When too few statics are found, StaticShortfall says what was found and what to change.
TEST(StaticDetection, TheShortfallMessageListsTheStillStretches) {
  ImuSimulationOptions so;
  so.statics = 5;
  so.static_duration = 1.5;
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(so, &sim).ok());
  StaticDetectionOptions o;
  o.min_static = 2;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  EXPECT_TRUE(d.intervals.empty());
  ASSERT_EQ(d.short_stretches.size(), 5u);
  for (size_t j = 0; j < 5; ++j) {
    EXPECT_NEAR(d.short_stretches[j].end - d.short_stretches[j].start, 1.5, 0.1) << j;
    EXPECT_NEAR(d.short_stretches[j].start, sim.t(sim.statics[j].first), 0.1) << j;
  }
  const std::string m = StaticShortfall(d);
  for (const char* part : {"static_window 1 s", "min_static 2 s", "threshold 3 × noise floor",
                           "found 0 static interval(s)",
                           "5 still stretch(es) shorter than "
                           "min_static (1.",
                           "longest 1.", "lower min_static", "a0 ", "g0 "}) {
    EXPECT_NE(m.find(part), std::string::npos) << "missing \"" << part << "\" in: " << m;
  }
  // A threshold below the noise: no stretch at all, and the advice names static_threshold.
  o.accel_threshold = 1e-6;
  o.gyro_threshold = 1e-6;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());
  EXPECT_TRUE(d.intervals.empty() && d.short_stretches.empty());
  const std::string none = StaticShortfall(d);
  EXPECT_NE(none.find("no shorter still stretch"), std::string::npos) << none;
  EXPECT_NE(none.find("static_threshold"), std::string::npos) << none;
  EXPECT_NE(none.find("a0 1e-06 reading units (static_threshold)"), std::string::npos) << none;
}

TEST(StaticDetection, StopsWhenTheTokenAsks) {
  ImuSimulation sim;
  ASSERT_TRUE(SimulateImu(Log(), &sim).ok());
  StopToken token;
  StaticDetectionOptions o;
  o.stop = &token;
  StaticDetection d;
  ASSERT_TRUE(DetectStatics(sim.t, Triads(sim), o, &d).ok());  // not stopped: runs
  token.RequestStop(StopReason::kDeadline);
  const Status s = DetectStatics(sim.t, Triads(sim), o, &d);
  EXPECT_EQ(s.code(), StatusCode::kStopped);
  EXPECT_EQ(s.reason(), Reason::kDeadline);
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
  o.static_window = 1;
  o.noise_floor_cluster_width = 1;
  s = DetectStatics(sim.t, Triads(sim), o, &d);
  EXPECT_NE(s.message().find("noise_floor_cluster_width"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace calibd::core
