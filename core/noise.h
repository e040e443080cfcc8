// The `noise` method (SPEC §7): white noise density N, bias instability B and rate random walk K
// of every channel of a long stationary inertial log, read from its overlapping Allan deviation
// (IEEE Std 952-1997; the units of Kalibr's IMU noise model, so that N and K are Kalibr's
// `*_noise_density` and `*_random_walk`).
//
// Model of the Allan variance of one channel (IEEE 952 Annex C):
//   σ²(τ) = N²/τ + (0.664 B)² + K² τ/3
// i.e. slope −½ (white noise, read at τ = 1 s: σ(1 s) = N), a flat floor (bias instability:
// floor = 0.664 B) and slope +½ (random walk, read at τ = 3 s: σ(3 s) = K).
//
// Method: the three coefficients (N², (0.664B)², K²/3) are fitted to the whole curve (cluster
// sizes >= min_fit_cluster) by weighted non-negative least squares on σ̂²(τ) (exact NNLS: every
// subset of the three terms is solved and the best feasible one kept), weights 1/Var(σ̂²) =
// edf/(2σ⁴) with σ² and Riley's EDF (for the term that dominates each point) from the current fit
// (five reweighting passes, the first from the observed values). A global fit was chosen over
// per-region slope lines because it needs no choice of regions, uses every point with its own
// precision, and lets the terms share the crossover zones where no single slope holds.
// Uncertainty (1σ): the overlapping estimates at neighbouring cluster times are strongly
// correlated (Corr(σ̂²(m), σ̂²(2m)) ≈ 0.52 for white noise, ≈ 0.88 for random walk, measured by
// simulation), so the weighted fit's (XᵀWX)⁻¹ is 1.4× (N) to 1.8× (K) too small. The covariance
// is the sandwich (XᵀWX)⁻¹ XᵀWΣWX (XᵀWX)⁻¹ with Σ = D R D, D the chi-square standard deviations
// and R an exponential correlation kernel in log2 m whose length depends on the dominant term
// (Paciorek's non-stationary form, positive definite). Generalised least squares with that Σ
// was tried and rejected: it fits below the data (Peelle's puzzle). The variances are propagated
// to N = √a, B = √c/0.664, K = √(3d) to first order; tests/core/noise_test.cc measures coverage.
// The σ convention (issue 28, as pca/imu/array): that σ is the bound the noise model gives
// (NoiseTerm::crb_std, basis "crb"). The fit's χ² is compared with what the model predicts for
// it, E χ² = tr M and Var χ² = 2 tr M² with M = W½(I−P)Σ(I−P)ᵀW½ (P the weighted hat matrix):
// above E χ² + 3 sd the curve does not follow N/B/K within its chi-square intervals, and the
// primary σ (and the visibility test) use the bound × √(χ²/E χ²) (basis "chi2_scaled", warned).
//
// Visibility: a term is reported only when it dominates (is the largest of the three) at one
// fitted cluster time at least and its coefficient is at least `min_significance` standard
// errors above zero; otherwise it is std::nullopt and a warning gives a 2σ upper bound and the
// log length (or sample rate, for N) that would show it if the term were at that bound
// (NoiseTerm::needed).
//
// Input checks: fewer than `min_samples` samples → kNotDeterminable; timestamps (when given)
// strictly increasing, rate from the median Δt, jitter = max |Δt − median| / median (warning
// above jitter_warning, kNotDeterminable above max_jitter: a gap or a clock that cannot be
// trusted); stationarity per channel (windows of `stationarity_window` seconds: a window variance
// beyond max_variance_ratio × the median window variance, or a jump of the window means beyond
// max_jump_ratio × their robust spread, means the sensor moved) → kNotDeterminable with the curve
// and terms still computed for the report but usable = false.
//
// Memory: the samples are read in place (float, not copied); one double per sample (the
// cumulative sum of the channel being processed: channels run one after the other), and, before
// that and released first, one double per sample for the median Δt when timestamps are given.
// Time: O(n · cluster times) per channel (bench/noise_bench: 2 h at 400 Hz, 6 channels, ~0.5 s
// of CPU); each channel's cluster times run on `threads` threads and the result does not depend
// on their number.
// Cost: O(C · n · M) time for C channels, n samples and M cluster sizes (core/allan.h), plus
// O(n log n) for the median Δt; the fit is O(M) per reweighting pass (5 passes, every subset of
// 3 terms). Memory O(n) besides the samples (one double per sample). Worst case at the job
// budget's largest input (5.9 GiB, the default on a 2-core 23 GiB machine, 7 B per value: 6
// channels and t, 128 M rows): ≈ 27 s of CPU (0.21 µs a row, measured to 16.8 M rows, linear:
// bench/README.md "Cost of every method").
//
// SPEC §7 result JSON from NoiseResult (for the server):
//   parameters.channels[i]  {name, unit, white_noise: white_noise.value, bias_instability:
//                            bias_instability.value, bias_instability_tau, random_walk:
//                            random_walk.value}  (nullopt → null, with the channel's warning)
//   uncertainty.channels[i] {name, white_noise_std: white_noise.std, bias_instability_std,
//                            random_walk_std}
//   diagnostics             rate, samples, allan[i] = {name, tau, adev, adev_lower, adev_upper}
//                            from channels[i].allan; also stationary, jitter, per-channel status
//   verdict / warnings      usable + reason, warnings
#ifndef CALIBD_CORE_NOISE_H_
#define CALIBD_CORE_NOISE_H_

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/allan.h"

