// CalibrateMag's geometric stages (core/mag.h, steps 4 and 5) and the small matrix helpers.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <vector>

#include "core/mag_internal.h"

namespace calibd::core::mag_internal {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

constexpr double kDegPerRad = 180 / 3.14159265358979323846;

std::string AxisName(int axis, int sign) { return std::string(sign > 0 ? "+" : "-") + "xyz"[axis]; }

std::string JoinAnd(const std::vector<std::string>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) {
    s += (i == 0 ? "" : (i + 1 == v.size() ? " and " : ", ")) + v[i];
  }
  return s;
}

// The statics' down directions d_j and calibrated field directions n_j = P(ȳ_j − h)/|·|.
void StaticDirections(const MagProblem& problem, const Vector3d& h, const Matrix3d& p,
                      std::vector<Vector3d>* d, std::vector<Vector3d>* n) {
  d->clear();
  n->clear();
  for (const MagStatic& s : problem.statics) {
    const double f = s.specific_force.norm();
    if (!(f > 0)) continue;
    const Vector3d mean = problem.y.middleCols(s.first, s.last - s.first + 1).rowwise().mean();
    const Vector3d m = p * (mean - h);
    if (!(m.norm() > 0)) continue;
    d->push_back(-s.specific_force / f);
    n->push_back(m.normalized());
  }
}

// Gauss-Newton for d_jᵀ R n_j = sin δ from (r, s) as given; the normal matrix and the residuals'
// sum of squares at the solution. False when the normal matrix is singular (statics tilted about
// one axis only).
bool SolveAlignment(const std::vector<Vector3d>& d, const std::vector<Vector3d>& n, Matrix3d* r,
                    double* s, Eigen::Matrix4d* h, double* ss) {
  for (int it = 0; it < 30; ++it) {
    h->setZero();
    Eigen::Vector4d g = Eigen::Vector4d::Zero();
    *ss = 0;
    for (size_t j = 0; j < d.size(); ++j) {
      const Vector3d rn = *r * n[j];
      Eigen::Vector4d jac;
      jac << rn.cross(d[j]), -1;
      const double rho = d[j].dot(rn) - *s;
      *h += jac * jac.transpose();
      g += jac * rho;
      *ss += rho * rho;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(*h);
    if (!(es.eigenvalues()(0) > 1e-6 * es.eigenvalues()(3))) return false;
    const Eigen::Vector4d step = -h->ldlt().solve(g);
    *r = ExpRotation(step.head<3>()) * *r;
    *s += step(3);
    if (step.norm() < 1e-13) break;
  }
  return true;
}

}  // namespace

Matrix3d Sym(const Vector6d& a) {
  Matrix3d m;
  m << a(0), a(1), a(2), a(1), a(3), a(4), a(2), a(4), a(5);
  return m;
}

Vector6d SymEntries(const Matrix3d& a) {
  Vector6d v;
  v << a(0, 0), a(0, 1), a(0, 2), a(1, 1), a(1, 2), a(2, 2);
  return v;
}

Matrix3d Skew(const Vector3d& v) {
  Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Matrix3d ExpRotation(const Vector3d& phi) {
  const double angle = phi.norm();
  if (angle < 1e-12) return Matrix3d::Identity() + Skew(phi);
  const Matrix3d k = Skew(phi / angle);
  return Matrix3d::Identity() + std::sin(angle) * k + (1 - std::cos(angle)) * k * k;
}

Matrix3d EntryStd(const std::vector<Matrix3d>& d, const Eigen::MatrixXd& cov) {
  Matrix3d s;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Eigen::VectorXd g(static_cast<Eigen::Index>(d.size()));
      for (size_t k = 0; k < d.size(); ++k) g(static_cast<Eigen::Index>(k)) = d[k](i, j);
      s(i, j) = std::sqrt(std::max(0.0, g.dot(cov * g)));
    }
  }
  return s;
}

