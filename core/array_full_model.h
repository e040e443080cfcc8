// The maximum-likelihood model of the full array calibration (core/array_full.h): parameter
// layout, the ML problem for core/block_lm.h and the gauge. Internal to core/array_full*.cc.
#ifndef CALIBD_CORE_ARRAY_FULL_MODEL_H_
#define CALIBD_CORE_ARRAY_FULL_MODEL_H_

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/array_full.h"
#include "core/array_model.h"
#include "core/block_lm.h"

namespace calibd::core::array_full_model {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec27 = Eigen::Matrix<double, 27, 1>;
using Mat27 = Eigen::Matrix<double, 27, 27>;
using Vec9 = Eigen::Matrix<double, 9, 1>;
using Vec10 = Eigen::Matrix<double, 10, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;

constexpr int kP = kArrayFullTriadParameters;
// Offsets in a triad's 27 parameters.
constexpr int kTa = 0, kBa = 9, kTg = 12, kBg = 21, kR = 24;

// [v]x and A = Omega_omega^2 + Omega_omega_dot (u = A r + s), as the rigid-body model's.
using array_model::MatrixA;
using array_model::Skew;

// d/d omega [omega x (omega x r)] = (omega . r) I + omega r^T - 2 r omega^T.
inline Mat3 CentripetalJacobian(const Vec3& w, const Vec3& r) {
  return w.dot(r) * Mat3::Identity() + w * r.transpose() - 2 * r * w.transpose();
}

// Orthonormal basis of the tangent plane of the sphere at s (a deterministic function of s).
inline Eigen::Matrix<double, 3, 2> SphereBasis(const Vec3& s) {
  int i = 0;
  s.cwiseAbs().minCoeff(&i);
  const Vec3 e = Vec3::Unit(i);
  const Vec3 b1 = e.cross(s).normalized();
  const Vec3 b2 = s.normalized().cross(b1);
  Eigen::Matrix<double, 3, 2> B;
  B << b1, b2;
  return B;
}

struct TriadParams {
  Mat3 Ta, Tg;
  Vec3 ba, bg, r;
};

inline std::vector<TriadParams> Unpack(const Eigen::VectorXd& theta, int K) {
  std::vector<TriadParams> c(K);
  for (int k = 0; k < K; ++k) {
    const double* p = theta.data() + kP * k;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        c[k].Ta(i, j) = p[kTa + 3 * i + j];
        c[k].Tg(i, j) = p[kTg + 3 * i + j];
      }
    c[k].ba = Vec3(p[kBa], p[kBa + 1], p[kBa + 2]);
    c[k].bg = Vec3(p[kBg], p[kBg + 1], p[kBg + 2]);
    c[k].r = Vec3(p[kR], p[kR + 1], p[kR + 2]);
  }
  return c;
}

// The data of the fit: static means and dynamic samples, column-wise.
struct FullData {
  int K = 0;
  int64_t J = 0;                       // statics
  int64_t Nd = 0;                      // dynamic samples
  Eigen::MatrixXd static_a, static_g;  // 3K x J means
  Eigen::VectorXd static_n;            // J sample counts
  Eigen::MatrixXd ya, yg;              // 3K x Nd
  std::vector<int64_t> dyn_index;      // Nd: sample index in the log
  double wa = 0, wg = 0;               // 1 / sigma (statics)
  double wa_d = 0, wg_d = 0;           // 1 / sigma (dynamic samples)
  double gravity = 9.80665;
};

// The ML problem for core/block_lm.h: blocks 0..J-1 are the statics, J.. the dynamic samples.
class FullProblem {
 public:
  static constexpr int kBlockDim = 9;
  static constexpr int kBlockStateDim = 10;  // (omega, omega_dot, s, 0) or (s, 0..., 1)
  static constexpr int kCouplingDim = Eigen::Dynamic;
  using SharedState = Eigen::VectorXd;
  using Context = std::vector<TriadParams>;
  using Normal = BlockNormal<9, Eigen::Dynamic>;
  struct Sums {
    std::vector<Mat27> H;
    Eigen::VectorXd g;
  };

  // The Schur term of a dynamic sample is built from its Kronecker structure (AddCouplingGram).
  static constexpr bool kStructuredCouplingGram = true;

  // structured_gram = false: every block's Schur term by block_lm's dense rank-k update (the
  // reference the structured one is tested against; same results up to rounding).
  FullProblem(const FullData& d, const Eigen::MatrixXd& E, bool structured_gram = true)
      : d_(d), E_(E), structured_gram_(structured_gram) {}

