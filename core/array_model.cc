// The motion estimator of CalibrateArray (core/array_model.h).
#include "core/array_model.h"

#include <Eigen/Cholesky>

namespace calibd::core::array_model {

MotionModel::MotionModel(const Eigen::Matrix3Xd& positions) : K(positions.cols()), r(positions) {
  r_bar = r.rowwise().mean();
  r_tilde = r.colwise() - r_bar;
  Mat3 M = Mat3::Zero();
  for (int i = 0; i < 3; ++i) Q[i].setZero();
  for (int k = 0; k < K; ++k) {
    const Vec3 rt = r_tilde.col(k);
    M += rt.squaredNorm() * Mat3::Identity() - rt * rt.transpose();
    R2 += r.col(k) * r.col(k).transpose();
    const Mat3 S = Skew(rt);
    for (int i = 0; i < 3; ++i) Q[i] += r(i, k) * S;
  }
  Eigen::LDLT<Mat3> ldlt(M);
  ok = ldlt.info() == Eigen::Success && (ldlt.vectorD().array() > 0).all();
  if (ok) M_inv = ldlt.solve(Mat3::Identity());
}

double MotionModel::Solve(const double* y, const Vec3& gbar, double gscatter, int G, double wa,
                          double wg, int max_iterations, Eigen::Matrix3Xd* z, Vec3* omega,
                          Vec3* omega_dot, Vec3* s) const {
  const ConstMap3X Y(y, 3, K);
  Vec3 w = *omega;
  Vec3 wd, sp;
  double cost = 0;
  bool done = false;
  for (int it = 0;; ++it) {
    // Evaluate the projected residuals at w.
    const double ww = w.squaredNorm();
    // z_k = y_k - (w (w . r_k) - r_k |w|^2)
    Vec3 z_sum = Vec3::Zero(), cross_sum = Vec3::Zero();
    for (int k = 0; k < K; ++k) {
      const Vec3 rk = r.col(k);
      const Vec3 zk = Y.col(k) - w * w.dot(rk) + ww * rk;
      z->col(k) = zk;
      z_sum += zk;
      cross_sum += r_tilde.col(k).cross(zk);
    }
    sp = z_sum / K;
    wd = M_inv * cross_sum;
    // e_k = z_k - s' - wd x r~_k, in place in z; Re = sum_k e_k r_k^T.
    double ssr = 0;
    Mat3 Re = Mat3::Zero();
    for (int k = 0; k < K; ++k) {
      const Vec3 ek = z->col(k) - sp - wd.cross(r_tilde.col(k));
      ssr += ek.squaredNorm();
      Re.col(0) += r(0, k) * ek;
      Re.col(1) += r(1, k) * ek;
      Re.col(2) += r(2, k) * ek;
    }
    const Vec3 eg = gbar - w;
    cost = wa * ssr + wg * (G * eg.squaredNorm() + gscatter);
    if (done || it >= max_iterations) break;
    // Gauss-Newton step on omega.
    Mat3 F[3];
    CentripetalJacobians(w, F);
    Mat3 JtJ = Mat3::Zero();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) JtJ += R2(i, j) * F[i].transpose() * F[j];
    Mat3 Jsum = Mat3::Zero(), B = Mat3::Zero();
    for (int i = 0; i < 3; ++i) {
      Jsum += (K * r_bar(i)) * F[i];
      B += Q[i] * F[i];
    }
    Vec3 rhs = Vec3::Zero();
    for (int i = 0; i < 3; ++i) rhs += F[i].transpose() * Re.col(i);
    Mat3 normal = wa * (JtJ - Jsum.transpose() * Jsum / K - B.transpose() * M_inv * B) +
                  (wg * G) * Mat3::Identity();
    const Vec3 dw = normal.ldlt().solve(wa * rhs + (wg * G) * eg);
    if (!dw.allFinite()) break;
    w += dw;
    done = dw.norm() <= 1e-14 * (1 + w.norm());
  }
  *omega = w;
  *omega_dot = wd;
  *s = sp - wd.cross(r_bar);
  return cost;
}

bool MotionPass(const Data& d, const Eigen::Matrix3Xd& r, const Weights& wt,
                const ChunkRunner& runner, int max_gn, MotionStates* x, MotionSums* total,
                const StopToken* stop) {
  const MotionModel model(r);
  if (!model.ok) return false;
  std::vector<MotionSums> sums(runner.NumChunks(d.N));
  runner.ForEachChunk(d.N, [&](int64_t c, int64_t begin, int64_t end) {
    MotionSums& acc = sums[c];
    acc.AtY = Eigen::Matrix3Xd::Zero(3, d.K);
    Eigen::Matrix3Xd z(3, d.K);
    for (int64_t n = begin; n < end; ++n) {
      if (((n - begin) & 15) == 0 && StopRequested(stop)) break;
      Vec3 w = x->col(n).head<3>(), wd, s;
      acc.cost += model.Solve(d.ya.col(n).data(), d.gbar.col(n), d.gscatter(n), d.G, wt.wa, wt.wg,
                              max_gn, &z, &w, &wd, &s);
      x->col(n) << w, wd, s;
      const Mat3 A = MatrixA(w, wd);
      acc.AtA.noalias() += A.transpose().lazyProduct(A);
      const ConstMap3X Y(d.ya.col(n).data(), 3, d.K);
      const Mat3 At = A.transpose();
      for (int k = 0; k < d.K; ++k) acc.AtY.col(k).noalias() += At.lazyProduct(Y.col(k) - s);
    }
  });
  total->cost = 0;
  total->AtA.setZero();
  total->AtY = Eigen::Matrix3Xd::Zero(3, d.K);
  for (const auto& s : sums) {
    total->cost += s.cost;
    total->AtA += s.AtA;
    total->AtY += s.AtY;
  }
  return true;
}

}  // namespace calibd::core::array_model
