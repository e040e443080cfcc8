#include "core/static_detection.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace calibd::core {
namespace {

constexpr int64_t kPollSamples = 65536;  // samples of work between two polls of the stop token
// Growth of a run (header): the mean of the c samples added at one end stays within
// kGrowthZ × floor × sqrt(1/c + 1/n) of the mean of the run's n samples. The floor is the spread
// of 3 axes (σ√3 for white noise), so noise alone exceeds it with P(χ²₃ > 27) ≈ 6e-6 per step.
constexpr double kGrowthZ = 3;
// At most this many windows of growth per end: the half-window the first quiet window held, and
// the windows a noise-free log's running sums call not quite quiet next to motion (their
// rounding), never a long creep.
constexpr int64_t kGrowthWindows = 2;

double Quantile(std::vector<double> x, double q) {
  if (x.empty()) return 0;
  const size_t k = std::min(x.size() - 1, static_cast<size_t>(q * static_cast<double>(x.size())));
  std::nth_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(k), x.end());
  return x[k];
}

// The noise floor of one triad from its window spreads (header: the smaller of the quantile and
// the median of the quietest cluster).
double NoiseFloor(std::vector<double> spreads, const StaticDetectionOptions& o) {
  if (spreads.empty()) return 0;
  const double by_quantile = Quantile(spreads, o.noise_floor_quantile);
  std::sort(spreads.begin(), spreads.end());
  const size_t n = spreads.size();
  const size_t m = std::min(n, std::max(static_cast<size_t>(o.noise_floor_min_windows),
                                        static_cast<size_t>(std::ceil(o.noise_floor_quiet_fraction *
                                                                      static_cast<double>(n)))));
  const double seed = spreads[m - 1];
  const size_t in_cluster = static_cast<size_t>(
      std::upper_bound(spreads.begin(), spreads.end(), o.noise_floor_cluster_width * seed) -
      spreads.begin());
  const double by_cluster = spreads[(in_cluster - 1) / 2];  // its median (lower for even counts)
  return std::min(by_quantile, by_cluster);
}

// Spread of every centred window of w = 2h+1 samples, for centres h .. N-h-1 (others: +inf).
// Running sums relative to an anchor re-taken (and the sums recomputed) every w centres, so the
// rounding error of the sums stays at the level of the window's own deviation from the anchor:
// a window inside a static whose anchor is in the same static has exactly zero spread when the
// readings are constant.
// False when `stop` asked for a stop (polled every ~65 536 centres).
bool WindowSpreads(const Eigen::MatrixX3d& y, int64_t h, const StopToken* stop,
                   Eigen::VectorXd* spread) {
  const int64_t n = y.rows();
  const int64_t w = 2 * h + 1;
  spread->setConstant(n, std::numeric_limits<double>::infinity());
  double s1[3], s2[3], anchor[3];
  int64_t since_poll = 0;
  for (int64_t c0 = h; c0 + h < n; c0 += w) {
    since_poll += 2 * w;
    if (since_poll >= kPollSamples) {
      since_poll = 0;
      if (StopRequested(stop)) return false;
    }
    for (int a = 0; a < 3; ++a) {
      anchor[a] = y(c0, a);
      s1[a] = s2[a] = 0;
      for (int64_t j = c0 - h; j <= c0 + h; ++j) {
        const double d = y(j, a) - anchor[a];
        s1[a] += d;
        s2[a] += d * d;
      }
    }
    const int64_t c_end = std::min(c0 + w, n - h);  // exclusive
    for (int64_t c = c0; c < c_end; ++c) {
      if (c > c0) {
        for (int a = 0; a < 3; ++a) {
          const double add = y(c + h, a) - anchor[a];
          const double del = y(c - h - 1, a) - anchor[a];
          s1[a] += add - del;
          s2[a] += add * add - del * del;
        }
      }
      double var = 0;
      for (int a = 0; a < 3; ++a) {
        var += std::max(
            0.0, (s2[a] - s1[a] * s1[a] / static_cast<double>(w)) / static_cast<double>(w - 1));
      }
      (*spread)(c) = std::sqrt(var);
    }
  }
  return true;
}

}  // namespace

