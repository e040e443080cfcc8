// The joint problem of CalibrateImus (core/imu.h, core/imu_internal.h): the rotation integrals,
// the residuals with their Jacobian in block structure, the block tridiagonal solve and the
// Levenberg-Marquardt minimiser.
#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

#include "core/imu_internal.h"

namespace calibd::core::imu_internal {
namespace {

Matrix3d Skew(const Vector3d& v) {
  Matrix3d s;
  s << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return s;
}

// Exp(φ) = I + A[φ]× + B[φ]×², and the right Jacobian J_r(φ) = I − B[φ]× + C[φ]×²
// (A = sinθ/θ, B = (1−cosθ)/θ², C = (θ−sinθ)/θ³), series below θ = 0.05 (error < 1e-17).
inline void ExpAndJr(const Vector3d& phi, Matrix3d* e, Matrix3d* jr) {
  const double x = phi.x(), y = phi.y(), z = phi.z();
  const double t2 = x * x + y * y + z * z;
  double a, b, c;
  if (t2 < 2.5e-3) {
    a = 1 - t2 / 6 * (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72)));
    b = 0.5 * (1 - t2 / 12 * (1 - t2 / 30 * (1 - t2 / 56 * (1 - t2 / 90))));
    c = (1 - t2 / 20 * (1 - t2 / 42 * (1 - t2 / 72 * (1 - t2 / 110)))) / 6;
  } else {
    const double th = std::sqrt(t2), s = std::sin(th), co = std::cos(th);
    a = s / th;
    b = (1 - co) / t2;
    c = (th - s) / (t2 * th);
  }
  // [φ]×² = φφᵀ − θ²I.
  const double xx = x * x - t2, yy = y * y - t2, zz = z * z - t2, xy = x * y, xz = x * z,
               yz = y * z;
  Matrix3d& E = *e;
  E(0, 0) = 1 + b * xx;
  E(1, 1) = 1 + b * yy;
  E(2, 2) = 1 + b * zz;
  E(0, 1) = b * xy - a * z;
  E(1, 0) = b * xy + a * z;
  E(0, 2) = b * xz + a * y;
  E(2, 0) = b * xz - a * y;
  E(1, 2) = b * yz - a * x;
  E(2, 1) = b * yz + a * x;
  if (jr == nullptr) return;
  Matrix3d& J = *jr;
  J(0, 0) = 1 + c * xx;
  J(1, 1) = 1 + c * yy;
  J(2, 2) = 1 + c * zz;
  J(0, 1) = c * xy + b * z;
  J(1, 0) = c * xy - b * z;
  J(0, 2) = c * xz - b * y;
  J(2, 0) = c * xz + b * y;
  J(1, 2) = c * yz + b * x;
  J(2, 1) = c * yz - b * x;
}

Mat32 TangentBasis(const Vector3d& u) {
  Vector3d a = std::abs(u.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
  Vector3d e1 = (a - u * u.dot(a)).normalized();
  Mat32 b;
  b.col(0) = e1;
  b.col(1) = u.cross(e1);
  return b;
}

// Steps between two polls of the stop token in a rotation's integral (~3 ms of work).
constexpr size_t kStepsPerPoll = 1 << 16;

// Integrates one rotation; with s != nullptr also the sums of the analytic Jacobian:
// s[l] = Σ_k P_k J_r(φ_k) Δt_k x_k,l (l = 0..2), s[3] = Σ_k P_k J_r(φ_k) Δt_k.
// Polls `stop` every kStepsPerPoll steps and returns early (a meaningless R) when it asks.
Matrix3d IntegrateSteps(const std::vector<Eigen::Vector4d>& steps, const Matrix3d& m,
                        const Vector3d& bias, Matrix3d* s, const StopToken* stop = nullptr) {
  Matrix3d r = Matrix3d::Identity(), e, jr;
  if (s != nullptr) {
    for (int l = 0; l < 4; ++l) s[l].setZero();
  }
  for (size_t k = 0; k < steps.size(); ++k) {
    if (k % kStepsPerPoll == kStepsPerPoll - 1 && StopRequested(stop)) break;
    const Eigen::Vector4d& st = steps[k];
    const double dt = st(3);
    const Vector3d x = st.head<3>() - bias;
    const Vector3d phi = m * x * dt;
    ExpAndJr(phi, &e, s != nullptr ? &jr : nullptr);
    r = (r * e).eval();
    if (s != nullptr) {
      const Matrix3d q = r * jr * dt;
      s[3] += q;
      for (int l = 0; l < 3; ++l) s[l] += q * x(l);
    }
  }
  return r;
}

State Plus(const State& x, const VectorXd& d) {
  State y = x;
  for (int q = 0; q < 6; ++q) y.p(kUpperRow[q], kUpperCol[q]) += d(kP + q);
  y.ba += d.segment<3>(kBa);
  for (int i = 0; i < 9; ++i) y.mg(i % 3, i / 3) += d(kMg + i);
  y.bg += d.segment<3>(kBg);
  for (size_t j = 0; j < y.u.size(); ++j) {
    const Mat32 b = TangentBasis(x.u[j]);
    y.u[j] = (x.u[j] + b * d.segment<2>(kShared + 2 * static_cast<int>(j))).normalized();
  }
  return y;
}

}  // namespace

