// Tests of saturation found in the data (core/saturation.h): clipped triads are found and counted
// exactly, a peak touched once, statics at the channel's extreme, quantized quiet logs and clean
// motion are not saturation, a configured limit overrides, bad input and the stop token.
#include "core/saturation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/imu_simulation.h"

namespace calibd::core {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A triad shaken hard (each axis a sum of two sines of random frequency 0.5-3 Hz and phase, peak
// `amplitude`) with white noise, 100 Hz, `seconds` long.
Eigen::MatrixX3d Shake(uint64_t seed, double amplitude, double noise, double seconds = 60) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> f(0.5, 3), phase(0, 2 * kPi);
  std::normal_distribution<double> normal;
  const int64_t n = static_cast<int64_t>(seconds * 100);
  Eigen::MatrixX3d y(n, 3);
  for (int a = 0; a < 3; ++a) {
    const double f1 = f(rng), f2 = f(rng), p1 = phase(rng), p2 = phase(rng);
    for (int64_t i = 0; i < n; ++i) {
      const double t = i / 100.0;
      y(i, a) = amplitude * (0.6 * std::sin(2 * kPi * f1 * t + p1) +
                             0.4 * std::sin(2 * kPi * f2 * t + p2)) +
                noise * normal(rng);
    }
  }
  return y;
}

// y clipped to [-limit, limit]; counts per channel and side of the clipped samples.
Eigen::MatrixX3d Clip(const Eigen::MatrixX3d& x, double limit, int64_t low[3], int64_t high[3]) {
  Eigen::MatrixX3d y = x;
  for (int a = 0; a < 3; ++a) {
    low[a] = high[a] = 0;
    for (Eigen::Index i = 0; i < y.rows(); ++i) {
      if (y(i, a) >= limit) {
        y(i, a) = limit;
        ++high[a];
      } else if (y(i, a) <= -limit) {
        y(i, a) = -limit;
        ++low[a];
      }
    }
  }
  return y;
}

TEST(Saturation, ClippedTriadsAreFoundAndCountedExactly) {
  // 20 seeds x 3 axes x 2 sides: every side clipped for 10 samples or more (nearly all: two sines
  // of peak 2 x limit / 1.5 over 60 s) has its level found and every clipped sample counted, none
  // more; a side never clipped has no level.
  int sides = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const Eigen::MatrixX3d x = Shake(seed, 2.0, 0.002);
    int64_t low[3], high[3];
    const Eigen::MatrixX3d y = Clip(x, 1.5, low, high);
    std::array<ChannelSaturation, 3> out;
    ASSERT_TRUE(FindTriadSaturation(y, "g0", SaturationOptions(), &out).ok());
    for (int a = 0; a < 3; ++a) {
      SCOPED_TRACE("seed " + std::to_string(seed) + " axis " + std::to_string(a));
      EXPECT_EQ(out[a].name, std::string("g0_") + "xyz"[a]);
      if (high[a] >= 10) {
        ++sides;
        EXPECT_EQ(out[a].high, 1.5);
        EXPECT_EQ(out[a].pinned_high, high[a]);
      } else if (high[a] == 0) {
        EXPECT_EQ(out[a].pinned_high, 0);
      }
      if (low[a] >= 10) {
        ++sides;
        EXPECT_EQ(out[a].low, -1.5);
        EXPECT_EQ(out[a].pinned_low, low[a]);
      } else if (low[a] == 0) {
        EXPECT_EQ(out[a].pinned_low, 0);
      }
      if (out[a].pinned() > 0) {
        EXPECT_EQ(out[a].source, "data");
      }
    }
  }
  EXPECT_GE(sides, 100);  // of 120: the test exercises what it claims
}