  int64_t NumBlocks() const { return d_.J + d_.Nd; }
  int SharedDim() const { return static_cast<int>(E_.cols()); }
  int CouplingDim() const { return kP * d_.K; }
  Context MakeContext(const SharedState& p) const { return Unpack(p, d_.K); }
  Sums MakeSums() const {
    return Sums{std::vector<Mat27>(d_.K, Mat27::Zero()), Eigen::VectorXd::Zero(kP * d_.K)};
  }
  void Merge(const Sums& from, Sums* into) const {
    for (int k = 0; k < d_.K; ++k) into->H[k] += from.H[k];
    into->g += from.g;
  }

  template <class X>
  void Linearize(int64_t n, const X& x, const Context& c, Normal* out, Sums* sums) const {
    Evaluate(n, Vec10(x), c, out, true, &sums->H, &sums->g);
  }
  template <class X>
  void BlockMatrices(int64_t n, const X& x, const Context& c, Normal* out) const {
    Evaluate(n, Vec10(x), c, out, true, nullptr, nullptr);
  }
  template <class X>
  double Cost(int64_t n, const X& x, const Context& c) const {
    Normal b;
    Evaluate(n, Vec10(x), c, &b, false, nullptr, nullptr);
    return b.cost;
  }
  template <class M>
  void Factored(int64_t, const M&, Sums*) const {}
  void AssembleShared(const Sums& sums, const Context&, SharedNormal* out) const {
    const int q = CouplingDim();
    Eigen::MatrixXd HE(q, E_.cols());
    for (int k = 0; k < d_.K; ++k)
      HE.middleRows(kP * k, kP).noalias() = sums.H[k] * E_.middleRows(kP * k, kP);
    out->H.noalias() = E_.transpose() * HE;
    out->g.noalias() = E_.transpose() * sums.g;
    out->lift = E_;
    out->coupling_weight = 1;
  }
  template <class X, class D>
  Vec10 PlusBlock(const X& x_in, const D& dx) const {
    Vec10 x = x_in;
    if (x(9) > 0.5) {
      const Vec3 s = x.head<3>();
      const Vec3 moved = s + SphereBasis(s) * dx.template head<2>();
      x.head<3>() = d_.gravity * moved.normalized();
    } else {
      x.head<9>() += dx;
    }
    return x;
  }
  SharedState PlusShared(const SharedState& p, const Eigen::VectorXd& dp) const {
    return p + E_ * dp;
  }
  double SharedMaxNorm(const SharedState& p) const { return p.cwiseAbs().maxCoeff(); }

