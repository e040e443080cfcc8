#include "core/fleet_stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

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

}  // namespace calibd::core
