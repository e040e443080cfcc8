// Stages 1 and 4 of core/thermal.h and the per-IMU run: averaging windows inside the statics,
// orientation groups, the six channel fits and the heating/cooling comparison.
#include "core/thermal.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/thermal_internal.h"

namespace calibd::core {
namespace thermal_internal {

void SetWindowTemperature(const Eigen::VectorXd& t, const Eigen::VectorXd& temp,
                          const WindowRange& range, double min_rate, ThermalWindow* w) {
  const int64_t n = range.last - range.first + 1;
  double t_mean = 0, temp_mean = 0;
  for (int64_t i = range.first; i <= range.last; ++i) {
    t_mean += t(i);
    temp_mean += temp(i);
  }
  t_mean /= n;
  temp_mean /= n;
  double stt = 0, sty = 0;
  for (int64_t i = range.first; i <= range.last; ++i) {
    const double dt = t(i) - t_mean;
    stt += dt * dt;
    sty += dt * (temp(i) - temp_mean);
  }
  w->temperature = temp_mean;
  w->rate = stt > 0 ? sty / stt : 0;
  w->phase = w->rate > min_rate ? 1 : (w->rate < -min_rate ? -1 : 0);
}

ChannelData SelectWindows(const std::vector<ThermalWindow>& windows, int c, int phase, double t_ref,
                          int orientations, const std::vector<double>& gravity_of_orientation) {
  ChannelData d;
  const bool gyro = c >= 3;
  d.group_of_orientation.assign(static_cast<size_t>(gyro ? 1 : orientations), -1);
  std::vector<int> rows;
  for (size_t i = 0; i < windows.size(); ++i) {
    if (phase == 0 || windows[i].phase == phase) rows.push_back(static_cast<int>(i));
  }
  d.x.resize(static_cast<Eigen::Index>(rows.size()));
  d.y.resize(d.x.size());
  d.sigma.resize(d.x.size());
  if (!gravity_of_orientation.empty()) d.gravity.resize(d.x.size());
  d.t_lo = std::numeric_limits<double>::infinity();
  d.t_hi = -d.t_lo;
  for (size_t r = 0; r < rows.size(); ++r) {
    const ThermalWindow& w = windows[static_cast<size_t>(rows[r])];
    const int o = gyro ? 0 : w.orientation;
    int& g = d.group_of_orientation[static_cast<size_t>(o)];
    if (g < 0) g = d.groups++;
    d.group.push_back(g);
    d.samples += w.samples;
    d.x(static_cast<Eigen::Index>(r)) = w.temperature - t_ref;
    d.y(static_cast<Eigen::Index>(r)) = w.mean(c);
    // A window without noise (a noise-free simulation) still needs a positive weight.
    d.sigma(static_cast<Eigen::Index>(r)) = std::max(w.mean_std(c), 1e-15);
    if (!gravity_of_orientation.empty())
      d.gravity(static_cast<Eigen::Index>(r)) = gravity_of_orientation[static_cast<size_t>(o)];
    d.t_lo = std::min(d.t_lo, w.temperature);
    d.t_hi = std::max(d.t_hi, w.temperature);
  }
  return d;
}

}  // namespace thermal_internal

namespace {

using thermal_internal::AddLagUncertainty;
using thermal_internal::ChannelData;
using thermal_internal::CheckLagDeterminable;
using thermal_internal::EstimateLag;
using thermal_internal::LaggedTemperature;
using thermal_internal::SelectWindows;
using thermal_internal::SetWindowTemperature;
using thermal_internal::WindowRange;

const char* const kChannelNames[6] = {"accelerometer.x", "accelerometer.y", "accelerometer.z",
                                      "gyroscope.x",     "gyroscope.y",     "gyroscope.z"};

std::string Format(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

// Stage 1 for one range of samples: the channel means and their σ, the temperature from temp.
ThermalWindow MakeWindow(const Eigen::VectorXd& t, const ThermalImuInput& imu,
                         const Eigen::VectorXd& temp, const WindowRange& range,
                         const ThermalOptions& options) {
  ThermalWindow w;
  const int64_t first = range.first, last = range.last, n = last - first + 1;
  w.start = t(first);
  w.end = t(last);
  w.samples = n;
  Eigen::Matrix<double, 6, 1> sum = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 1> sq = Eigen::Matrix<double, 6, 1>::Zero();
  // Centre on the first sample so the sums of squares keep their precision.
  Eigen::Matrix<double, 6, 1> origin;
  origin << imu.accel->row(first).transpose(), imu.gyro->row(first).transpose();
  for (int64_t i = first; i <= last; ++i) {
    Eigen::Matrix<double, 6, 1> v;
    v << imu.accel->row(i).transpose(), imu.gyro->row(i).transpose();
    v -= origin;
    sum += v;
    sq += v.cwiseProduct(v);
  }
  const Eigen::Matrix<double, 6, 1> mean = sum / static_cast<double>(n);
  const Eigen::Matrix<double, 6, 1> var =
      ((sq - static_cast<double>(n) * mean.cwiseProduct(mean)) / static_cast<double>(n - 1))
          .cwiseMax(0.0);
  w.mean = origin + mean;
  w.mean_std = (var / static_cast<double>(n)).cwiseSqrt();
  const double root_n = std::sqrt(static_cast<double>(n));
  if (options.accel_noise) w.mean_std.head<3>().setConstant(*options.accel_noise / root_n);
  if (options.gyro_noise) w.mean_std.tail<3>().setConstant(*options.gyro_noise / root_n);
  SetWindowTemperature(t, temp, range, options.min_rate, &w);
  return w;
}

// E[ln s²] − ln σ² for the sample variance s² of ν + 1 Gaussian samples: ψ(ν/2) − ln(ν/2).
double LogVarianceBias(double nu) {
  double x = 0.5 * nu, shift = 0;
  for (; x < 6; x += 1) shift -= 1 / x;  // ψ(x) = ψ(x + 1) − 1/x
  const double x2 = 1 / (x * x);
  const double psi = std::log(x) - 0.5 / x - x2 * (1.0 / 12 - x2 * (1.0 / 120 - x2 / 252));
  return psi + shift - std::log(0.5 * nu);
}

// Stage 1's variance function: per channel whose σ the options do not give, the windows' log
// sample variances, less their bias LogVarianceBias(n − 1), fitted by a quadratic in the window's
// temperature weighted by (n − 1)/2 (ln s² has variance ψ'(ν/2) ≈ 2/ν); each window's σ of the
// mean is then √(exp(fit)/n). A window's own s² from ~500 samples is off by ~6 % and its weight
// by ~13 %: that noise in the weights costs ~2 % of squared error against the flight stacks'
// unweighted cubic (README); the smooth function keeps a noise that changes with temperature.
// Windows with s² = 0 (quantised or noise-free readings) take the function's value; fewer than
// 3 windows with s² > 0 leave the channel's own σ.
void SmoothWindowVariances(const ThermalOptions& options, std::vector<ThermalWindow>* windows) {
  if (windows->empty()) return;
  double lo = windows->front().temperature, hi = lo;
  for (const ThermalWindow& w : *windows) {
    lo = std::min(lo, w.temperature);
    hi = std::max(hi, w.temperature);
  }
  const double mid = 0.5 * (lo + hi), half = std::max(0.5 * (hi - lo), 1e-9);
  for (int c = 0; c < 6; ++c) {
    if ((c < 3 && options.accel_noise) || (c >= 3 && options.gyro_noise)) continue;
    Eigen::Matrix3d ata = Eigen::Matrix3d::Zero();
    Eigen::Vector3d atz = Eigen::Vector3d::Zero();
    int used = 0;
    for (const ThermalWindow& w : *windows) {
      const double n = static_cast<double>(w.samples);
      const double s2 = w.mean_std(c) * w.mean_std(c) * n;
      if (!(s2 > 0)) continue;
      const double u = (w.temperature - mid) / half;
      const Eigen::Vector3d row(1, u, u * u);
      const double weight = 0.5 * (n - 1);
      ata.noalias() += weight * row * row.transpose();
      atz += weight * row * (std::log(s2) - LogVarianceBias(n - 1));
      ++used;
    }
    if (used < 3) continue;
    const Eigen::Vector3d beta = ata.ldlt().solve(atz);
    if (!beta.allFinite()) continue;
    for (ThermalWindow& w : *windows) {
      const double u = (w.temperature - mid) / half;
      const double log_s2 = beta(0) + u * (beta(1) + u * beta(2));
      w.mean_std(c) = std::sqrt(std::exp(log_s2) / static_cast<double>(w.samples));
    }
  }
}

std::vector<WindowRange> CutWindows(const StaticDetection& statics, const ThermalOptions& options) {
  std::vector<WindowRange> ranges;
  const int64_t per = std::max<int64_t>(
      3, static_cast<int64_t>(std::llround(options.window / statics.sample_period)));
  for (const StaticInterval& s : statics.intervals) {
    const int64_t count = std::max<int64_t>(1, (s.samples + per / 2) / per);
    for (int64_t j = 0; j < count; ++j) {
      const int64_t first = s.first + j * per;
      const int64_t last = j + 1 == count ? s.last : first + per - 1;
      if (last - first + 1 >= 3) ranges.push_back({first, last});
    }
  }
  return ranges;
}

// Groups windows by gravity direction (greedy, against each group's first window).
int GroupOrientations(double tolerance, std::vector<ThermalWindow>* windows) {
  std::vector<Eigen::Vector3d> heads;
  for (ThermalWindow& w : *windows) {
    const Eigen::Vector3d d = w.mean.head<3>().normalized();
    int found = -1;
    for (size_t g = 0; g < heads.size() && found < 0; ++g) {
      if (std::acos(std::clamp(d.dot(heads[g]), -1.0, 1.0)) <= tolerance)
        found = static_cast<int>(g);
    }
    if (found < 0) {
      found = static_cast<int>(heads.size());
      heads.push_back(d);
    }
    w.orientation = found;
  }
  return static_cast<int>(heads.size());
}

// The reading at x = T − t_ref in dense group g (intercept plus the bias curve, plus G times the
// scale curve where the fit has one) and its variance.
void BiasAt(const ThermalPolyFit& f, int g, double gravity, double x, double* value, double* var) {
  const int groups = static_cast<int>(f.intercepts.size());
  const int p = f.order;
  const bool with_scale = f.scale_coefficients.size() > 0;
  Eigen::VectorXd v = Eigen::VectorXd::Zero(groups + (with_scale ? 2 : 1) * p);
  v(g) = 1;
  double power = 1;
  for (int k = 0; k < p; ++k) {
    power *= x;
    v(groups + k) = power;
    if (with_scale) v(groups + p + k) = gravity * power;
  }
  *value = f.intercepts(g) + ThermalCurve(f.coefficients, x);
  if (with_scale) *value += gravity * ThermalCurve(f.scale_coefficients, x);
  *var = v.dot(f.full_covariance * v);
}

// Stage 4 for one channel: heating and cooling apart at the curve's order.
// `gravity_of_orientation` as for SelectWindows (the channel's scale curve, or empty).
void CompareHeatingCooling(const std::vector<ThermalWindow>& windows, int c, double t_ref,
                           int orientations, double scale, int grid_points, double critical_z,
                           const std::vector<double>& gravity_of_orientation, ThermalChannel* ch) {
  const ChannelData h = SelectWindows(windows, c, 1, t_ref, orientations, gravity_of_orientation);
  const ChannelData k = SelectWindows(windows, c, -1, t_ref, orientations, gravity_of_orientation);
  int common = -1;  // an orientation both phases saw
  for (size_t o = 0; o < h.group_of_orientation.size() && common < 0; ++o) {
    if (h.group_of_orientation[o] >= 0 && k.group_of_orientation[o] >= 0)
      common = static_cast<int>(o);
  }
  const double lo = std::max(h.t_lo, k.t_lo), hi = std::min(h.t_hi, k.t_hi);
  if (common < 0 || !(hi > lo)) return;
  const int order = ch->fit.order;
  ThermalPolyFit fh, fk;
  if (!FitThermalPolynomial(h.x, h.y, h.sigma, h.group, h.groups, order, order, scale, h.samples,
                            &fh, h.gravity)
           .ok() ||
      !FitThermalPolynomial(k.x, k.y, k.sigma, k.group, k.groups, order, order, scale, k.samples,
                            &fk, k.gravity)
           .ok() ||
      fh.dof < 1 || fk.dof < 1) {
    return;
  }
  const double g_common =
      gravity_of_orientation.empty() ? 0.0 : gravity_of_orientation[static_cast<size_t>(common)];
  ch->hysteresis_tested = true;
  ch->hysteresis_temperatures.resize(grid_points);
  ch->hysteresis_difference.resize(grid_points);
  ch->hysteresis_z.resize(grid_points);
  for (int i = 0; i < grid_points; ++i) {
    const double temp = lo + (hi - lo) * i / (grid_points - 1);
    double vh, varh, vk, vark;
    BiasAt(fh, h.group_of_orientation[static_cast<size_t>(common)], g_common, temp - t_ref, &vh,
           &varh);
    BiasAt(fk, k.group_of_orientation[static_cast<size_t>(common)], g_common, temp - t_ref, &vk,
           &vark);
    const double sd = std::sqrt(varh + vark);
    ch->hysteresis_temperatures(i) = temp;
    ch->hysteresis_difference(i) = vh - vk;
    ch->hysteresis_z(i) = sd > 0 ? (vh - vk) / sd : 0;
    ch->max_abs_z = std::max(ch->max_abs_z, std::abs(ch->hysteresis_z(i)));
  }
  ch->hysteresis_flagged = ch->max_abs_z > critical_z;
}

// The windows' temperature span into r (t_min, t_max, phase counts); kNotDeterminable below
// min_range, naming the span found.
Status SetRange(const ThermalOptions& options, ThermalImuResult* r) {
  r->t_min = r->t_max = r->windows[0].temperature;
  r->heating_windows = r->cooling_windows = 0;
  for (const ThermalWindow& w : r->windows) {
    r->t_min = std::min(r->t_min, w.temperature);
    r->t_max = std::max(r->t_max, w.temperature);
    r->heating_windows += w.phase > 0;
    r->cooling_windows += w.phase < 0;
  }
  const double range = r->t_max - r->t_min;
  if (range < options.min_range) {
    return Status::NotDeterminable(
        "IMU " + r->name + ": the statics span " + Format(range) + " °C (" + Format(r->t_min) +
        " to " + Format(r->t_max) + " °C), below min_range " + Format(options.min_range) +
        " °C: the temperature dependence is not determinable; record a warm-up or chamber ramp "
        "over a wider range");
  }
  return Status::Ok();
}

// Stage 1 and 5: the windows (temperatures of the sensor where a lag is given or estimated).
Status MakeWindows(const Eigen::VectorXd& t, const ThermalImuInput& imu,
                   const ThermalOptions& options, std::vector<WindowRange>* ranges,
                   ThermalImuResult* r) {
  const std::vector<TriadSeries> triads = {{"a" + imu.name, TriadKind::kAccelerometer, imu.accel},
                                           {"g" + imu.name, TriadKind::kGyroscope, imu.gyro}};
  Status st = DetectStatics(t, triads, options.statics, &r->statics);
  if (!st.ok()) return st;
  *ranges = CutWindows(r->statics, options);
  if (ranges->size() < 3) {
    return Status::NotDeterminable("IMU " + imu.name + ": " + std::to_string(ranges->size()) +
                                   " averaging windows of " + Format(options.window) +
                                   " s in the statics; " + StaticShortfall(r->statics));
  }
  for (const WindowRange& range : *ranges) {
    r->windows.push_back(MakeWindow(t, imu, *imu.temp, range, options));
  }
  SmoothWindowVariances(options, &r->windows);
  r->orientations = GroupOrientations(options.orientation_tolerance, &r->windows);
  st = SetRange(options, r);
  if (!st.ok() || options.lag == ThermalLagMode::kNone) return st;
  double tau = options.lag_seconds;
  if (options.lag == ThermalLagMode::kEstimate) {
    st = CheckLagDeterminable(r->windows, imu.name);
    if (st.ok())
      st = EstimateLag(t, *imu.temp, *ranges, options, 0.5 * (r->t_max - r->t_min), r, &tau);
    if (!st.ok()) return st;
  }
  r->lag = tau;
  const Eigen::VectorXd sensor = LaggedTemperature(t, *imu.temp, tau, options.lag_start);
  for (size_t w = 0; w < ranges->size(); ++w) {
    SetWindowTemperature(t, sensor, (*ranges)[w], options.min_rate, &r->windows[w]);
  }
  return SetRange(options, r);
}

// The curve and its bands on the grid.
void Band(const ThermalImuResult& r, ThermalChannel* ch) {
  const Eigen::Index n = r.grid.size();
  ch->grid_value.resize(n);
  ch->grid_std.resize(n);
  ch->grid_crb_std.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double x = r.grid(i) - r.t_ref;
    ch->grid_value(i) = ThermalCurve(ch->fit.coefficients, x);
    ch->grid_std(i) = ThermalCurveStd(ch->fit.covariance, x);
    ch->grid_crb_std(i) = ThermalCurveStd(ch->fit.crb, x);
  }
  if (!ch->scale_estimated) return;
  ch->grid_scale_value.resize(n);
  ch->grid_scale_std.resize(n);
  ch->grid_scale_crb_std.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double x = r.grid(i) - r.t_ref;
    ch->grid_scale_value(i) = ThermalCurve(ch->fit.scale_coefficients, x);
    ch->grid_scale_std(i) = ThermalCurveStd(ch->fit.scale_covariance, x);
    ch->grid_scale_crb_std(i) = ThermalCurveStd(ch->fit.scale_crb, x);
  }
}

// Stage 2b: a group is near axis a when |n_a| >= this (within 60°); only those determine b0_a, S_a.
constexpr double kAxisFace = 0.5;

// Stage 2b: the intercepts' split I_g = b0_a + S_a n_{g,a} on the determined axes.
struct GravitySplit {
  std::array<bool, 3> determined{};
  Eigen::MatrixXd directions;  // groups × 3, unit gravity directions n_g
  Eigen::Vector3d b0 = Eigen::Vector3d::Zero(), b0_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d magnitude = Eigen::Vector3d::Zero();  // S_a
};

// Alternates the directions n_g = normalize((I_g − b0) / S) and, per determined axis, the
// generalised least squares of I_{·,a} on [1, n_{·,a}] under the intercepts' covariance.
// estimate false: only the directions from the current b0 and S.
void SplitIntercepts(const ThermalImuResult& r, GravitySplit* s, bool estimate = true) {
  const Eigen::Index groups = r.channels[0].fit.intercepts.size();
  Eigen::MatrixXd intercepts(groups, 3);
  for (int a = 0; a < 3; ++a) intercepts.col(a) = r.channels[static_cast<size_t>(a)].fit.intercepts;
  s->directions.resize(groups, 3);
  for (int iteration = 0; iteration < 100; ++iteration) {
    double mean_magnitude = 0;
    int known = 0;
    for (int a = 0; a < 3; ++a) {
      if (s->determined[static_cast<size_t>(a)]) mean_magnitude += s->magnitude(a), ++known;
    }
    mean_magnitude = known > 0 ? mean_magnitude / known : intercepts.rowwise().norm().mean();
    Eigen::Vector3d unit;
    for (int a = 0; a < 3; ++a)
      unit(a) = s->determined[static_cast<size_t>(a)] ? s->magnitude(a) : mean_magnitude;
    for (Eigen::Index g = 0; g < groups; ++g) {
      s->directions.row(g) =
          (intercepts.row(g) - s->b0.transpose()).cwiseQuotient(unit.transpose()).normalized();
    }
    if (!estimate) return;
    const Eigen::Vector3d before = s->b0;
    for (int a = 0; a < 3; ++a) {
      if (!s->determined[static_cast<size_t>(a)]) continue;
      Eigen::MatrixXd x(groups, 2);
      x.col(0).setOnes();
      x.col(1) = s->directions.col(a);
      const Eigen::MatrixXd sigma =
          r.channels[static_cast<size_t>(a)].fit.full_covariance.topLeftCorner(groups, groups);
      // Weighted by 1/σ² of each intercept (stable where their covariance is near singular, as
      // without noise); the σ from the full covariance: b = A I, Cov(b) = A Σ Aᵀ.
      // Groups far from the axis (|n_a| < kAxisFace) are left out: their n_a is (I_a − b0_a)/S,
      // so they fit any b0 and would only feign information on it.
      Eigen::VectorXd w = sigma.diagonal().cwiseMax(1e-300).cwiseInverse();
      for (Eigen::Index g = 0; g < groups; ++g) {
        if (std::abs(s->directions(g, a)) < kAxisFace) w(g) = 0;
      }
      const Eigen::MatrixXd xw = x.transpose() * w.asDiagonal();
      const Eigen::MatrixXd estimator = (xw * x).inverse() * xw;  // 2 × groups
      const Eigen::Vector2d estimate = estimator * intercepts.col(a);
      const Eigen::Matrix2d info_inv = estimator * sigma * estimator.transpose();
      s->b0(a) = estimate(0);
      s->magnitude(a) = estimate(1);
      s->b0_std(a) = std::sqrt(std::max(0.0, info_inv(0, 0)));
    }
    if ((s->b0 - before).cwiseAbs().maxCoeff() <= 1e-13 * mean_magnitude && iteration > 0) break;
  }
}

// Stage 2b: which axes the orientation groups determine (else the channel's scale_reason).
GravitySplit DeterminedAxes(const ThermalOptions& options, ThermalImuResult* r) {
  GravitySplit split;
  const char* const axes = "xyz";
  if (r->orientations < 2) {
    for (int a = 0; a < 3; ++a) {
      r->channels[static_cast<size_t>(a)].scale_reason =
          "one orientation: gravity, the bias at t_ref and the scale are not separable; hold the "
          "device in opposite faces (e.g. +" +
          std::string(1, axes[a]) + " and -" + std::string(1, axes[a]) + ")";
    }
    return split;
  }
  const Eigen::Index groups = r->channels[0].fit.intercepts.size();
  Eigen::MatrixXd intercepts(groups, 3);
  for (int a = 0; a < 3; ++a)
    intercepts.col(a) = r->channels[static_cast<size_t>(a)].fit.intercepts;
  const Eigen::VectorXd norms = intercepts.rowwise().norm();
  split.magnitude.setConstant(norms.mean());
  const std::vector<int> dense =
      SelectWindows(r->windows, 0, 0, r->t_ref, r->orientations).group_of_orientation;
  for (int a = 0; a < 3; ++a) {
    const Eigen::VectorXd n = intercepts.col(a).cwiseQuotient(norms);
    double lo = 2, hi = -2;  // over the groups near the axis
    for (Eigen::Index g = 0; g < groups; ++g) {
      if (std::abs(n(g)) >= kAxisFace) lo = std::min(lo, n(g)), hi = std::max(hi, n(g));
    }
    const double spread = hi > lo ? hi - lo : 0.0;
    split.determined[static_cast<size_t>(a)] = spread >= options.scale_min_spread;
    if (!split.determined[static_cast<size_t>(a)]) {
      r->channels[static_cast<size_t>(a)].scale_reason =
          "the " + std::to_string(r->orientations) + " orientations' gravity directions differ " +
          "along " + std::string(1, axes[a]) + " by " + Format(spread) +
          " (unit vectors, over the groups within 60° of the axis), below scale_min_spread " +
          Format(options.scale_min_spread) + ": add the faces +" + std::string(1, axes[a]) +
          " and -" + std::string(1, axes[a]);
      continue;
    }
    // The curves separate only where the faces of both signs were held at the same
    // temperatures; elsewhere they rest on the polynomials' extrapolation.
    double t_lo[2] = {1e300, 1e300}, t_hi[2] = {-1e300, -1e300};  // + and − faces
    for (const ThermalWindow& w : r->windows) {
      const int g = dense[static_cast<size_t>(w.orientation)];
      if (g < 0 || std::abs(n(g)) < kAxisFace) continue;
      const int side = n(g) > 0 ? 0 : 1;
      t_lo[side] = std::min(t_lo[side], w.temperature);
      t_hi[side] = std::max(t_hi[side], w.temperature);
    }
    const double overlap = std::min(t_hi[0], t_hi[1]) - std::max(t_lo[0], t_lo[1]);
    if (!(overlap >= options.min_range)) {
      split.determined[static_cast<size_t>(a)] = false;
      const std::string ax(1, axes[a]);
      r->channels[static_cast<size_t>(a)].scale_reason =
          t_hi[1] < t_lo[1] || t_hi[0] < t_lo[0]
              ? "no faces of both signs along " + ax + ": add the faces +" + ax + " and -" + ax
              : "the +" + ax + " faces (" + Format(t_lo[0]) + " to " + Format(t_hi[0]) +
                    " °C) and -" + ax + " faces (" + Format(t_lo[1]) + " to " + Format(t_hi[1]) +
                    " °C) share less than min_range " + Format(options.min_range) +
                    " °C: hold both faces across the range (e.g. one through the warm-up, the "
                    "other through the cool-down)";
    }
  }
  return split;
}

// Per orientation, G = S_a n_{g,a} (0 for an orientation absent from the fit).
std::vector<double> GravityOfOrientation(const GravitySplit& split, int a,
                                         const std::vector<int>& group_of_orientation) {
  std::vector<double> out(group_of_orientation.size(), 0.0);
  for (size_t o = 0; o < out.size(); ++o) {
    if (group_of_orientation[o] >= 0)
      out[o] = split.magnitude(a) * split.directions(group_of_orientation[o], a);
  }
  return out;
}

// Stage 2b after stage 2's fits: the accelerometer's bias at t_ref and, where determined, the
// channel refitted with the scale columns. gravity[a]: the axis's G per orientation (empty
// without a scale curve), for the hysteresis fits.
void SeparateGravity(const ThermalOptions& options, double scale, ThermalImuResult* r,
                     std::array<std::vector<double>, 3>* gravity) {
  GravitySplit split = DeterminedAxes(options, r);
  if (split.determined == std::array<bool, 3>{}) return;
  SplitIntercepts(*r, &split);
  std::array<bool, 3> with_scale = split.determined;
  if (options.lag == ThermalLagMode::kEstimate) {
    with_scale = {};
    for (int a = 0; a < 3; ++a) {
      if (split.determined[static_cast<size_t>(a)]) {
        r->channels[static_cast<size_t>(a)].scale_reason =
            "lag estimate: the lag's profile models bias curves only; give the lag in seconds "
            "(or none) for the scale curve";
      }
    }
  }
  const std::vector<int> dense =
      SelectWindows(r->windows, 0, 0, r->t_ref, r->orientations).group_of_orientation;
  std::vector<Eigen::Vector3d> history;  // b0 of the last rounds, for the extrapolation
  for (int round = 0; round < 200 && with_scale != std::array<bool, 3>{}; ++round) {
    for (int a = 0; a < 3; ++a) {
      if (!with_scale[static_cast<size_t>(a)]) continue;
      ThermalChannel& ch = r->channels[static_cast<size_t>(a)];
      (*gravity)[static_cast<size_t>(a)] = GravityOfOrientation(split, a, dense);
      const ChannelData d = SelectWindows(r->windows, a, 0, r->t_ref, r->orientations,
                                          (*gravity)[static_cast<size_t>(a)]);
      const int lowest = std::max(0, std::min({options.min_order, options.max_order,
                                               (static_cast<int>(d.x.size()) - d.groups - 1) / 2}));
      ThermalPolyFit fit;
      const Status st = FitThermalPolynomial(d.x, d.y, d.sigma, d.group, d.groups, lowest,
                                             options.max_order, scale, d.samples, &fit, d.gravity);
      if (!st.ok()) {  // the bias-only fit stays
        with_scale[static_cast<size_t>(a)] = false;
        (*gravity)[static_cast<size_t>(a)].clear();
        ch.scale_reason = "too few windows for the bias and scale curves together: " + st.message();
        continue;
      }
      ch.fit = std::move(fit);
      ch.scale_estimated = true;
    }
    const Eigen::Vector3d before = split.b0;
    SplitIntercepts(*r, &split);
    if ((split.b0 - before).cwiseAbs().maxCoeff() <= 1e-12 * split.magnitude.cwiseAbs().maxCoeff())
      break;
    // The alternation contracts slowly where an axis's opposite faces were held at temperatures
    // the other groups do not cover (b0 then moves by nearly equal steps): Aitken's Δ² on every
    // third round jumps to the fixed point of the sequence.
    history.push_back(split.b0);
    if (history.size() == 3) {
      for (int a = 0; a < 3; ++a) {
        const double d1 = history[1](a) - history[0](a), d2 = history[2](a) - history[1](a);
        if (std::abs(d2 - d1) > 0 && std::abs(d2) < std::abs(d1))
          split.b0(a) = history[2](a) - d2 * d2 / (d2 - d1);
      }
      SplitIntercepts(*r, &split, false);
      history.clear();
    }
  }
  for (int a = 0; a < 3; ++a) {
    if (!split.determined[static_cast<size_t>(a)]) continue;
    r->accel_at_t_ref[static_cast<size_t>(a)] = split.b0(a);
    r->accel_at_t_ref_std[static_cast<size_t>(a)] = split.b0_std(a);
    r->accel_gravity[static_cast<size_t>(a)] = split.magnitude(a);
  }
}

// kInvalidInput unless the IMU's arrays have one row per t and its temperatures are finite.
Status CheckInput(const Eigen::VectorXd& t, const ThermalImuInput& imu) {
  if (!imu.accel || !imu.gyro || !imu.temp || imu.accel->rows() != t.size() ||
      imu.gyro->rows() != t.size() || imu.temp->size() != t.size()) {
    return Status::InvalidInput("IMU " + imu.name +
                                ": accelerometer, gyroscope and temperature need one row per t");
  }
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    if (!std::isfinite((*imu.temp)(i))) {
      return Status::InvalidInput("IMU " + imu.name + ": temperature not finite at sample " +
                                  std::to_string(i));
    }
  }
  return Status::Ok();
}

