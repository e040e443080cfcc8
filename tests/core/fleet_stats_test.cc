// core/fleet_stats.h: the robust summary estimates a normal fleet's centre and σ, ignores a few
// outliers, and flags them by robust z.
#include "core/fleet_stats.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/array_simulation.h"
#include "tests/lib/monte_carlo.h"

namespace calibd::core {
namespace {

TEST(FleetStats, TheSpreadEstimatesSigmaAndTheMedianTheCentreOfANormalFleet) {
  // 200 fleets of 100 devices: the spread's mean over fleets within 4 standard errors of σ (the
  // MAD's efficiency is 37 %: one fleet's spread has a relative standard error of about
  // 1.166/√n), the median's RMS error near √(π/2) σ/√n.
  GaussianRng rng(7);
  const int fleets = 200, n = 100;
  const double sigma = 0.02, centre = 1.5;
  double spread_sum = 0, median_sq = 0;
  for (int f = 0; f < fleets; ++f) {
    std::vector<double> x(n);
    for (double& v : x) v = centre + sigma * rng.Normal();
    const RobustSummary s = Summarize(x, 10);
    spread_sum += s.spread;
    median_sq += (s.median - centre) * (s.median - centre);
  }
  const double spread_se = sigma * 1.166 / std::sqrt(n) / std::sqrt(fleets);
  EXPECT_NEAR(spread_sum / fleets, sigma, 4 * spread_se);
  const double median_rms = std::sqrt(median_sq / fleets);
  const double expected = std::sqrt(M_PI / 2) * sigma / std::sqrt(n);
  EXPECT_NEAR(median_rms / expected, 1, 4 * monte_carlo::StdRatioStandardError(fleets));
}

TEST(FleetStats, AFewOutliersMoveNeitherTheMedianNorTheSpreadAndAreFlagged) {
  std::vector<double> x;
  for (int i = 0; i < 50; ++i) x.push_back(10 + 0.1 * ((i % 10) - 4.5));
  const RobustSummary clean = Summarize(x, 8);
  x.push_back(25);
  x.push_back(-3);
  const RobustSummary s = Summarize(x, 8);
  EXPECT_NEAR(s.median, clean.median, 0.06);
  EXPECT_NEAR(s.spread, clean.spread, 0.1 * clean.spread);
  EXPECT_GT(RobustZ(25, s), 3.5);
  EXPECT_LT(RobustZ(-3, s), -3.5);
  EXPECT_LT(std::abs(RobustZ(10.2, s)), 3.5);
  EXPECT_EQ(s.n, 52);
  EXPECT_EQ(s.min, -3);
  EXPECT_EQ(s.max, 25);
  int64_t total = 0;
  for (int64_t c : s.counts) total += c;
  EXPECT_EQ(total, 52);
  ASSERT_EQ(s.edges.size(), 9u);
  EXPECT_EQ(s.edges.front(), -3);
  EXPECT_EQ(s.edges.back(), 25);
}

TEST(FleetStats, EqualValuesHaveNoSpreadAndOnlyADifferentValueIsInfinitelyFar) {
  const RobustSummary s = Summarize({2, 2, 2, 2, 3}, 5);
  EXPECT_EQ(s.median, 2);
  EXPECT_EQ(s.spread, 0);
  EXPECT_EQ(RobustZ(2, s), 0);
  EXPECT_TRUE(std::isinf(RobustZ(3, s)));
  EXPECT_EQ(Summarize({}, 5).n, 0);
  const RobustSummary one = Summarize({4}, 5);
  EXPECT_EQ(one.counts.size(), 1u);
  EXPECT_EQ(one.median, 4);
}

// The calibrated threshold holds its family-wise false-alarm rate: a normal unit with m
// independent parameters, each judged against a normal fleet of n devices, is flagged in a
// fraction α of trials (4 000 trials per case: the standard error of a rate of 0.05 is 0.0034;
// the bounds are ±3.5 of them). The normal quantile at the same Šidák level, which ignores the
// fleet's own uncertainty, flags a small fleet's units several times too often, and the fixed
// |z| of 5 far too rarely for large fleets: the test tells the three apart.
TEST(FleetStats, TheCalibratedThresholdHoldsTheFamilyWiseFalseAlarmRate) {
  const double alpha = 0.05;
  const int m = 10, trials = 4000;
  for (int64_t n : {8, 12, 30, 100}) {
    const double p = SidakLevel(alpha, m);
    const double critical = RobustZCritical(n, p);
    double normal = 0;  // the two-sided normal quantile: erfc(c / √2) = p, by bisection
    for (double lo = 0, hi = 40, i = 0; i < 200; ++i, normal = 0.5 * (lo + hi)) {
      (std::erfc(0.5 * (lo + hi) / std::sqrt(2.0)) > p ? lo : hi) = 0.5 * (lo + hi);
    }
    GaussianRng rng(900 + static_cast<uint64_t>(n));
    int flagged = 0, flagged_normal = 0, flagged_five = 0;
    std::vector<double> fleet(static_cast<size_t>(n));
    for (int t = 0; t < trials; ++t) {
      double worst = 0;
      for (int j = 0; j < m; ++j) {
        for (double& x : fleet) x = rng.Normal();
        worst = std::max(worst, std::abs(RobustZ(rng.Normal(), Summarize(fleet, 1))));
      }
      flagged += worst > critical;
      flagged_normal += worst > normal;
      flagged_five += worst > 5;
    }
    const double rate = static_cast<double>(flagged) / trials;
    std::printf(
        "n %lld: critical |z| %.2f (normal %.2f); family-wise rate %.4f, with the normal "
        "quantile %.4f, with |z| > 5 %.4f\n",
        static_cast<long long>(n), critical, normal, rate,
        static_cast<double>(flagged_normal) / trials, static_cast<double>(flagged_five) / trials);
    EXPECT_NEAR(rate, alpha, 3.5 * std::sqrt(alpha * (1 - alpha) / trials)) << "n " << n;
    if (n <= 12) {
      EXPECT_GT(flagged_normal, 2 * flagged) << "n " << n;
    }
  }
  EXPECT_NEAR(SidakLevel(0.05, 1), 0.05, 1e-15);
  EXPECT_NEAR(SidakLevel(0.05, 10), 1 - std::pow(0.95, 0.1), 1e-15);
  EXPECT_TRUE(std::isnan(RobustZCritical(2, 0.01)));
  EXPECT_EQ(RobustZCritical(30, 0.001), RobustZCritical(30, 0.001));  // deterministic
}

}  // namespace
}  // namespace calibd::core
