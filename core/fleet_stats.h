// Robust statistics of one parameter over a product's fleet (SPEC §10, issue #27): the median, the
// spread as 1.4826 × the median absolute deviation (the standard deviation for normal values,
// unmoved by a few outliers), a histogram, and each value's robust z = (x − median) / spread
// (Iglewicz & Hoaglin's modified z). Pure numerics; thread-compatible.
#ifndef CALIBD_CORE_FLEET_STATS_H_
#define CALIBD_CORE_FLEET_STATS_H_

#include <cstdint>
#include <vector>

namespace calibd::core {

struct RobustSummary {
  int64_t n = 0;
  double median = 0;
  double spread = 0;  // 1.4826 × MAD; 0 when at least half the values are equal
  double min = 0, max = 0;
  // `bins` equal bins over [min, max] (edges: bins + 1 values; one bin when min == max).
  std::vector<double> edges;
  std::vector<int64_t> counts;
};

// The summary of `values` (finite; empty: n = 0 and nothing else). bins >= 1.
RobustSummary Summarize(std::vector<double> values, int bins);

// (x − median) / spread; with spread 0: 0 for x == median, else ±infinity.
double RobustZ(double x, const RobustSummary& s);

}  // namespace calibd::core

#endif  // CALIBD_CORE_FLEET_STATS_H_