Status CalibrateImu(const Eigen::VectorXd& t, const ThermalImuInput& imu,
                    const ThermalOptions& options, ThermalImuResult* r) {
  r->name = imu.name;
  std::vector<WindowRange> ranges;
  Status st = MakeWindows(t, imu, options, &ranges, r);
  if (!st.ok()) return st;
  const double range = r->t_max - r->t_min;
  r->t_ref = options.t_ref.value_or(0.5 * (r->t_min + r->t_max));
  const double scale = 0.5 * range;
  r->grid.resize(options.grid_points);
  for (int i = 0; i < options.grid_points; ++i) {
    r->grid(i) = r->t_min + range * i / (options.grid_points - 1);
  }
  r->hysteresis_threshold_z =
      BonferroniCriticalZ(options.hysteresis_alpha, 6 * options.grid_points);
  for (int c = 0; c < 6; ++c) {
    ThermalChannel ch;
    ch.name = kChannelNames[c];
    const ChannelData d = SelectWindows(r->windows, c, 0, r->t_ref, r->orientations);
    // The floor, capped where the windows leave no residual degree of freedom at it (the fit
    // then refuses only when not even a constant has one).
    const int lowest = std::max(0, std::min({options.min_order, options.max_order,
                                             static_cast<int>(d.x.size()) - d.groups - 1}));
    st = FitThermalPolynomial(d.x, d.y, d.sigma, d.group, d.groups, lowest, options.max_order,
                              scale, d.samples, &ch.fit);
    if (!st.ok())
      return Status::NotDeterminable("IMU " + imu.name + ", " + ch.name + ": " + st.message());
    r->channels.push_back(std::move(ch));
  }
  std::array<std::vector<double>, 3> gravity;
  SeparateGravity(options, scale, r, &gravity);
  for (int c = 0; c < 6; ++c) {
    CompareHeatingCooling(r->windows, c, r->t_ref, r->orientations, scale, options.grid_points,
                          r->hysteresis_threshold_z,
                          c < 3 ? gravity[static_cast<size_t>(c)] : std::vector<double>(),
                          &r->channels[static_cast<size_t>(c)]);
  }
  if (options.lag == ThermalLagMode::kEstimate) {
    st = AddLagUncertainty(t, *imu.temp, ranges, options, r);
    if (!st.ok()) return st;
  }
  Eigen::Vector3d gyro_bias, gyro_std;
  for (int c = 0; c < 6; ++c) {
    ThermalChannel& ch = r->channels[static_cast<size_t>(c)];
    Band(*r, &ch);
    if (c >= 3) {
      gyro_bias(c - 3) = ch.fit.intercepts(0);
      gyro_std(c - 3) = ch.fit.intercept_std;
    }
  }
  r->gyro_at_t_ref = gyro_bias;
  r->gyro_at_t_ref_std = gyro_std;
  return Status::Ok();
}

}  // namespace