bool SolveNormal(const Normal& h, const std::vector<char>& active, double lambda,
                 const VectorXd& rhs_in, VectorXd* delta, Mat21* shared_inverse) {
  const int dim = h.Size();
  const int n = static_cast<int>(h.d.size());
  auto on = [&](int i) { return active[static_cast<size_t>(i)] != 0; };
  // Damped diagonal, then the Jacobi scale of every unknown (1 for inactive ones).
  VectorXd diag(dim), scale(dim);
  for (int i = 0; i < dim; ++i) {
    const double hii = h.Diagonal(i);
    diag(i) = on(i) ? hii + lambda * std::max(hii, 1e-300) : 1.0;
    scale(i) = 1 / std::sqrt(diag(i));
  }
  if (!scale.allFinite()) return false;
  auto entry = [&](int i, int j, double v) {  // scaled, masked, damped entry
    if (!on(i) || !on(j)) return i == j ? 1.0 : 0.0;
    return i == j ? 1.0 : scale(i) * v * scale(j);
  };
  Mat21 a;
  for (int i = 0; i < kShared; ++i) {
    for (int j = 0; j < kShared; ++j) a(i, j) = entry(i, j, h.a(i, j));
  }
  MatrixXd et(2 * n, kShared);  // Eᵀ, scaled
  for (int i = 0; i < kShared; ++i) {
    for (int c = 0; c < 2 * n; ++c) et(c, i) = entry(i, kShared + c, h.e(i, c));
  }
  VectorXd rhs(dim);
  for (int i = 0; i < dim; ++i) rhs(i) = on(i) ? scale(i) * rhs_in(i) : 0.0;
  // Block tridiagonal Cholesky C = L Lᵀ: diagonal blocks l[j] (lower), sub-diagonal m[j] =
  // L(j+1, j).
  std::vector<Eigen::Matrix2d> l(static_cast<size_t>(n)),
      m(static_cast<size_t>(std::max(0, n - 1)));
  auto block = [&](const Eigen::Matrix2d& src, int si, int sj) {
    Eigen::Matrix2d b;
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 2; ++c)
        b(r, c) = entry(kShared + 2 * si + r, kShared + 2 * sj + c, src(r, c));
    }
    return b;
  };
  for (int j = 0; j < n; ++j) {
    Eigen::Matrix2d dj = block(h.d[static_cast<size_t>(j)], j, j);
    if (j > 0) dj -= m[static_cast<size_t>(j - 1)] * m[static_cast<size_t>(j - 1)].transpose();
    const Eigen::LLT<Eigen::Matrix2d> llt(dj);
    if (llt.info() != Eigen::Success) return false;
    l[static_cast<size_t>(j)] = llt.matrixL();
    if (j + 1 < n) {
      // L(j+1, j) L(j, j)ᵀ = C(j+1, j) = F_jᵀ.
      const Eigen::Matrix2d fjt = block(h.f[static_cast<size_t>(j)], j, j + 1).transpose();
      m[static_cast<size_t>(j)] = l[static_cast<size_t>(j)]
                                      .triangularView<Eigen::Lower>()
                                      .solve(fjt.transpose())
                                      .transpose();
    }
  }
  // C⁻¹ [Eᵀ | r_u] by forward and back substitution.
  MatrixXd x(2 * n, kShared + 1);
  x.leftCols<kShared>() = et;
  x.col(kShared) = rhs.tail(2 * n);
  for (int j = 0; j < n; ++j) {
    auto xj = x.middleRows<2>(2 * j);
    if (j > 0) xj -= m[static_cast<size_t>(j - 1)] * x.middleRows<2>(2 * (j - 1));
    l[static_cast<size_t>(j)].triangularView<Eigen::Lower>().solveInPlace(xj);
  }
  for (int j = n - 1; j >= 0; --j) {
    auto xj = x.middleRows<2>(2 * j);
    if (j + 1 < n) xj -= m[static_cast<size_t>(j)].transpose() * x.middleRows<2>(2 * (j + 1));
    l[static_cast<size_t>(j)].transpose().triangularView<Eigen::Upper>().solveInPlace(xj);
  }
  // Schur complement onto the shared unknowns.
  Mat21 s = a - et.transpose() * x.leftCols<kShared>();
  s = (0.5 * (s + s.transpose())).eval();
  const Eigen::Matrix<double, kShared, 1> rs =
      rhs.head<kShared>() - et.transpose() * x.col(kShared);
  const Eigen::LDLT<Mat21> ldlt(s);
  if (ldlt.info() != Eigen::Success) return false;
  const Eigen::Matrix<double, kShared, 1> ds = ldlt.solve(rs);
  VectorXd out(dim);
  out.head<kShared>() = ds;
  out.tail(2 * n) = x.col(kShared) - x.leftCols<kShared>() * ds;
  *delta = scale.cwiseProduct(out);
  if (shared_inverse != nullptr) {
    const Mat21 si = ldlt.solve(Mat21::Identity());
    *shared_inverse = scale.head<kShared>().asDiagonal() * si * scale.head<kShared>().asDiagonal();
    if (!shared_inverse->allFinite()) return false;
  }
  return delta->allFinite();
}

