// The pieces of CalibratePca (core/pca.h) shared between its files; internal to core/pca*.cc.
//   core/pca_fisher.cc    the model (positions on the sphere, residuals, cost) and the reduced
//                         Fisher information (ReducedFisher, dense or low rank)
//   core/pca_fit.cc       the closed forms (bias-free and affine) and the ML refinement
//   core/pca_coverage.cc  the coverage of the sphere and its advice
//   core/pca_stages.cc    the stages of one calibration (core/pca_stages.h)
// Everything works on readings already divided by CalibratePca's power-of-two unit. Pure
// numerics, no shared state: thread-compatible.
#ifndef CALIBD_CORE_PCA_INTERNAL_H_
#define CALIBD_CORE_PCA_INTERNAL_H_

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/pca.h"
#include "core/stop_token.h"

namespace calibd::core::pca_internal {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// x printed with a printf format (at most 63 characters).
inline std::string Fmt(const char* format, double x) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, x);
  return buf;
}
// x with 3 significant digits, as messages quote numbers.
inline std::string Num(double x) { return Fmt("%.3g", x); }

// The model state: sensitivities, biases, positions.
struct Fit {
  Eigen::MatrixXd a;  // d×m
  Eigen::VectorXd b;  // m
  Eigen::MatrixXd v;  // d×n, |v_j| = c
};

// Optimal positions on the sphere |v_j| = c for given a (d×m) and b (m); m: the m×n readings.
Eigen::MatrixXd ProjectPositions(const Eigen::MatrixXd& m, const Eigen::MatrixXd& a,
                                 const Eigen::VectorXd& b, double c);
// m − aᵀv − b (m×n).
Eigen::MatrixXd Residuals(const Eigen::MatrixXd& m, const Fit& fit);
// Half the squared norm of the residuals.
double Cost(const Eigen::MatrixXd& m, const Fit& fit);
// Regressor of sensor parameters θ_i: ṽ_j = [v_j; 1] (with bias) or v_j.
Eigen::MatrixXd Regressors(const Eigen::MatrixXd& v, bool with_bias);

// S⁺ (the pseudo-inverse of the reduced information at unit noise, in the equilibrated
// coordinates θ'_i = [c·a_i; b_i], regressors ṽ_j = [u_j; 1] with u_j = v_j/c on the unit sphere)
// through M = S + κ N Nᵀ: with N an orthonormal basis of the gauge null space, S⁺ = M⁻¹ − N Nᵀ/κ.
// The equilibration scales all sensitivity columns by one factor c and the bias columns by 1, so
// the minimum-norm gauge (hence every σ) is unchanged while S no longer mixes the scales 1 and c².
// ok() false when S is singular beyond the gauge (some parameter not determined by the data).
// Immutable once built: its const methods may be called from several threads.
class ReducedFisher {
 public:
  // a: d×m (equilibrated), u: d×n on the unit sphere. Not ok() when `stop` asked while the dense
  // information was built (the caller checks it).
  ReducedFisher(const Eigen::MatrixXd& a, const Eigen::MatrixXd& u, bool with_bias,
                PcaInformationSolver solver, const StopToken* stop = nullptr);
  bool ok() const { return ok_; }

  // S⁺ rhs (the minimum-norm solution of S x = rhs).
  Eigen::VectorXd Solve(const Eigen::VectorXd& rhs) const;

  // The p×p diagonal blocks of S⁺, one per sensor: all that the reported σ need.
  std::vector<Eigen::MatrixXd> DiagonalBlocks() const;

 private:
  void InitDense(const Eigen::MatrixXd& a, const Eigen::MatrixXd& u, bool with_bias);
  void InitLowRank(const Eigen::MatrixXd& a, const Eigen::MatrixXd& u, bool with_bias);

  const StopToken* stop_ = nullptr;
  int d_, m_, n_, p_;
  Eigen::MatrixXd nb_;
  double kappa_ = 0;
  bool ok_ = false;
  bool low_rank_ = false;
  Eigen::LLT<Eigen::MatrixXd> llt_;  // dense: M
  Eigen::MatrixXd vi_;               // low rank: V⁻¹
  Eigen::MatrixXd b_;                // low rank: D⁻¹ Y (pm × r)
  Eigen::VectorXd lambda_;           // low rank: eigenvalues of K
  Eigen::MatrixXd q_;                // low rank: eigenvectors of K
};

// The paper's Algorithm 2 on the m×n readings mm. Fills fit (a, b = 0, v unconstrained) and the
// rank diagnostics of result (singular_values, rank_gap, g_eigenvalues).
Status ClosedFormBiasFree(const Eigen::MatrixXd& mm, int d, double c, const PcaOptions& options,
                          PcaResult* result, Fit* fit);
// The affine closed form (issue #8): PCA of the centred readings, algebraic ellipsoid fit. Fills
// fit and the same diagnostics.
Status ClosedFormAffine(const Eigen::MatrixXd& mm, int d, double c, const PcaOptions& options,
                        PcaResult* result, Fit* fit);

// Maximum-likelihood Gauss-Newton (variable projection over positions). Only accepted steps
// lower the cost, so the result is never worse than the start.
// At most max_iterations Gauss-Newton steps of at most 20 step halvings each; polls `stop` at
// every step and halving (returns at once, *fit the last accepted estimate). Returns the number
// of accepted steps; *cost is the cost of *fit.
int Refine(const Eigen::MatrixXd& mm, double c, bool with_bias, int max_iterations,
           PcaInformationSolver solver_kind, Fit* fit, double* cost, const StopToken* stop);

// Coverage of the sphere by the field directions (see PcaCoverage). v: d×n in the result's frame;
// frame_note names the frame's axes for the advice.
PcaCoverage Coverage(const Eigen::MatrixXd& v, bool with_bias, const std::string& frame_note);

// The coverage of positions the fit failed on, seen through the nominal sensitivities (d×m):
// each position's field is the least-squares v_j = (N Nᵀ)⁻¹ N m_j of its readings (biases, when
// unknown, are ignored: a guide to which orientations are missing, not an estimate). Leaves the
// coverage unknown without a nominal or when the nominal axes do not span d dimensions.
void CoverageFromNominal(const Eigen::MatrixXd& mm, const PcaOptions& options, PcaResult* result);

// Marks result unusable with s's message as the reason; returns s.
Status Fail(Status s, PcaResult* result);

}  // namespace calibd::core::pca_internal

#endif  // CALIBD_CORE_PCA_INTERNAL_H_