bool ThermalOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* what) {
    *error = what;
    return false;
  };
  if (!(window > 0)) return fail("window must be > 0 s");
  if (max_order < 1 || max_order > 8) return fail("max_order must be in [1, 8]");
  if (min_order < 0 || min_order > 8) return fail("min_order must be in [0, 8]");
  if (t_ref && !std::isfinite(*t_ref)) return fail("t_ref must be finite");
  if (!(min_range >= 0)) return fail("min_range must be >= 0 °C");
  if (!(min_rate >= 0)) return fail("min_rate must be >= 0 °C/s");
  if (grid_points < 2) return fail("grid_points must be >= 2");
  if (!(hysteresis_alpha > 0 && hysteresis_alpha < 1)) return fail("hysteresis_alpha in (0, 1)");
  if (!(orientation_tolerance > 0)) return fail("orientation_tolerance must be > 0");
  if (!(scale_min_spread > 0 && scale_min_spread <= 2)) return fail("scale_min_spread in (0, 2]");
  if (lag == ThermalLagMode::kFixed && !(lag_seconds > 0 && std::isfinite(lag_seconds)))
    return fail("a fixed lag must be > 0 s");
  if (!(lag_max > 0 && std::isfinite(lag_max))) return fail("lag_max must be > 0 s");
  if (!(lag_start > 0)) return fail("lag_start must be > 0 s");
  for (const std::optional<double>& noise : {accel_noise, gyro_noise}) {
    if (noise && !(*noise > 0 && std::isfinite(*noise))) return fail("a noise σ must be > 0");
  }
  return statics.IsValid(error);
}

