#include "core/static_detection.h"

#include <algorithm>
#include <cmath>

namespace calibd::core {
namespace {

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
void WindowSpreads(const Eigen::MatrixX3d& y, int64_t h, Eigen::VectorXd* spread) {
  const int64_t n = y.rows();
  const int64_t w = 2 * h + 1;
  spread->setConstant(n, std::numeric_limits<double>::infinity());
  double s1[3], s2[3], anchor[3];
  for (int64_t c0 = h; c0 + h < n; c0 += w) {
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
  for (int64_t i = 1; i < n; ++i) {
    const bool gap = t(i) - t(i - 1) > options.gap_factor * b.sample_period;
    if (gap) b.gaps.push_back({i, t(i - 1), t(i)});
    gap_prefix[static_cast<size_t>(i + 1)] = gap_prefix[static_cast<size_t>(i)] + (gap ? 1 : 0);
  }
  int64_t h = std::max<int64_t>(1, std::llround(0.5 * options.static_window / b.sample_period));
  h = std::min(h, (n - 1) / 2);
  const int64_t w = 2 * h + 1;
  b.window_samples = w;

  // Saturation.
  const size_t k_triads = triads.size();
  b.saturated_per_triad.assign(k_triads, 0);
  std::vector<int64_t> sat_prefix(static_cast<size_t>(n + 1), 0);
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
    WindowSpreads(*s.readings, h, &spread);
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
  int64_t c = 0;
  while (c < n) {
    if (!is_static(c)) {
      ++c;
      continue;
    }
    const int64_t first = c;
    while (c + 1 < n && is_static(c + 1)) ++c;
    const int64_t last = c;
    ++c;
    if (t(last) - t(first) < options_.min_static) continue;
    StaticInterval iv;
    iv.first = first;
    iv.last = last;
    iv.start = t(first);
    iv.end = t(last);
    iv.samples = last - first + 1;
    for (const TriadSeries& s : triads_) {
      const auto block = s.readings->middleRows(first, iv.samples);
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

Status DetectStatics(const Eigen::VectorXd& t, const std::vector<TriadSeries>& triads,
                     const StaticDetectionOptions& options, StaticDetection* out) {
  StaticDetector detector;
  Status s = detector.Init(t, triads, options);
  if (!s.ok()) return s;
  *out = detector.Detect();
  return Status::Ok();
}

}  // namespace calibd::core