const char* TriadKindName(TriadKind kind) {
  return kind == TriadKind::kAccelerometer ? "accelerometer" : "gyroscope";
}

bool StaticDetectionOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(static_window)) return fail("static_window must be a finite number > 0 (s)");
  if (!(std::isfinite(min_static) && min_static >= 0)) {
    return fail("min_static must be a finite number >= 0 (s)");
  }
  if (!positive(threshold_multiplier)) return fail("threshold multiplier must be > 0");
  if (!(noise_floor_quantile > 0 && noise_floor_quantile < 1)) {
    return fail("noise_floor_quantile must be in (0, 1)");
  }
  if (noise_floor_min_windows < 1) return fail("noise_floor_min_windows must be >= 1");
  if (!(noise_floor_quiet_fraction >= 0 && noise_floor_quiet_fraction < 1)) {
    return fail("noise_floor_quiet_fraction must be in [0, 1)");
  }
  if (!(std::isfinite(noise_floor_cluster_width) && noise_floor_cluster_width > 1)) {
    return fail("noise_floor_cluster_width must be a finite number > 1");
  }
  if (!(std::isfinite(gap_factor) && gap_factor > 1)) return fail("gap_factor must be > 1");
  if (accel_threshold && !positive(*accel_threshold)) {
    return fail("static_threshold (accelerometer) must be a finite number > 0");
  }
  if (gyro_threshold && !positive(*gyro_threshold)) {
    return fail("static_threshold (gyroscope) must be a finite number > 0");
  }
  return true;
}

