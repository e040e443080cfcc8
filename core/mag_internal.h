// Stages of CalibrateMag (core/mag.h) shared by its files: core/mag.cc (start, maximum likelihood,
// uncertainty) and core/mag_geometry.cc (alignment, coverage, disturbed spans). Not a public
// interface.
#ifndef CALIBD_CORE_MAG_INTERNAL_H_
#define CALIBD_CORE_MAG_INTERNAL_H_

#include <Eigen/Core>
#include <vector>

#include "core/mag.h"

namespace calibd::core::mag_internal {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Vector9d = Eigen::Matrix<double, 9, 1>;
using Matrix9d = Eigen::Matrix<double, 9, 9>;

// The symmetric matrix of its upper-triangle entries a = (a00, a01, a02, a11, a12, a22).
Eigen::Matrix3d Sym(const Vector6d& a);
Vector6d SymEntries(const Eigen::Matrix3d& a);
// Rodrigues: the rotation exp([φ]×).
Eigen::Matrix3d ExpRotation(const Eigen::Vector3d& phi);
Eigen::Matrix3d Skew(const Eigen::Vector3d& v);

// The ellipsoid y = h + A u, |u| = 1 (A symmetric positive definite, reading units), with each
// sample's direction u_i (columns) and its robust weight.
struct Ellipsoid {
  Eigen::Vector3d h = Eigen::Vector3d::Zero();
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  Eigen::Matrix3Xd u;
};

// σ of the entries of a matrix that depends linearly on parameters with covariance `cov`:
// d[k] = ∂M/∂p_k. Returns the 3×3 matrix of sqrt(Σ_kl d[k]_ij cov_kl d[l]_ij).
Eigen::Matrix3d EntryStd(const std::vector<Eigen::Matrix3d>& d, const Eigen::MatrixXd& cov);

// Stage 4: R and the dip from the statics (fills alignment, dip, their σ, alignment_note; makes
// soft_iron R P with its σ). `cov_primary` and `cov_crb`: the covariances of θ = (h, a) (9×9) the
// alignment carries through; `cov_p`: the one P's entries in R P take (the primary's with the
// offsets' wander, step 3c, which the alignment must not carry: the statics' scatter already
// holds the wander within the log, and the shift to the next log moves no static of this one;
// null: cov_primary).
void EstimateAlignment(const MagProblem& problem, const MagOptions& options, const Ellipsoid& fit,
                       const Eigen::MatrixXd& cov_primary, const Eigen::MatrixXd& cov_crb,
                       MagResult* result, const Eigen::MatrixXd* cov_p = nullptr);

// Stage 5: coverage of the field directions u_i with weight >= options.disturbed_weight.
MagCoverage AssessCoverage(const Eigen::Matrix3Xd& u, const Eigen::VectorXd& w,
                           const MagOptions& options);

// Spans of the samples whose weight is under options.disturbed_weight, those closer than
// options.span_merge_seconds merged; `residual` the residual norms in µT.
std::vector<MagSpan> DisturbedSpans(const Eigen::VectorXd& t, const Eigen::VectorXd& w,
                                    const Eigen::VectorXd& residual, const MagOptions& options);

}  // namespace calibd::core::mag_internal

#endif  // CALIBD_CORE_MAG_INTERNAL_H_