  // C_n^T H^-1 C_n of dynamic sample n (H^-1 = Linv^T Linv) into the lower triangle of *T by
  // triad pairs k >= l: with F_k the 6 x 27 Jacobian of triad k's readings in its own
  // parameters and W_k = Linv J_x,k^T (9 x 6), the (k, l) block is F_k^T (W_k^T W_l) F_l, and
  // F_k is Kronecker-structured (d(T u)/d vec_row(T) = I3 (x) u^T), so the block costs about
  // 2 flops per entry instead of the dense 9 x 27 x 27. Statics (and structured_gram = false):
  // false, the dense path.
  template <class X, class M>
  bool AddCouplingGram(int64_t n, const X& x_in, const Context& c, const M& Linv,
                       Eigen::MatrixXd* T) const {
    if (!structured_gram_ || n < d_.J) return false;
    const int K = d_.K;
    const double wa = d_.wa_d, wg = d_.wg_d;
    const Vec10 x = x_in;
    const Vec3 w = x.head<3>(), wd = x.segment<3>(3), s = x.segment<3>(6);
    const Mat3 A = MatrixA(w, wd);
    // Per triad: whitened u (accel T_a column factor), wa T_a A (position), W_k (9 x 6).
    thread_local std::vector<Vec3> ua;
    thread_local std::vector<Mat3> PA;
    thread_local Eigen::Matrix<double, 9, Eigen::Dynamic> W;
    ua.resize(K);
    PA.resize(K);
    W.resize(9, 6 * K);
    const Vec3 wgw = wg * w;
    for (int k = 0; k < K; ++k) {
      const TriadParams& p = c[k];
      ua[k] = wa * (A * p.r + s);
      PA[k] = wa * p.Ta * A;
      Eigen::Matrix<double, 3, 9> dU;
      dU << CentripetalJacobian(w, p.r), -Skew(p.r), Mat3::Identity();
      const Eigen::Matrix<double, 3, 9> Jx = wa * p.Ta * dU;
      W.middleCols<3>(6 * k).noalias() = Linv.lazyProduct(Jx.transpose());
      W.middleCols<3>(6 * k + 3).noalias() =
          Linv.template leftCols<3>().lazyProduct(wg * p.Tg.transpose());
    }
    // Block (a, b), a >= b: Y = F_a^T (W_a^T W_b) (27 x 6), then column by column Y F_b.
    for (int b = 0; b < K; ++b) {
      for (int a = b; a < K; ++a) {
        const Eigen::Matrix<double, 6, 6> Mt =
            W.middleCols<6>(6 * b).transpose().lazyProduct(W.middleCols<6>(6 * a));
        Eigen::Matrix<double, 6, 27> Yt;  // Y^T = M^T F_a
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            Yt.col(kTa + 3 * i + j) = ua[a](j) * Mt.col(i);
            Yt.col(kTg + 3 * i + j) = wgw(j) * Mt.col(3 + i);
          }
        Yt.middleCols<3>(kBa) = wa * Mt.leftCols<3>();
        Yt.middleCols<3>(kBg) = wg * Mt.rightCols<3>();
        Yt.middleCols<3>(kR).noalias() = Mt.leftCols<3>().lazyProduct(PA[a]);
        const Eigen::Matrix<double, 27, 6> Y = Yt.transpose();
        auto Tab = T->block<27, 27>(kP * a, kP * b);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            Tab.col(kTa + 3 * i + j) += ua[b](j) * Y.col(i);
            Tab.col(kTg + 3 * i + j) += wgw(j) * Y.col(3 + i);
          }
        Tab.middleCols<3>(kBa) += wa * Y.leftCols<3>();
        Tab.middleCols<3>(kBg) += wg * Y.rightCols<3>();
        Tab.middleCols<3>(kR).noalias() += Y.leftCols<3>().lazyProduct(PA[b]);
      }
    }
    return true;
  }

  // Raw (unwhitened) residuals of block n: accel and gyro, 3K each, added squared per triad
  // into acc (K x 2).
  void AddSquaredResiduals(int64_t n, const Vec10& x, const Context& c,
                           Eigen::MatrixX2d* acc) const {
    for (int k = 0; k < d_.K; ++k) {
      Vec3 ea, eg;
      if (n < d_.J) {
        const double sq = std::sqrt(d_.static_n(n));
        ea = sq * (d_.static_a.col(n).segment<3>(3 * k) - c[k].Ta * x.head<3>() - c[k].ba);
        eg = sq * (d_.static_g.col(n).segment<3>(3 * k) - c[k].bg);
      } else {
        const int64_t m = n - d_.J;
        const Vec3 w = x.head<3>();
        const Vec3 u = MatrixA(w, x.segment<3>(3)) * c[k].r + x.segment<3>(6);
        ea = d_.ya.col(m).segment<3>(3 * k) - c[k].Ta * u - c[k].ba;
        eg = d_.yg.col(m).segment<3>(3 * k) - c[k].Tg * w - c[k].bg;
      }
      (*acc)(k, 0) += ea.squaredNorm();
      (*acc)(k, 1) += eg.squaredNorm();
    }
  }

 private:
  // Residuals r = whitened (y - prediction); J = d r / d(unknowns) = -w d prediction.
  // full: also H, g and C of the block. H_pp/g_p sums when H/g are given.
  void Evaluate(int64_t n, const Vec10& x, const Context& c, Normal* out, bool full,
                std::vector<Mat27>* H, Eigen::VectorXd* g) const {
    const int K = d_.K;
    out->cost = 0;
    if (full) {
      out->H.setZero();
      out->g.setZero();
      out->C.setZero(9, CouplingDim());
    }
    if (n < d_.J) {
      EvaluateStatic(n, x, c, out, full, H, g);
      return;
    }
    const int64_t m = n - d_.J;
    const double wa = d_.wa_d, wg = d_.wg_d;
    const Vec3 w = x.head<3>(), wd = x.segment<3>(3), s = x.segment<3>(6);
    const Mat3 A = MatrixA(w, wd);
    for (int k = 0; k < K; ++k) {
      const TriadParams& p = c[k];
      const int o = kP * k;
      const Vec3 u = A * p.r + s;
      const Vec3 ea = wa * (d_.ya.col(m).segment<3>(3 * k) - p.Ta * u - p.ba);
      const Vec3 eg = wg * (d_.yg.col(m).segment<3>(3 * k) - p.Tg * w - p.bg);
      out->cost += ea.squaredNorm() + eg.squaredNorm();
      if (!full && !g) continue;
      // Accelerometer: J_p over (T_a row-major, b_a, r). (Products of these small fixed-size
      // matrices are lazy: Eigen would send e.g. a 15x3 by 3x15 product to its GEMM kernel,
      // whose packing costs more than the product.)
      Eigen::Matrix<double, 3, 15> Jp = Eigen::Matrix<double, 3, 15>::Zero();
      for (int i = 0; i < 3; ++i) Jp.block<1, 3>(i, 3 * i) = -wa * u.transpose();
      Jp.block<3, 3>(0, 9) = -wa * Mat3::Identity();
      Jp.block<3, 3>(0, 12) = -wa * p.Ta * A;
      // Gyroscope: J_p over (T_g row-major, b_g).
      Eigen::Matrix<double, 3, 12> Jg = Eigen::Matrix<double, 3, 12>::Zero();
      for (int i = 0; i < 3; ++i) Jg.block<1, 3>(i, 3 * i) = -wg * w.transpose();
      Jg.block<3, 3>(0, 9) = -wg * Mat3::Identity();
      if (g) {
        const Eigen::Matrix<double, 15, 1> ga = -Jp.transpose().lazyProduct(ea);
        g->segment<12>(o) += ga.head<12>();
        g->segment<3>(o + kR) += ga.tail<3>();
        g->segment<12>(o + kTg) -= Jg.transpose().lazyProduct(eg);
      }
      if (!full) continue;
      Eigen::Matrix<double, 3, 9> dU;
      dU << CentripetalJacobian(w, p.r), -Skew(p.r), Mat3::Identity();
      const Eigen::Matrix<double, 3, 9> Jx = -wa * p.Ta * dU;
      const Mat3 Jxg = -wg * p.Tg;
      out->H.noalias() += Jx.transpose().lazyProduct(Jx);
      out->H.topLeftCorner<3, 3>().noalias() += Jxg.transpose().lazyProduct(Jxg);
      out->g.noalias() -= Jx.transpose() * ea;
      out->g.head<3>().noalias() -= Jxg.transpose() * eg;
      const Eigen::Matrix<double, 9, 15> CJ = Jx.transpose().lazyProduct(Jp);
      out->C.block(0, o, 9, 12) += CJ.leftCols<12>();
      out->C.block(0, o + kR, 9, 3) += CJ.rightCols<3>();
      out->C.block(0, o + kTg, 3, 12).noalias() += Jxg.transpose().lazyProduct(Jg);
      if (H) {
        Mat27& h = (*H)[k];
        const Eigen::Matrix<double, 15, 15> hp = Jp.transpose().lazyProduct(Jp);
        h.topLeftCorner<12, 12>() += hp.topLeftCorner<12, 12>();
        h.block<12, 3>(0, kR) += hp.topRightCorner<12, 3>();
        h.block<3, 12>(kR, 0) += hp.bottomLeftCorner<3, 12>();
        h.block<3, 3>(kR, kR) += hp.bottomRightCorner<3, 3>();
        h.block<12, 12>(kTg, kTg).noalias() += Jg.transpose().lazyProduct(Jg);
      }
    }
  }

  void EvaluateStatic(int64_t j, const Vec10& x, const Context& c, Normal* out, bool full,
                      std::vector<Mat27>* H, Eigen::VectorXd* g) const {
    const double sq = std::sqrt(d_.static_n(j));
    const double wa = d_.wa * sq, wg = d_.wg * sq;
    const Vec3 s = x.head<3>();
    const Eigen::Matrix<double, 3, 2> Bs = SphereBasis(s);
    Eigen::Matrix2d H2 = Eigen::Matrix2d::Zero();
    Eigen::Vector2d g2 = Eigen::Vector2d::Zero();
    for (int k = 0; k < d_.K; ++k) {
      const TriadParams& p = c[k];
      const int o = kP * k;
      const Vec3 ea = wa * (d_.static_a.col(j).segment<3>(3 * k) - p.Ta * s - p.ba);
      const Vec3 eg = wg * (d_.static_g.col(j).segment<3>(3 * k) - p.bg);
      out->cost += ea.squaredNorm() + eg.squaredNorm();
      if (!full && !g) continue;
      Eigen::Matrix<double, 3, 12> Jp = Eigen::Matrix<double, 3, 12>::Zero();
      for (int i = 0; i < 3; ++i) Jp.block<1, 3>(i, 3 * i) = -wa * s.transpose();
      Jp.block<3, 3>(0, 9) = -wa * Mat3::Identity();
      if (g) {
        g->segment<12>(o) -= Jp.transpose() * ea;
        g->segment<3>(o + kBg) += wg * eg;
      }
      if (!full) continue;
      const Eigen::Matrix<double, 3, 2> Jx = -wa * p.Ta * Bs;
      H2.noalias() += Jx.transpose() * Jx;
      g2.noalias() -= Jx.transpose() * ea;
      out->C.block(0, o, 2, 12).noalias() += Jx.transpose().lazyProduct(Jp);
      if (H) {
        Mat27& h = (*H)[k];
        h.topLeftCorner<12, 12>().noalias() += Jp.transpose().lazyProduct(Jp);
        h.block<3, 3>(kBg, kBg).diagonal().array() += wg * wg;
      }
    }
    if (full) {
      // The unused tangent coordinates 2..8: identity Hessian, zero gradient and coupling.
      out->H.setIdentity();
      out->H.topLeftCorner<2, 2>() = H2;
      out->g.head<2>() = g2;
    }
  }

  const FullData& d_;
  const Eigen::MatrixXd& E_;
  bool structured_gram_ = true;
};

