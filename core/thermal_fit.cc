// Stages 2 and 3 of core/thermal.h: the weighted polynomial fit of one channel, its order chosen
// by AICc, its covariance under the σ convention, and the curve's band.
#include <Eigen/QR>
#include <cmath>
#include <limits>

#include "core/thermal.h"

namespace calibd::core {
namespace {

// One weighted least-squares fit at a fixed order, in the scaled variable u = x / scale.
struct ScaledFit {
  Eigen::VectorXd params;  // groups intercepts, then a_1..a_p (coefficients of u^k)
  Eigen::MatrixXd cov;     // (AᵀWA)⁻¹ in the scaled parameters
  double chi2 = 0;
};

ScaledFit SolveScaled(const Eigen::VectorXd& u, const Eigen::VectorXd& y,
                      const Eigen::VectorXd& sigma, const std::vector<int>& group, int groups,
                      int order) {
  const int n = static_cast<int>(u.size());
  const int m = groups + order;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n, m);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const double w = 1.0 / sigma(i);
    a(i, group[static_cast<size_t>(i)]) = w;
    double p = 1;
    for (int k = 1; k <= order; ++k) {
      p *= u(i);
      a(i, groups + k - 1) = w * p;
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

double Aicc(double chi2, int n, int k) {
  if (n - k - 1 <= 0) return std::numeric_limits<double>::infinity();
  const double rss = std::max(chi2, 1e-300);
  return n * std::log(rss / n) + 2.0 * k + 2.0 * k * (k + 1.0) / (n - k - 1.0);
}

}  // namespace

Status FitThermalPolynomial(const Eigen::VectorXd& x, const Eigen::VectorXd& y,
                            const Eigen::VectorXd& sigma, const std::vector<int>& group, int groups,
                            int min_order, int max_order, double scale, ThermalPolyFit* out) {
  const int n = static_cast<int>(x.size());
  if (y.size() != n || sigma.size() != n || static_cast<int>(group.size()) != n || groups < 1 ||
      min_order < 0 || max_order < min_order || !(scale > 0)) {
    return Status::InvalidInput("thermal fit: inconsistent inputs");
  }
  for (int i = 0; i < n; ++i) {
    if (!(sigma(i) > 0) || !std::isfinite(y(i)) || !std::isfinite(x(i))) {
      return Status::InvalidInput("thermal fit: window " + std::to_string(i) +
                                  " has a non-finite mean or a σ that is not positive");
    }
  }
  const Eigen::VectorXd u = x / scale;
  *out = ThermalPolyFit();
  int best = -1;
  double best_aicc = std::numeric_limits<double>::infinity();
  for (int p = min_order; p <= max_order; ++p) {
    const int k = groups + p + 1;  // regression parameters plus the noise scale
    if (n - groups - p < 1) break;
    const ScaledFit f = SolveScaled(u, y, sigma, group, groups, p);
    ThermalOrderRow row{p, f.chi2, Aicc(f.chi2, n, k)};
    out->table.push_back(row);
    if (row.aicc < best_aicc) {
      best_aicc = row.aicc;
      best = p;
    }
  }
  if (best < 0) {
    return Status::NotDeterminable("thermal fit: " + std::to_string(n) + " windows for " +
                                   std::to_string(groups) +
                                   " orientation groups: too few to fit even a constant with a "
                                   "noise check; record longer statics");
  }
  const ScaledFit f = SolveScaled(u, y, sigma, group, groups, best);
  const int m = groups + best;
  Eigen::VectorXd unscale = Eigen::VectorXd::Ones(m);
  for (int k = 1; k <= best; ++k) unscale(groups + k - 1) = std::pow(scale, -k);
  const Eigen::VectorXd params = unscale.asDiagonal() * f.params;
  const Eigen::MatrixXd crb_full = unscale.asDiagonal() * f.cov * unscale.asDiagonal();
  out->order = best;
  out->chi2 = f.chi2;
  out->dof = n - m;
  const double chi2_per_dof = out->dof > 0 ? f.chi2 / out->dof : 1.0;
  const bool scaled = out->dof > 0 && chi2_per_dof > 1 + 2.326 * std::sqrt(2.0 / out->dof);
  out->basis = scaled ? "chi2_scaled" : "crb";
  out->full_covariance = scaled ? Eigen::MatrixXd(crb_full * chi2_per_dof) : crb_full;
  out->intercepts = params.head(groups);
  out->coefficients = params.tail(best);
  out->crb = crb_full.bottomRightCorner(best, best);
  out->covariance = out->full_covariance.bottomRightCorner(best, best);
  out->intercept_std = std::sqrt(out->full_covariance(0, 0));
  double rss = 0, noise = 0;
  for (int i = 0; i < n; ++i) {
    const double pred =
        params(group[static_cast<size_t>(i)]) + ThermalCurve(out->coefficients, x(i));
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
