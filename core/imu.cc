#include "core/imu.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace calibd::core {
namespace {

using Eigen::Matrix3d;
using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;
using Mat32 = Eigen::Matrix<double, 3, 2>;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Unknowns of the joint problem: P (6, upper triangle row-major: 00 01 02 11 12 22), b_a (3),
// M_g (9, column-major), b_g (3), then 2 tangent coordinates of u_j per static.
constexpr int kP = 0, kBa = 6, kMg = 9, kBg = 18, kShared = 21;
constexpr int kUpperRow[6] = {0, 0, 0, 1, 1, 2};
constexpr int kUpperCol[6] = {0, 1, 2, 1, 2, 2};

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

double AngleBetween(const Vector3d& a, const Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

struct StaticData {
  Vector3d ya, yg;  // means, reading units
  double n = 0;     // samples
};
struct RotationData {
  int j = 0;                           // from static j to j+1
  int64_t first = 0, last = 0;         // samples
  double sum_c2 = 0;                   // Σ c_k² (s²): variance factor of the integrated noise
  double weight = 1;                   // 1/σ_θ
  std::vector<Eigen::Vector4d> steps;  // per step k: ½(y_k + y_{k+1}) (3), Δt_k
};

struct State {
  Matrix3d p = Matrix3d::Identity();  // M_a⁻¹, upper triangular
  Vector3d ba = Vector3d::Zero();
  Matrix3d mg = Matrix3d::Identity();
  Vector3d bg = Vector3d::Zero();
  std::vector<Vector3d> u;
};

struct Problem {
  const VectorXd* t = nullptr;
  const Eigen::MatrixX3d* gyro = nullptr;
  double g = kImuStandardGravity;
  std::vector<StaticData> statics;
  std::vector<RotationData> rotations;
  Vector3d wa = Vector3d::Ones(), wg = Vector3d::Ones();  // 1/σ per axis, reading units
  bool use_accel = true, use_gyro_statics = false, use_rotations = false;
  std::vector<char> active;         // per unknown
  const StopToken* stop = nullptr;  // polled in the rotation integrals and every LM iteration

  int Size() const { return kShared + 2 * static_cast<int>(statics.size()); }
  int Statics() const { return static_cast<int>(statics.size()); }
};

// Steps between two polls of the stop token in a rotation's integral (~3 ms of work).
constexpr size_t kStepsPerPoll = 1 << 16;

using Mat21 = Eigen::Matrix<double, kShared, kShared>;

// The Gauss-Newton matrix H = JᵀJ and gradient Jᵀr of the problem, stored in their block
// structure (issue #20: no dense matrix over the directions, whose number grows with the
// statics): the 21 shared unknowns (dense), their coupling to the 2n direction unknowns, and the
// directions' own part, block tridiagonal with 2×2 blocks (a static's accelerometer residual
// touches its u_j alone, a rotation u_j and u_{j+1}). O(n) memory; solved in O(n) time.
struct Normal {
  Mat21 a;                         // shared × shared
  MatrixXd e;                      // kShared × 2n: shared × directions
  std::vector<Eigen::Matrix2d> d;  // n: u_j × u_j
  std::vector<Eigen::Matrix2d> f;  // n − 1: u_j × u_{j+1} (u_{j+1} × u_j is its transpose)
  VectorXd g;                      // kShared + 2n

  void SetZero(int n) {
    a.setZero();
    e.setZero(kShared, 2 * n);
    d.assign(static_cast<size_t>(n), Eigen::Matrix2d::Zero());
    f.assign(static_cast<size_t>(std::max(0, n - 1)), Eigen::Matrix2d::Zero());
    g.setZero(kShared + 2 * n);
  }
  int Size() const { return static_cast<int>(g.size()); }
  double Diagonal(int i) const {
    if (i < kShared) return a(i, i);
    const int j = (i - kShared) / 2, r = (i - kShared) % 2;
    return d[static_cast<size_t>(j)](r, r);
  }
  // H(i, j) += v for the entries stored (the upper parts; a symmetric caller adds both (i, j)
  // and (j, i), the lower one is dropped here). Directions more than one static apart never meet.
  void Add(int i, int j, double v) {
    if (i < kShared) {
      if (j < kShared) {
        a(i, j) += v;
      } else {
        e(i, j - kShared) += v;
      }
      return;
    }
    if (j < kShared) return;
    const int si = (i - kShared) / 2, ri = (i - kShared) % 2;
    const int sj = (j - kShared) / 2, rj = (j - kShared) % 2;
    if (si == sj) {
      d[static_cast<size_t>(si)](ri, rj) += v;
    } else if (sj == si + 1) {
      f[static_cast<size_t>(si)](ri, rj) += v;
    }
  }
  // H x.
  VectorXd Times(const VectorXd& x) const {
    const int n = static_cast<int>(d.size());
    VectorXd y(x.size());
    const auto xs = x.head<kShared>();
    const auto xu = x.tail(2 * n);
    y.head<kShared>() = a * xs + e * xu;
    y.tail(2 * n) = e.transpose() * xs;
    for (int j = 0; j < n; ++j) {
      y.segment<2>(kShared + 2 * j) += d[static_cast<size_t>(j)] * x.segment<2>(kShared + 2 * j);
      if (j + 1 < n) {
        const Eigen::Matrix2d& fj = f[static_cast<size_t>(j)];
        y.segment<2>(kShared + 2 * j) += fj * x.segment<2>(kShared + 2 * (j + 1));
        y.segment<2>(kShared + 2 * (j + 1)) += fj.transpose() * x.segment<2>(kShared + 2 * j);
      }
    }
    return y;
  }
};

// Solves (H + λ diag(H)) δ = rhs over the active unknowns (inactive ones held: δ_i = 0), with
// Jacobi scaling for conditioning (the parameters span many orders of magnitude). The direction
// unknowns are eliminated by a block tridiagonal Cholesky factorisation, the 21 shared unknowns
// solved from their Schur complement S = A − E C⁻¹ Eᵀ: O(n · 21²) time, O(n · 21) memory.
// With `shared_inverse` (λ = 0, all active: the Fisher information) it also receives S⁻¹ in the
// unscaled unknowns: the covariance of the shared unknowns with the directions marginalised.
// False when a pivot is not positive or the solution is not finite.
bool SolveNormal(const Normal& h, const std::vector<char>& active, double lambda,
                 const VectorXd& rhs_in, VectorXd* delta, Mat21* shared_inverse = nullptr) {
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

Matrix3d Integrate(const VectorXd& t, const Eigen::MatrixX3d& y, const Matrix3d& m,
                   const Vector3d& bias, int64_t first, int64_t last, Matrix3d* s) {
  return IntegrateSteps(Steps(t, y, first, last), m, bias, s);
}

// ½ Σ r² at `x`; with h, the Gauss-Newton matrix JᵀJ and gradient Jᵀr (block structure).
// Stopped by pr.stop: the cost returned is then meaningless (the caller checks the token).
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

struct LmSummary {
  int iterations = 0;
  bool converged = false;
  bool stopped = false;  // pr.stop asked: *x is the last accepted point
  std::vector<double> cost;
};

// Levenberg-Marquardt (Marquardt's diagonal scaling) over the active unknowns, at most
// max_iterations accepted steps and 40 rejected ones in a row (λ from 1e-6 past 1e10 by
// factors of 10); polls pr.stop every iteration and inside every evaluation.
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

// Reported quantities from the internal unknowns: b_a, K_a, T_a(01,02,12), b_g, K_g, T_g offdiag.
VectorXd Reported(const State& x) {
  VectorXd out(21);
  const Matrix3d ma = x.p.inverse();
  out.segment<3>(0) = x.ba;
  for (int i = 0; i < 3; ++i) out(3 + i) = ma(i, i);
  out(6) = ma(0, 1) / ma(1, 1);
  out(7) = ma(0, 2) / ma(2, 2);
  out(8) = ma(1, 2) / ma(2, 2);
  out.segment<3>(9) = x.bg;
  for (int i = 0; i < 3; ++i) out(12 + i) = x.mg(i, i);
  out(15) = x.mg(0, 1) / x.mg(1, 1);
  out(16) = x.mg(0, 2) / x.mg(2, 2);
  out(17) = x.mg(1, 0) / x.mg(0, 0);
  out(18) = x.mg(1, 2) / x.mg(2, 2);
  out(19) = x.mg(2, 0) / x.mg(0, 0);
  out(20) = x.mg(2, 1) / x.mg(1, 1);
  return out;
}

VectorXd Internal(const State& x) {
  VectorXd v(21);
  for (int q = 0; q < 6; ++q) v(q) = x.p(kUpperRow[q], kUpperCol[q]);
  v.segment<3>(6) = x.ba;
  for (int i = 0; i < 9; ++i) v(9 + i) = x.mg(i % 3, i / 3);
  v.segment<3>(18) = x.bg;
  return v;
}

State FromInternal(const VectorXd& v, const State& like) {
  State x = like;
  x.p.setZero();
  for (int q = 0; q < 6; ++q) x.p(kUpperRow[q], kUpperCol[q]) = v(q);
  x.ba = v.segment<3>(6);
  for (int i = 0; i < 9; ++i) x.mg(i % 3, i / 3) = v(9 + i);
  x.bg = v.segment<3>(18);
  return x;
}

void FillTriad(const Matrix3d& m, const Vector3d& b, TriadCalibration* tc) {
  tc->bias = b;
  tc->matrix = m;
  tc->scale = m.diagonal();
  tc->misalignment = m * tc->scale.cwiseInverse().asDiagonal();
}

struct AccelFit {
  bool ok = false;
  bool stopped = false;  // options.stop asked during the fit
  std::string failure;
  State x;
  Problem pr;
  double chi2 = kNaN;
  int dof = 0;
  int iterations = 0;
};

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

// Pooled within-static σ per axis (reading units) of triad `tri`.
Vector3d PooledStd(const StaticDetection& d, int tri) {
  Vector3d ss = Vector3d::Zero();
  double dof = 0;
  for (const StaticInterval& iv : d.intervals) {
    if (iv.samples < 2) continue;
    ss += (iv.std[static_cast<size_t>(tri)].array().square() * (iv.samples - 1.0)).matrix();
    dof += static_cast<double>(iv.samples - 1);
  }
  return dof > 0 ? Vector3d((ss / dof).cwiseSqrt()) : Vector3d::Zero();
}

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

std::string AxisName(int axis, int sign) { return std::string(sign > 0 ? "+" : "-") + "xyz"[axis]; }

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

// Keeps the `cap` longest intervals of `d` (ties: the earlier), in time order: the number of
// statics the fits take is bounded whatever the log (issue #20). The rotations then join the
// kept statics across the dropped ones (still valid: the gyroscope integrates through them).
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

Status Fail(Status s, ImuTermination term, ImuResult* r) {
  r->usable = false;
  r->termination = term;
  r->reason = s.message();
  return s;
}

// The failure of a run that options.stop stopped during `stage`.
Status Stopped(const ImuOptions& o, const std::string& stage, ImuResult* r) {
  return Fail(StoppedStatus(*o.stop, "imu: " + stage), ImuTermination::kStopped, r);
}

// Steps 3-5 and the diagnostics for IMU k, given its accelerometer fit on the chosen detection.
Status Finish(const VectorXd& t, const ImuReadings& imu, int k, const ImuOptions& o, AccelFit fit,
              ImuResult* res) {
  const StaticDetection& det = res->detection;
  const Eigen::MatrixX3d& yg = *imu.gyro;
  Problem pr = fit.pr;
  State x = fit.x;
  const int n = static_cast<int>(pr.statics.size());
  res->accel_iterations = fit.iterations;
  pr.t = &t;
  pr.gyro = &yg;
  pr.stop = o.stop;

  // Gyroscope noise and bias.
  Vector3d sg =
      o.gyro_noise ? Vector3d::Constant(*o.gyro_noise / o.gyro_unit) : PooledStd(det, 2 * k + 1);
  sg = sg.cwiseMax(1e-9 / o.gyro_unit);
  pr.wg = sg.cwiseInverse();
  res->accel_noise = pr.wa.cwiseInverse() * o.accel_unit;
  res->gyro_noise = sg * o.gyro_unit;
  {
    Vector3d sum = Vector3d::Zero();
    double cnt = 0;
    for (const StaticData& s : pr.statics) {
      sum += s.yg * s.n;
      cnt += s.n;
    }
    x.bg = sum / cnt;
  }
  x.mg = o.gyro_unit * Matrix3d::Identity();

  // Rotations between consecutive statics.
  const Matrix3d ma0 = o.accel_unit * Matrix3d::Identity();
  const Vector3d ba0 = Vector3d::Constant(o.nominal_accel_bias);
  const Matrix3d mg0 = o.gyro_unit * Matrix3d::Identity();
  const Vector3d bg0 = Vector3d::Constant(o.nominal_gyro_bias);
  for (int j = 0; j + 1 < n; ++j) {
    if (StopRequested(o.stop)) return Stopped(o, "rotations", res);
    const StaticInterval& a = det.intervals[static_cast<size_t>(j)];
    const StaticInterval& b = det.intervals[static_cast<size_t>(j + 1)];
    ImuRotationDiagnostics rd;
    rd.from = j;
    rd.to = j + 1;
    rd.start = a.end;
    rd.end = b.start;
    for (const TimeGap& g : det.gaps) {
      if (g.index > a.last && g.index <= b.first) rd.excluded = "gap in t";
    }
    for (int64_t i = a.last; i <= b.first && rd.excluded.empty(); ++i) {
      const auto row = yg.row(i);
      if (row.minCoeff() <= o.gyro_saturation_low || row.maxCoeff() >= o.gyro_saturation_high) {
        rd.excluded = "saturated gyroscope samples";
      }
    }
    rd.used = rd.excluded.empty();
    if (rd.used) {
      RotationData r;
      r.j = j;
      r.first = a.last;
      r.last = b.first;
      for (int64_t i = r.first; i <= r.last; ++i) {
        const double c =
            0.5 * ((i > r.first ? t(i) - t(i - 1) : 0) + (i < r.last ? t(i + 1) - t(i) : 0));
        r.sum_c2 += c * c;
      }
      r.steps = Steps(t, yg, r.first, r.last);
      pr.rotations.push_back(r);
    }
    res->rotations.push_back(rd);
  }
  auto set_weights = [&](const Matrix3d& mg) {
    const Matrix3d cov = mg * sg.array().square().matrix().asDiagonal() * mg.transpose();
    const double var = cov.trace() / 3;
    for (RotationData& r : pr.rotations) r.weight = 1 / std::sqrt(var * r.sum_c2);
  };
  const bool estimate_bias = o.gyro_bias == GyroBiasModel::kEstimate;
  const int needed_rotations = estimate_bias ? 6 : 5;
  if (static_cast<int>(pr.rotations.size()) < needed_rotations) {
    return Fail(
        Status::NotDeterminable(
            Reason::kTooFewRotations,
            "the gyroscope needs at least " + std::to_string(needed_rotations) +
                " rotations between consecutive statics, " + std::to_string(pr.rotations.size()) +
                " are usable: record more static orientations joined by rotations"),
        ImuTermination::kTooFewRotations, res);
  }

  // Gyroscope fit: M_g (and b_g for kEstimate), accelerometer and u_j held.
  set_weights(mg0);
  pr.use_accel = false;
  pr.use_gyro_statics = false;
  pr.use_rotations = true;
  pr.active.assign(static_cast<size_t>(pr.Size()), 0);
  for (int i = 0; i < 9; ++i) pr.active[static_cast<size_t>(kMg + i)] = 1;
  if (estimate_bias) {
    for (int i = 0; i < 3; ++i) pr.active[static_cast<size_t>(kBg + i)] = 1;
  }
  LmSummary gs = Minimize(pr, o.max_iterations, &x);
  res->gyro_iterations = gs.iterations;
  if (gs.stopped) return Stopped(o, "gyroscope fit", res);
  bool max_iter = !gs.converged;
  res->cost = gs.cost;

  // Joint refinement: everything, every residual.
  set_weights(x.mg);
  pr.use_accel = true;
  pr.use_gyro_statics = !estimate_bias;
  pr.use_rotations = true;
  pr.active.assign(static_cast<size_t>(pr.Size()), 1);
  if (o.joint_refinement) {
    LmSummary js = Minimize(pr, o.max_iterations, &x);
    res->joint_iterations = js.iterations;
    if (js.stopped) return Stopped(o, "joint refinement", res);
    max_iter = max_iter || !js.converged;
    res->cost = js.cost;
  }

  // Uncertainty: inverse Fisher information, u_j marginalised, then to the reported quantities.
  if (StopRequested(o.stop)) return Stopped(o, "uncertainty", res);
  Normal h;
  const double cost = Evaluate(pr, x, &h);
  if (StopRequested(o.stop)) return Stopped(o, "uncertainty", res);
  const int dim = pr.Size();
  const int residuals =
      3 * n * (pr.use_gyro_statics ? 2 : 1) + 3 * static_cast<int>(pr.rotations.size());
  // Rotation residuals carry 2 independent components (the one along u is second order).
  const int informative = residuals - static_cast<int>(pr.rotations.size());
  res->degrees_of_freedom = informative - dim;
  res->chi2_per_dof = res->degrees_of_freedom > 0 ? 2 * cost / res->degrees_of_freedom : kNaN;
  // The covariance of the shared unknowns: the inverse of their Schur complement (the directions
  // eliminated block by block), no dense matrix over the directions.
  Mat21 cov_int = Mat21::Zero();
  VectorXd unused;
  const bool solved = SolveNormal(h, pr.active, 0.0, VectorXd::Zero(dim), &unused, &cov_int);
  cov_int = (0.5 * (cov_int + cov_int.transpose())).eval();
  if (!solved || !cov_int.allFinite() || (cov_int.diagonal().array() <= 0).any()) {
    return Fail(Status::NotDeterminable(
                    Reason::kSingularInformation,
                    "the information matrix is singular: the statics and rotations do not "
                    "determine every parameter (add orientations and turn about every axis)"),
                ImuTermination::kDegenerate, res);
  }
  const VectorXd th = Internal(x);
  MatrixXd jmap(21, 21);
  for (int i = 0; i < 21; ++i) {
    const double step = 1e-6 * std::max(std::abs(th(i)), std::sqrt(cov_int(i, i)) * 1e-3 + 1e-300);
    VectorXd tp = th, tm = th;
    tp(i) += step;
    tm(i) -= step;
    jmap.col(i) = (Reported(FromInternal(tp, x)) - Reported(FromInternal(tm, x))) / (2 * step);
  }
  res->covariance = jmap * cov_int * jmap.transpose();
  const VectorXd sd = res->covariance.diagonal().cwiseMax(0).cwiseSqrt();

  // Parameters.
  const Matrix3d ma = x.p.inverse();
  FillTriad(ma, x.ba, &res->accelerometer);
  FillTriad(x.mg, x.bg, &res->gyroscope);
  TriadCalibration& ac = res->accelerometer;
  TriadCalibration& gc = res->gyroscope;
  ac.bias_std = sd.segment<3>(0);
  ac.scale_std = sd.segment<3>(3);
  ac.misalignment_std.setZero();
  ac.misalignment_std(0, 1) = sd(6);
  ac.misalignment_std(0, 2) = sd(7);
  ac.misalignment_std(1, 2) = sd(8);
  gc.bias_std = sd.segment<3>(9);
  gc.scale_std = sd.segment<3>(12);
  gc.misalignment_std.setZero();
  gc.misalignment_std(0, 1) = sd(15);
  gc.misalignment_std(0, 2) = sd(16);
  gc.misalignment_std(1, 0) = sd(17);
  gc.misalignment_std(1, 2) = sd(18);
  gc.misalignment_std(2, 0) = sd(19);
  gc.misalignment_std(2, 1) = sd(20);

  // Diagnostics: statics.
  double ss_before = 0, ss_after = 0;
  for (int j = 0; j < n; ++j) {
    const StaticInterval& iv = det.intervals[static_cast<size_t>(j)];
    ImuStaticDiagnostics sd_j;
    sd_j.start = iv.start;
    sd_j.end = iv.end;
    sd_j.first = iv.first;
    sd_j.last = iv.last;
    sd_j.samples = iv.samples;
    sd_j.accel_mean = iv.mean[static_cast<size_t>(2 * k)];
    sd_j.accel_std = iv.std[static_cast<size_t>(2 * k)];
    sd_j.gyro_mean = iv.mean[static_cast<size_t>(2 * k + 1)];
    sd_j.gyro_std = iv.std[static_cast<size_t>(2 * k + 1)];
    sd_j.gravity_direction = x.u[static_cast<size_t>(j)];
    sd_j.norm_residual_before = (ma0 * (sd_j.accel_mean - ba0)).norm() - o.gravity;
    sd_j.norm_residual_after = (ma * (sd_j.accel_mean - x.ba)).norm() - o.gravity;
    ss_before += sd_j.norm_residual_before * sd_j.norm_residual_before;
    ss_after += sd_j.norm_residual_after * sd_j.norm_residual_after;
    res->statics.push_back(sd_j);
  }
  res->accel_norm_rms_before = std::sqrt(ss_before / n);
  res->accel_norm_rms_after = std::sqrt(ss_after / n);

  // Diagnostics: rotations and excitation.
  Vector3d per_axis = Vector3d::Zero();
  double rb = 0, ra = 0;
  int used = 0;
  for (ImuRotationDiagnostics& rd : res->rotations) {
    if (StopRequested(o.stop)) return Stopped(o, "diagnostics", res);
    const StaticInterval& a = det.intervals[static_cast<size_t>(rd.from)];
    const StaticInterval& b = det.intervals[static_cast<size_t>(rd.to)];
    const Matrix3d r_after = Integrate(t, yg, x.mg, x.bg, a.last, b.first, nullptr);
    const Matrix3d r_before = Integrate(t, yg, mg0, bg0, a.last, b.first, nullptr);
    const Vector3d u0b = (ma0 * (a.mean[static_cast<size_t>(2 * k)] - ba0)).normalized();
    const Vector3d u1b = (ma0 * (b.mean[static_cast<size_t>(2 * k)] - ba0)).normalized();
    rd.angle = Eigen::AngleAxisd(r_after).angle();
    rd.direction_error_before = AngleBetween(r_before.transpose() * u0b, u1b);
    rd.direction_error_after = AngleBetween(r_after.transpose() * x.u[static_cast<size_t>(rd.from)],
                                            x.u[static_cast<size_t>(rd.to)]);
    if (!rd.used) continue;
    ++used;
    rb += rd.direction_error_before * rd.direction_error_before;
    ra += rd.direction_error_after * rd.direction_error_after;
    for (int64_t i = a.last; i < b.first; ++i) {
      const Vector3d w = x.mg * (0.5 * (yg.row(i) + yg.row(i + 1)).transpose() - x.bg);
      per_axis += w.cwiseAbs() * (t(i + 1) - t(i));
    }
  }
  res->gyro_direction_rms_before = used ? std::sqrt(rb / used) : 0;
  res->gyro_direction_rms_after = used ? std::sqrt(ra / used) : 0;
  Coverage(x.u, per_axis, &res->coverage);
  if (!res->coverage.sufficient) res->warnings.push_back("coverage: " + res->coverage.verdict);
  if (n < o.recommended_statics) {
    res->warnings.push_back(std::to_string(n) + " static intervals: at least " +
                            std::to_string(o.recommended_statics) + " are recommended");
  }
  if (res->chi2_per_dof > 4) {
    std::ostringstream w;
    w.precision(3);
    w << "residuals are " << std::sqrt(res->chi2_per_dof)
      << " times what the white noise of the statics explains (bias instability, motion "
         "during statics or a wrong model): the uncertainty is optimistic by that factor";
    res->warnings.push_back(w.str());
  }

  // Plausibility.
  for (int i = 0; i < 3; ++i) {
    const double ra_i = ac.scale(i) / o.accel_unit, rg_i = gc.scale(i) / o.gyro_unit;
    std::ostringstream m;
    m.precision(4);
    if (!(std::abs(ra_i - 1) <= o.max_scale_deviation)) {
      m << "accelerometer scale "
        << "xyz"[i] << " is " << ra_i
        << " times the nominal accel_unit: wrong accel_unit or gravity? (a gain known only "
           "roughly: raise max_scale_deviation, now "
        << o.max_scale_deviation << ")";
    } else if (!(std::abs(rg_i - 1) <= o.max_scale_deviation)) {
      m << "gyroscope scale "
        << "xyz"[i] << " is " << rg_i
        << " times the nominal gyro_unit: wrong gyro_unit (deg/s vs rad/s?) (a gain known "
           "only roughly: raise max_scale_deviation, now "
        << o.max_scale_deviation << ")";
    }
    if (!m.str().empty()) {
      return Fail(Status::NotDeterminable(Reason::kImplausibleEstimate, m.str()),
                  ImuTermination::kImplausible, res);
    }
  }
  if (!(res->gyro_direction_rms_after <= o.max_direction_error)) {
    std::ostringstream m;
    m.precision(3);
    m << "after calibration the gravity direction still misses by " << res->gyro_direction_rms_after
      << " rad RMS per rotation (limit " << o.max_direction_error
      << "): the gyroscope does not explain the rotations: wrong gyro_unit (deg/s vs rad/s?), "
         "saturation or a wrong time column";
    return Fail(Status::NotDeterminable(Reason::kImplausibleEstimate, m.str()),
                ImuTermination::kImplausible, res);
  }
  res->usable = true;
  res->reason.clear();
  res->termination = max_iter ? ImuTermination::kMaxIterations : ImuTermination::kConverged;
  if (max_iter) res->warnings.push_back("a Levenberg-Marquardt stage reached max_iterations");
  return Status::Ok();
}

}  // namespace

double Wgs84NormalGravity(double latitude_deg, double height_m) {
  // Somigliana: γ = γ_e (1 + k sin²φ) / sqrt(1 − e² sin²φ); free air to second order (WGS-84).
  const double a = 6378137.0, f = 1 / 298.257223563, gm = 3.986004418e14, omega = 7292115e-11;
  const double ge = 9.7803253359, k = 0.00193185265241, e2 = 6.69437999013e-3;
  const double phi = latitude_deg * 3.14159265358979323846 / 180;
  const double s2 = std::sin(phi) * std::sin(phi);
  const double g0 = ge * (1 + k * s2) / std::sqrt(1 - e2 * s2);
  const double m = omega * omega * a * a * (a * (1 - f)) / gm;
  return g0 * (1 - 2 / a * (1 + f + m - 2 * f * s2) * height_m + 3 / (a * a) * height_m * height_m);
}

const char* GyroBiasModelName(GyroBiasModel model) {
  return model == GyroBiasModel::kStatics ? "statics" : "estimate";
}

const char* ImuTerminationName(ImuTermination t) {
  switch (t) {
    case ImuTermination::kNotRun:
      return "not_run";
    case ImuTermination::kConverged:
      return "converged";
    case ImuTermination::kMaxIterations:
      return "max_iterations";
    case ImuTermination::kInvalidInput:
      return "invalid_input";
    case ImuTermination::kTooFewStatics:
      return "too_few_statics";
    case ImuTermination::kTooFewRotations:
      return "too_few_rotations";
    case ImuTermination::kDegenerate:
      return "degenerate";
    case ImuTermination::kImplausible:
      return "implausible";
    case ImuTermination::kStopped:
      return "stopped";
  }
  return "unknown";
}

std::string ImuResult::BriefReport() const {
  int used = 0;
  for (const ImuRotationDiagnostics& r : rotations) used += r.used ? 1 : 0;
  char buf[640];
  std::snprintf(buf, sizeof buf,
                "imu %s: %s%s; termination %s, %zu statics, %d of %zu rotations used, iterations "
                "%d/%d/%d (accel/gyro/joint), chi2/dof %.4g, |a|-g rms %.3g -> %.3g m/s^2, gyro "
                "direction rms %.3g -> %.3g rad",
                name.c_str(), usable ? "usable" : "not usable: ", usable ? "" : reason.c_str(),
                ImuTerminationName(termination), statics.size(), used, rotations.size(),
                accel_iterations, gyro_iterations, joint_iterations, chi2_per_dof,
                accel_norm_rms_before, accel_norm_rms_after, gyro_direction_rms_before,
                gyro_direction_rms_after);
  return buf;
}

bool ImuOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  auto pos = [](double v) { return std::isfinite(v) && v > 0; };
  if (!pos(accel_unit)) return fail("accel_unit must be a finite number > 0");
  if (!pos(gyro_unit)) return fail("gyro_unit must be a finite number > 0");
  if (!pos(gravity)) return fail("gravity must be a finite number > 0 (m/s^2)");
  if (!std::isfinite(nominal_accel_bias) || !std::isfinite(nominal_gyro_bias)) {
    return fail("nominal biases must be finite");
  }
  std::string e;
  if (!detection.IsValid(&e)) return fail(e);
  for (double m : threshold_multipliers) {
    if (!pos(m)) return fail("threshold_multipliers must be finite numbers > 0");
  }
  if (min_statics < 9) return fail("min_statics must be >= 9 (the accelerometer has 9 unknowns)");
  if (recommended_statics < min_statics) return fail("recommended_statics must be >= min_statics");
  if (accel_noise && !pos(*accel_noise)) return fail("accel_noise must be a finite number > 0");
  if (gyro_noise && !pos(*gyro_noise)) return fail("gyro_noise must be a finite number > 0");
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (max_statics < min_statics) return fail("max_statics must be >= min_statics");
  if (!pos(max_scale_deviation)) return fail("max_scale_deviation must be > 0");
  if (!pos(max_direction_error)) return fail("max_direction_error must be > 0 (rad)");
  if (!(accel_saturation_low < accel_saturation_high) ||
      !(gyro_saturation_low < gyro_saturation_high)) {
    return fail("saturation_low must be below saturation_high");
  }
  return true;
}

Eigen::Matrix3d IntegrateRotation(const Eigen::VectorXd& t, const Eigen::MatrixX3d& gyro,
                                  const Eigen::Matrix3d& matrix, const Eigen::Vector3d& bias,
                                  int64_t first, int64_t last) {
  return Integrate(t, gyro, matrix, bias, first, last, nullptr);
}

Status CalibrateImus(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                     const ImuOptions& options, std::vector<ImuResult>* results) {
  results->assign(imus.size(), ImuResult());
  for (size_t k = 0; k < imus.size(); ++k) {
    (*results)[k].name = imus[k].name;
    (*results)[k].gravity = options.gravity;
    (*results)[k].gyro_bias_model = options.gyro_bias;
  }
  auto fail_all = [&](Status s, ImuTermination term) {
    for (ImuResult& r : *results) Fail(s, term, &r);
    return s;
  };
  std::string error;
  if (!options.IsValid(&error)) {
    return fail_all(Status::InvalidInput(Reason::kInvalidConfig, "imu options: " + error),
                    ImuTermination::kInvalidInput);
  }
  if (imus.empty()) {
    return fail_all(Status::InvalidInput(Reason::kInvalidRecording, "the log has no IMU"),
                    ImuTermination::kInvalidInput);
  }
  std::vector<TriadSeries> triads;
  for (const ImuReadings& imu : imus) {
    if (imu.accel == nullptr || imu.gyro == nullptr) {
      return fail_all(Status::InvalidInput(Reason::kInvalidRecording,
                                           "IMU " + imu.name + " lacks accelerometer or gyroscope"),
                      ImuTermination::kInvalidInput);
    }
    TriadSeries a{"a" + imu.name,     TriadKind::kAccelerometer,    imu.accel,
                  options.accel_unit, options.accel_saturation_low, options.accel_saturation_high};
    TriadSeries g{"g" + imu.name,    TriadKind::kGyroscope,       imu.gyro,
                  options.gyro_unit, options.gyro_saturation_low, options.gyro_saturation_high};
    triads.push_back(a);
    triads.push_back(g);
  }
  auto stopped_all = [&](const std::string& stage) {
    return fail_all(StoppedStatus(*options.stop, "imu: " + stage), ImuTermination::kStopped);
  };
  if (StopRequested(options.stop)) return stopped_all("static detection");
  StaticDetector detector;
  Status s = detector.Init(t, triads, options.detection);
  if (s.code() == StatusCode::kStopped) return fail_all(s, ImuTermination::kStopped);
  if (!s.ok()) return fail_all(s, ImuTermination::kInvalidInput);
  if (StopRequested(options.stop)) return stopped_all("static detection");

  // Candidate thresholds.
  std::vector<double> mults = options.threshold_multipliers;
  const bool overridden = options.detection.accel_threshold && options.detection.gyro_threshold;
  if (mults.empty() || overridden) mults = {options.detection.threshold_multiplier};
  struct Candidate {
    StaticDetection det;
    int64_t found = 0;  // statics the detection found (det keeps at most max_statics)
    std::vector<AccelFit> fits;
    double criterion = kNaN;
  };
  std::vector<Candidate> cands;
  int best = -1, most = -1;
  int64_t capped_from = 0;  // statics found by the chosen detection when over max_statics
  for (double m : mults) {
    if (StopRequested(options.stop)) return stopped_all("threshold choice");
    Candidate c;
    c.det = detector.Detect(m);
    c.found = static_cast<int64_t>(c.det.intervals.size());
    KeepLongestStatics(options.max_statics, &c.det);
    if (StopRequested(options.stop)) return stopped_all("threshold choice");
    const int n = static_cast<int>(c.det.intervals.size());
    if (most < 0 || n > static_cast<int>(cands[static_cast<size_t>(most)].det.intervals.size())) {
      most = static_cast<int>(cands.size());
    }
    if (n >= options.min_statics) {
      double chi2 = 0;
      int dof = 0;
      bool ok = true;
      for (size_t k = 0; k < imus.size(); ++k) {
        c.fits.push_back(FitAccelerometer(c.det, static_cast<int>(k), options));
        if (c.fits.back().stopped) return stopped_all("accelerometer fit");
        ok = ok && c.fits.back().ok;
        chi2 += c.fits.back().chi2;
        dof += c.fits.back().dof;
      }
      if (ok) c.criterion = dof > 0 ? chi2 / dof : 0;
    }
    cands.push_back(std::move(c));
  }
  for (size_t i = 0; i < cands.size(); ++i) {
    if (std::isnan(cands[i].criterion)) continue;
    if (best < 0 || cands[i].criterion < cands[static_cast<size_t>(best)].criterion) {
      best = static_cast<int>(i);
    }
  }
  const int chosen = best >= 0 ? best : most;
  const Candidate& picked = cands[static_cast<size_t>(chosen)];
  if (picked.found > static_cast<int64_t>(picked.det.intervals.size())) capped_from = picked.found;
  for (size_t k = 0; k < imus.size(); ++k) {
    ImuResult& r = (*results)[k];
    r.detection = picked.det;
    if (capped_from > 0) {
      r.warnings.push_back(
          "static detection found " + std::to_string(capped_from) +
          " static intervals, more than max_statics (" + std::to_string(options.max_statics) +
          "): the fits use the " + std::to_string(options.max_statics) +
          " longest (so many usually means a time column not in seconds, or a static_window "
          "far shorter than the holds)");
    }
    if (!overridden && mults.size() > 1) {
      for (size_t i = 0; i < cands.size(); ++i) {
        ImuThresholdTrial tr;
        tr.multiplier = mults[i];
        tr.statics = static_cast<int>(cands[i].det.intervals.size());
        if (!cands[i].fits.empty() && cands[i].fits[k].ok && cands[i].fits[k].dof > 0) {
          tr.accel_chi2_per_dof = cands[i].fits[k].chi2 / cands[i].fits[k].dof;
        }
        tr.chosen = static_cast<int>(i) == chosen;
        r.threshold_trials.push_back(tr);
      }
      std::ostringstream w;
      w << "threshold multiplier " << mults[static_cast<size_t>(chosen)]
        << " × noise floor, chosen among " << mults.size()
        << " candidates as the one whose accelerometer fit has the smallest chi²/dof";
      r.threshold_choice = w.str();
    } else {
      r.threshold_choice = overridden ? "static_threshold given" : "single multiplier given";
    }
  }
  if (best < 0) {
    const StaticDetection& d = cands[static_cast<size_t>(chosen)].det;
    const int n = static_cast<int>(d.intervals.size());
    // Which orientations are there (nominal conversion, first IMU) and which are missing.
    std::vector<Vector3d> u;
    for (const StaticInterval& iv : d.intervals) {
      const Vector3d v = iv.mean[0] - Vector3d::Constant(options.nominal_accel_bias);
      if (v.norm() > 0) u.push_back(v.normalized());
    }
    ImuCoverage cov;
    Coverage(u, Vector3d::Ones(), &cov);
    std::ostringstream m;
    m << "found " << n << " static intervals, at least " << options.min_statics << " are needed ("
      << options.recommended_statics << " or more recommended)";
    if (n >= options.min_statics) m << ", but they do not determine the accelerometer";
    m << ": "
      << (cov.missing_up.empty()
              ? "hold the board still for a few seconds in more orientations spread over the "
                "sphere"
              : cov.verdict);
    if (n < options.min_statics) m << "; " << StaticShortfall(d);  // what was found, what to change
    const std::string msg = m.str();
    // Enough statics that do not determine the ellipsoid: their orientations are the problem.
    const Reason why =
        n >= options.min_statics ? Reason::kPoorOrientationCoverage : Reason::kTooFewStatics;
    for (ImuResult& r : *results) {
      Fail(Status::NotDeterminable(why, msg), ImuTermination::kTooFewStatics, &r);
      r.coverage = cov;
    }
    return Status::NotDeterminable(why, msg);
  }
  Status first_failure;
  for (size_t k = 0; k < imus.size(); ++k) {
    Status st = Finish(t, imus[k], static_cast<int>(k), options,
                       cands[static_cast<size_t>(best)].fits[k], &(*results)[k]);
    if (st.code() == StatusCode::kStopped) {
      // Every IMU not finished is stopped too; the status says where the first one was.
      for (size_t i = k + 1; i < imus.size(); ++i) {
        Fail(st, ImuTermination::kStopped, &(*results)[i]);
      }
      return st;
    }
    if (!st.ok() && first_failure.ok()) {
      first_failure =
          Status(st.code(), "IMU " + imus[k].name + ": " + st.message()).WithReason(st.reason());
    }
  }
  return first_failure;
}

Status CalibrateImu(const Eigen::VectorXd& t, const Eigen::MatrixX3d& accel,
                    const Eigen::MatrixX3d& gyro, const ImuOptions& options, ImuResult* result) {
  std::vector<ImuResult> results;
  Status s = CalibrateImus(t, {ImuReadings{"0", &accel, &gyro}}, options, &results);
  *result = std::move(results[0]);
  return s;
}

}  // namespace calibd::core
