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

// Šidák's per-parameter level for a family-wise false-alarm rate `alpha` over m independent
// parameters: 1 − (1 − alpha)^(1/m). For positively correlated parameters (a unit's scales move
// together) the family-wise rate is then at most alpha. alpha in (0, 1), m >= 1.
double SidakLevel(double alpha, int m);

// The |RobustZ| a new unit exceeds with probability p when it and the n devices of the fleet are
// drawn from one normal distribution: the two-sided critical value of the modified z, which is
// much wider than the normal quantile for small fleets (the median and the MAD of n values are
// uncertain themselves). Computed by Monte Carlo over the fleet with the new unit integrated
// exactly given each fleet (Rao-Blackwellised: P(|z| > c) = mean_k [Φ(m_k − c s_k) +
// Φ(−m_k − c s_k)], m_k and s_k the median and spread of fleet k), then bisection on c; fixed
// seed, so deterministic. `draws` fleets (>= 1000) for n <= 500; fewer for larger n (n × draws
// <= 10⁷, at least 2 000), where z is close to normal anyway. n >= 3, p in (0, 1). O(draws n).
double RobustZCritical(int64_t n, double p, int draws = 20000);

}  // namespace calibd::core

#endif  // CALIBD_CORE_FLEET_STATS_H_
