// Stages 2 and 3 of core/thermal.h: the weighted polynomial fits of one channel at every order,
// their BIC-weighted average, its covariance under the σ convention, and the curve's band.
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "core/thermal.h"

namespace calibd::core {
namespace {

// One weighted least-squares fit at a fixed order, in the scaled variable u = x / scale.
struct ScaledFit {
  Eigen::VectorXd params;  // groups intercepts, a_1..a_p (of u^k), then e_1..e_p (of G u^k)
  Eigen::MatrixXd cov;     // (AᵀWA)⁻¹ in the scaled parameters
  double chi2 = 0;
};

// `gravity` empty: no scale columns; else per window the gravity component G_w of the columns
// G_w u^k.
ScaledFit SolveScaled(const Eigen::VectorXd& u, const Eigen::VectorXd& y,
                      const Eigen::VectorXd& sigma, const std::vector<int>& group, int groups,
                      int order, const Eigen::VectorXd& gravity) {
  const int n = static_cast<int>(u.size());
  const bool with_scale = gravity.size() > 0;
  const int m = groups + (with_scale ? 2 : 1) * order;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n, m);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const double w = 1.0 / sigma(i);
    a(i, group[static_cast<size_t>(i)]) = w;
    double p = 1;
    for (int k = 1; k <= order; ++k) {
      p *= u(i);
      a(i, groups + k - 1) = w * p;
      if (with_scale) a(i, groups + order + k - 1) = w * gravity(i) * p;
    }
    b(i) = w * y(i);
  }
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(a);
  ScaledFit fit;
  fit.params = qr.solve(b);
  fit.chi2 = (a * fit.params - b).squaredNorm();
  const Eigen::MatrixXd r = qr.matrixQR().topRows(m).triangularView<Eigen::Upper>();
  const Eigen::MatrixXd r_inv =
      r.triangularView<Eigen::Upper>().solve(Eigen::MatrixXd::Identity(m, m));
  fit.cov = r_inv * r_inv.transpose();
  return fit;
}

// BIC with the noise scale estimated: n ln(χ²/n) + k ln N, n the windows, k the regression
// parameters plus the scale, N = max(samples, n) the penalty's count (core/thermal.h stage 2:
// the samples for the curve's weights, the windows for the band's).
double Bic(double chi2, int n, int k, int64_t samples) {
  return n * std::log(std::max(chi2, 1e-300) / n) +
         k * std::log(static_cast<double>(std::max<int64_t>(samples, n)));
}

// One order's fit unscaled to x and padded to `top`: parameters (intercepts, c_1..c_top, then
// with scale d_1..d_top) and their white-noise and primary covariances.
struct OrderFit {
  Eigen::VectorXd params;
  Eigen::MatrixXd crb, primary;
  double chi2 = 0;
  int dof = 0;
  bool scaled = false;
};

OrderFit FitOrder(const Eigen::VectorXd& u, const Eigen::VectorXd& y, const Eigen::VectorXd& sigma,
                  const std::vector<int>& group, int groups, int order, int top, double scale,
                  const Eigen::VectorXd& gravity) {
  const int blocks = gravity.size() > 0 ? 2 : 1;
  const int n = static_cast<int>(u.size()), m = groups + blocks * order;
  const int padded = groups + blocks * top;
  const ScaledFit f = SolveScaled(u, y, sigma, group, groups, order, gravity);
  // Row j of the order's parameters goes to place[j] of the padded ones, times unscale(j).
  Eigen::VectorXd unscale = Eigen::VectorXd::Ones(m);
  std::vector<int> place(static_cast<size_t>(m));
  for (int g = 0; g < groups; ++g) place[static_cast<size_t>(g)] = g;
  for (int b = 0; b < blocks; ++b) {
    for (int k = 1; k <= order; ++k) {
      const int j = groups + b * order + k - 1;
      unscale(j) = std::pow(scale, -k);
      place[static_cast<size_t>(j)] = groups + b * top + k - 1;
    }
  }
  OrderFit out;
  out.params = Eigen::VectorXd::Zero(padded);
  out.crb = Eigen::MatrixXd::Zero(padded, padded);
  for (int i = 0; i < m; ++i) {
    out.params(place[static_cast<size_t>(i)]) = unscale(i) * f.params(i);
    for (int j = 0; j < m; ++j) {
      out.crb(place[static_cast<size_t>(i)], place[static_cast<size_t>(j)]) =
          unscale(i) * f.cov(i, j) * unscale(j);
    }
  }
  out.chi2 = f.chi2;
  out.dof = n - m;
  const double chi2_per_dof = out.dof > 0 ? f.chi2 / out.dof : 1.0;
  out.scaled = out.dof > 0 && chi2_per_dof > 1 + 2.326 * std::sqrt(2.0 / out.dof);
  out.primary = out.scaled ? Eigen::MatrixXd(out.crb * chi2_per_dof) : out.crb;
  return out;
}

}  // namespace

