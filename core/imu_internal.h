// The pieces of CalibrateImus (core/imu.h) shared between its files; internal to core/imu*.cc.
//   core/imu_solver.cc  the joint problem: its unknowns, the rotation integrals, the
//   block-structured
//                       Gauss-Newton matrix and the Levenberg-Marquardt minimiser
//   core/imu_accel.cc   the statics: the accelerometer fit (step 2), the coverage of orientations
//                       and the cap on statics
//   core/imu_stages.cc  steps 3-5 and the diagnostics of one IMU (core/imu_stages.h)
// Pure numerics, no shared state: thread-compatible.
#ifndef CALIBD_CORE_IMU_INTERNAL_H_
#define CALIBD_CORE_IMU_INTERNAL_H_

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/imu.h"
#include "core/static_detection.h"
#include "core/stop_token.h"

namespace calibd::core::imu_internal {

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

using Mat21 = Eigen::Matrix<double, kShared, kShared>;

inline double AngleBetween(const Vector3d& a, const Vector3d& b) {
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
                 const VectorXd& rhs_in, VectorXd* delta, Mat21* shared_inverse = nullptr);

// Per step k from sample first to last: ½(y_k + y_{k+1}) (3) and Δt_k.
std::vector<Eigen::Vector4d> Steps(const VectorXd& t, const Eigen::MatrixX3d& y, int64_t first,
                                   int64_t last);

// The rotation from sample first to last of the gyroscope y (reading units) through
// ω = m (y − bias); with s != nullptr also the sums of the analytic Jacobian (IntegrateSteps in
// core/imu_solver.cc).
Matrix3d Integrate(const VectorXd& t, const Eigen::MatrixX3d& y, const Matrix3d& m,
                   const Vector3d& bias, int64_t first, int64_t last, Matrix3d* s);

// ½ Σ r² at `x`; with h, the Gauss-Newton matrix JᵀJ and gradient Jᵀr (block structure).
// Stopped by pr.stop: the cost returned is then meaningless (the caller checks the token).
double Evaluate(const Problem& pr, const State& x, Normal* h);

struct LmSummary {
  int iterations = 0;
  bool converged = false;
  bool stopped = false;  // pr.stop asked: *x is the last accepted point
  std::vector<double> cost;
};

// Levenberg-Marquardt (Marquardt's diagonal scaling) over the active unknowns, at most
// max_iterations accepted steps and 40 rejected ones in a row (λ from 1e-6 past 1e10 by
// factors of 10); polls pr.stop every iteration and inside every evaluation.
LmSummary Minimize(const Problem& pr, int max_iterations, State* x);

// The accelerometer fit of one IMU on one detection (step 2): the problem over its statics and
// the estimate, with its χ² and degrees of freedom.
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

// The accelerometer fit of IMU k (triad 2k) on detection d: closed-form ellipsoid start, then
// Levenberg-Marquardt over M_a, b_a and the gravity directions.
AccelFit FitAccelerometer(const StaticDetection& d, int k, const ImuOptions& o);

// The coverage of the gravity directions u (unit, body frame) and of the rotation per axis.
void Coverage(const std::vector<Vector3d>& u, const Vector3d& rot_axis, ImuCoverage* c);

// Keeps the `cap` longest intervals of `d` (ties: the earlier), in time order: the number of
// statics the fits take is bounded whatever the log (issue #20). The rotations then join the
// kept statics across the dropped ones (still valid: the gyroscope integrates through them).
void KeepLongestStatics(int cap, StaticDetection* d);

// Marks r unusable with termination `term` and s's message as the reason; returns s.
Status Fail(Status s, ImuTermination term, ImuResult* r);

// The failure of a run that options.stop stopped during `stage`.
Status Stopped(const ImuOptions& o, const std::string& stage, ImuResult* r);

}  // namespace calibd::core::imu_internal

#endif  // CALIBD_CORE_IMU_INTERNAL_H_
