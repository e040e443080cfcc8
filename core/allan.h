// Overlapping Allan deviation (IEEE Std 952-1997, Annex C; Riley, "Handbook of Frequency Stability
// Analysis", NIST SP 1065, 2008, Eq. 14) of one channel of rate samples y_1..y_n taken every τ0
// seconds, at cluster times τ = m·τ0:
//
//   σ²(τ) = 1 / (2 (n − 2m + 1)) · Σ_{k=0}^{n−2m} (ȳ_{k+m} − ȳ_k)²,
//   ȳ_k = (1/m) Σ_{i=k+1}^{k+m} y_i = (S_{k+m} − S_k) / m,   S_k = Σ_{i≤k} (y_i − ȳ),
//
// i.e. every cluster start k is used (the "overlapping" estimator). With the cumulative sum S each
// cluster time costs O(n), independent of m. Precision: the samples are centred on their mean
// (accumulated in long double) before S is formed, S is accumulated in long double and stored as
// double, and the squares are summed in blocks of 8192 (double) added to a long double total per
// cluster size; the result agrees with a direct O(n·m) summation to ~1e-12 relative for hours-long
// logs with large offsets (tests/core/allan_test.cc).
//
// Confidence intervals: the chi-square interval of Riley §5.3 (Eq. 48),
//   σ² · edf / χ²(1 − α/2, edf) ≤ σ²_true ≤ σ² · edf / χ²(α/2, edf),
// with the equivalent degrees of freedom edf of the overlapping estimator from the simple
// approximations of Riley's Table 5 (Howe, Allan, Barnes) for the noise type that dominates at τ:
// white FM (white rate noise: the angle/velocity random walk N), flicker FM (bias instability B)
// and random-walk FM (rate random walk K). N in those formulas is the number of phase points, n+1.
//
// Memory: one double per sample (the cumulative sum, 8 bytes a sample: the precision above) while
// a channel is processed; the samples themselves stay float and are not copied. The cluster
// sizes and blocks of cluster starts of one channel run on several threads (AllanOptions) over
// that one sum; each block's partial sum goes to its own slot and the slots are added in block
// order, so the result is bit-identical for any number of threads. Thread-compatible: no shared
// state.
//
// Cost: O(n · M) time, O(n) memory (8 bytes a sample) for n samples and M cluster sizes (M <=
// log2(n/4) + 1 with octaves, <= taus_per_decade · log10(n/4) + 1 otherwise, at most 100 per
// decade). Worst case at the noise job budget's largest input (5.9 GiB, the default on a 2-core
// 23 GiB machine, 7 B per value, 7 columns: 128 M samples a channel, 25 octaves): ≈ 4.5 s of CPU
// a channel (bench/README.md "Cost of every method").
#ifndef CALIBD_CORE_ALLAN_H_
#define CALIBD_CORE_ALLAN_H_

#include <cstdint>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/block_lm.h"
#include "core/stop_token.h"

namespace calibd::core {

// Power-law noise types of a rate signal (in Riley's frequency-data names) as they matter for
// the equivalent degrees of freedom of the Allan variance.
enum class AllanNoiseType {
  kWhiteFm,       // white rate noise: σ ∝ τ^−½ (white noise density N)
  kFlickerFm,     // flicker rate noise: σ flat (bias instability B)
  kRandomWalkFm,  // random-walk rate noise: σ ∝ τ^+½ (rate random walk K)
};
const char* AllanNoiseTypeName(AllanNoiseType type);  // "white" | "flicker" | "random_walk"

struct AllanOptions {
  // Cluster-time spacing: 0 = octaves (m = 1, 2, 4, ...); k > 0 = k points per decade
  // (m = round(10^(j/k)), duplicates removed). 0 <= taus_per_decade <= 100.
  int taus_per_decade = 0;
  // Two-sided probability of the confidence interval; default 0.6827 (±1σ of a normal), so that
  // the interval is comparable with the 1σ uncertainties of the terms. 0 < confidence < 1.
  double confidence = 0.6827;
  // Threads of one channel's computation when no executor is given; 0 = hardware concurrency.
  // The result does not depend on it. >= 0.
  int threads = 1;
  // Optional: runs the blocks instead of the built-in threads (e.g. the server's shared pool).
  TaskExecutor executor;
  // Polled (core/stop_token.h) for every block of 8192 cluster starts (a few ms at the most)
  // and between the passes: when it asks, ComputeAllanDeviation returns core::StoppedStatus at
  // once. Null: never stops.
  const StopToken* stop = nullptr;