Status FitThermalPolynomial(const Eigen::VectorXd& x, const Eigen::VectorXd& y,
                            const Eigen::VectorXd& sigma, const std::vector<int>& group, int groups,
                            int min_order, int max_order, double scale, int64_t samples,
                            ThermalPolyFit* out, const Eigen::VectorXd& gravity) {
  const int n = static_cast<int>(x.size());
  const int blocks = gravity.size() > 0 ? 2 : 1;
  if (y.size() != n || sigma.size() != n || static_cast<int>(group.size()) != n || groups < 1 ||
      (blocks == 2 && gravity.size() != n) || min_order < 0 || max_order < min_order ||
      !(scale > 0) || samples < 0) {
    return Status::InvalidInput("thermal fit: inconsistent inputs");
  }
  for (int i = 0; i < n; ++i) {
    if (!(sigma(i) > 0) || !std::isfinite(y(i)) || !std::isfinite(x(i)) ||
        (blocks == 2 && !std::isfinite(gravity(i)))) {
      return Status::InvalidInput("thermal fit: window " + std::to_string(i) +
                                  " has a non-finite mean or a σ that is not positive");
    }
  }
  *out = ThermalPolyFit();
  // Orders with at least one residual degree of freedom (a noise check).
  const int top = std::min(max_order, (n - groups - 1) / blocks);
  if (top < min_order) {
    return Status::NotDeterminable("thermal fit: " + std::to_string(n) + " windows for " +
                                   std::to_string(groups) +
                                   " orientation groups: too few to fit even a constant with a "
                                   "noise check; record longer statics");
  }
  const Eigen::VectorXd u = x / scale;
  std::vector<OrderFit> fits;
  double bic_min = std::numeric_limits<double>::infinity();
  for (int p = min_order; p <= top; ++p) {
    fits.push_back(FitOrder(u, y, sigma, group, groups, p, top, scale, gravity));
    out->table.push_back(
        {p, fits.back().chi2, Bic(fits.back().chi2, n, groups + blocks * p + 1, samples), 0});
    bic_min = std::min(bic_min, out->table.back().bic);
  }
  // Weights ∝ exp(−ΔBIC/2); the curve is their average, its covariance the mixture over the band
  // weights (each order's primary plus the spread of the orders' parameters about the average).
  std::vector<double> band_bic(fits.size());
  for (size_t i = 0; i < fits.size(); ++i) {
    band_bic[i] = Bic(fits[i].chi2, n, groups + blocks * out->table[i].order + 1, n);
  }
  const double band_bic_min = *std::min_element(band_bic.begin(), band_bic.end());
  double total = 0, band_total = 0;
  for (size_t i = 0; i < fits.size(); ++i) {
    total += out->table[i].weight = std::exp(-0.5 * (out->table[i].bic - bic_min));
    band_total += out->table[i].band_weight = std::exp(-0.5 * (band_bic[i] - band_bic_min));
  }
  const int m = groups + blocks * top;
  Eigen::VectorXd params = Eigen::VectorXd::Zero(m);
  size_t heaviest = 0;
  for (size_t i = 0; i < fits.size(); ++i) {
    out->table[i].weight /= total;
    out->table[i].band_weight /= band_total;
    params += out->table[i].weight * fits[i].params;
    if (out->table[i].weight > out->table[heaviest].weight) heaviest = i;
  }
  out->full_covariance = Eigen::MatrixXd::Zero(m, m);
  Eigen::MatrixXd crb_full = Eigen::MatrixXd::Zero(m, m);
  for (size_t i = 0; i < fits.size(); ++i) {
    const Eigen::VectorXd d = fits[i].params - params;
    const double v = out->table[i].band_weight;
    out->full_covariance += v * (fits[i].primary + d * d.transpose());
    crb_full += v * fits[i].crb;
  }
  out->order = top;
  out->chi2 = fits[heaviest].chi2;
  out->dof = fits[heaviest].dof;
  out->basis = fits[heaviest].scaled ? "chi2_scaled" : "crb";
  out->intercepts = params.head(groups);
  out->coefficients = params.segment(groups, top);
  out->crb = crb_full.block(groups, groups, top, top);
  out->covariance = out->full_covariance.block(groups, groups, top, top);
  if (blocks == 2) {
    out->scale_coefficients = params.tail(top);
    out->scale_crb = crb_full.bottomRightCorner(top, top);
    out->scale_covariance = out->full_covariance.bottomRightCorner(top, top);
  }
  out->intercept_std = std::sqrt(out->full_covariance(0, 0));
  double rss = 0, noise = 0;
  for (int i = 0; i < n; ++i) {
    double pred = params(group[static_cast<size_t>(i)]) + ThermalCurve(out->coefficients, x(i));
    if (blocks == 2) pred += gravity(i) * ThermalCurve(out->scale_coefficients, x(i));
    rss += (y(i) - pred) * (y(i) - pred);
    noise += sigma(i) * sigma(i);
  }
  out->residual_rms = std::sqrt(rss / n);
  out->noise_rms = std::sqrt(noise / n);
  return Status::Ok();
}

double ThermalCurve(const Eigen::VectorXd& coefficients, double x) {
  double value = 0, p = 1;
  for (int k = 0; k < coefficients.size(); ++k) {
    p *= x;
    value += coefficients(k) * p;
  }
  return value;
}

double ThermalCurveStd(const Eigen::MatrixXd& covariance, double x) {
  const int p = static_cast<int>(covariance.rows());
  Eigen::VectorXd v(p);
  double power = 1;
  for (int k = 0; k < p; ++k) {
    power *= x;
    v(k) = power;
  }
  return p == 0 ? 0.0 : std::sqrt(std::max(0.0, v.dot(covariance * v)));
}

double BonferroniCriticalZ(double alpha, int tests) {
  const double tail = alpha / (2.0 * std::max(1, tests));  // P(Z > z) wanted
  double lo = 0, hi = 40;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (0.5 * std::erfc(mid / std::sqrt(2.0)) > tail) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

}  // namespace calibd::core