Status StaticDetector::Init(const Eigen::VectorXd& t, const std::vector<TriadSeries>& triads,
                            const StaticDetectionOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput("static detection: " + error);
  const int64_t n = t.size();
  if (n < 3)
    return Status::InvalidInput("the log needs at least 3 samples, it has " + std::to_string(n));
  if (triads.empty()) return Status::InvalidInput("static detection needs at least one triad");
  for (int64_t i = 0; i < n; ++i) {
    if (!std::isfinite(t(i))) {
      return Status::InvalidInput("t is not a finite number at sample " + std::to_string(i));
    }
    if (i > 0 && !(t(i) > t(i - 1))) {
      return Status::InvalidInput("t must be strictly increasing: sample " + std::to_string(i) +
                                  " (t = " + std::to_string(t(i)) + ") is not after sample " +
                                  std::to_string(i - 1) + " (t = " + std::to_string(t(i - 1)) +
                                  ")");
    }
  }
  for (const TriadSeries& s : triads) {
    if (s.readings == nullptr) return Status::InvalidInput("triad " + s.name + " has no readings");
    if (s.readings->rows() != n) {
      return Status::InvalidInput("triad " + s.name + " has " + std::to_string(s.readings->rows()) +
                                  " samples, t has " + std::to_string(n));
    }
    if (!(std::isfinite(s.unit) && s.unit > 0)) {
      return Status::InvalidInput("triad " + s.name + ": unit must be a finite number > 0");
    }
    if (!s.readings->allFinite()) {
      for (int64_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
          if (!std::isfinite((*s.readings)(i, a))) {
            return Status::InvalidInput("triad " + s.name + ": reading " + "xyz"[a] +
                                        " at sample " + std::to_string(i) +
                                        " is not a finite number");
          }
        }
      }
    }
  }
  t_ = &t;
  triads_ = triads;
  options_ = options;
  StaticDetection& b = base_;
  b = StaticDetection();

  // Sample period and gaps.
  std::vector<double> dt(static_cast<size_t>(n - 1));
  for (int64_t i = 1; i < n; ++i) dt[static_cast<size_t>(i - 1)] = t(i) - t(i - 1);
  b.sample_period = Quantile(dt, 0.5);
  std::vector<int64_t> gap_prefix(static_cast<size_t>(n + 1), 0);  // gaps at steps < i
  gap_before_.assign(static_cast<size_t>(n), 0);
  for (int64_t i = 1; i < n; ++i) {
    const bool gap = t(i) - t(i - 1) > options.gap_factor * b.sample_period;
    if (gap) b.gaps.push_back({i, t(i - 1), t(i)});
    gap_before_[static_cast<size_t>(i)] = gap ? 1 : 0;
    gap_prefix[static_cast<size_t>(i + 1)] = gap_prefix[static_cast<size_t>(i)] + (gap ? 1 : 0);
  }
  int64_t h = std::max<int64_t>(1, std::llround(0.5 * options.static_window / b.sample_period));
  h = std::min(h, (n - 1) / 2);
  const int64_t w = 2 * h + 1;
  b.window_samples = w;
  b.static_window = options.static_window;
  b.min_static = options.min_static;

  // Saturation.
  const size_t k_triads = triads.size();
  b.saturated_per_triad.assign(k_triads, 0);
  std::vector<int64_t> sat_prefix(static_cast<size_t>(n + 1), 0);
  sample_saturated_.assign(static_cast<size_t>(n), 0);
  if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "static detection");
  for (int64_t i = 0; i < n; ++i) {
    bool sat = false;
    for (size_t k = 0; k < k_triads; ++k) {
      const auto row = triads[k].readings->row(i);
      if (row.minCoeff() <= triads[k].saturation_low ||
          row.maxCoeff() >= triads[k].saturation_high) {
        ++b.saturated_per_triad[k];
        sat = true;
      }
    }
    if (sat) ++b.saturated_samples;
    sample_saturated_[static_cast<size_t>(i)] = sat ? 1 : 0;
    sat_prefix[static_cast<size_t>(i + 1)] = sat_prefix[static_cast<size_t>(i)] + (sat ? 1 : 0);
  }
  blocked_.assign(static_cast<size_t>(n), 1);
  for (int64_t c = h; c + h < n; ++c) {
    const auto lo = static_cast<size_t>(c - h), hi = static_cast<size_t>(c + h + 1);
    const bool sat = sat_prefix[hi] - sat_prefix[lo] > 0;
    // Steps inside the window: between samples lo..hi-1, i.e. step indices lo+1 .. hi-1.
    const bool gap = gap_prefix[hi] - gap_prefix[lo + 1] > 0;
    blocked_[static_cast<size_t>(c)] = (sat || gap) ? 1 : 0;
  }

  // Spreads, floors and thresholds.
  ratio_mult_.setZero(n);
  ratio_abs_.setZero(n);
  Eigen::VectorXd spread;
  for (size_t k = 0; k < k_triads; ++k) {
    const TriadSeries& s = triads[k];
    if (!WindowSpreads(*s.readings, h, options.stop, &spread)) {
      return StoppedStatus(*options.stop, "static detection");
    }
    std::vector<double> samples;
    for (int64_t c = h; c + h < n; c += w) {
      if (!blocked_[static_cast<size_t>(c)]) samples.push_back(spread(c));
    }
    const double scale = s.readings->cwiseAbs().maxCoeff();
    const double eps = 1e-12 * std::max(scale, 1e-300);
    const double floor = std::max(NoiseFloor(std::move(samples), options), eps);
    const std::optional<double>& override_thr =
        s.kind == TriadKind::kAccelerometer ? options.accel_threshold : options.gyro_threshold;
    b.triad_names.push_back(s.name);
    b.noise_floor.push_back(floor);
    b.noise_floor_si.push_back(floor * s.unit);
    b.threshold_overridden.push_back(override_thr.has_value());
    b.threshold.push_back(override_thr ? *override_thr : 0);
    Eigen::VectorXd& ratio = override_thr ? ratio_abs_ : ratio_mult_;
    const double denom = override_thr ? *override_thr : floor;
    for (int64_t c = 0; c < n; ++c) ratio(c) = std::max(ratio(c), spread(c) / denom);
  }
  return Status::Ok();
}