Status CalibrateThermal(const Eigen::VectorXd& t, const std::vector<ThermalImuInput>& imus,
                        const ThermalOptions& options, ThermalResult* out) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput("thermal options: " + error);
  if (imus.empty()) return Status::InvalidInput("thermal: no IMU in the log");
  *out = ThermalResult();
  for (const ThermalImuInput& imu : imus) {
    if (Status s = CheckInput(t, imu); !s.ok()) return s;
    ThermalImuResult r;
    const Status st = CalibrateImu(t, imu, options, &r);
    if (!st.ok()) return st;
    for (int a = 0; a < 3 && r.orientations > 1; ++a) {
      const ThermalChannel& ch = r.channels[static_cast<size_t>(a)];
      if (!ch.scale_estimated) {
        out->warnings.push_back(
            "IMU " + imu.name + ", " + ch.name + ": scale curve" +
            (r.accel_at_t_ref[static_cast<size_t>(a)] ? "" : " and bias at t_ref") +
            " not estimated (null): " + ch.scale_reason);
      }
    }
    if (r.lag_std && !(*r.lag_std < 0.5 * *r.lag)) {
      out->warnings.push_back("IMU " + imu.name + ": the lag is weakly determined (τ = " +
                              Format(*r.lag) + " ± " + Format(*r.lag_std) +
                              " s): the curves' bands include its uncertainty; a longer cool-down "
                              "or faster temperature changes determine it better");
    }
    out->imus.push_back(std::move(r));
  }
  return Status::Ok();
}

Status FindThermalWindows(const Eigen::VectorXd& t, const ThermalImuInput& imu,
                          const ThermalOptions& options, ThermalImuResult* out) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput("thermal options: " + error);
  if (Status s = CheckInput(t, imu); !s.ok()) return s;
  *out = ThermalImuResult();
  out->name = imu.name;
  std::vector<WindowRange> ranges;
  return MakeWindows(t, imu, options, &ranges, out);
}

}  // namespace calibd::core