std::vector<Eigen::Vector4d> Steps(const VectorXd& t, const Eigen::MatrixX3d& y, int64_t first,
                                   int64_t last) {
  std::vector<Eigen::Vector4d> steps(static_cast<size_t>(std::max<int64_t>(0, last - first)));
  for (int64_t i = first; i < last; ++i) {
    Eigen::Vector4d& st = steps[static_cast<size_t>(i - first)];
    for (int a = 0; a < 3; ++a) st(a) = 0.5 * (y(i, a) + y(i + 1, a));
    st(3) = t(i + 1) - t(i);
  }
  return steps;
}

Matrix3d Integrate(const VectorXd& t, const Eigen::MatrixX3d& y, const Matrix3d& m,
                   const Vector3d& bias, int64_t first, int64_t last, Matrix3d* s) {
  return IntegrateSteps(Steps(t, y, first, last), m, bias, s);
}

double Evaluate(const Problem& pr, const State& x, Normal* h) {
  const bool jac = h != nullptr;
  if (jac) h->SetZero(pr.Statics());
  double cost = 0;
  auto accumulate = [&](const Vector3d& r, const MatrixXd& jb, const std::vector<int>& idx) {
    const MatrixXd jtj = jb.transpose() * jb;
    const VectorXd jtr = jb.transpose() * r;
    for (size_t a = 0; a < idx.size(); ++a) {
      h->g(idx[a]) += jtr(static_cast<Eigen::Index>(a));
      for (size_t b = 0; b < idx.size(); ++b) {
        h->Add(idx[a], idx[b], jtj(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)));
      }
    }
  };
  const int n = static_cast<int>(pr.statics.size());
  if (pr.use_accel) {
    std::vector<int> idx(11);
    for (int i = 0; i < 9; ++i) idx[i] = i;
    MatrixXd jb(3, 11);
    for (int j = 0; j < n; ++j) {
      const StaticData& s = pr.statics[j];
      const double sq = std::sqrt(s.n);
      const Vector3d w = pr.wa * sq;
      const Vector3d r = w.cwiseProduct(s.ya - x.ba - pr.g * x.p * x.u[j]);
      cost += 0.5 * r.squaredNorm();
      if (!jac) continue;
      jb.setZero();
      for (int q = 0; q < 6; ++q) {
        const int k = kUpperRow[q], l = kUpperCol[q];
        jb(k, kP + q) = -w(k) * pr.g * x.u[j](l);
      }
      jb.block<3, 3>(0, kBa) = -w.asDiagonal().toDenseMatrix();
      jb.block<3, 2>(0, 9) = -(w.asDiagonal() * (pr.g * x.p * TangentBasis(x.u[j])));
      idx[9] = kShared + 2 * j;
      idx[10] = kShared + 2 * j + 1;
      accumulate(r, jb, idx);
    }
  }
  if (pr.use_gyro_statics) {
    const std::vector<int> idx = {kBg, kBg + 1, kBg + 2};
    MatrixXd jb(3, 3);
    for (int j = 0; j < n; ++j) {
      const StaticData& s = pr.statics[j];
      const Vector3d w = pr.wg * std::sqrt(s.n);
      const Vector3d r = w.cwiseProduct(s.yg - x.bg);
      cost += 0.5 * r.squaredNorm();
      if (!jac) continue;
      jb = -w.asDiagonal().toDenseMatrix();
      accumulate(r, jb, idx);
    }
  }
  if (pr.use_rotations) {
    std::vector<int> idx(16);
    for (int i = 0; i < 12; ++i) idx[i] = kMg + i;  // M_g (9) then b_g (3)
    MatrixXd jb(3, 16);
    Matrix3d s[4];
    for (const RotationData& rot : pr.rotations) {
      if (StopRequested(pr.stop)) break;
      const Matrix3d r = IntegrateSteps(rot.steps, x.mg, x.bg, jac ? s : nullptr, pr.stop);
      const Vector3d v = r.transpose() * x.u[rot.j];
      const Vector3d res = rot.weight * (v - x.u[rot.j + 1]);
      cost += 0.5 * res.squaredNorm();
      if (!jac) continue;
      const Matrix3d vr = rot.weight * Skew(v) * r.transpose();
      for (int l = 0; l < 3; ++l) jb.block<3, 3>(0, 3 * l) = vr * s[l];
      jb.block<3, 3>(0, 9) = -vr * s[3] * x.mg;
      jb.block<3, 2>(0, 12) = rot.weight * r.transpose() * TangentBasis(x.u[rot.j]);
      jb.block<3, 2>(0, 14) = -rot.weight * TangentBasis(x.u[rot.j + 1]);
      idx[12] = kShared + 2 * rot.j;
      idx[13] = kShared + 2 * rot.j + 1;
      idx[14] = kShared + 2 * (rot.j + 1);
      idx[15] = kShared + 2 * (rot.j + 1) + 1;
      accumulate(res, jb, idx);
    }
  }
  return cost;
}

