// Stage 5 of core/thermal.h: the first-order lag between the temperature reading and the sensing
// element — the lagged temperature, when a log determines τ, its profile estimate, and its σ with
// the curves' covariance widened by it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "core/thermal.h"
#include "core/thermal_internal.h"

namespace calibd::core::thermal_internal {
namespace {

std::string Format(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

// The windows' temperature span of one phase (+1 heating, −1 cooling).
struct PhaseSpan {
  int windows = 0;
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
};

PhaseSpan Span(const std::vector<ThermalWindow>& windows, int phase, double lo, double hi) {
  PhaseSpan s;
  for (const ThermalWindow& w : windows) {
    if (w.phase != phase || w.temperature < lo || w.temperature > hi) continue;
    ++s.windows;
    s.lo = std::min(s.lo, w.temperature);
    s.hi = std::max(s.hi, w.temperature);
  }
  return s;
}

// Steps dT_s/dt = (T_r − T_s)/τ over the samples (core/thermal_internal.h LaggedTemperature),
// calling visit(i, T_s(i)) in order, without storing them.
template <typename Visit>
void RunLag(const Eigen::VectorXd& t, const Eigen::VectorXd& reading, double tau, double start,
            Visit visit) {
  const Eigen::Index n = t.size();
  if (!(tau > 0)) {
    for (Eigen::Index i = 0; i < n; ++i) visit(i, reading(i));
    return;
  }
  if (n == 0) return;
  // The initial state: a least-squares line through the first `start` seconds, at t(0).
  double st = 0, sy = 0, stt = 0, sty = 0;
  Eigen::Index m = 0;
  for (; m < n && (m < 2 || t(m) - t(0) <= start); ++m) {
    const double dt = t(m) - t(0);
    st += dt;
    sy += reading(m);
    stt += dt * dt;
    sty += dt * reading(m);
  }
  const double det = m * stt - st * st;
  double state = det > 0 ? (sy * stt - st * sty) / det : sy / m;
  visit(0, state);
  // The gain of the last step, reused while the steps agree to 1e-9 (a regular rate: one expm1).
  double dt = -1, a = 0;
  for (Eigen::Index i = 1; i < n; ++i) {
    const double step = t(i) - t(i - 1);
    if (std::abs(step - dt) > 1e-9 * dt) {
      dt = step;
      a = -std::expm1(-dt / tau);
    }
    state += a * (0.5 * (reading(i) + reading(i - 1)) - state);
    visit(i, state);
  }
}

// The profile −2 ln L at τ: Σ over the channels of n ln χ²_c, each channel fitted at orders[c].
// `work` holds the windows; their temperatures are overwritten.
double Profile(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
               const std::vector<WindowRange>& ranges, const ThermalOptions& options, double scale,
               int orientations, const int orders[6], double tau, std::vector<ThermalWindow>* work,
               Status* status) {
  const Eigen::VectorXd temps =
      LaggedWindowTemperatures(t, reading, tau, options.lag_start, ranges);
  for (size_t w = 0; w < work->size(); ++w) {
    (*work)[w].temperature = temps(static_cast<Eigen::Index>(w));
  }
  const double t_ref = temps.mean();  // χ² does not depend on it: the polynomial has an intercept
  double total = 0;
  for (int c = 0; c < 6; ++c) {
    const ChannelData d = SelectWindows(*work, c, 0, t_ref, orientations);
    ThermalPolyFit fit;
    const Status st = FitThermalPolynomial(d.x, d.y, d.sigma, d.group, d.groups, orders[c],
                                           orders[c], scale, d.samples, &fit);
    if (!st.ok()) {
      *status = st;
      return std::numeric_limits<double>::infinity();
    }
    total += static_cast<double>(d.x.size()) * std::log(std::max(fit.chi2, 1e-300));
  }
  return total;
}

}  // namespace

Eigen::VectorXd LaggedTemperature(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                                  double tau, double start) {
  Eigen::VectorXd out(t.size());
  RunLag(t, reading, tau, start, [&](Eigen::Index i, double temp) { out(i) = temp; });
  return out;
}

Eigen::VectorXd LaggedWindowTemperatures(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                                         double tau, double start,
                                         const std::vector<WindowRange>& ranges) {
  Eigen::VectorXd out = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(ranges.size()));
  size_t w = 0;
  RunLag(t, reading, tau, start, [&](Eigen::Index i, double temp) {
    if (w == ranges.size() || i < ranges[w].first) return;
    out(static_cast<Eigen::Index>(w)) += temp;
    if (i == ranges[w].last) {
      out(static_cast<Eigen::Index>(w)) /=
          static_cast<double>(ranges[w].last - ranges[w].first + 1);
      ++w;
    }
  });
  return out;
}

Status CheckLagDeterminable(const std::vector<ThermalWindow>& windows, const std::string& imu) {
  const double inf = std::numeric_limits<double>::infinity();
  const PhaseSpan heating = Span(windows, 1, -inf, inf), cooling = Span(windows, -1, -inf, inf);
  double lo = inf, hi = -inf;
  for (const ThermalWindow& w : windows) {
    lo = std::min(lo, w.temperature);
    hi = std::max(hi, w.temperature);
  }
  const double common_lo = std::max(heating.lo, cooling.lo);
  const double common_hi = std::min(heating.hi, cooling.hi);
  const PhaseSpan h = Span(windows, 1, common_lo, common_hi);
  const PhaseSpan k = Span(windows, -1, common_lo, common_hi);
  if (common_hi - common_lo >= 0.25 * (hi - lo) && h.windows >= 3 && k.windows >= 3) {
    return Status::Ok();
  }
  auto span = [](const PhaseSpan& s) {
    return s.windows == 0 ? std::string("none")
                          : std::to_string(s.windows) + " windows, " + Format(s.lo) + " to " +
                                Format(s.hi) + " °C";
  };
  return Status::NotDeterminable(
      "IMU " + imu +
      ": lag \"estimate\" is not determinable from this log: it needs heating and "
      "cooling over a common temperature range (at least a quarter of the " +
      Format(hi - lo) + " °C range, with 3 windows of each); heating: " + span(heating) +
      "; cooling: " + span(cooling) +
      ". A single warm-up (or cool-down) passes each temperature once, so a lag cannot be told "
      "from a different curve; record a warm-up followed by a cool-down, or give the lag in "
      "seconds (lag: <s>) or none");
}

Status EstimateLag(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                   const std::vector<WindowRange>& ranges, const ThermalOptions& options,
                   double scale, ThermalImuResult* imu, double* tau) {
  std::vector<ThermalWindow> work = imu->windows;
  int orders[6];
  std::fill(orders, orders + 6, options.max_order);
  Status status = Status::Ok();
  auto profile = [&](double candidate) {
    return Profile(t, reading, ranges, options, scale, imu->orientations, orders, candidate, &work,
                   &status);
  };
  // A grid of 0 and 24 log-spaced values up to lag_max (1/1000 of it first: neighbours 1.33×
  // apart), at the highest order offered (it nests the truth), then the orders chosen at its
  // minimum.
  const int m = 25;
  imu->lag_grid.resize(m);
  imu->lag_profile.resize(m);
  for (int j = 0; j < m; ++j) {
    imu->lag_grid(j) = j == 0 ? 0.0 : options.lag_max * std::pow(1e-3, (m - 1.0 - j) / (m - 2.0));
    imu->lag_profile(j) = profile(imu->lag_grid(j));
    if (!status.ok()) return status;
  }
  Eigen::Index best;
  imu->lag_profile.minCoeff(&best);
  const double centre = imu->lag_grid(best);
  profile(centre);  // leaves the windows at the grid's best τ
  for (int c = 0; c < 6; ++c) {
    const ChannelData d = SelectWindows(work, c, 0, 0.0, imu->orientations);
    ThermalPolyFit fit;
    status = FitThermalPolynomial(d.x, d.y, d.sigma, d.group, d.groups, 0, options.max_order, scale,
                                  d.samples, &fit);
    if (!status.ok()) return status;
    orders[c] = fit.order;
  }
  // Golden section between the grid's neighbours of the minimum, at the curves' orders.
  double a = imu->lag_grid(std::max<Eigen::Index>(0, best - 1));
  double b = imu->lag_grid(std::min<Eigen::Index>(m - 1, best + 1));
  const double g = 0.5 * (std::sqrt(5.0) - 1);
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = profile(x1), f2 = profile(x2);
  for (int i = 0; i < 30 && status.ok(); ++i) {  // the bracket shrinks to 1e-6 of its width
    if (f1 <= f2) {
      b = x2;
      x2 = x1;
      f2 = f1;
      x1 = b - g * (b - a);
      f1 = profile(x1);
    } else {
      a = x1;
      x1 = x2;
      f1 = f2;
      x2 = a + g * (b - a);
      f2 = profile(x2);
    }
  }
  if (!status.ok()) return status;
  *tau = f1 <= f2 ? x1 : x2;
  imu->lag_profile.array() -= imu->lag_profile.minCoeff();
  return Status::Ok();
}

Status AddLagUncertainty(const Eigen::VectorXd& t, const Eigen::VectorXd& reading,
                         const std::vector<WindowRange>& ranges, const ThermalOptions& options,
                         ThermalImuResult* imu) {
  const double tau = *imu->lag;
  // ∂(window temperature)/∂τ by a central difference (one-sided at τ = 0).
  const double step = std::max(0.01 * tau, 0.05);
  const double lo = std::max(0.0, tau - step), hi = tau + step;
  const Eigen::VectorXd slope =
      (LaggedWindowTemperatures(t, reading, hi, options.lag_start, ranges) -
       LaggedWindowTemperatures(t, reading, lo, options.lag_start, ranges)) /
      (hi - lo);
  double info = 0, info_crb = 0;  // S of core/thermal.h stage 5, primary and white-noise
  Eigen::VectorXd h[6];
  double s[6];
  for (int c = 0; c < 6; ++c) {
    ThermalPolyFit& f = imu->channels[static_cast<size_t>(c)].fit;
    const ChannelData d = SelectWindows(imu->windows, c, 0, imu->t_ref, imu->orientations);
    const int groups = d.groups, p = f.order;
    Eigen::VectorXd b = Eigen::VectorXd::Zero(groups + p);
    double dd = 0;
    for (Eigen::Index i = 0; i < d.x.size(); ++i) {
      // The whitened row of the design and of ∂y/∂τ = curve'(x) ∂T/∂τ.
      const double w = 1.0 / d.sigma(i), x = d.x(i);
      double derivative = 0, power = 1;
      Eigen::VectorXd row = Eigen::VectorXd::Zero(groups + p);
      row(d.group[static_cast<size_t>(i)]) = w;
      for (int k = 1; k <= p; ++k) {
        derivative += k * f.coefficients(k - 1) * power;
        power *= x;
        row(groups + k - 1) = w * power;
      }
      const double g = w * derivative * slope(i);
      b += g * row;
      dd += g * g;
    }
    s[c] = f.basis == "chi2_scaled" ? f.chi2 / f.dof : 1.0;
    const Eigen::MatrixXd m_inv = f.full_covariance / s[c];
    h[c] = m_inv * b;
    const double schur = std::max(0.0, dd - b.dot(h[c]));
    info += schur / s[c];
    info_crb += schur;
  }
  if (!(info > 0) || !(info_crb > 0)) {
    return Status::NotDeterminable("IMU " + imu->name +
                                   ": the log carries no information on the lag (the curves are "
                                   "flat where it heats and cools); give lag none or in seconds");
  }
  imu->lag_std = std::sqrt(1.0 / info);
  imu->lag_crb_std = std::sqrt(1.0 / info_crb);
  for (int c = 0; c < 6; ++c) {
    ThermalPolyFit& f = imu->channels[static_cast<size_t>(c)].fit;
    const Eigen::Index p = f.order;
    const Eigen::MatrixXd hh = h[c] * h[c].transpose();
    f.full_covariance += hh / info;
    f.covariance = f.full_covariance.bottomRightCorner(p, p);
    f.crb += hh.bottomRightCorner(p, p) / info_crb;
    f.intercept_std = std::sqrt(f.full_covariance(0, 0));
  }
  return Status::Ok();
}

}  // namespace calibd::core::thermal_internal