void EstimateAlignment(const MagProblem& problem, const MagOptions& options, const Ellipsoid& fit,
                       const Eigen::MatrixXd& cov_primary, const Eigen::MatrixXd& cov_crb,
                       MagResult* result, const Eigen::MatrixXd* cov_p) {
  const double field = result->field;
  const Matrix3d p = result->soft_iron_symmetric;
  std::vector<Vector3d> d, n;
  StaticDirections(problem, fit.h, p, &d, &n);
  const int count = static_cast<int>(d.size());
  if (count < options.min_alignment_statics) {
    result->alignment_note =
        count == 0 ? "not estimated: the log has no accelerometer statics"
                   : "not estimated: " + std::to_string(count) + " statics, at least " +
                         std::to_string(options.min_alignment_statics) +
                         " needed (hold the device still in more orientations)";
    return;
  }
  Matrix3d r = Matrix3d::Identity();
  double s = 0;
  for (int j = 0; j < count; ++j) s += d[j].dot(n[j]) / count;
  Eigen::Matrix4d h;
  double ss = 0;
  if (!SolveAlignment(d, n, &r, &s, &h, &ss)) {
    result->alignment_note =
        "not estimated: the statics' orientations do not determine the rotation (tilted about "
        "one axis only): hold the device still in orientations tilted about different axes";
    return;
  }
  if (!(std::abs(s) < 1)) {
    result->alignment_note = "not estimated: the dip's sine came out at " + std::to_string(s);
    return;
  }
  // σ: the statics' scatter, plus the ellipsoid's own uncertainty carried through n_j (an error
  // of h or P moves every n_j alike, which the scatter does not show in full): ∂(φ, sin δ)/∂θ and
  // ∂ρ_j/∂θ (ρ_j = d_jᵀ R n_j − sin δ at the solution) by central differences over θ = (h, a), a
  // the entries of A = F P⁻¹.
  Eigen::Matrix<double, 4, 9> jac;
  Eigen::MatrixXd g(count, 9);  // ∂ρ/∂θ at fixed (R, sin δ)
  const Matrix3d a = field * p.inverse();
  auto residuals = [&](const std::vector<Vector3d>& dk, const std::vector<Vector3d>& nk) {
    Eigen::VectorXd rho(count);
    for (int j = 0; j < count; ++j) rho(j) = dk[j].dot(r * nk[j]) - s;
    return rho;
  };
  for (int k = 0; k < 9; ++k) {
    Eigen::Vector4d side[2];
    Eigen::VectorXd rho[2];
    for (int sign = 0; sign < 2; ++sign) {
      const double eps = (sign ? -1 : 1) * 1e-6 * std::max(1.0, a.norm());
      Vector3d hk = fit.h;
      Matrix3d ak = a;
      if (k < 3) {
        hk(k) += eps;
      } else {
        Vector6d e = Vector6d::Zero();
        e(k - 3) = eps;
        ak += Sym(e);
      }
      std::vector<Vector3d> dk, nk;
      StaticDirections(problem, hk, field * ak.inverse(), &dk, &nk);
      rho[sign] = residuals(dk, nk);
      Matrix3d rk = r;
      double sk = s;
      Eigen::Matrix4d hh;
      double ssk = 0;
      SolveAlignment(dk, nk, &rk, &sk, &hh, &ssk);
      const Eigen::AngleAxisd delta(rk * r.transpose());
      side[sign] << delta.angle() * delta.axis(), sk;
    }
    const double step = 2e-6 * std::max(1.0, a.norm());
    jac.col(k) = (side[0] - side[1]) / step;
    g.col(k) = (rho[0] - rho[1]) / step;
  }
  // The statics' own errors (noise of their means, the accelerometer's errors), variance τ² per
  // static, from the scatter ss with ν = count − 4 degrees of freedom. The ellipsoid's error δθ
  // adds (I − Π) G δθ to the residuals (Π the projection onto the columns of the alignment's
  // Jacobian J: the part R and sin δ absorb), E = tr((I − Π) G C Gᵀ) to ss: subtracted, else it
  // would be counted twice (in the scatter and in jac C jacᵀ; 200 simulated logs of 40 turns gave
  // the alignment z RMS 0.87 with it counted twice). τ̂² = max(ss − E, 0) / ν, and an error over
  // τ̂ is Student-t with ν degrees of freedom, variance ν/(ν − 2), not 1 (z RMS √(8/6) = 1.15 with
  // 12 statics; 400 simulated logs gave the dip 1.17): the scatter's covariance τ̂² (JᵀJ)⁻¹ is
  // scaled by ν/(ν − 2), the variance of the t posterior (flat prior on the angles and the dip,
  // Jeffreys on τ), so that the σ is the error's standard deviation. ν >= 3 by
  // min_alignment_statics.
  Eigen::MatrixXd j_align(count, 4);
  for (int j = 0; j < count; ++j) j_align.row(j) << (r * n[j]).cross(d[j]).transpose(), -1;
  const Eigen::MatrixXd residual_maker =
      Eigen::MatrixXd::Identity(count, count) - j_align * h.inverse() * j_align.transpose();
  const int dof = count - 4;
  const double t_variance = static_cast<double>(dof) / (dof - 2);
  auto scatter = [&](const Eigen::MatrixXd& cov_theta) -> Eigen::Matrix4d {
    const double from_ellipsoid = (residual_maker * g * cov_theta * g.transpose()).trace();
    return t_variance * std::max(ss - from_ellipsoid, 0.0) / dof * h.inverse();
  };
  const Eigen::Matrix4d cov = scatter(cov_primary) + jac * cov_primary * jac.transpose();
  const Eigen::Matrix4d cov_bound = scatter(cov_crb) + jac * cov_crb * jac.transpose();
  result->alignment = r;
  result->dip = std::asin(s) * kDegPerRad;
  const double dip_scale = kDegPerRad / std::sqrt(1 - s * s);
  result->std.alignment = cov.diagonal().head<3>().cwiseMax(0).cwiseSqrt();
  result->std.dip = std::sqrt(std::max(0.0, cov(3, 3))) * dip_scale;
  result->crb.alignment = cov_bound.diagonal().head<3>().cwiseMax(0).cwiseSqrt();
  result->crb.dip = std::sqrt(std::max(0.0, cov_bound(3, 3))) * dip_scale;
  result->soft_iron = r * p;
  // σ of S = R P: P's entries (∂P/∂a_k = −F A⁻¹ E_k A⁻¹) through R, and R's small angles through
  // [δφ]× R P.
  std::vector<Matrix3d> ds;
  const Matrix3d a_inv = a.inverse();
  for (int k = 0; k < 6; ++k) {
    Vector6d e = Vector6d::Zero();
    e(k) = 1;
    ds.push_back(-field * r * a_inv * Sym(e) * a_inv);
  }
  for (int k = 0; k < 3; ++k) ds.push_back(Skew(Vector3d::Unit(k)) * r * p);
  const Eigen::MatrixXd& p_primary = cov_p != nullptr ? *cov_p : cov_primary;
  for (const auto& [theta, align, out] : {std::tuple{&p_primary, &cov, &result->std},
                                          std::tuple{&cov_crb, &cov_bound, &result->crb}}) {
    Eigen::MatrixXd c = Eigen::MatrixXd::Zero(9, 9);
    c.topLeftCorner(6, 6) = theta->bottomRightCorner(6, 6);
    c.bottomRightCorner(3, 3) = align->topLeftCorner<3, 3>();
    out->soft_iron = EntryStd(ds, c);
  }
  result->alignment_note = "from " + std::to_string(count) + " statics";
}