LmSummary Minimize(const Problem& pr, int max_iterations, State* x) {
  LmSummary sum;
  Normal h;
  double cost = Evaluate(pr, *x, &h);
  sum.cost.push_back(cost);
  if (StopRequested(pr.stop)) {
    sum.stopped = true;
    return sum;
  }
  double lambda = 1e-6;
  while (sum.iterations < max_iterations) {
    if (StopRequested(pr.stop)) {
      sum.stopped = true;
      break;
    }
    VectorXd delta;
    if (!SolveNormal(h, pr.active, lambda, -h.g, &delta)) break;
    const State y = Plus(*x, delta);
    // The trial point is evaluated with its Jacobian: most steps are accepted, and one pass over
    // the rotations with the Jacobian is cheaper than a cost pass and a Jacobian pass.
    Normal h_new;
    const double new_cost = Evaluate(pr, y, &h_new);
    if (StopRequested(pr.stop)) {
      sum.stopped = true;
      break;
    }
    const double step_norm2 = delta.dot(h.Times(delta));  // ‖J δ‖²
    if (std::isfinite(new_cost) && new_cost < cost) {
      const double decrease = cost - new_cost;
      *x = y;
      ++sum.iterations;
      cost = new_cost;
      std::swap(h, h_new);
      sum.cost.push_back(cost);
      lambda = std::max(lambda / 5, 1e-12);
      if (decrease <= 1e-9 * cost || step_norm2 <= 1e-20 * (cost + 1e-300)) {
        sum.converged = true;
        break;
      }
    } else {
      // No decrease: converged to rounding when the predicted step is negligible.
      if (step_norm2 <= 1e-14 * (2 * cost + 1e-300) || lambda > 1e10) {
        sum.converged = true;
        break;
      }
      lambda *= 10;
    }
  }
  return sum;
}

}  // namespace calibd::core::imu_internal