namespace calibd::core {

// The failure reasons only noise meets (base/status.h Reason; their catalog entries are in
// methods/noise/noise_method.cc FailureReasons()).
namespace noise_reason {
// Sample times jitter too much for the Allan deviation
inline constexpr Reason kIrregularSampling{"irregular_sampling"};
// A noise log that moves
inline constexpr Reason kNotStationary{"not_stationary"};
}  // namespace noise_reason

struct NoiseOptions {
  // Cluster-time spacing of the Allan curve: 0 = octaves, k = k per decade (SPEC
  // `taus_per_decade`). 0..100.
  int taus_per_decade = 0;
  // Two-sided probability of adev_lower/adev_upper; default ±1σ. (0, 1).
  double confidence = 0.6827;
  // Fewer samples are refused (kNotDeterminable). >= 16.
  int64_t min_samples = 300;
  // Cluster sizes below this are shown but not fitted: a sensor's anti-aliasing filter
  // correlates neighbouring samples and lowers the first points of the curve. >= 1.
  int64_t min_fit_cluster = 4;
  // A term is visible only when its fitted coefficient is at least this many standard errors
  // above zero (and it dominates somewhere). >= 0.
  double min_significance = 3.0;
  // Sample period τ0 (seconds) when no timestamps are given; with timestamps the median Δt is
  // used and this is ignored. > 0 when set.
  std::optional<double> sample_period;
  // Timestamp jitter max |Δt − median Δt| / median Δt: a warning above jitter_warning, refused
  // (kNotDeterminable) above max_jitter (e.g. a gap of one lost sample is a jitter of 1).
  // 0 <= jitter_warning <= max_jitter.
  double jitter_warning = 0.05;
  double max_jitter = 0.5;
  // Stationarity check: window length in seconds (at least 16 samples per window, at least 8
  // windows, else the check is skipped with a warning). > 0.
  double stationarity_window = 1.0;
  // A window whose variance exceeds this × the median window variance means the sensor moved
  // (Gaussian noise with 16 samples per window exceeds 4.5× once in 10⁹ windows). > 1.
  double max_variance_ratio = 10.0;
  // A jump between the means of adjacent windows beyond this × their robust spread (1.4826 ×
  // median absolute deviation of the jumps, at least the white-noise expectation) means the
  // sensor moved (tilted, knocked). > 1.
  double max_jump_ratio = 10.0;
  // Threads of each channel's Allan variance (channels run one at a time: one cumulative sum in
  // memory); 0 = std::thread::hardware_concurrency(). The result does not depend on it. >= 0.
  int threads = 0;
  // Optional: runs those tasks instead of the built-in threads (e.g. the server's shared pool).
  TaskExecutor executor;
  // Polled (core/stop_token.h) per channel and inside each channel's Allan sweep (every block of
  // 8192 cluster starts): when it asks, EstimateNoise returns core::StoppedStatus at once (the
  // channels not analysed stay kNotRun). Null: never stops.
  const StopToken* stop = nullptr;

