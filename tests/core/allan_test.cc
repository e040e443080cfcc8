// Tests of the overlapping Allan deviation: the O(n) cumulative-sum algorithm against direct
// summation, its precision on long logs with large offsets, the white-noise law σ = N/√τ, and the
// chi-square intervals from the equivalent degrees of freedom (coverage over many seeds, and the
// EDF against the Monte-Carlo variance of the estimator).
#include "core/allan.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <vector>

#include "core/noise_simulation.h"
#include "core/pca_simulation.h"

namespace calibd::core {
namespace {

std::vector<float> WhiteNoise(int64_t n, double sigma, double offset, uint64_t seed) {
  PcaRandom rng(seed);
  std::vector<float> y(static_cast<size_t>(n));
  for (auto& v : y) v = static_cast<float>(offset + sigma * rng.Normal());
  return y;
}

NoiseSimulationOptions OneChannel(double rate, double duration, double n, double k, double b,
                                  double offset, uint64_t seed) {
  NoiseSimulationOptions o;
  o.rate = rate;
  o.duration = duration;
  NoiseSimulationChannel c;
  c.white_noise = n;
  c.random_walk = k;
  c.bias_instability = b;
  c.offset = offset;
  o.channels = {c};
  o.seed = seed;
  return o;
}

TEST(AllanClusterSizes, OctavesAndDecadesFromOneSampleToAQuarterOfTheLog) {
  EXPECT_EQ(AllanClusterSizes(4096, 0),
            (std::vector<int64_t>{1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024}));
  EXPECT_EQ(AllanClusterSizes(4095, 0).back(), 512);
  EXPECT_TRUE(AllanClusterSizes(3, 0).empty());
  const std::vector<int64_t> d = AllanClusterSizes(400, 10);
  EXPECT_EQ(d.front(), 1);
  EXPECT_EQ(d.back(), 100);
  for (size_t j = 1; j < d.size(); ++j) EXPECT_GT(d[j], d[j - 1]);
  // 10 per decade: 1 2 3 4 5 6 8 10 13 16 20 25 32 40 50 63 79 100.
  EXPECT_EQ(d.size(), 18u);
}

TEST(OverlappingAllanVariance, FastEqualsDirectSummationToRounding) {
  // White noise + random walk + Gauss-Markov on a large offset, both spacings.
  const NoiseSimulation sim = SimulateNoise(OneChannel(100, 60, 2e-3, 5e-4, 3e-4, 9.81, 3));
  const float* y = sim.samples.col(0).data();
  const int64_t n = sim.samples.rows();
  for (int per_decade : {0, 7}) {
    const std::vector<int64_t> m = AllanClusterSizes(n, per_decade);
    const std::vector<double> fast = OverlappingAllanVariance(y, n, m);
    const std::vector<double> slow = OverlappingAllanVarianceDirect(y, n, m);
    ASSERT_EQ(fast.size(), slow.size());
    double worst = 0;
    for (size_t j = 0; j < m.size(); ++j) {
      worst = std::max(worst, std::fabs(fast[j] - slow[j]) / slow[j]);
    }
    std::printf("n=%lld, %zu cluster times: largest relative difference %.2e\n",
                static_cast<long long>(n), m.size(), worst);
    EXPECT_LT(worst, 1e-11);
  }
  // The non-overlapping reference agrees in expectation only; at m = 1 both use every difference.
  const std::vector<double> non = NonOverlappingAllanVarianceDirect(y, n, {1});
  const std::vector<double> over = OverlappingAllanVariance(y, n, {1});
  EXPECT_NEAR(non[0], over[0], 1e-12 * over[0]);
}

TEST(OverlappingAllanVariance, KeepsPrecisionForAnHourAt1kHzOnGravity) {
  // 3.6 M samples of 9.81 m/s² + 1e-3 noise: an uncentred double cumulative sum reaches 3.5e7
  // (ulp 7e-9), which would cost ~1e-5 relative at m = 1. Subtracting 8 is exact in float, so
  // the two logs have exactly the same Allan variance.
  const int64_t n = 3600 * 1000;
  std::vector<float> y = WhiteNoise(n, 1e-3, 9.81, 11);
  std::vector<float> shifted(y.size());
  for (size_t i = 0; i < y.size(); ++i) shifted[i] = y[i] - 8.0f;
  const std::vector<int64_t> m = AllanClusterSizes(n, 0);
  const std::vector<double> a = OverlappingAllanVariance(y.data(), n, m);
  const std::vector<double> b = OverlappingAllanVariance(shifted.data(), n, m);
  for (size_t j = 0; j < m.size(); ++j) EXPECT_NEAR(a[j], b[j], 1e-10 * b[j]) << "m=" << m[j];
  const std::vector<int64_t> small = {1, 2, 8};
  const std::vector<double> fast = OverlappingAllanVariance(y.data(), n, small);
  const std::vector<double> slow = OverlappingAllanVarianceDirect(y.data(), n, small);
  for (size_t j = 0; j < small.size(); ++j) {
    EXPECT_NEAR(fast[j], slow[j], 1e-11 * slow[j]) << "m=" << small[j];
  }
}

TEST(OverlappingAllanVariance, IsBitIdenticalForAnyNumberOfThreads) {
  // More than 256 blocks of 8192 starts (two groups of tasks), short and long cluster sizes.
  const int64_t n = 2200000;
  const std::vector<float> y = WhiteNoise(n, 2e-2, 9.81, 5);
  const std::vector<int64_t> m = AllanClusterSizes(n, 3);
  const std::vector<double> one = OverlappingAllanVariance(y.data(), n, m, 1);
  int executor_tasks = 0;
  const TaskExecutor serial = [&](int64_t tasks, const std::function<void(int64_t)>& run) {
    for (int64_t i = tasks; i-- > 0;) run(i);  // any order
    executor_tasks += static_cast<int>(tasks);
  };
  for (const std::vector<double>& other :
       {OverlappingAllanVariance(y.data(), n, m, 2), OverlappingAllanVariance(y.data(), n, m, 3),
        OverlappingAllanVariance(y.data(), n, m, 1, serial)}) {
    ASSERT_EQ(other.size(), one.size());
    for (size_t j = 0; j < m.size(); ++j) EXPECT_EQ(other[j], one[j]) << "m=" << m[j];
  }
  EXPECT_GT(executor_tasks, 269);  // the executor ran the blocks (269 blocks of short m)
}

TEST(OverlappingAllanVariance, FloatSamplesMatchTheDoubleReferenceToAStatedTolerance) {
  // The server holds the samples as float (4 bytes each); the cumulative sum stays double. The
  // only loss is the rounding of each sample to float: a white error of standard deviation
  // q = ulp/√12 (ulp of the offset: 9.5e-7 on 9.81 m/s²) against the per-sample σ = N·√rate =
  // 5e-3 m/s² of a MEMS accelerometer at 100 Hz (N = 5e-4 m/s²/√Hz; the random walk only adds
  // to the signal). By Cauchy-Schwarz the Allan variance then moves by at most 2ρ + ρ² relative,
  // ρ² = Σ d_q² / Σ d_signal² ≈ q²/σ² over the cluster differences; the tolerance is 2ρ with a
  // factor 2 for the fluctuation of that ratio at the longest τ (few clusters): 2.2e-4 on
  // gravity, 7e-7 on a gyroscope's small offset. A float cumulative sum (7 digits over 360 k
  // samples) or half-precision storage miss it by orders of magnitude. The reference is the
  // double samples' Allan variance from a long double cumulative sum.
  const int64_t n = 100 * 3600;
  for (const double offset : {9.81, 0.0123}) {
    const NoiseSimulation sim = SimulateNoise(OneChannel(100, 3600, 5e-4, 3e-5, 0, 0, 17));
    std::vector<double> yd(static_cast<size_t>(n));
    PcaRandom extra(29);
    // Double samples with digits a float cannot hold.
    for (int64_t i = 0; i < n; ++i) {
      yd[static_cast<size_t>(i)] =
          offset + static_cast<double>(sim.samples(i, 0)) + 1e-9 * extra.Normal();
    }
    std::vector<float> yf(yd.begin(), yd.end());
    const std::vector<int64_t> m = AllanClusterSizes(n, 5);
    const std::vector<double> fast = OverlappingAllanVariance(yf.data(), n, m, 2);
    std::vector<long double> s(static_cast<size_t>(n) + 1, 0.0L);
    for (int64_t i = 0; i < n; ++i) s[i + 1] = s[i] + (yd[i] - offset);
    double worst = 0;
    for (size_t j = 0; j < m.size(); ++j) {
      const int64_t k = m[j], count = n - 2 * k + 1;
      long double sum = 0;
      for (int64_t i = 0; i < count; ++i) {
        const long double d = s[i + 2 * k] - 2 * s[i + k] + s[i];
        sum += d * d;
      }
      const double reference = static_cast<double>(sum / (2.0L * k * k * count));
      worst = std::max(worst, std::fabs(fast[j] - reference) / reference);
    }
    std::printf("offset %g: float storage vs double reference, largest relative difference %.2e\n",
                offset, worst);
    const double ulp =
        std::nextafter(static_cast<float>(offset), 1e9f) - static_cast<float>(offset);
    const double rho = ulp / std::sqrt(12.0) / (5e-4 * std::sqrt(100.0));
    EXPECT_LT(worst, 4 * rho) << "offset " << offset;
    EXPECT_GT(worst, 0.0);  // the float rounding is there, and measured
  }
}

TEST(ChiSquareQuantile, MatchesTabulatedValues) {
  EXPECT_NEAR(ChiSquareQuantile(0.975, 1), 5.023886187, 1e-8);
  EXPECT_NEAR(ChiSquareQuantile(0.025, 10), 3.246972780, 1e-8);
  EXPECT_NEAR(ChiSquareQuantile(0.5, 2), 2 * std::log(2.0), 1e-10);
  EXPECT_NEAR(ChiSquareQuantile(0.95, 100), 124.3421134, 1e-6);
  EXPECT_NEAR(ChiSquareQuantile(0.15865, 1e6), 1e6 - std::sqrt(2e6), 2.0);
  for (double dof : {0.7, 1.0, 3.3, 40.0, 5e4}) {
    for (double p : {0.001, 0.15865, 0.5, 0.84135, 0.999}) {
      EXPECT_NEAR(RegularizedGammaP(dof / 2, ChiSquareQuantile(p, dof) / 2), p, 1e-10);
    }
  }
}

TEST(AllanDeviation, WhiteNoiseFollowsInverseSqrtTauWithinEdfBounds) {
  const double rate = 100, density = 2e-3;  // N, unit/√Hz
  const int64_t n = 200000;
  const std::vector<float> y = WhiteNoise(n, density * std::sqrt(rate), 0.5, 5);
  AllanOptions o;
  o.confidence = 0.999;
  AllanCurve curve;
  ASSERT_TRUE(ComputeAllanDeviation(y.data(), n, 1 / rate, o, &curve).ok());
  ASSERT_EQ(curve.size(), AllanClusterSizes(n, 0).size());
  for (size_t j = 0; j < curve.size(); ++j) {
    const double truth = density / std::sqrt(curve.tau[j]);
    EXPECT_LE(curve.adev_lower[j], truth) << "tau=" << curve.tau[j];
    EXPECT_GE(curve.adev_upper[j], truth) << "tau=" << curve.tau[j];
    EXPECT_LT(curve.adev_lower[j], curve.adev[j]);
    EXPECT_GT(curve.adev_upper[j], curve.adev[j]);
  }
  // A wrong law fails: σ = N/τ (slope −1) is far outside the intervals at long τ.
  EXPECT_LT(density / curve.tau.back(), 0.5 * curve.adev_lower.back());
}

// For each cluster size: fraction of seeds whose interval covers the true Allan deviation, and
// the Monte-Carlo variance of σ̂² against 2σ⁴/edf.
struct Coverage {
  std::vector<int64_t> m;
  std::vector<double> covered, variance_ratio;
};

Coverage MeasureCoverage(double white, double walk, AllanNoiseType type, int seeds, int64_t n) {
  Coverage c;
  const double rate = 100;
  c.m = AllanClusterSizes(n, 0);
  c.covered.assign(c.m.size(), 0);
  std::vector<double> sum(c.m.size(), 0), sum2(c.m.size(), 0), truth(c.m.size());
  const NoiseSimulationOptions base = OneChannel(rate, n / rate, white, walk, 0, 0, 0);
  for (size_t j = 0; j < c.m.size(); ++j) truth[j] = SimulatedAllanVariance(base, 0, c.m[j]);
  AllanCurve curve;
  for (int s = 0; s < seeds; ++s) {
    NoiseSimulationOptions o = base;
    o.seed = 1000 + s;
    const NoiseSimulation sim = SimulateNoise(o);
    EXPECT_TRUE(
        ComputeAllanDeviation(sim.samples.col(0).data(), n, 1 / rate, AllanOptions(), &curve).ok());
    SetAllanConfidence({type}, 0.6827, &curve);
    for (size_t j = 0; j < c.m.size(); ++j) {
      const double t = std::sqrt(truth[j]);
      c.covered[j] += curve.adev_lower[j] <= t && t <= curve.adev_upper[j];
      sum[j] += curve.avar[j] / truth[j];
      sum2[j] += curve.avar[j] * curve.avar[j] / (truth[j] * truth[j]);
    }
  }
  for (size_t j = 0; j < c.m.size(); ++j) {
    c.covered[j] /= seeds;
    const double mean = sum[j] / seeds;
    const double var = sum2[j] / seeds - mean * mean;
    c.variance_ratio.push_back(var * AllanEdf(type, n, c.m[j]) / 2);  // 1 when the EDF is right
    std::printf("m=%6lld coverage %.3f  mean ratio %.3f  var*edf/2 %.3f\n",
                static_cast<long long>(c.m[j]), c.covered[j], mean, c.variance_ratio.back());
  }
  return c;
}

// Each point is a binomial proportion over `seeds` seeds, SE = √(p(1−p)/seeds) (0.023 for 400):
// ±3 SE up to an eighth of the log. At the last point (m = n/4, edf ≈ 2-4) Riley's EDF
// approximations and the chi-square shape are known to be rough: ±0.12 there.
// The variance ratio is the sample variance over `seeds` of avar / truth, which is χ²_ν / ν
// (ν = edf) when the EDF is right: variance 2/ν, excess kurtosis 12/ν, so the sample variance has
// the relative standard error √((2 + 12/ν) / seeds) (0.071 for large ν and 400 seeds, 0.12 for
// ν = 3). ±3 standard errors at every point (was a fixed ±0.25, ±0.4 at m = n/4; ±4 standard
// errors for the 11 points would be looser than that, 0.28, and 3 passes with margin).
void ExpectNominalCoverage(const Coverage& c, int seeds, int64_t n, AllanNoiseType type) {
  const double p = 0.6827;
  for (size_t j = 0; j < c.m.size(); ++j) {
    const double tolerance = 8 * c.m[j] <= n ? 3 * std::sqrt(p * (1 - p) / seeds) : 0.12;
    EXPECT_NEAR(c.covered[j], p, tolerance) << "m=" << c.m[j];
    const double edf = AllanEdf(type, n, c.m[j]);
    const double ratio_se = std::sqrt((2 + 12 / edf) / seeds);
    EXPECT_NEAR(c.variance_ratio[j], 1.0, 3 * ratio_se) << "m=" << c.m[j] << " edf " << edf;
  }
}

TEST(AllanConfidence, WhiteNoiseIntervalsCoverTheTruthAtTheNominalRate) {
  const int seeds = 400;
  ExpectNominalCoverage(MeasureCoverage(1e-3, 0, AllanNoiseType::kWhiteFm, seeds, 4096), seeds,
                        4096, AllanNoiseType::kWhiteFm);
}

TEST(AllanConfidence, RandomWalkIntervalsCoverTheTruthAtTheNominalRate) {
  const int seeds = 400;
  ExpectNominalCoverage(MeasureCoverage(0, 1e-3, AllanNoiseType::kRandomWalkFm, seeds, 4096), seeds,
                        4096, AllanNoiseType::kRandomWalkFm);
}

TEST(AllanConfidence, WrongNoiseTypeMissesTheNominalRate) {
  // White-noise EDF for a random-walk log claims too many degrees of freedom: the estimator
  // varies 1.4-1.7 times more than 2σ⁴/edf says, and the intervals cover too rarely. Pooled over
  // m = 8..512 (7 points, 300 seeds each; the pooled SE is at most that of one point, 0.027).
  const int seeds = 300;
  const Coverage c = MeasureCoverage(0, 1e-3, AllanNoiseType::kWhiteFm, seeds, 4096);
  double coverage = 0, ratio = 0;
  int points = 0;
  for (size_t j = 0; j < c.m.size(); ++j) {
    if (c.m[j] < 8 || c.m[j] > 512) continue;
    coverage += c.covered[j];
    ratio += c.variance_ratio[j];
    ++points;
  }
  EXPECT_LT(coverage / points, 0.6827 - 3 * std::sqrt(0.6827 * 0.3173 / seeds));
  EXPECT_GT(ratio / points, 1.3);
}

TEST(AllanDeviation, RefusesBadInputNamingIt) {
  std::vector<float> y(100, 1.0f);
  AllanCurve curve;
  EXPECT_EQ(ComputeAllanDeviation(y.data(), 3, 0.01, AllanOptions(), &curve).code(),
            StatusCode::kInvalidInput);
  EXPECT_EQ(ComputeAllanDeviation(y.data(), 100, 0, AllanOptions(), &curve).code(),
            StatusCode::kInvalidInput);
  y[42] = std::nanf("");
  const Status s = ComputeAllanDeviation(y.data(), 100, 0.01, AllanOptions(), &curve);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("sample 42"), std::string::npos) << s.message();
  AllanOptions bad;
  bad.taus_per_decade = -1;
  EXPECT_FALSE(bad.IsValid(nullptr));
  bad = AllanOptions();
  bad.confidence = 1;
  std::string error;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("confidence"), std::string::npos);
}

}  // namespace
}  // namespace calibd::core