StaticDetection StaticDetector::Detect(std::optional<double> multiplier) const {
  StaticDetection d = base_;
  const double m = multiplier.value_or(options_.threshold_multiplier);
  d.threshold_multiplier = m;
  for (size_t k = 0; k < triads_.size(); ++k) {
    if (!d.threshold_overridden[k]) d.threshold[k] = m * d.noise_floor[k];
  }
  d.threshold_si.resize(triads_.size());
  for (size_t k = 0; k < triads_.size(); ++k) {
    d.threshold_si[k] = d.threshold[k] * triads_[k].unit;
  }
  const Eigen::VectorXd& t = *t_;
  const int64_t n = t.size();
  auto is_static = [&](int64_t c) {
    return !blocked_[static_cast<size_t>(c)] && ratio_mult_(c) <= m && ratio_abs_(c) <= 1.0;
  };
  const size_t k_triads = triads_.size();
  std::vector<Eigen::RowVector3d> core_mean(k_triads), added(k_triads);
  int64_t core_samples = 1;  // of the run being grown
  // Grows [first, last] by one sample at a time in direction `step` (-1, +1) up to kGrowthWindows
  // windows (header): sample i joins when it is not saturated, no gap lies between it and the run,
  // every triad's |y_i - mean| <= its threshold, and the mean of the samples added on this side
  // stays within kGrowthZ × floor / sqrt(count) of the run's mean (so a smooth motion's onset, each
  // sample below the threshold, cannot bias the static's mean by more than noise).
  auto grow = [&](int64_t from, int step, int64_t limit) {
    for (auto& a : added) a.setZero();
    int64_t i = from, count = 0;
    const double inv_core = 1.0 / static_cast<double>(core_samples);
    while (count < kGrowthWindows * d.window_samples) {
      const int64_t next = i + step;
      if (step < 0 ? next < limit : next > limit) break;
      if (sample_saturated_[static_cast<size_t>(next)]) break;
      if (gap_before_[static_cast<size_t>(step < 0 ? i : next)]) break;
      bool ok = true;
      for (size_t k = 0; k < k_triads && ok; ++k) {
        const auto row = triads_[k].readings->row(next);
        const double floor = d.noise_floor[k];
        ok = (row - core_mean[k]).norm() <= d.threshold[k] &&
             ((added[k] + row) / static_cast<double>(count + 1) - core_mean[k]).norm() <=
                 kGrowthZ * floor * std::sqrt(1.0 / static_cast<double>(count + 1) + inv_core);
      }
      if (!ok) break;
      for (size_t k = 0; k < k_triads; ++k) added[k] += triads_[k].readings->row(next);
      i = next;
      ++count;
    }
    return i;
  };
  int64_t prev_last = -1;  // the previous grown run's last sample
  int64_t since_poll = 0;
  int64_t c = 0;
  while (c < n) {
    if (++since_poll >= kPollSamples) {
      since_poll = 0;
      if (StopRequested(options_.stop)) {
        d.stopped = true;
        return d;
      }
    }
    if (!is_static(c)) {
      ++c;
      continue;
    }
    const int64_t core_first = c;
    while (c + 1 < n && is_static(c + 1)) ++c;
    const int64_t core_last = c;
    ++c;
    since_poll += core_last - core_first;
    for (size_t k = 0; k < k_triads; ++k) {
      core_mean[k] =
          triads_[k].readings->middleRows(core_first, core_last - core_first + 1).colwise().mean();
    }
    core_samples = core_last - core_first + 1;
    const int64_t first = grow(core_first, -1, prev_last + 1);
    const int64_t last = grow(core_last, +1, n - 1);
    prev_last = last;
    if (t(last) - t(first) < options_.min_static) {
      d.short_stretches.push_back({t(first), t(last), first, last});
      continue;
    }
    // The statistics and the samples the fits use: the run of quiet windows' centres (at least
    // half a window from any motion the windows saw: the grown margin may hold the sub-noise
    // onset of a smooth motion, which would bias the static's mean and shorten the rotations
    // between statics). The extent: the grown run.
    StaticInterval iv;
    iv.first = core_first;
    iv.last = core_last;
    iv.start = t(core_first);
    iv.end = t(core_last);
    iv.samples = core_last - core_first + 1;
    iv.extent_first = first;
    iv.extent_last = last;
    iv.extent_start = t(first);
    iv.extent_end = t(last);
    for (const TriadSeries& s : triads_) {
      const auto block = s.readings->middleRows(iv.first, iv.samples);
      const Eigen::RowVector3d mean = block.colwise().mean();
      Eigen::Vector3d sd = Eigen::Vector3d::Zero();
      if (iv.samples > 1) {
        sd =
            ((block.rowwise() - mean).colwise().squaredNorm() / static_cast<double>(iv.samples - 1))
                .cwiseSqrt()
                .transpose();
      }
      iv.mean.push_back(mean.transpose());
      iv.std.push_back(sd);
    }
    d.static_samples += iv.samples;
    d.intervals.push_back(std::move(iv));
  }
  return d;
}

