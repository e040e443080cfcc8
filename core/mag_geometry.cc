// CalibrateMag's geometric stages (core/mag.h, steps 4 and 5) and the small matrix helpers.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <string>
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

// The statics' down directions d_j and calibrated field directions n_j (unit vectors).
void StaticDirections(const MagProblem& problem, const Ellipsoid& fit, const Matrix3d& p,
                      std::vector<Vector3d>* d, std::vector<Vector3d>* n) {
  for (const MagStatic& s : problem.statics) {
    const double f = s.specific_force.norm();
    if (!(f > 0)) continue;
    const Vector3d mean = problem.y.middleCols(s.first, s.last - s.first + 1).rowwise().mean();
    const Vector3d m = p * (mean - fit.h);
    if (!(m.norm() > 0)) continue;
    d->push_back(-s.specific_force / f);
    n->push_back(m.normalized());
  }
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
                       const std::vector<Matrix3d>& dp, const Eigen::MatrixXd& cov_a_primary,
                       const Eigen::MatrixXd& cov_a_crb, MagResult* result) {
  const Matrix3d p = result->soft_iron_symmetric;
  std::vector<Vector3d> d, n;
  StaticDirections(problem, fit, p, &d, &n);
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
  Eigen::Matrix4d h = Eigen::Matrix4d::Zero();
  double ss = 0;
  for (int it = 0; it < 30; ++it) {
    h.setZero();
    Eigen::Vector4d g = Eigen::Vector4d::Zero();
    ss = 0;
    for (int j = 0; j < count; ++j) {
      const Vector3d rn = r * n[j];
      Eigen::Vector4d jac;
      jac << rn.cross(d[j]), -1;
      const double rho = d[j].dot(rn) - s;
      h += jac * jac.transpose();
      g += jac * rho;
      ss += rho * rho;
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d> es(h);
    if (!(es.eigenvalues()(0) > 1e-6 * es.eigenvalues()(3))) {
      result->alignment_note =
          "not estimated: the statics' orientations do not determine the rotation (tilted about "
          "one axis only): hold the device still in orientations tilted about different axes";
      return;
    }
    const Eigen::Vector4d step = -h.ldlt().solve(g);
    r = ExpRotation(step.head<3>()) * r;
    s += step(3);
    if (step.norm() < 1e-12) break;
  }
  if (!(std::abs(s) < 1)) {
    result->alignment_note = "not estimated: the dip's sine came out at " + std::to_string(s);
    return;
  }
  const Eigen::Matrix4d cov = ss / std::max(count - 4, 1) * h.inverse();
  result->alignment = r;
  result->dip = std::asin(s) * kDegPerRad;
  result->std.alignment = cov.diagonal().head<3>().cwiseMax(0).cwiseSqrt();
  result->std.dip = std::sqrt(std::max(0.0, cov(3, 3))) / std::sqrt(1 - s * s) * kDegPerRad;
  result->crb.alignment = result->std.alignment;  // the statics' scatter is the only noise model
  result->crb.dip = result->std.dip;
  result->soft_iron = r * p;
  // σ of S = R P: P's entries through R, and R's small angles through [δφ]× R P.
  std::vector<Matrix3d> ds;
  for (const Matrix3d& dpk : dp) ds.push_back(r * dpk);
  for (int k = 0; k < 3; ++k) ds.push_back(Skew(Vector3d::Unit(k)) * r * p);
  for (const auto& [cov_a, out] :
       {std::pair{&cov_a_primary, &result->std}, std::pair{&cov_a_crb, &result->crb}}) {
    Eigen::MatrixXd c = Eigen::MatrixXd::Zero(9, 9);
    c.topLeftCorner(6, 6) = *cov_a;
    c.bottomRightCorner(3, 3) = cov.topLeftCorner<3, 3>();
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
