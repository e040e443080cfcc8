// Standard errors of the Monte-Carlo statistics the numerics tests compare with reported σ, so
// that each tolerance is derived from the number of trials instead of a fixed ±10-20 %.
//
// For `samples` independent normal errors of variance σ², the mean of their squares (about the
// true value, or about the sample mean with samples = trials − 1) divided by σ² is χ²_samples /
// samples: mean 1, standard error √(2 / samples). Its square root (an RMS error / σ or sample
// std / σ ratio) has, to first order, half that relative error: √(1 / (2 · samples)).
//
// When each trial gives d correlated errors with covariance C (positions of one array, parameters
// of one fit), their sum of squares has mean tr C and variance 2 tr(C²): the trial counts as
// d_eff = (tr C)² / tr(C²) independent errors (EffectiveDimension), between 1 and d.
//
// Tests assert within ±3 standard errors, or ±4 where one test makes many such checks (each says
// which); a σ off by 30 % is then far outside (the bounds are at most ±0.16 on a σ ratio).
#ifndef CALIBD_TESTS_LIB_MONTE_CARLO_H_
#define CALIBD_TESTS_LIB_MONTE_CARLO_H_

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

namespace calibd::monte_carlo {

// Standard error of (mean of squares) / σ² over `samples` independent normal errors.
inline double VarianceRatioStandardError(double samples) { return std::sqrt(2.0 / samples); }

// Standard error of √((mean of squares) / σ²): an RMS / σ or a sample-std / σ ratio.
inline double StdRatioStandardError(double samples) { return std::sqrt(0.5 / samples); }

// Standard error of the mean of `samples` independent values of standard deviation `sigma`.
inline double MeanStandardError(double sigma, double samples) { return sigma / std::sqrt(samples); }

// The mean of the independent values `x` (at least 2), and its standard error from their own
// scatter in `*se`.
inline double MeanAndStandardError(const std::vector<double>& x, double* se) {
  double mean = 0, var = 0;
  for (double v : x) mean += v / x.size();
  for (double v : x) var += (v - mean) * (v - mean) / (x.size() - 1);
  *se = std::sqrt(var / x.size());
  return mean;
}

// Standard error of the median of the independent values `x`, without assuming their
// distribution: the number of values below the true median is Binomial(T, 1/2), standard deviation
// √T / 2, so the order statistics √T / 2 ranks either side of the middle bound about ±1 standard
// error; half their distance estimates it.
inline double MedianStandardError(std::vector<double> x) {
  if (x.size() < 4) return 0;
  std::sort(x.begin(), x.end());
  const double t = static_cast<double>(x.size());
  const double half = std::sqrt(t) / 2;
  const size_t lo = static_cast<size_t>(std::max(0.0, std::floor(t / 2 - half)));
  const size_t hi = std::min(x.size() - 1, static_cast<size_t>(std::ceil(t / 2 + half)));
  return (x[hi] - x[lo]) / 2;
}

// Number of independent errors a sum of squares of errors with covariance `c` is worth:
// (tr C)² / tr(C²), d when C is a multiple of the identity, 1 when the errors are one error.
inline double EffectiveDimension(const Eigen::MatrixXd& c) {
  const double trace = c.trace();
  return trace * trace / c.cwiseProduct(c.transpose()).sum();
}

}  // namespace calibd::monte_carlo

#endif  // CALIBD_TESTS_LIB_MONTE_CARLO_H_
