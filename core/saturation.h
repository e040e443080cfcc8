// Saturation found in the data (issue #20): which samples of a raw triad are pinned at the
// sensor's full scale, without a configured limit. Numerics only; the method adapters drop the
// pinned samples from their fits (and, for statics, every window holding one) and report them.
//
// Rule, per channel (one axis of a triad), for each extreme M of the channel (its maximum, then
// its minimum):
//   M is a saturation level when at least one run of >= `min_run` consecutive samples exactly
//   equal to M
//    (a) is entered or left by a jump: |M - y| of the sample just before or just after the run
//        is >= max(jump_range_fraction × (max - min), jump_noise_factor × σ_n, 3 × q), σ_n the
//        channel's noise from its quietest stretches (the 10 % quantile over blocks of 32 samples
//        of the RMS third difference / √20) and q its reading quantum (the smallest nonzero step:
//        1 count for integer counts), and
//    (b) happens while the triad moves: some other axis of the triad changes within the run.
//   Then every sample equal to M is pinned (single samples at M too: a fast signal often touches
//   its clip level for one sample only).
// Why: a clipped signal reaches its level with the slope of the motion that saturates it (a)
// and during motion (b), and the level is its extreme. A peak touched once is not a run; a static
// that happens to be the channel's extreme is left by a noise-sized step (a fails) with every
// axis quiet (b fails when noise-free: a simulation's constant static); a rate table's constant
// rate in a noisy log fails (a). What the rule misses: a signal that creeps into saturation
// slowly (no jump) or levels that vary along the log (on-chip offset correction after the clip):
// configure the limit then.
// Measured: on the nine MIMU4444 recordings (int16 counts at 62.5 Hz, clipped at +32767 and
// -32768) every gyroscope channel's two levels are established by 7 or more qualifying runs of
// >= 3 samples and no accelerometer level is found; on imu_tk's Xsens log (offset-binary counts,
// unclipped) no level is found even with jump_range_fraction 0.
// Configured limits (`low`/`high`) replace the search: values <= low or >= high are pinned.
//
// Cost: O(N) per channel (a few scans, one nth_element over N/32 block values), N/32 doubles of
// scratch. Pure numerics, thread-compatible.
#ifndef CALIBD_CORE_SATURATION_H_
#define CALIBD_CORE_SATURATION_H_

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/stop_token.h"

namespace calibd::core {

struct SaturationOptions {
  int min_run = 3;                     // >= 2: identical samples at the extreme establishing it
  double jump_range_fraction = 0.005;  // in [0, 1): entry/exit step >= this × (max - min) ...
  double jump_noise_factor = 8;        // >= 0: ... and >= this × the channel's noise σ_n
  // Configured limits, reading units (SPEC `gyro_saturation`, `accel_saturation`): when either is
  // set the data are not searched; values <= low or >= high are pinned. Default: none (search).
  std::optional<double> low;
  std::optional<double> high;
  const StopToken* stop = nullptr;  // polled once per channel and extreme; may be null

  bool IsValid(std::string* error) const;
};

// What one channel holds at its clip levels.
struct ChannelSaturation {
  std::string name;    // e.g. "g3_x"
  std::string source;  // "data" (found by the rule), "config" (configured limit), "" (none)
  // The levels, reading units: samples <= low or >= high are pinned. ±infinity: no level.
  double low = -std::numeric_limits<double>::infinity();
  double high = std::numeric_limits<double>::infinity();
  int64_t pinned_low = 0, pinned_high = 0;  // samples at or beyond each level

  int64_t pinned() const { return pinned_low + pinned_high; }
};

// The three channels of one triad (N×3, reading units, finite), named name + "_x" / "_y" / "_z".
// kInvalidInput: options not valid, non-finite readings (names channel and sample). kStopped:
// the token asked for a stop.
Status FindTriadSaturation(const Eigen::Ref<const Eigen::MatrixXd>& y, const std::string& name,
                           const SaturationOptions& options, std::array<ChannelSaturation, 3>* out);
Status FindTriadSaturation(const Eigen::Ref<const Eigen::MatrixXf>& y, const std::string& name,
                           const SaturationOptions& options, std::array<ChannelSaturation, 3>* out);

// One limit pair for a set of channels read by a method that takes one per sensor kind: the
// tightest (largest low, smallest high) over the channels with a level. A channel that reaches
// another's level is at its full scale too (sensors of one kind share their range), so the extra
// samples this drops are at the clip anyway.
struct SaturationLimits {
  double low = -std::numeric_limits<double>::infinity();
  double high = std::numeric_limits<double>::infinity();
  bool any() const { return std::isfinite(low) || std::isfinite(high); }
};
SaturationLimits CombinedLimits(const std::vector<ChannelSaturation>& channels);

// A symmetric limit s (|y| >= s pinned) covering the combined limits: min(high, -low) over the
// finite ones; nullopt when there is none or it is not > 0 (levels not around zero).
std::optional<double> SymmetricLimit(const SaturationLimits& limits);

}  // namespace calibd::core

#endif  // CALIBD_CORE_SATURATION_H_
