// The statics of CalibrateImus (core/imu.h, core/imu_internal.h): the accelerometer fit of step 2
// (closed-form ellipsoid start, then Levenberg-Marquardt), the coverage of the orientations and the
// cap on the number of statics.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/imu_internal.h"

namespace calibd::core::imu_internal {
namespace {

// Closed-form affine start: ellipsoid through the static means (ȳ_j), |M(ȳ − b)| = g.
// Works in z = (ȳ − c)·s with c the mean of the means and s = unit/g (well conditioned).
bool EllipsoidFit(const std::vector<StaticData>& st, double unit, double g, Matrix3d* m_out,
                  Vector3d* b_out) {
  const int n = static_cast<int>(st.size());
  Vector3d c = Vector3d::Zero();
  for (const auto& s : st) c += s.ya;
  c /= n;
  const double sc = unit / g;
  MatrixXd d(n, 10);
  for (int j = 0; j < n; ++j) {
    const Vector3d z = (st[j].ya - c) * sc;
    d.row(j) << z.x() * z.x(), z.y() * z.y(), z.z() * z.z(), 2 * z.x() * z.y(), 2 * z.x() * z.z(),
        2 * z.y() * z.z(), z.x(), z.y(), z.z(), 1;
  }
  Eigen::JacobiSVD<MatrixXd> svd(d, Eigen::ComputeFullV);
  const VectorXd th = svd.matrixV().col(9);
  Matrix3d q;
  q << th(0), th(3), th(4), th(3), th(1), th(5), th(4), th(5), th(2);
  const Vector3d l = th.segment<3>(6);
  Eigen::FullPivLU<Matrix3d> lu(q);
  if (!lu.isInvertible()) return false;
  const Vector3d z0 = -0.5 * lu.solve(l);
  const double k = z0.dot(q * z0) - th(9);
  if (!(std::abs(k) > 0)) return false;
  const Matrix3d a = q / k;
  Eigen::LLT<Matrix3d> llt(a);
  if (llt.info() != Eigen::Success) return false;
  const Matrix3d mz = llt.matrixL().transpose();  // upper, a = mzᵀ mz
  *m_out = g * sc * mz;
  *b_out = c + z0 / sc;
  return m_out->allFinite() && b_out->allFinite();
}

// Static data of IMU k for a detection: accelerometer triad 2k, gyroscope triad 2k+1.
std::vector<StaticData> StaticsOf(const StaticDetection& d, int k) {
  std::vector<StaticData> out;
  for (const StaticInterval& iv : d.intervals) {
    StaticData s;
    s.ya = iv.mean[static_cast<size_t>(2 * k)];
    s.yg = iv.mean[static_cast<size_t>(2 * k + 1)];
    s.n = static_cast<double>(iv.samples);
    out.push_back(s);
  }
  return out;
}

std::string AxisName(int axis, int sign) { return std::string(sign > 0 ? "+" : "-") + "xyz"[axis]; }

}  // namespace

AccelFit FitAccelerometer(const StaticDetection& d, int k, const ImuOptions& o) {
  AccelFit f;
  f.pr.g = o.gravity;
  f.pr.stop = o.stop;
  f.pr.statics = StaticsOf(d, k);
  const int n = static_cast<int>(f.pr.statics.size());
  Vector3d sa =
      o.accel_noise ? Vector3d::Constant(*o.accel_noise / o.accel_unit) : PooledStd(d, 2 * k);
  sa = sa.cwiseMax(1e-9 * o.gravity / o.accel_unit);
  f.pr.wa = sa.cwiseInverse();
  Matrix3d ma;
  Vector3d ba;
  if (!EllipsoidFit(f.pr.statics, o.accel_unit, o.gravity, &ma, &ba)) {
    f.failure =
        "the static orientations do not determine the accelerometer (no ellipsoid "
        "through the static means): add orientations spread over the sphere";
    return f;
  }
  f.x.p = ma.inverse();
  f.x.p.triangularView<Eigen::StrictlyLower>().setZero();
  f.x.ba = ba;
  f.x.mg = o.gyro_unit * Matrix3d::Identity();
  for (const StaticData& s : f.pr.statics) f.x.u.push_back((ma * (s.ya - ba)).normalized());
  f.pr.use_accel = true;
  f.pr.active.assign(static_cast<size_t>(f.pr.Size()), 0);
  for (int i = 0; i < 9; ++i) f.pr.active[static_cast<size_t>(i)] = 1;
  for (int i = kShared; i < f.pr.Size(); ++i) f.pr.active[static_cast<size_t>(i)] = 1;
  const LmSummary s = Minimize(f.pr, o.max_iterations, &f.x);
  f.iterations = s.iterations;
  if (s.stopped) {
    f.stopped = true;
    f.failure = "stopped";
    return f;
  }
  f.dof = 3 * n - 9 - 2 * n;
  f.chi2 = 2 * s.cost.back();
  f.ok = true;
  return f;
}

void Coverage(const std::vector<Vector3d>& u, const Vector3d& rot_axis, ImuCoverage* c) {
  Matrix3d s = Matrix3d::Zero();
  for (const Vector3d& v : u) s += v * v.transpose();
  s *= 3.0 / std::max<size_t>(1, u.size());
  Eigen::SelfAdjointEigenSolver<Matrix3d> es(s);
  c->gravity_eigenvalues = es.eigenvalues();
  c->min_eigenvalue = es.eigenvalues()(0);
  c->least_covered_direction = es.eigenvectors().col(0);
  c->missing_up.clear();
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign : {1, -1}) {
      double best = -1;
      for (const Vector3d& v : u) best = std::max(best, sign * v(axis));
      if (best < std::cos(45 * 3.14159265358979323846 / 180)) {
        c->missing_up.push_back(AxisName(axis, sign));
      }
    }
  }
  c->rotation_per_axis = rot_axis;
  c->weak_axes.clear();
  const double mx = rot_axis.maxCoeff();
  for (int axis = 0; axis < 3; ++axis) {
    if (!(rot_axis(axis) >= 0.2 * mx) || mx <= 0)
      c->weak_axes.push_back(std::string(1, "xyz"[axis]));
  }
  std::ostringstream v;
  c->sufficient = c->min_eigenvalue >= 0.2 && c->missing_up.empty() && c->weak_axes.empty();
  if (c->sufficient) {
    v << "good: the static orientations span the sphere and every axis was turned";
  } else {
    const char* sep = "";
    if (!c->missing_up.empty()) {
      v << "add orientations with the board's ";
      for (size_t i = 0; i < c->missing_up.size(); ++i) {
        v << (i ? (i + 1 == c->missing_up.size() ? " or " : ", ") : "") << c->missing_up[i];
      }
      v << " axis up";
      sep = "; ";
    } else if (c->min_eigenvalue < 0.2) {
      const Vector3d d = c->least_covered_direction;
      int axis = 0;
      d.cwiseAbs().maxCoeff(&axis);
      v << "the static orientations lie close to a plane: add orientations with the board's "
        << AxisName(axis, 1) << " or " << AxisName(axis, -1) << " axis up";
      sep = "; ";
    }
    if (!c->weak_axes.empty()) {
      v << sep << "turn the board more about its ";
      for (size_t i = 0; i < c->weak_axes.size(); ++i) v << (i ? " and " : "") << c->weak_axes[i];
      v << " axis between statics";
    }
  }
  c->verdict = v.str();
}

void KeepLongestStatics(int cap, StaticDetection* d) {
  const size_t n = d->intervals.size();
  if (n <= static_cast<size_t>(cap)) return;
  std::vector<size_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return d->intervals[a].samples > d->intervals[b].samples;
  });
  order.resize(static_cast<size_t>(cap));
  std::sort(order.begin(), order.end());
  std::vector<StaticInterval> kept;
  kept.reserve(order.size());
  int64_t samples = 0;
  for (size_t i : order) {
    samples += d->intervals[i].samples;
    kept.push_back(std::move(d->intervals[i]));
  }
  d->intervals = std::move(kept);
  d->static_samples = samples;
}

}  // namespace calibd::core::imu_internal
