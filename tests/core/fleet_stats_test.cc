// core/fleet_stats.h: the robust summary estimates a normal fleet's centre and σ, ignores a few
// outliers, and flags them by robust z.
#include "core/fleet_stats.h"

#include <gtest/gtest.h>

#include <cmath>
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

}  // namespace
}  // namespace calibd::core