TEST(Saturation, QuantizedCountsClippedAtTheInt16RangeAreFound) {
  // MIMU4444-like: int16 counts at 62.5 Hz... here 100 Hz, a shake beyond full scale, the noise a
  // few counts; clipped at 32767 / -32768 (asymmetric).
  const Eigen::MatrixX3d x = Shake(7, 40000, 3).array().round();
  Eigen::MatrixX3d y = x;
  int64_t high[3] = {0, 0, 0}, low[3] = {0, 0, 0};
  for (int a = 0; a < 3; ++a)
    for (Eigen::Index i = 0; i < y.rows(); ++i) {
      if (y(i, a) >= 32767) y(i, a) = 32767, ++high[a];
      if (y(i, a) <= -32768) y(i, a) = -32768, ++low[a];
    }
  std::array<ChannelSaturation, 3> out;
  ASSERT_TRUE(FindTriadSaturation(y, "g1", SaturationOptions(), &out).ok());
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(out[a].high, 32767);
    EXPECT_EQ(out[a].low, -32768);
    EXPECT_EQ(out[a].pinned_high, high[a]);
    EXPECT_EQ(out[a].pinned_low, low[a]);
  }
  // The float overload (the noise method's columns) gives the same.
  std::array<ChannelSaturation, 3> out_f;
  const Eigen::MatrixXf yf = y.cast<float>();
  ASSERT_TRUE(FindTriadSaturation(yf, "g1", SaturationOptions(), &out_f).ok());
  for (int a = 0; a < 3; ++a) EXPECT_EQ(out_f[a].pinned(), out[a].pinned());
}

TEST(Saturation, CleanMotionIsNotSaturation) {
  // The same shakes without clipping: no level on any channel of 50 seeds.
  for (uint64_t seed = 1; seed <= 50; ++seed) {
    const Eigen::MatrixX3d y = Shake(seed, 2.0, 0.002);
    std::array<ChannelSaturation, 3> out;
    ASSERT_TRUE(FindTriadSaturation(y, "g0", SaturationOptions(), &out).ok());
    for (int a = 0; a < 3; ++a) {
      EXPECT_EQ(out[a].pinned(), 0) << "seed " << seed << " axis " << a;
      EXPECT_EQ(out[a].source, "");
      EXPECT_FALSE(std::isfinite(out[a].high));
      EXPECT_FALSE(std::isfinite(out[a].low));
    }
  }
}

TEST(Saturation, APeakTouchedOnceIsNotSaturation) {
  // A clean shake with its maximum repeated on the next sample would be a run; a single sample
  // at the maximum (the peak itself, far above everything else) is not.
  Eigen::MatrixX3d y = Shake(3, 2.0, 0.002);
  Eigen::Index peak = 0;
  y.col(0).maxCoeff(&peak);
  y(peak, 0) = 10;  // a spike: one sample, entered and left by a jump
  std::array<ChannelSaturation, 3> out;
  ASSERT_TRUE(FindTriadSaturation(y, "a0", SaturationOptions(), &out).ok());
  EXPECT_EQ(out[0].pinned(), 0);
  // The same spike held for 3 samples while the triad moves is a clip.
  const Eigen::Index at = peak + 1 < y.rows() - 2 ? peak : peak - 3;
  y(at, 0) = y(at + 1, 0) = y(at + 2, 0) = 10;
  ASSERT_TRUE(FindTriadSaturation(y, "a0", SaturationOptions(), &out).ok());
  EXPECT_EQ(out[0].pinned_high, at == peak ? 3 : 4);
}

TEST(Saturation, StaticsAtTheExtremeAreNotSaturation) {
  // imu_tk-style logs, noise-free and noisy: the statics' constant (or quiet) readings are often
  // a channel's extreme (an axis pointing up), entered smoothly and with every axis quiet.
  for (double noise : {0.0, 1.0}) {
    for (uint64_t seed = 1; seed <= 10; ++seed) {
      ImuSimulationOptions so;
      so.seed = seed;
      so.accel_noise *= noise;
      so.gyro_noise *= noise;
      ImuSimulation sim;
      ASSERT_TRUE(SimulateImu(so, &sim).ok());
      for (const Eigen::MatrixX3d* y : {&sim.accel, &sim.gyro}) {
        std::array<ChannelSaturation, 3> out;
        ASSERT_TRUE(FindTriadSaturation(*y, "x", SaturationOptions(), &out).ok());
        for (int a = 0; a < 3; ++a) {
          EXPECT_EQ(out[a].pinned(), 0) << "noise " << noise << " seed " << seed << " axis " << a;
        }
      }
    }
  }
}