namespace {

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

std::string StaticShortfall(const StaticDetection& d) {
  std::string m = "static detection (static_window " + Num(d.static_window) + " s, min_static " +
                  Num(d.min_static) + " s, threshold ";
  bool any_multiplied = false;
  for (size_t k = 0; k < d.triad_names.size(); ++k) {
    any_multiplied = any_multiplied || !d.threshold_overridden[k];
  }
  if (any_multiplied) m += Num(d.threshold_multiplier) + " × noise floor, ";
  m += "window spread";
  const size_t shown = std::min<size_t>(d.triad_names.size(), 4);
  for (size_t k = 0; k < shown; ++k) {
    m += (k ? ", " : " ") + d.triad_names[k] + " " + Num(d.threshold[k]) + " reading units" +
         (d.threshold_overridden[k] ? " (static_threshold)" : "");
  }
  if (d.triad_names.size() > shown) m += ", ...";
  m += ") found ";
  auto list = [](const auto& items, size_t max) {
    std::string out;
    for (size_t i = 0; i < items.size() && i < max; ++i) {
      out += (i ? ", " : "") + Num(items[i].end - items[i].start) + " s at " + Num(items[i].start) +
             " s";
    }
    if (items.size() > max) out += ", ...";
    return out;
  };
  std::vector<StillStretch> found;
  for (const StaticInterval& iv : d.intervals) {
    found.push_back({iv.extent_start, iv.extent_end, iv.extent_first, iv.extent_last});
  }
  m += std::to_string(d.intervals.size()) + " static interval(s)";
  if (!found.empty()) m += " (" + list(found, 6) + ")";
  if (d.short_stretches.empty()) {
    m += " and no shorter still stretch";
  } else {
    double longest = 0;
    for (const StillStretch& s : d.short_stretches) longest = std::max(longest, s.end - s.start);
    m += " and " + std::to_string(d.short_stretches.size()) +
         " still stretch(es) shorter than min_static (" + list(d.short_stretches, 6) +
         "; longest " + Num(longest) + " s)";
  }
  if (d.saturated_samples > 0) {
    m += "; " + std::to_string(d.saturated_samples) +
         " saturated sample(s) block every window holding one";
  }
  if (d.intervals.empty() && d.short_stretches.empty()) {
    m += ": the spread of a " + Num(d.static_window) +
         " s window never stayed under the threshold: hold the board still for at least " +
         Num(std::max(d.static_window, d.min_static)) +
         " s per orientation, use a shorter static_window, or set static_threshold above the "
         "spread at rest (in reading units)";
  } else if (!d.short_stretches.empty()) {
    m += ": hold each static at least " + Num(std::max(d.static_window, d.min_static)) +
         " s, or lower min_static (and static_window) below the still stretches' lengths";
  } else {
    m += ": record more statics (in more orientations)";
  }
  return m;
}

Status DetectStatics(const Eigen::VectorXd& t, const std::vector<TriadSeries>& triads,
                     const StaticDetectionOptions& options, StaticDetection* out) {
  StaticDetector detector;
  Status s = detector.Init(t, triads, options);
  if (!s.ok()) return s;
  *out = detector.Detect();
  if (out->stopped) return StoppedStatus(*options.stop, "static detection");
  return Status::Ok();
}

}  // namespace calibd::core
