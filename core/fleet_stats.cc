#include "core/fleet_stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/array_simulation.h"

namespace calibd::core {
namespace {

// The median of v (reorders it); v not empty.
double MedianOf(std::vector<double>* v) {
  const size_t mid = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + mid, v->end());
  const double upper = (*v)[mid];
  if (v->size() % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(v->begin(), v->begin() + mid));
}

}  // namespace

RobustSummary Summarize(std::vector<double> values, int bins) {
  RobustSummary s;
  s.n = static_cast<int64_t>(values.size());
  if (values.empty()) return s;
  bins = std::max(bins, 1);
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  s.min = *lo;
  s.max = *hi;
  const int used_bins = s.max > s.min ? bins : 1;
  s.edges.resize(used_bins + 1);
  for (int b = 0; b <= used_bins; ++b) s.edges[b] = s.min + (s.max - s.min) * b / used_bins;
  s.counts.assign(used_bins, 0);
  for (double x : values) {
    const int b = s.max > s.min ? static_cast<int>((x - s.min) / (s.max - s.min) * used_bins) : 0;
    ++s.counts[std::min(b, used_bins - 1)];
  }
  s.median = MedianOf(&values);
  for (double& x : values) x = std::abs(x - s.median);
  s.spread = 1.482602218505602 * MedianOf(&values);
  return s;
}

double RobustZ(double x, const RobustSummary& s) {
  const double d = x - s.median;
  if (s.spread > 0) return d / s.spread;
  if (d == 0) return 0;
  return d > 0 ? std::numeric_limits<double>::infinity() : -std::numeric_limits<double>::infinity();
}

double SidakLevel(double alpha, int m) { return -std::expm1(std::log1p(-alpha) / std::max(m, 1)); }

double RobustZCritical(int64_t n, double p, int draws) {
  if (n < 3 || !(p > 0 && p < 1)) return std::numeric_limits<double>::quiet_NaN();
  const int64_t k = n <= 500 ? std::max(draws, 1000)
                             : std::max<int64_t>(2000, std::min<int64_t>(draws, 10000000 / n));
  GaussianRng rng(0x5eed0f1ee7ULL + static_cast<uint64_t>(n));
  std::vector<double> medians(static_cast<size_t>(k)), spreads(static_cast<size_t>(k));
  std::vector<double> fleet(static_cast<size_t>(n));
  for (int64_t j = 0; j < k; ++j) {
    for (double& x : fleet) x = rng.Normal();
    const RobustSummary s = Summarize(fleet, 1);
    medians[static_cast<size_t>(j)] = s.median;
    spreads[static_cast<size_t>(j)] = s.spread;
  }
  // P(|x − m| > c s) for x ~ N(0, 1), averaged over the fleets; decreasing in c.
  auto tail = [&](double c) {
    double sum = 0;
    for (size_t j = 0; j < medians.size(); ++j) {
      const double m = medians[j], w = c * spreads[j];
      sum += 0.5 * (std::erfc((w - m) / std::sqrt(2.0)) + std::erfc((w + m) / std::sqrt(2.0)));
    }
    return sum / static_cast<double>(medians.size());
  };
  double lo = 0, hi = 1;
  while (tail(hi) > p && hi < 1e6) hi *= 2;
  for (int i = 0; i < 60 && hi - lo > 1e-6 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (tail(mid) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace calibd::core