  bool IsValid(std::string* error) const;
};

// Cluster sizes m from 1 to floor(n/4) (τ from one sample period to a quarter of the log) with
// the given spacing, ascending, without duplicates. Empty when n < 4.
std::vector<int64_t> AllanClusterSizes(int64_t n, int taus_per_decade);

// Overlapping Allan variance σ²(m·τ0) of y[0..n) for every m in `clusters` (each 1 <= m <= n/2),
// O(n) per cluster size from the centred cumulative sum, on `threads` threads (or `executor`;
// see AllanOptions), bit-identical for any number. Precondition: y finite.
// Polls `stop` (may be null) for every block: when it asks, returns early with partial values
// (the caller checks the token).
std::vector<double> OverlappingAllanVariance(const float* y, int64_t n,
                                             const std::vector<int64_t>& clusters, int threads = 1,
                                             const TaskExecutor& executor = {},
                                             const StopToken* stop = nullptr);

// The same by direct summation of every cluster average, O(n·m) per cluster size, accumulated in
// long double: the reference for tests and benchmarks, not for production use.
std::vector<double> OverlappingAllanVarianceDirect(const float* y, int64_t n,
                                                   const std::vector<int64_t>& clusters);

// Non-overlapping Allan variance (clusters k·m, k = 0, 1, ...; IEEE 952 Eq. C.3 without overlap),
// direct summation; O(n) per cluster size. A straightforward reference for benchmarks: it uses
// about m times fewer differences than the overlapping estimator, hence wider intervals.
std::vector<double> NonOverlappingAllanVarianceDirect(const float* y, int64_t n,
                                                      const std::vector<int64_t>& clusters);

// Equivalent degrees of freedom of the overlapping Allan variance at cluster size m from n
// samples (Riley, NIST SP 1065, Table 5), at least 1. Precondition: 1 <= m <= n/2.
double AllanEdf(AllanNoiseType type, int64_t n, int64_t m);

// Quantile x of the chi-square distribution with `dof` (> 0, need not be an integer) degrees of
// freedom: P(X <= x) = p, 0 < p < 1. Accurate to ~1e-10 relative (regularised incomplete gamma
// function, Newton steps safeguarded by bisection).
double ChiSquareQuantile(double p, double dof);

// Regularised lower incomplete gamma function P(a, x) = γ(a, x)/Γ(a), a > 0, x >= 0; the
// chi-square distribution function is P(dof/2, x/2).
double RegularizedGammaP(double a, double x);

// One channel's Allan deviation curve, with its confidence interval.
struct AllanCurve {
  double tau0 = 0;                         // sample period τ0, seconds
  int64_t samples = 0;                     // n
  std::vector<int64_t> cluster;            // m
  std::vector<double> tau;                 // m·τ0, seconds
  std::vector<double> avar;                // σ²(τ), unit²
  std::vector<double> adev;                // σ(τ), unit
  std::vector<double> adev_lower;          // lower end of the interval, unit
  std::vector<double> adev_upper;          // upper end of the interval, unit
  std::vector<double> edf;                 // equivalent degrees of freedom
  std::vector<AllanNoiseType> noise_type;  // the type whose EDF was used
  double confidence = 0;                   // two-sided probability of [adev_lower, adev_upper]

  size_t size() const { return tau.size(); }
};

// Fills curve->edf, adev_lower and adev_upper for the given noise types (one per point, or one
// for all points when noise_types has a single entry) and confidence.
void SetAllanConfidence(const std::vector<AllanNoiseType>& noise_types, double confidence,
                        AllanCurve* curve);

// The Allan deviation of y[0..n) sampled every tau0 seconds at the cluster times of
// AllanClusterSizes, with intervals for white rate noise (SetAllanConfidence can redo them for
// the noise type that dominates each point, as EstimateNoise does). kInvalidInput: bad options,
// tau0 not finite and > 0, y null, n < 4, or a sample not finite (the message names its index).
Status ComputeAllanDeviation(const float* y, int64_t n, double tau0, const AllanOptions& options,
                             AllanCurve* curve);

}  // namespace calibd::core

#endif  // CALIBD_CORE_ALLAN_H_
