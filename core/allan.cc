#include "core/allan.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

namespace calibd::core {
namespace {

// Centred cumulative sum S_0 = 0, S_k = Σ_{i<k} (y_i − ȳ), k = 0..n (n+1 values).
std::vector<double> CentredCumulativeSum(const float* y, int64_t n) {
  long double total = 0;
  for (int64_t i = 0; i < n; ++i) total += y[i];
  const double mean = static_cast<double>(total / static_cast<long double>(n));
  std::vector<double> s(static_cast<size_t>(n) + 1);
  long double running = 0;
  s[0] = 0;
  for (int64_t i = 0; i < n; ++i) {
    running += static_cast<double>(y[i]) - mean;
    s[static_cast<size_t>(i) + 1] = static_cast<double>(running);
  }
  return s;
}

// Σ_{k=begin}^{end−1} (S[k+2m] − 2 S[k+m] + S[k])² with four double accumulators.
double SecondDifferenceSquares(const double* s, int64_t m, int64_t begin, int64_t end) {
  double acc[4] = {0, 0, 0, 0};
  int64_t k = begin;
  for (; k + 4 <= end; k += 4) {
    for (int j = 0; j < 4; ++j) {
      const double d = s[k + j + 2 * m] - 2.0 * s[k + j + m] + s[k + j];
      acc[j] += d * d;
    }
  }
  for (; k < end; ++k) {
    const double d = s[k + 2 * m] - 2.0 * s[k + m] + s[k];
    acc[0] += d * d;
  }
  return (acc[0] + acc[1]) + (acc[2] + acc[3]);
}

// Normal quantile (Acklam's rational approximation, ~1e-9 relative), for starting values only.
double NormalQuantile(double p) {
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,  -2.759285104469687e+02,
                             1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01, -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  const double plow = 0.02425;
  if (p < plow) {
    const double q = std::sqrt(-2 * std::log(p));
    return (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
           ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  }
  if (p > 1 - plow) return -NormalQuantile(1 - p);
  const double q = p - 0.5;
  const double r = q * q;
  return (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
         (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
}

}  // namespace

const char* AllanNoiseTypeName(AllanNoiseType type) {
  switch (type) {
    case AllanNoiseType::kWhiteFm:
      return "white";
    case AllanNoiseType::kFlickerFm:
      return "flicker";
    case AllanNoiseType::kRandomWalkFm:
      return "random_walk";
  }
  return "?";
}

bool AllanOptions::IsValid(std::string* error) const {
  auto fail = [error](const char* what) {
    if (error != nullptr) *error = what;
    return false;
  };
  if (taus_per_decade < 0 || taus_per_decade > 100) {
    return fail("taus_per_decade must be between 0 (octaves) and 100");
  }
  if (!(confidence > 0 && confidence < 1)) return fail("confidence must be in (0, 1)");
  if (threads < 0) return fail("threads must be >= 0 (0: hardware concurrency)");
  return true;
}

std::vector<int64_t> AllanClusterSizes(int64_t n, int taus_per_decade) {
  std::vector<int64_t> m;
  const int64_t max_m = n / 4;
  if (max_m < 1) return m;
  if (taus_per_decade <= 0) {
    for (int64_t k = 1; k <= max_m; k *= 2) m.push_back(k);
    return m;
  }
  for (int j = 0;; ++j) {
    const double v = std::pow(10.0, static_cast<double>(j) / taus_per_decade);
    const int64_t k = static_cast<int64_t>(std::llround(v));
    if (k > max_m) break;
    if (m.empty() || k > m.back()) m.push_back(k);
  }
  return m;
}

std::vector<double> OverlappingAllanVariance(const float* y, int64_t n,
                                             const std::vector<int64_t>& clusters, int threads,
                                             const TaskExecutor& executor, const StopToken* stop) {
  std::vector<double> avar(clusters.size(), std::numeric_limits<double>::quiet_NaN());
  if (n < 2) return avar;
  const std::vector<double> s = CentredCumulativeSum(y, n);
  // Blocks of kBlock cluster starts, each block's partial sum (double) added to a long double
  // total per cluster size, in block order. Cache blocking: every cluster size with 2m <= kBlock
  // is done block by block, all of them while the block's window of S (at most 2·kBlock doubles)
  // is in cache, so the short cluster times cost one pass over S together instead of one pass
  // each. Tasks: one per block for the short cluster sizes, one per (long cluster size, block);
  // kGroup blocks at a time, so the partial sums take O(clusters · kGroup) memory.
  constexpr int64_t kBlock = 8192, kGroup = 256;
  std::vector<long double> total(clusters.size(), 0.0L);
  std::vector<size_t> small, large;
  for (size_t j = 0; j < clusters.size(); ++j) {
    const int64_t m = clusters[j];
    if (m < 1 || 2 * m > n) continue;
    (2 * m <= kBlock ? small : large).push_back(j);
  }
  const int64_t blocks = (n + kBlock - 1) / kBlock;
  const int64_t ns = static_cast<int64_t>(small.size()), nl = static_cast<int64_t>(large.size());
  std::vector<double> partial(static_cast<size_t>((ns + nl) * kGroup), 0.0);
  auto block_sum = [&](size_t j, int64_t block) {
    const int64_t count = n - 2 * clusters[j] + 1;
    const int64_t begin = block * kBlock, end = std::min(begin + kBlock, count);
    return begin < end ? SecondDifferenceSquares(s.data(), clusters[j], begin, end) : 0.0;
  };
  for (int64_t g0 = 0; g0 < blocks; g0 += kGroup) {
    if (StopRequested(stop)) return avar;
    const int64_t gb = std::min(kGroup, blocks - g0);
    const std::function<void(int64_t)> task = [&](int64_t item) {
      if (StopRequested(stop)) return;
      if (item < gb) {
        for (int64_t a = 0; a < ns; ++a) {
          partial[static_cast<size_t>(a * kGroup + item)] = block_sum(small[a], g0 + item);
        }
      } else {
        const int64_t a = (item - gb) / gb, b = (item - gb) % gb;
        partial[static_cast<size_t>((ns + a) * kGroup + b)] = block_sum(large[a], g0 + b);
      }
    };
    const int64_t tasks = gb * (1 + nl);
    if (executor) {
      executor(tasks, task);
    } else if (threads == 1) {
      for (int64_t i = 0; i < tasks; ++i) task(i);
    } else {
      RunTasksOnThreads(threads, tasks, task);
    }
    for (int64_t a = 0; a < ns + nl; ++a) {
      const size_t j = a < ns ? small[a] : large[a - ns];
      const int64_t count = n - 2 * clusters[j] + 1;
      for (int64_t b = 0; b < gb; ++b) {
        if ((g0 + b) * kBlock < count) total[j] += partial[static_cast<size_t>(a * kGroup + b)];
      }
    }
  }
  for (size_t j = 0; j < clusters.size(); ++j) {
    const int64_t m = clusters[j];
    if (m < 1 || 2 * m > n) continue;
    const int64_t count = n - 2 * m + 1;
    avar[j] = static_cast<double>(total[j] / (2.0L * static_cast<long double>(m) * m * count));
  }
  return avar;
}

std::vector<double> OverlappingAllanVarianceDirect(const float* y, int64_t n,
                                                   const std::vector<int64_t>& clusters) {
  std::vector<double> avar(clusters.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t j = 0; j < clusters.size(); ++j) {
    const int64_t m = clusters[j];
    if (m < 1 || 2 * m > n) continue;
    const int64_t count = n - 2 * m + 1;
    long double sum = 0;
    for (int64_t k = 0; k < count; ++k) {
      long double first = 0, second = 0;
      for (int64_t i = 0; i < m; ++i) {
        first += y[k + i];
        second += y[k + m + i];
      }
      const long double d = (second - first) / m;
      sum += d * d;
    }
    avar[j] = static_cast<double>(sum / (2.0L * count));
  }
  return avar;
}

std::vector<double> NonOverlappingAllanVarianceDirect(const float* y, int64_t n,
                                                      const std::vector<int64_t>& clusters) {
  std::vector<double> avar(clusters.size(), std::numeric_limits<double>::quiet_NaN());
  for (size_t j = 0; j < clusters.size(); ++j) {
    const int64_t m = clusters[j];
    const int64_t groups = m >= 1 ? n / m : 0;
    if (groups < 2) continue;
    double sum = 0, previous = 0;
    for (int64_t g = 0; g < groups; ++g) {
      double cluster_sum = 0;
      for (int64_t i = 0; i < m; ++i) cluster_sum += y[g * m + i];
      const double average = cluster_sum / m;
      if (g > 0) sum += (average - previous) * (average - previous);
      previous = average;
    }
    avar[j] = sum / (2.0 * (groups - 1));
  }
  return avar;
}

double AllanEdf(AllanNoiseType type, int64_t n, int64_t m) {
  const double N = static_cast<double>(n) + 1;  // phase points
  const double mm = static_cast<double>(m);
  double edf = 1;
  switch (type) {
    case AllanNoiseType::kWhiteFm:
      edf = (3 * (N - 1) / (2 * mm) - 2 * (N - 2) / N) * 4 * mm * mm / (4 * mm * mm + 5);
      break;
    case AllanNoiseType::kFlickerFm:
      edf = m == 1 ? 2 * (N - 2) / (2.3 * N - 4.9) : 5 * N * N / (4 * mm * (N + 3 * mm));
      break;
    case AllanNoiseType::kRandomWalkFm:
      edf =
          (N - 2) / mm * ((N - 1) * (N - 1) - 3 * mm * (N - 1) + 4 * mm * mm) / ((N - 3) * (N - 3));
      break;
  }
  return std::isfinite(edf) ? std::max(edf, 1.0) : 1.0;
}

double RegularizedGammaP(double a, double x) {
  if (x <= 0) return 0;
  const double log_prefactor = a * std::log(x) - x - std::lgamma(a);
  if (x < a + 1) {  // series
    double term = 1 / a, sum = term;
    for (int k = 1; k < 100000; ++k) {
      term *= x / (a + k);
      sum += term;
      if (std::fabs(term) < std::fabs(sum) * 1e-16) break;
    }
    return std::min(1.0, sum * std::exp(log_prefactor));
  }
  // Continued fraction for Q (modified Lentz).
  const double tiny = 1e-300;
  double b = x + 1 - a, c = 1 / tiny, d = 1 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::fabs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    const double delta = d * c;
    h *= delta;
    if (std::fabs(delta - 1) < 1e-16) break;
  }
  return std::max(0.0, 1 - std::exp(log_prefactor) * h);
}

double ChiSquareQuantile(double p, double dof) {
  if (!(p > 0 && p < 1) || !(dof > 0)) return std::numeric_limits<double>::quiet_NaN();
  const double k = dof / 2;
  auto cdf = [k](double x) { return RegularizedGammaP(k, x / 2); };
  const double log_norm = -k * std::log(2.0) - std::lgamma(k);
  auto pdf = [k, log_norm](double x) {
    return x > 0 ? std::exp(log_norm + (k - 1) * std::log(x) - x / 2) : 0.0;
  };
  // Wilson-Hilferty start, then Newton inside a bisection bracket.
  const double z = NormalQuantile(p);
  const double h = 2 / (9 * dof);
  double x = dof * std::pow(std::max(1 - h + z * std::sqrt(h), 1e-3), 3);
  double lo = 0, hi = std::max(2 * dof, 10.0);
  while (cdf(hi) < p) hi *= 2;
  if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
  for (int it = 0; it < 300; ++it) {
    const double f = cdf(x) - p;
    if (f < 0) {
      lo = x;
    } else {
      hi = x;
    }
    const double density = pdf(x);
    double next = density > 0 ? x - f / density : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::fabs(next - x) <= 1e-13 * x || hi - lo <= 1e-14 * hi) return next;
    x = next;
  }
  return x;
}

void SetAllanConfidence(const std::vector<AllanNoiseType>& noise_types, double confidence,
                        AllanCurve* curve) {
  const size_t size = curve->tau.size();
  curve->edf.assign(size, std::numeric_limits<double>::quiet_NaN());
  curve->adev_lower.assign(size, std::numeric_limits<double>::quiet_NaN());
  curve->adev_upper.assign(size, std::numeric_limits<double>::quiet_NaN());
  curve->noise_type.assign(size, AllanNoiseType::kWhiteFm);
  curve->confidence = confidence;
  const double alpha = 1 - confidence;
  for (size_t j = 0; j < size; ++j) {
    const AllanNoiseType type =
        noise_types.empty()
            ? AllanNoiseType::kWhiteFm
            : noise_types[noise_types.size() == 1 ? 0 : std::min(j, noise_types.size() - 1)];
    curve->noise_type[j] = type;
    const double edf = AllanEdf(type, curve->samples, curve->cluster[j]);
    curve->edf[j] = edf;
    const double avar = curve->avar[j];
    if (!std::isfinite(avar)) continue;
    curve->adev_lower[j] = std::sqrt(avar * edf / ChiSquareQuantile(1 - alpha / 2, edf));
    curve->adev_upper[j] = std::sqrt(avar * edf / ChiSquareQuantile(alpha / 2, edf));
  }
}

Status ComputeAllanDeviation(const float* y, int64_t n, double tau0, const AllanOptions& options,
                             AllanCurve* curve) {
  *curve = AllanCurve();
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput("allan options: " + error);
  if (!(tau0 > 0) || !std::isfinite(tau0)) {
    return Status::InvalidInput("the sample period must be a finite number > 0");
  }
  if (y == nullptr || n < 4) {
    return Status::InvalidInput("the Allan deviation needs at least 4 samples, not " +
                                std::to_string(y == nullptr ? 0 : n));
  }
  for (int64_t i = 0; i < n; ++i) {
    if (!std::isfinite(y[i])) {
      return Status::InvalidInput("sample " + std::to_string(i) + " is not a finite number");
    }
  }
  curve->tau0 = tau0;
  curve->samples = n;
  curve->cluster = AllanClusterSizes(n, options.taus_per_decade);
  if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "allan deviation");
  curve->avar = OverlappingAllanVariance(y, n, curve->cluster, options.threads, options.executor,
                                         options.stop);
  if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "allan deviation");
  for (size_t j = 0; j < curve->cluster.size(); ++j) {
    curve->tau.push_back(static_cast<double>(curve->cluster[j]) * tau0);
    curve->adev.push_back(std::sqrt(curve->avar[j]));
  }
  SetAllanConfidence({AllanNoiseType::kWhiteFm}, options.confidence, curve);
  return Status::Ok();
}

}  // namespace calibd::core
