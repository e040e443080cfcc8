#include "core/saturation.h"

#include <algorithm>
#include <cmath>

namespace calibd::core {
namespace {

constexpr double kQuantumFactor = 3;  // a jump is at least 3 reading quanta (header)

// The channel's noise σ from its quietest stretches (header): the 10 % quantile over blocks of
// kNoiseBlock samples of sqrt(mean((third difference)²) / 20) (white noise: var = 20σ²; smooth
// motion adds little to third differences at inertial rates: (ω dt)³ of its amplitude).
constexpr Eigen::Index kNoiseBlock = 32;
template <class M>
double NoiseScale(const M& y, int a, std::vector<double>* scratch) {
  const Eigen::Index n = y.rows();
  std::vector<double>& blocks = *scratch;
  blocks.clear();
  auto v = [&](Eigen::Index i) { return static_cast<double>(y(i, a)); };
  for (Eigen::Index b = 0; b + kNoiseBlock + 3 <= n; b += kNoiseBlock) {
    double ss = 0;
    for (Eigen::Index i = b; i < b + kNoiseBlock; ++i) {
      const double d3 = v(i + 3) - 3 * v(i + 2) + 3 * v(i + 1) - v(i);
      ss += d3 * d3;
    }
    blocks.push_back(std::sqrt(ss / (20.0 * kNoiseBlock)));
  }
  if (blocks.empty()) return 0;
  const size_t k = blocks.size() / 10;
  std::nth_element(blocks.begin(), blocks.begin() + static_cast<std::ptrdiff_t>(k), blocks.end());
  return blocks[k];
}

// The channel's reading quantum: the smallest nonzero |first difference| (1 count for integer
// counts; tiny for real-valued readings).
template <class M>
double Quantum(const M& y, int a) {
  double q = std::numeric_limits<double>::infinity();
  for (Eigen::Index i = 1; i < y.rows(); ++i) {
    const double d = std::abs(static_cast<double>(y(i, a)) - static_cast<double>(y(i - 1, a)));
    if (d > 0) q = std::min(q, d);
  }
  return std::isfinite(q) ? q : 0;
}

// Whether `level` (an extreme of column a) is a clip level by the header's rule; counts the
// samples equal to it.
template <class M>
bool IsClipLevel(const M& y, int a, double level, double jump, int min_run, int64_t* count) {
  const Eigen::Index n = y.rows();
  bool found = false;
  *count = 0;
  for (Eigen::Index i = 0; i < n;) {
    if (static_cast<double>(y(i, a)) != level) {
      ++i;
      continue;
    }
    Eigen::Index j = i;
    while (j + 1 < n && static_cast<double>(y(j + 1, a)) == level) ++j;
    *count += j - i + 1;
    if (!found && j - i + 1 >= min_run) {
      double step = 0;
      if (i > 0) step = std::abs(level - static_cast<double>(y(i - 1, a)));
      if (j + 1 < n) step = std::max(step, std::abs(level - static_cast<double>(y(j + 1, a))));
      bool moving = false;
      for (int b = 0; b < 3 && !moving; ++b) {
        if (b == a) continue;
        for (Eigen::Index r = i + 1; r <= j && !moving; ++r) moving = y(r, b) != y(i, b);
      }
      found = step >= jump && step > 0 && moving;
    }
    i = j + 1;
  }
  return found;
}

template <class M>
Status FindImpl(const M& y, const std::string& name, const SaturationOptions& o,
                std::array<ChannelSaturation, 3>* out) {
  std::string error;
  if (!o.IsValid(&error)) return Status::InvalidInput("saturation: " + error);
  if (y.cols() != 3) {
    return Status::InvalidInput("saturation: triad " + name + " has " + std::to_string(y.cols()) +
                                " columns, not 3");
  }
  const Eigen::Index n = y.rows();
  std::vector<double> scratch;
  for (int a = 0; a < 3; ++a) {
    ChannelSaturation& c = (*out)[static_cast<size_t>(a)];
    c = ChannelSaturation();
    c.name = name + "_" + "xyz"[a];
    if (StopRequested(o.stop)) return StoppedStatus(*o.stop, "saturation search");
    double mx = -std::numeric_limits<double>::infinity();
    double mn = std::numeric_limits<double>::infinity();
    for (Eigen::Index i = 0; i < n; ++i) {
      const double v = static_cast<double>(y(i, a));
      if (!std::isfinite(v)) {
        return Status::InvalidInput("saturation: " + c.name + " at sample " + std::to_string(i) +
                                    " is not a finite number");
      }
      mx = std::max(mx, v);
      mn = std::min(mn, v);
    }
    if (o.low || o.high) {
      c.source = "config";
      if (o.low) c.low = *o.low;
      if (o.high) c.high = *o.high;
      for (Eigen::Index i = 0; i < n; ++i) {
        const double v = static_cast<double>(y(i, a));
        if (v <= c.low) ++c.pinned_low;
        if (v >= c.high) ++c.pinned_high;
      }
      continue;
    }
    if (n < 3 || !(mx > mn)) continue;  // a constant channel has no clip to find
    // Polled between the passes over the channel (each one pass over n samples).
    if (StopRequested(o.stop)) return StoppedStatus(*o.stop, "saturation search");
    const double noise = NoiseScale(y, a, &scratch);
    if (StopRequested(o.stop)) return StoppedStatus(*o.stop, "saturation search");
    const double quantum = Quantum(y, a);
    if (StopRequested(o.stop)) return StoppedStatus(*o.stop, "saturation search");
    const double jump = std::max(
        {o.jump_range_fraction * (mx - mn), o.jump_noise_factor * noise, kQuantumFactor * quantum});
    int64_t count = 0;
    if (IsClipLevel(y, a, mx, jump, o.min_run, &count)) {
      c.high = mx;
      c.pinned_high = count;
    }
    if (StopRequested(o.stop)) return StoppedStatus(*o.stop, "saturation search");
    if (IsClipLevel(y, a, mn, jump, o.min_run, &count)) {
      c.low = mn;
      c.pinned_low = count;
    }
    if (c.pinned() > 0) c.source = "data";
  }
  return Status::Ok();
}

}  // namespace

bool SaturationOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  if (min_run < 2) return fail("min_run must be >= 2 (a single sample at the extreme is a peak)");
  if (!(jump_range_fraction >= 0 && jump_range_fraction < 1)) {
    return fail("jump_range_fraction must be in [0, 1)");
  }
  if (!(std::isfinite(jump_noise_factor) && jump_noise_factor >= 0)) {
    return fail("jump_noise_factor must be a finite number >= 0");
  }
  if ((low && std::isnan(*low)) || (high && std::isnan(*high))) {
    return fail("saturation limits must be numbers");
  }
  if (low && high && !(*low < *high)) return fail("the low saturation limit must be below high");
  return true;
}

Status FindTriadSaturation(const Eigen::Ref<const Eigen::MatrixXd>& y, const std::string& name,
                           const SaturationOptions& options,
                           std::array<ChannelSaturation, 3>* out) {
  return FindImpl(y, name, options, out);
}

Status FindTriadSaturation(const Eigen::Ref<const Eigen::MatrixXf>& y, const std::string& name,
                           const SaturationOptions& options,
                           std::array<ChannelSaturation, 3>* out) {
  return FindImpl(y, name, options, out);
}

SaturationLimits CombinedLimits(const std::vector<ChannelSaturation>& channels) {
  SaturationLimits l;
  for (const ChannelSaturation& c : channels) {  // a channel without a level holds ±infinity
    l.low = std::max(l.low, c.low);
    l.high = std::min(l.high, c.high);
  }
  return l;
}

std::optional<double> SymmetricLimit(const SaturationLimits& limits) {
  double s = std::numeric_limits<double>::infinity();
  if (std::isfinite(limits.high)) s = std::min(s, limits.high);
  if (std::isfinite(limits.low)) s = std::min(s, -limits.low);
  if (!std::isfinite(s) || !(s > 0)) return std::nullopt;  // not a centred sensor's range
  return s;
}

}  // namespace calibd::core