TEST(Saturation, AQuietQuantizedLogIsNotSaturation) {
  // A noise log in counts (σ 0.7 count): runs of equal values at the extremes are common, but
  // they are left by noise-sized steps.
  // Coarse (σ 0.3 count: readings -1, 0, +1 around the mean, the extremes held for 3 samples
  // now and then) to fine.
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  for (double sigma : {0.3, 0.7, 2.0}) {
    for (int trial = 0; trial < 20; ++trial) {
      Eigen::MatrixX3d y(20000, 3);
      for (Eigen::Index i = 0; i < y.rows(); ++i)
        for (int a = 0; a < 3; ++a) y(i, a) = std::round(100 + sigma * normal(rng));
      std::array<ChannelSaturation, 3> out;
      ASSERT_TRUE(FindTriadSaturation(y, "g0", SaturationOptions(), &out).ok());
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(out[a].pinned(), 0) << "sigma " << sigma << " trial " << trial;
      }
    }
  }
}

TEST(Saturation, AConfiguredLimitOverridesTheSearch) {
  int64_t low[3], high[3];
  const Eigen::MatrixX3d y = Clip(Shake(2, 2.0, 0.002), 1.5, low, high);
  SaturationOptions o;
  o.low = -1.2;
  o.high = 1.2;
  std::array<ChannelSaturation, 3> out;
  ASSERT_TRUE(FindTriadSaturation(y, "g0", o, &out).ok());
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(out[a].source, "config");
    EXPECT_EQ(out[a].high, 1.2);
    EXPECT_EQ(out[a].pinned_high, (y.col(a).array() >= 1.2).count());
    EXPECT_EQ(out[a].pinned_low, (y.col(a).array() <= -1.2).count());
    EXPECT_GT(out[a].pinned_high, high[a]);
  }
  // A configured limit on clean data counts what reaches it, too.
  const Eigen::MatrixX3d clean = Shake(2, 1.0, 0.002);
  ASSERT_TRUE(FindTriadSaturation(clean, "g0", o, &out).ok());
  for (int a = 0; a < 3; ++a) EXPECT_EQ(out[a].pinned(), 0);
}

TEST(Saturation, CombinedAndSymmetricLimits) {
  std::vector<ChannelSaturation> c(3);
  c[0].low = -1998.05;
  c[0].high = 1997.99;
  c[1].high = 1998.5;
  const SaturationLimits l = CombinedLimits(c);
  EXPECT_EQ(l.low, -1998.05);
  EXPECT_EQ(l.high, 1997.99);
  EXPECT_TRUE(l.any());
  ASSERT_TRUE(SymmetricLimit(l).has_value());
  EXPECT_EQ(*SymmetricLimit(l), 1997.99);
  EXPECT_FALSE(CombinedLimits({ChannelSaturation()}).any());
  EXPECT_FALSE(SymmetricLimit(SaturationLimits()).has_value());
  // Offset-binary levels [0, 65535] are not a centred range: no symmetric limit.
  EXPECT_FALSE(SymmetricLimit(SaturationLimits{0, 65535}).has_value());
}

TEST(Saturation, BadInputAndStop) {
  Eigen::MatrixX3d y = Shake(1, 1, 0.01, 1);
  std::array<ChannelSaturation, 3> out;
  SaturationOptions bad;
  bad.min_run = 1;
  Status s = FindTriadSaturation(y, "g0", bad, &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("min_run"), std::string::npos) << s.message();
  bad = SaturationOptions();
  bad.low = 2;
  bad.high = 1;
  EXPECT_EQ(FindTriadSaturation(y, "g0", bad, &out).code(), StatusCode::kInvalidInput);
  y(17, 1) = std::nan("");
  s = FindTriadSaturation(y, "g0", SaturationOptions(), &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("g0_y at sample 17"), std::string::npos) << s.message();
  y(17, 1) = 0;
  StopToken token;
  token.RequestStop(StopReason::kCancelled);
  SaturationOptions o;
  o.stop = &token;
  s = FindTriadSaturation(y, "g0", o, &out);
  EXPECT_EQ(s.code(), StatusCode::kStopped);
  EXPECT_EQ(s.reason(), Reason::kCancelled);
}

}  // namespace
}  // namespace calibd::core
