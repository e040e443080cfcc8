// Static detection for raw inertial logs (SPEC §7): which stretches of a continuous log were
// recorded at rest, found from the log's own noise floor; no initial static period is needed.
//
// Spread of triad k at sample i: the RMS deviation from the mean vector over the centred window
// of w samples (w = static_window / median sample period, odd, >= 3):
//   s_k(i) = sqrt(Σ_axes var(y_axis over window i)),   in the triad's reading units.
// Noise floor of triad k, from s_k over non-overlapping windows (windows touching a gap or a
// saturated sample excluded): the smaller of
//  (a) their `noise_floor_quantile` quantile (the floor when at least that fraction of the log is
//      static), and
//  (b) the median of the quietest cluster: the windows with s_k <= `noise_floor_cluster_width` ×
//      s_quiet, where s_quiet is the m-th smallest spread, m = max(`noise_floor_min_windows`,
//      ceil(`noise_floor_quiet_fraction` × windows)) (so a few stuck or lucky windows below the
//      statics do not set it);
// at least a tiny absolute floor (so a noise-free log still works). (b) finds the statics' noise
// when they are only a few per cent of a log with a long dynamic phase, where (a) lies in the
// motion; when statics are plentiful (a) is the smaller and the floor is as before. Threshold of
// triad k: `threshold_multiplier` × floor, or the absolute override for its kind. Sample i is
// static when the window centred on it contains no gap and no saturated sample and every triad's
// spread is <= its threshold. A run of static samples [first, last] is then grown back out at
// each end, by the half-window the first and last quiet windows already held and on while the
// samples stay still (at most 2 windows; without noise the windows next to motion carry rounding
// from their running sums):
// a sample joins while it is no gap and no saturated sample away, every triad's deviation from
// the run's mean, |y_i - mean|, stays <= its threshold (a spike stops it), and the mean of the
// c samples added at that end stays within 3 × floor × sqrt(1/c + 1/n) of the mean of the run's n
// samples (a smooth motion's onset, each sample still under the threshold, stops it before it can
// bias the static's mean by much more than its noise; white noise alone stops it rarely);
// never into the previous run's samples. A static interval is a grown run (its extent) spanning
// >= min_static, so a static of length L >= min_static is found when it holds a whole window (a
// 2 s static with a 1 s window and min_static 1 s, noise-free or noisy). Its statistics and the
// samples the fits use (first..last) stay the run itself, at least half a window from any motion
// the windows saw: the extent's edges may hold the sub-noise onset of a smooth motion (measured on
// simulated 1 - cos rotations: up to 0.14 s, tests/core/static_detection_test.cc), which biased
// the imu fits' Monte-Carlo means when used. Motion above the threshold never merges into a static
// (a bump splits it or trims it).
// Slow bias drift does not change a 1 s window's spread, so drift does not hide statics. Grown runs
// shorter than min_static are reported as `short_stretches` (what StaticShortfall() describes when
// a method finds too few statics).
//
// Cost: O(N × triads) for Init (one pass of running sums per triad), O(N × triads) per Detect.
// `options.stop` is polled every 65 536 samples of each pass: Init returns kStopped, Detect
// returns what it found so far with `stopped` set (the caller's next poll ends the run).
//
// Works in reading units: thresholds and statistics are reported in the triads' own units (the
// criterion is relative to the noise floor, so units do not matter); `unit` converts them to SI
// for the SI fields. Pure numerics, thread-compatible.
#ifndef CALIBD_CORE_STATIC_DETECTION_H_
#define CALIBD_CORE_STATIC_DETECTION_H_

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/stop_token.h"

namespace calibd::core {

enum class TriadKind { kAccelerometer, kGyroscope };
const char* TriadKindName(TriadKind kind);  // "accelerometer" | "gyroscope"

// One sensor triad of the log. Non-owning: `readings` must outlive the call.
struct TriadSeries {
  std::string name;                            // e.g. "a0", "g0" (for messages and reports)
  TriadKind kind = TriadKind::kAccelerometer;  // selects the absolute threshold override
  const Eigen::MatrixX3d* readings = nullptr;  // N×3, reading units
  double unit = 1;  // SI (m/s², rad/s) per reading unit, > 0; only scales the *_si fields
  // Saturation limits in reading units: a sample with any axis <= saturation_low or
  // >= saturation_high is saturated (dropped: never part of a static). Default: none.
  double saturation_low = -std::numeric_limits<double>::infinity();
  double saturation_high = std::numeric_limits<double>::infinity();
};

struct StaticDetectionOptions {
  double static_window = 1.0;         // s, > 0: window over which the spread is measured
  double min_static = 1.0;            // s, >= 0: shortest static interval kept (first..last)
  double threshold_multiplier = 3.0;  // > 0: threshold = multiplier × noise floor
  double noise_floor_quantile = 0.1;  // in (0, 1): the floor's quantile when at least this
                                      // fraction of the log's windows is static
  // The quietest cluster (see above), for logs with fewer statics: its seed is the m-th quietest
  // window, m = max(min_windows, ceil(quiet_fraction × windows)); it spans width × the seed.
  int noise_floor_min_windows = 3;            // >= 1
  double noise_floor_quiet_fraction = 0.005;  // in [0, 1)
  double noise_floor_cluster_width = 2.0;     // > 1
  double gap_factor = 1.5;  // > 1: a step t[i] - t[i-1] > gap_factor × median period is
                            // a gap (reported; windows across it are never static)
  // Absolute thresholds on the spread (reading units of the triads of that kind), overriding
  // multiplier × floor for every triad of that kind (SPEC `static_threshold`). nullopt: from the
  // noise floor.
  std::optional<double> accel_threshold;
  std::optional<double> gyro_threshold;
  const StopToken* stop = nullptr;  // polled in every pass over the log; may be null