MagCoverage AssessCoverage(const Eigen::Matrix3Xd& u, const Eigen::VectorXd& w,
                           const MagOptions& options) {
  MagCoverage c;
  Matrix3d scatter = Matrix3d::Zero();
  int64_t used = 0;
  Eigen::Vector3d best_plus = Eigen::Vector3d::Constant(-1), best_minus = best_plus;
  for (Eigen::Index i = 0; i < u.cols(); ++i) {
    if (w(i) < options.disturbed_weight) continue;
    scatter += u.col(i) * u.col(i).transpose();
    best_plus = best_plus.cwiseMax(u.col(i));
    best_minus = best_minus.cwiseMax(-u.col(i));
    ++used;
  }
  scatter *= 3.0 / std::max<int64_t>(1, used);
  Eigen::SelfAdjointEigenSolver<Matrix3d> es(scatter);
  c.eigenvalues = es.eigenvalues();
  c.least_covered_direction = es.eigenvectors().col(0);
  const double cos45 = std::sqrt(0.5);
  for (int axis = 0; axis < 3; ++axis) {
    if (best_plus(axis) < cos45) c.missing.push_back(AxisName(axis, 1));
    if (best_minus(axis) < cos45) c.missing.push_back(AxisName(axis, -1));
  }
  c.sufficient = c.eigenvalues(0) >= options.min_coverage_eigenvalue && c.missing.empty();
  if (c.sufficient) {
    c.verdict = "good: the field came within 45° of every magnetometer axis";
  } else if (!c.missing.empty()) {
    c.verdict =
        "turn the device so that the field (north, tilted down by the dip) comes within "
        "45° of its " +
        JoinAnd(c.missing) + " axis";
  } else {
    int axis = 0;
    c.least_covered_direction.cwiseAbs().maxCoeff(&axis);
    c.verdict =
        "the field directions lie close to a plane: turn the device about more axes "
        "(tilt it and turn it over), bringing its " +
        AxisName(axis, 1) + " or " + AxisName(axis, -1) + " axis along the field";
  }
  return c;
}

std::vector<MagSpan> DisturbedSpans(const Eigen::VectorXd& t, const Eigen::VectorXd& w,
                                    const Eigen::VectorXd& residual, const MagOptions& options) {
  std::vector<MagSpan> spans;
  for (Eigen::Index i = 0; i < w.size(); ++i) {
    if (w(i) >= options.disturbed_weight) continue;
    if (spans.empty() || t(i) - spans.back().end > options.span_merge_seconds) {
      spans.push_back({t(i), t(i), 0, 0});
    }
    MagSpan& s = spans.back();
    s.end = t(i);
    ++s.samples;
    s.max_residual = std::max(s.max_residual, residual(i));
  }
  return spans;
}

}  // namespace calibd::core::mag_internal