  bool IsValid(std::string* error) const;
};

// One channel of the log, read in place.
struct NoiseChannelInput {
  std::string name;             // e.g. "g0_x"
  std::string unit;             // SI unit of the samples, e.g. "rad/s" or "m/s^2" (for reports)
  const float* data = nullptr;  // NoiseProblem::samples values, valid during EstimateNoise
};

struct NoiseProblem {
  int64_t samples = 0;                      // n, the same for every channel
  std::vector<NoiseChannelInput> channels;  // at least one
  // Timestamps, seconds, n values strictly increasing, or nullptr (then options.sample_period
  // is required). Valid during EstimateNoise.
  const double* times = nullptr;
};

// Why a channel's terms are (not) usable.
enum class NoiseChannelStatus {
  kNotRun,         // sentinel: the analysis stopped before this channel
  kOk,             // the visible terms may be used
  kNotStationary,  // the sensor moved during the log: the Allan curve is meaningless
  kConstant,       // every sample equal (dead or saturated sensor): nothing to fit
};
const char* NoiseChannelStatusName(NoiseChannelStatus status);  // "ok" | "not_stationary" | ...

// Per-channel stationarity figures (see NoiseOptions).
struct NoiseStationarity {
  bool checked = false;        // false when the log has too few windows for the check
  bool stationary = true;      // verdict
  int64_t window_samples = 0;  // samples per window
  int64_t windows = 0;
  double max_variance_ratio = std::numeric_limits<double>::quiet_NaN();  // largest / median
  double max_variance_time = std::numeric_limits<double>::quiet_NaN();   // window start, s
  double max_jump_ratio = std::numeric_limits<double>::quiet_NaN();      // largest / spread
  double max_jump_time = std::numeric_limits<double>::quiet_NaN();       // s, between windows
};

// A term read from the curve. Fields the SPEC reports: value and std (1σ), both absent when
// the term is not visible; the rest is for reports and for the fitted line of plots.
struct NoiseTerm {
  std::optional<double> value;  // N (unit/√Hz), B (unit) or K (unit/s/√Hz); nullopt: not visible
  std::optional<double> std;    // 1σ of value: the primary σ (see NoiseChannelResult's basis)
  // The noise model's own 1σ (the sandwich from the Allan points' chi-square spread: the bound
  // when the curve follows N/B/K); equals std when the basis is "crb". With value.
  std::optional<double> crb_std;
  // Fitted coefficient (N², (0.664B)² or K²/3, ≥ 0, the fit's line even when not visible) and
  // its 1σ, so plots can draw every fitted line.
  double coefficient = 0;
  double coefficient_std = std::numeric_limits<double>::quiet_NaN();
  // 2σ upper bound of the term (same unit as value), for not-visible terms' warnings.
  double upper_bound = std::numeric_limits<double>::quiet_NaN();
  // Not visible: the log length (s) in which the term, were it at upper_bound and the others
  // as fitted, would dominate somewhere and stand min_significance + 1 standard errors above
  // zero (reported with ≈ 84 % probability; predicted from the fit's own covariance model, at
  // least twice this log); for N instead the longest sample period (s) that would show it.
  // +inf when nothing would (the other terms hide it everywhere). NaN when visible.
  double needed = std::numeric_limits<double>::quiet_NaN();
};

struct NoiseChannelResult {
  std::string name;
  std::string unit;
  NoiseChannelStatus status = NoiseChannelStatus::kNotRun;
  std::string reason;  // why not kOk; empty when kOk

  NoiseTerm white_noise;                       // N, unit/√Hz (Kalibr *_noise_density)
  NoiseTerm bias_instability;                  // B, unit
  std::optional<double> bias_instability_tau;  // s: τ of the floor (minimum of the fitted
                                               // curve, or the longest τ when no K); with B
  NoiseTerm random_walk;                       // K, unit/s/√Hz (Kalibr *_random_walk)

  AllanCurve allan;  // tau, adev, adev_lower, adev_upper (and edf, noise type per point)
  std::vector<double> fitted_adev;  // √ of the fitted model at each tau (for plots)
  int fit_points = 0;               // cluster times used by the fit (m >= min_fit_cluster)
  double fit_chi2 = std::numeric_limits<double>::quiet_NaN();  // Σ w (σ̂² − model)²
  // What the noise model predicts for fit_chi2 (the points are correlated, so not points − 3)
  // and fit_chi2 / that: ≈ 1 when the curve follows N/B/K.
  double chi2_expected = std::numeric_limits<double>::quiet_NaN();
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  // "crb": the terms' std are the model's σ (fit_chi2 within 3 of its standard deviations of
  // chi2_expected); "chi2_scaled": the model's σ × √chi2_per_dof, with a warning.
  std::string uncertainty_basis = "crb";
  double mean = std::numeric_limits<double>::quiet_NaN();  // of the samples, unit
  NoiseStationarity stationarity;
  std::vector<std::string> warnings;  // this channel's, also copied to NoiseResult::warnings
};

// Fields start at sentinels and are filled as far as the analysis got (see EstimateNoise).
struct NoiseResult {
  bool usable = false;  // true iff EstimateNoise returned OK
  std::string reason;   // why not usable; empty when usable

  double rate = std::numeric_limits<double>::quiet_NaN();           // Hz = 1/τ0
  double sample_period = std::numeric_limits<double>::quiet_NaN();  // τ0, s
  int64_t samples = 0;                                              // n
  double duration = std::numeric_limits<double>::quiet_NaN();       // n τ0, s
  bool timestamps = false;                                          // rate from timestamps
  double jitter = std::numeric_limits<double>::quiet_NaN();         // max |Δt − τ0| / τ0
  int64_t jitter_index = -1;  // sample i whose Δt = t_i − t_{i−1} is the worst

  bool stationary = false;  // every checked channel stationary (the verdict)
  std::vector<NoiseChannelResult> channels;
  std::vector<std::string> warnings;  // plain words, channel names included

  // One line per channel: N, B, K with 1σ, or why not.
  std::string BriefReport() const;
};

// Analyses every channel. Errors (result->reason says the same):
//  - kInvalidInput: options not valid, no channel, null data, timestamps not strictly increasing
//    or not finite (message names the sample), a sample not finite (names channel and sample),
//    no timestamps and no sample_period.
//  - kNotDeterminable: fewer than min_samples samples; jitter above max_jitter (names the sample
//    and time); a channel not stationary (names the channel, the time and the ratio) — in this
//    last case every channel's curve and terms are still filled, with usable = false.
// Constant channels are reported (status kConstant, warning) without failing the analysis.
Status EstimateNoise(const NoiseProblem& problem, const NoiseOptions& options, NoiseResult* result);

}  // namespace calibd::core

#endif  // CALIBD_CORE_NOISE_H_