  bool IsValid(std::string* error) const;
};

// A static interval: the samples the fits use (first..last: the centres of its quiet windows,
// at least half a window from any motion the windows saw) and its extent (the run grown back out,
// header: the static as found, what min_static is compared with).
struct StaticInterval {
  double start = 0, end = 0;                // t[first], t[last], s
  int64_t first = -1, last = -1;            // sample indices, inclusive
  int64_t samples = 0;                      // last - first + 1
  std::vector<Eigen::Vector3d> mean;        // per triad (order of the input), reading units
  std::vector<Eigen::Vector3d> std;         // per triad, per axis sample std (n - 1), reading units
  double extent_start = 0, extent_end = 0;  // t[extent_first], t[extent_last], s
  int64_t extent_first = -1, extent_last = -1;  // the grown run, inclusive
};

// A grown run of static samples shorter than min_static (not an interval).
struct StillStretch {
  double start = 0, end = 0;      // t[first], t[last], s
  int64_t first = -1, last = -1;  // sample indices, inclusive
};

struct TimeGap {
  int64_t index = -1;  // first sample after the gap
  double start = 0;    // t[index - 1]
  double end = 0;      // t[index]
};

struct StaticDetection {
  std::vector<StaticInterval> intervals;  // in time order
  double sample_period = 0;               // median t step, s
  int64_t window_samples = 0;             // w
  double threshold_multiplier = 0;        // the multiplier used
  // Per triad (order of the input), reading units; *_si: times the triad's unit.
  std::vector<std::string> triad_names;
  std::vector<double> noise_floor;         // robust floor of the spread
  std::vector<double> threshold;           // spread threshold used
  std::vector<bool> threshold_overridden;  // the absolute override was used
  std::vector<double> threshold_si;
  std::vector<double> noise_floor_si;
  std::vector<TimeGap> gaps;
  int64_t saturated_samples = 0;              // samples with any triad saturated
  std::vector<int64_t> saturated_per_triad;   // per triad
  int64_t static_samples = 0;                 // Σ interval samples
  std::vector<StillStretch> short_stretches;  // still, but shorter than min_static, time order
  double static_window = 0, min_static = 0;   // the options' (s), for messages
  bool stopped = false;                       // Detect ended early: options.stop was set
};

// Precomputes the spreads of every window once, so several thresholds can be tried cheaply
// (imu_tk's idea: try several multipliers and let the caller keep the best fit).
class StaticDetector {
 public:
  // kInvalidInput: options not valid, fewer than 3 samples, t not finite or not strictly
  // increasing (message names the index), triads of a different length than t, non-finite
  // readings (names triad, sample and axis), no triad. The triads' readings are only read here.
  Status Init(const Eigen::VectorXd& t, const std::vector<TriadSeries>& triads,
              const StaticDetectionOptions& options);

  // Intervals for one multiplier (the options' one when nullopt). Requires a successful Init.
  StaticDetection Detect(std::optional<double> multiplier = std::nullopt) const;

 private:
  const Eigen::VectorXd* t_ = nullptr;
  std::vector<TriadSeries> triads_;
  StaticDetectionOptions options_;
  StaticDetection base_;        // floors, gaps, saturation, period, window
  Eigen::VectorXd ratio_mult_;  // per centre: max over floor-based triads of spread / floor
  Eigen::VectorXd ratio_abs_;   // per centre: max over overridden triads of spread / threshold
  std::vector<char> blocked_;   // per centre: window touches a gap or a saturated sample
  std::vector<char> sample_saturated_;  // per sample
  std::vector<char> gap_before_;        // per sample i: the step t[i-1] -> t[i] is a gap
};

// What a method that found fewer statics than it needs tells the user (appended to its message):
// the intervals and the still stretches found with their lengths, the window, minimum and
// threshold used, and what to change (longer statics, a shorter static_window or min_static,
// static_threshold). E.g. "static detection (static_window 1 s, min_static 1 s, threshold 3 ×
// noise floor: a0 0.0173, g0 0.00346 reading units) found 2 intervals (4.1, 3.9 s) and 3 still
// stretches shorter than min_static (0.62 s at 12.3 s, ...): ...".
std::string StaticShortfall(const StaticDetection& d);

// One-shot convenience: Init + Detect(). kStopped when options.stop asked for a stop.
Status DetectStatics(const Eigen::VectorXd& t, const std::vector<TriadSeries>& triads,
                     const StaticDetectionOptions& options, StaticDetection* out);

}  // namespace calibd::core

#endif  // CALIBD_CORE_STATIC_DETECTION_H_
