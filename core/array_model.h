// The model of CalibrateArray (core/array.h): the usable samples, the per-sample motion estimator,
// the motion pass of the block coordinate descent and the joint ML problem for core/block_lm.h.
// Internal to core/array.cc and core/array_model.cc. Thread-compatible: the const methods of
// MotionModel and PositionsProblem are called from several chunks at once.
#ifndef CALIBD_CORE_ARRAY_MODEL_H_
#define CALIBD_CORE_ARRAY_MODEL_H_

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cstdint>
#include <vector>

#include "core/block_lm.h"
#include "core/stop_token.h"

namespace calibd::core::array_model {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec9 = Eigen::Matrix<double, 9, 1>;
using Mat9 = Eigen::Matrix<double, 9, 9>;
using Mat4 = Eigen::Matrix4d;
using Mat12x9 = Eigen::Matrix<double, 12, 9>;
using ConstMap3X = Eigen::Map<const Eigen::Matrix3Xd>;

// [v]x: Skew(v) u = v x u. (Also the full model's, core/array_full_model.h.)
inline Mat3 Skew(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// A_n = Omega_omega^2 + Omega_omega_dot (the paper's Eq. 8): u = A r + s.
inline Mat3 MatrixA(const Vec3& omega, const Vec3& omega_dot) {
  return omega * omega.transpose() - omega.squaredNorm() * Mat3::Identity() + Skew(omega_dot);
}

// F_i(omega) = d/d omega [omega x (omega x e_i)], so that the Jacobian of the centripetal term
// of a triad at r is sum_i r_i F_i(omega).
inline void CentripetalJacobians(const Vec3& omega, Mat3 F[3]) {
  for (int i = 0; i < 3; ++i) {
    F[i] = omega(i) * Mat3::Identity();
    F[i].col(i) += omega;
    F[i].row(i) -= 2 * omega.transpose();
  }
}

// ----- The usable samples, laid out per sample.
struct Data {
  int K = 0;
  int G = 0;
  int64_t N = 0;
  Eigen::MatrixXd ya;        // 3K x N: sample n's accelerometer readings are column n
  Eigen::Matrix3Xd gbar;     // 3 x N: mean of the gyroscope triads
  Eigen::VectorXd gscatter;  // N: sum_j |y_g^(j) - gbar|^2
};

// ----- Per-sample ML motion given the positions (the estimator of Skog et al., ref. [4]):
// omega_dot and s enter linearly; with centred positions r~_k = r_k - r_bar and s' = s +
// omega_dot x r_bar they decouple: s' = mean_k z_k, omega_dot = M^-1 sum_k r~_k x z_k, with
// z_k = y_k - omega x (omega x r_k) and M = sum_k [r~_k]x^T [r~_k]x. Gauss-Newton on omega on the
// projected (concentrated) cost. Everything that depends only on the geometry is computed once.
struct MotionModel {
  int K = 0;
  Eigen::Matrix3Xd r;        // positions
  Eigen::Matrix3Xd r_tilde;  // centred
  Vec3 r_bar = Vec3::Zero();
  Mat3 M_inv = Mat3::Zero();
  Mat3 R2 = Mat3::Zero();  // sum_k r_k r_k^T
  Mat3 Q[3];               // Q_i = sum_k r_ki [r~_k]x
  bool ok = false;

  // The geometry of the positions (3 x K); ok false when they cannot carry the estimator
  // (collinear).
  explicit MotionModel(const Eigen::Matrix3Xd& positions);

  // Solves for (omega, omega_dot, s) of one sample; *omega is the starting point. z: 3K
  // workspace. Returns the sample's cost (weighted, including the gyro scatter).
  double Solve(const double* y, const Vec3& gbar, double gscatter, int G, double wa, double wg,
               int max_iterations, Eigen::Matrix3Xd* z, Vec3* omega, Vec3* omega_dot,
               Vec3* s) const;
};

// Per-chunk sums of one motion pass.
struct MotionSums {
  double cost = 0;
  Mat3 AtA = Mat3::Zero();
  Eigen::Matrix3Xd AtY;  // column k: sum_n A_n^T (y_k - s_n)
};

struct Weights {
  double wa = 0;  // 1 / sigma_a^2
  double wg = 0;  // 1 / sigma_g^2
};

using MotionStates = Eigen::Matrix<double, 9, Eigen::Dynamic>;  // column n: (omega, omega_dot, s)

// Motion step for every sample (x: 9 x N in/out, omega rows used as starting point), plus the
// sums needed by the closed-form position update of Eq. (9). Returns false if the geometry
// cannot carry the motion estimator (collinear).
// Polls `stop` every 16 samples: when it asks, the sums are partial (the caller checks it).
bool MotionPass(const Data& d, const Eigen::Matrix3Xd& r, const Weights& wt,
                const ChunkRunner& runner, int max_gn, MotionStates* x, MotionSums* total,
                const StopToken* stop);

// ----- The joint ML problem for the block solver (core/block_lm.h): one 9-dimensional block
// x_n = (omega, omega_dot, s) per sample, shared parameters the positions of the free triads.
//
// Per sample the Jacobian of triad k's prediction s + A r_k with respect to x_n is
// J_k = sum_a c_ka E_a with c_k = (1, r_k) and E_0 = [0 0 I], E_i = [F_i -[e_i]x 0]. Hence
//   H_xx = sum_k J_k^T J_k / sa^2 + G/sg^2 (omega block) = E^T (R (x) I3) E / sa^2 + ...,
//   R = sum_k c_k c_k^T (4x4, constant over samples),
//   H_x r_k = sum_a c_ka P_a / sa^2 with P_a = E_a^T A_n,
// i.e. H_x,r = (1/sa^2) P_n Mf in the block solver's compressed form: C_n = P_n (9 x 12), lift
// Mf (12 x 3(K-1), block (a, j) = c_{a,k_j} I3), weight 1/sa^2. The reduced matrix then needs
// one 12x12 sum per sample, whatever K. H_rr is block diagonal, sum_n A_n^T A_n / sa^2 for
// every free triad.
class PositionsProblem {
 public:
  static constexpr int kBlockDim = 9;
  static constexpr int kBlockStateDim = 9;
  static constexpr int kCouplingDim = 12;
  using SharedState = Eigen::Matrix3Xd;  // 3 x K, all positions (the reference stays fixed)
  using Normal = BlockNormal<9, 12>;
  struct Context {
    Eigen::Matrix3Xd r;                          // positions
    Eigen::Matrix<double, 4, Eigen::Dynamic> c;  // 4 x K: (1, r_k)
    Mat4 Lt = Mat4::Zero();                      // R = Lt^T Lt
  };
  struct Sums {
    Mat3 AtA = Mat3::Zero();
    Eigen::Matrix3Xd br;          // 3 x K: sum_n A_n^T e_n,k
    double ssr_a = 0, ssr_g = 0;  // unweighted residual sums of squares
    double lev_g = 0;             // gyro leverage sum_n tr(H^-1 of omega) G / sg^2 (Factored)
  };

  PositionsProblem(const Data& d, const Weights& wt, const std::vector<int>& free)
      : d_(d), wt_(wt), wgG_(wt.wg * d.G), free_(free) {}

  int64_t NumBlocks() const { return d_.N; }
  int SharedDim() const { return 3 * static_cast<int>(free_.size()); }
  int CouplingDim() const { return 12; }

  Context MakeContext(const Eigen::Matrix3Xd& r) const {
    Context g;
    const int K = r.cols();
    g.r = r;
    g.c.resize(4, K);
    g.c.row(0).setOnes();
    g.c.bottomRows(3) = r;
    const Mat4 R = g.c * g.c.transpose();
    Eigen::SelfAdjointEigenSolver<Mat4> es(R);
    const Eigen::Vector4d sq = es.eigenvalues().cwiseMax(0).cwiseSqrt();
    g.Lt = sq.asDiagonal() * es.eigenvectors().transpose();  // Lt^T Lt = V L V^T = R
    return g;
  }

  Sums MakeSums() const {
    Sums s;
    s.br = Eigen::Matrix3Xd::Zero(3, d_.K);
    return s;
  }

  void Merge(const Sums& from, Sums* into) const {
    into->AtA += from.AtA;
    into->br += from.br;
    into->ssr_a += from.ssr_a;
    into->ssr_g += from.ssr_g;
    into->lev_g += from.lev_g;
  }

  void Linearize(int64_t n, const Vec9& x, const Context& ctx, Normal* out, Sums* sums) const {
    Mat3 A, F[3];
    Blocks(x, ctx, &A, F, out);
    const Vec3 w = x.head<3>(), s = x.tail<3>();
    const ConstMap3X Y(d_.ya.col(n).data(), 3, d_.K);
    // Residuals e_k = y_k - s - A r_k; f = sum_k e_k c_k^T; br_k += A^T e_k.
    double ssr_a = 0;
    Eigen::Matrix<double, 3, 4> f = Eigen::Matrix<double, 3, 4>::Zero();
    const Mat3 At = A.transpose();
    for (int k = 0; k < d_.K; ++k) {
      const Vec3 rk = ctx.r.col(k);
      const Vec3 ek = Y.col(k) - s - A.lazyProduct(rk);
      ssr_a += ek.squaredNorm();
      f.col(0) += ek;
      f.col(1) += rk(0) * ek;
      f.col(2) += rk(1) * ek;
      f.col(3) += rk(2) * ek;
      sums->br.col(k).noalias() += At.lazyProduct(ek);
    }
    const Vec3 eg = d_.gbar.col(n) - w;
    const double ssr_g = d_.G * eg.squaredNorm() + d_.gscatter(n);
    out->cost = wt_.wa * ssr_a + wt_.wg * ssr_g;
    Vec9& g = out->g;
    g.head<3>() =
        F[0].transpose() * f.col(1) + F[1].transpose() * f.col(2) + F[2].transpose() * f.col(3);
    g.segment<3>(3) = Vec3::UnitX().cross(f.col(1)) + Vec3::UnitY().cross(f.col(2)) +
                      Vec3::UnitZ().cross(f.col(3));
    g.tail<3>() = f.col(0);
    g *= wt_.wa;
    g.head<3>() += wgG_ * eg;
    sums->AtA.noalias() += At.lazyProduct(A);
    sums->ssr_a += ssr_a;
    sums->ssr_g += ssr_g;
  }

  void BlockMatrices(int64_t, const Vec9& x, const Context& ctx, Normal* out) const {
    Mat3 A, F[3];
    Blocks(x, ctx, &A, F, out);
  }

  double Cost(int64_t n, const Vec9& x, const Context& ctx) const {
    const Vec3 w = x.head<3>(), s = x.tail<3>();
    const Mat3 A = MatrixA(w, x.segment<3>(3));
    const ConstMap3X Y(d_.ya.col(n).data(), 3, d_.K);
    double ssr_a = 0;
    for (int k = 0; k < d_.K; ++k) {
      const Vec3 rk = ctx.r.col(k);
      ssr_a += (Y.col(k) - s - A.lazyProduct(rk)).squaredNorm();
    }
    return wt_.wa * ssr_a + wt_.wg * (d_.G * (d_.gbar.col(n) - w).squaredNorm() + d_.gscatter(n));
  }

  // tr([H^-1]_omega,omega) = squared norm of the first 3 columns of L^-1.
  void Factored(int64_t, const Mat9& L_inverse, Sums* sums) const {
    sums->lev_g += wgG_ * L_inverse.leftCols<3>().squaredNorm();
  }

  void AssembleShared(const Sums& sums, const Context& ctx, SharedNormal* out) const {
    const int m = static_cast<int>(free_.size());
    out->lift = Eigen::MatrixXd::Zero(12, 3 * m);
    for (int j = 0; j < m; ++j)
      for (int a = 0; a < 4; ++a)
        out->lift.block<3, 3>(3 * a, 3 * j) = ctx.c(a, free_[j]) * Mat3::Identity();
    out->coupling_weight = wt_.wa;
    const Mat3 Hrr = wt_.wa * sums.AtA;
    out->H = Eigen::MatrixXd::Zero(3 * m, 3 * m);
    out->g.resize(3 * m);
    for (int j = 0; j < m; ++j) {
      out->H.block<3, 3>(3 * j, 3 * j) = Hrr;
      out->g.segment<3>(3 * j) = wt_.wa * sums.br.col(free_[j]);
    }
  }

  Vec9 PlusBlock(const Vec9& x, const Vec9& dx) const { return x + dx; }

  Eigen::Matrix3Xd PlusShared(const Eigen::Matrix3Xd& r, const Eigen::VectorXd& dr) const {
    Eigen::Matrix3Xd out = r;
    for (size_t j = 0; j < free_.size(); ++j) out.col(free_[j]) += dr.segment<3>(3 * j);
    return out;
  }

  double SharedMaxNorm(const Eigen::Matrix3Xd& r) const { return r.cwiseAbs().maxCoeff(); }

 private:
  // A_n, the F_i, H_xx (undamped) and P_n (into out->C) at x.
  void Blocks(const Vec9& x, const Context& ctx, Mat3* A, Mat3 F[3], Normal* out) const {
    const Vec3 w = x.head<3>(), wd = x.segment<3>(3);
    *A = MatrixA(w, wd);
    CentripetalJacobians(w, F);
    Mat12x9 E = Mat12x9::Zero();
    E.block<3, 3>(0, 6).setIdentity();
    for (int i = 0; i < 3; ++i) {
      E.block<3, 3>(3 + 3 * i, 0) = F[i];
      E.block<3, 3>(3 + 3 * i, 3) = -Skew(Vec3::Unit(i));
    }
    const Mat4& Lt = ctx.Lt;
    Mat12x9 Et;
    for (int a = 0; a < 4; ++a) {
      Et.block<3, 9>(3 * a, 0) = Lt(a, 0) * E.block<3, 9>(0, 0);
      for (int bb = 1; bb < 4; ++bb)
        Et.block<3, 9>(3 * a, 0) += Lt(a, bb) * E.block<3, 9>(3 * bb, 0);
    }
    out->H.noalias() = wt_.wa * Et.transpose().lazyProduct(Et);
    out->H.topLeftCorner<3, 3>().diagonal().array() += wgG_;
    for (int a = 0; a < 4; ++a)
      out->C.block<9, 3>(0, 3 * a).noalias() = E.block<3, 9>(3 * a, 0).transpose().lazyProduct(*A);
  }

  const Data& d_;
  Weights wt_;
  double wgG_;
  std::vector<int> free_;
};

}  // namespace calibd::core::array_model

#endif  // CALIBD_CORE_ARRAY_MODEL_H_