// Orthonormal basis of the gauge-fixed subspace of theta (27K): all coordinates but the
// reference's T_a lower entries and position; the 3K T_g diagonals restricted to sum zero
// (Helmert contrasts).
inline Eigen::MatrixXd GaugeBasis(int K, int reference) {
  const int q = kP * K;
  std::vector<int> free;
  std::vector<int> diag;
  for (int k = 0; k < K; ++k)
    for (int l = 0; l < kP; ++l) {
      const int i = kP * k + l;
      if (k == reference && (l == kTa + 3 || l == kTa + 6 || l == kTa + 7 || l >= kR)) continue;
      if (l == kTg || l == kTg + 4 || l == kTg + 8) {
        diag.push_back(i);
        continue;
      }
      free.push_back(i);
    }
  const int m = static_cast<int>(diag.size());
  Eigen::MatrixXd E = Eigen::MatrixXd::Zero(q, static_cast<int>(free.size()) + m - 1);
  int col = 0;
  for (int i : free) E(i, col++) = 1;
  for (int a = 1; a < m; ++a, ++col) {
    const double norm = std::sqrt(static_cast<double>(a) * (a + 1));
    for (int b = 0; b < a; ++b) E(diag[b], col) = 1 / norm;
    E(diag[a], col) = -a / norm;
  }
  return E;
}

// Ellipsoid through the static means: M upper triangular, b with |M (y_j - b)| = g (the
// closed form of core/imu.cc, worked in scaled coordinates for conditioning).
inline bool EllipsoidFit(const Eigen::Matrix3Xd& y, double g, Mat3* m_out, Vec3* b_out) {
  const int n = static_cast<int>(y.cols());
  const Vec3 c = y.rowwise().mean();
  const double sc = 1 / g;
  Eigen::MatrixXd d(n, 10);
  for (int j = 0; j < n; ++j) {
    const Vec3 z = (y.col(j) - c) * sc;
    d.row(j) << z.x() * z.x(), z.y() * z.y(), z.z() * z.z(), 2 * z.x() * z.y(), 2 * z.x() * z.z(),
        2 * z.y() * z.z(), z.x(), z.y(), z.z(), 1;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(d, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  if (!(sv(8) > 1e-9 * sv(0))) return false;  // the statics do not determine a quadric
  const Eigen::VectorXd th = svd.matrixV().col(9);
  Mat3 q;
  q << th(0), th(3), th(4), th(3), th(1), th(5), th(4), th(5), th(2);
  const Vec3 l = th.segment<3>(6);
  Eigen::FullPivLU<Mat3> lu(q);
  if (!lu.isInvertible()) return false;
  const Vec3 z0 = -0.5 * lu.solve(l);
  const double k = z0.dot(q * z0) - th(9);
  if (!(std::abs(k) > 0)) return false;
  Eigen::LLT<Mat3> llt(q / k);
  if (llt.info() != Eigen::Success) return false;
  const Mat3 mz = llt.matrixL().transpose();
  *m_out = g * sc * mz;
  *b_out = c + z0 / sc;
  return m_out->allFinite() && b_out->allFinite();
}

}  // namespace calibd::core::array_full_model

#endif  // CALIBD_CORE_ARRAY_FULL_MODEL_H_
