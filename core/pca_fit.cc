// The estimates of CalibratePca (core/pca.h): the closed forms and the maximum-likelihood
// refinement (core/pca_internal.h).
//
// Closed form (kNone) — the paper's Algorithm 2: e = first d left singular vectors of m, b = eᵀm,
// g from the least squares c² = b_jᵀ g b_j, g = qᵀλq, â = λ^{-1/2} q eᵀ.
// Closed form (kEstimate) — the affine extension of issue #8: the readings lie near the
// d-dimensional affine subspace μ̄ + span(e) (PCA of the readings centred on their mean μ̄); in
// coordinates y_j = eᵀ(m_j − μ̄) they lie on the ellipsoid (y − y0)ᵀ M (y − y0) = c², found by an
// algebraic least-squares fit; with M = LᵀL, v_j = L(y_j − y0), â = L^{-T} eᵀ, b = μ̄ + e y0.
// For m = d, e is just a rotation of the readings, so the single-triad case needs nothing special.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "core/pca_internal.h"

namespace calibd::core::pca_internal {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// Left singular vectors (all, m×min(m,n) at least d columns) and singular values of x (m×n),
// O(n m²) for n >= m through a QR of xᵀ.
void LeftSvd(const MatrixXd& x, MatrixXd* e, VectorXd* sv) {
  const Eigen::Index m = x.rows();
  const Eigen::Index n = x.cols();
  if (n >= m) {
    Eigen::HouseholderQR<MatrixXd> qr(x.transpose());
    const MatrixXd r = qr.matrixQR().topRows(m).triangularView<Eigen::Upper>();
    Eigen::JacobiSVD<MatrixXd> svd(r.transpose(), Eigen::ComputeFullU);
    *e = svd.matrixU();
    *sv = svd.singularValues();
  } else {
    Eigen::JacobiSVD<MatrixXd> svd(x, Eigen::ComputeThinU);
    *e = svd.matrixU();
    *sv = svd.singularValues();
  }
}

// Checks that the readings span d clear dimensions (rank gap). Fills the diagnostics.
Status CheckRank(const VectorXd& sv, int d, const PcaOptions& options, bool affine,
                 PcaResult* result) {
  result->singular_values = sv;
  const double s1 = sv(0);
  result->rank_gap = sv.size() > d ? (sv(d) > 0 ? sv(d - 1) / sv(d) : kInf) : kInf;
  const std::string readings = affine ? "the readings (minus their mean)" : "the readings";
  if (!(s1 > 0)) {
    return Status::NotDeterminable(
        Reason::kNoSignal,
        "all readings are " + std::string(affine ? "equal" : "zero") +
            ": nothing to calibrate; check the recording (were the sensors on, was the field "
            "applied?)");
  }
  const std::string what_instead =
      " This happens when all positions lie in one plane (e.g. the device was only turned about "
      "one axis" +
      std::string(affine ? "" : " through a horizontal field") +
      "); record orientations spread over the whole sphere, so that the field points in at "
      "least " +
      std::to_string(d) + " independent directions.";
  if (sv(d - 1) <= 1e-10 * s1) {
    return Status::NotDeterminable(Reason::kPoorOrientationCoverage,
                                   readings + " span fewer than d = " + std::to_string(d) +
                                       " dimensions (singular value " + std::to_string(d) + " is " +
                                       Num(sv(d - 1) / s1) + " times the largest)." + what_instead);
  }
  if (result->rank_gap < options.min_rank_gap) {
    return Status::NotDeterminable(
        pca_reason::kNoRankGap,
        "no clear gap between singular values " + std::to_string(d) + " and " +
            std::to_string(d + 1) + " of " + readings + " (ratio " + Num(result->rank_gap) +
            ", at least " + Num(options.min_rank_gap) +
            " needed): the field is not seen in d clearly independent directions above the noise." +
            what_instead + " If the field is too weak for the noise, average longer per position.");
  }
  return Status::Ok();
}

// The first d left singular vectors *e (m×d) of x and all its singular values *sv, after
// CheckRank (whose failure it returns).
Status PrincipalSubspace(const MatrixXd& x, int d, const PcaOptions& options, bool affine,
                         PcaResult* result, MatrixXd* e, VectorXd* sv) {
  MatrixXd e_all;
  LeftSvd(x, &e_all, sv);
  Status s = CheckRank(*sv, d, options, affine, result);
  if (!s.ok()) return s;
  *e = e_all.leftCols(d);
  return Status::Ok();
}

// Row of the symmetric-matrix design: yᵀ M y = Σ_{k<=l} f_kl M_kl, f = y_k y_l (×2 off-diagonal).
void QuadraticRow(const VectorXd& y, double* row) {
  const Eigen::Index d = y.size();
  int idx = 0;
  for (Eigen::Index k = 0; k < d; ++k) {
    for (Eigen::Index l = k; l < d; ++l) row[idx++] = (k == l ? 1.0 : 2.0) * y(k) * y(l);
  }
}
MatrixXd SymmetricFromVector(const VectorXd& x, int d) {
  MatrixXd g(d, d);
  int idx = 0;
  for (int k = 0; k < d; ++k) {
    for (int l = k; l < d; ++l) g(k, l) = g(l, k) = x(idx++);
  }
  return g;
}

const char* kSpreadAdvice =
    "record orientations spread over the whole sphere (not all turned about one axis, which puts "
    "the field on a cone)";

}  // namespace

// The paper's Algorithm 2. Fills fit (a, b = 0, v unconstrained) and diagnostics.
Status ClosedFormBiasFree(const MatrixXd& mm, int d, double c, const PcaOptions& options,
                          PcaResult* result, Fit* fit) {
  const int m = static_cast<int>(mm.rows());
  const int n = static_cast<int>(mm.cols());
  MatrixXd e;
  VectorXd sv;
  Status s = PrincipalSubspace(mm, d, options, false, result, &e, &sv);
  if (!s.ok()) return s;
  const MatrixXd b = e.transpose() * mm;  // d×n
  // Least squares c² = b_jᵀ g b_j, with b scaled to unit RMS for conditioning.
  const double scale = sv(0) / std::sqrt(static_cast<double>(n));
  const int nq = d * (d + 1) / 2;
  MatrixXd design(n, nq);
  std::vector<double> row(nq);
  for (int j = 0; j < n; ++j) {
    QuadraticRow(b.col(j) / scale, row.data());
    for (int k = 0; k < nq; ++k) design(j, k) = row[k];
  }
  const VectorXd rhs = VectorXd::Constant(n, c * c);
  Eigen::HouseholderQR<MatrixXd> qr(design);
  const MatrixXd r = qr.matrixQR().topRows(std::min(n, nq)).triangularView<Eigen::Upper>();
  Eigen::JacobiSVD<MatrixXd> svd(r, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const VectorXd dsv = svd.singularValues();
  if (dsv.size() < nq || dsv(nq - 1) <= 1e-10 * dsv(0)) {
    return Status::NotDeterminable(
        Reason::kPoorOrientationCoverage,
        "the positions do not determine the field's quadratic form g (the " + std::to_string(nq) +
            " equations c² = b_jᵀ g b_j are degenerate): the field directions "
            "lie on a cone or another quadric; " +
            kSpreadAdvice + ".");
  }
  const VectorXd qtb = (qr.householderQ().transpose() * rhs).head(nq);
  const VectorXd x = svd.matrixV() * (svd.matrixU().transpose() * qtb).cwiseQuotient(dsv);
  const MatrixXd g = SymmetricFromVector(x, d) / (scale * scale);
  Eigen::SelfAdjointEigenSolver<MatrixXd> eig(g);
  const VectorXd lambda = eig.eigenvalues();
  result->g_eigenvalues = lambda;
  if (!(lambda(0) > 1e-12 * std::abs(lambda(d - 1)))) {
    return Status::NotDeterminable(
        Reason::kNotAnEllipsoid,
        "g is not positive definite (its eigenvalues, whose signs decide it, " + Num(lambda(0)) +
            " ... " + Num(lambda(d - 1)) +
            "): the readings are not those of bias-free linear sensors in a field of constant "
            "magnitude. Likely causes: sensor biases not removed (use bias: estimate, or record "
            "the "
            "static/moving layout), the field changed between positions, or too much noise for so "
            "few positions; record more positions, " +
            std::string(kSpreadAdvice) + ".");
  }
  const MatrixXd q = eig.eigenvectors().transpose();  // paper: g = qᵀ λ q
  const VectorXd sqrt_lambda = lambda.cwiseSqrt();
  fit->a = sqrt_lambda.cwiseInverse().asDiagonal() * q * e.transpose();
  fit->b = VectorXd::Zero(m);
  fit->v = sqrt_lambda.asDiagonal() * q * b;
  return Status::Ok();
}

// The affine closed form (issue #8): PCA of the centred readings, algebraic ellipsoid fit.
Status ClosedFormAffine(const MatrixXd& mm, int d, double c, const PcaOptions& options,
                        PcaResult* result, Fit* fit) {
  const int n = static_cast<int>(mm.cols());
  const VectorXd mean = mm.rowwise().mean();
  const MatrixXd centred = mm.colwise() - mean;
  MatrixXd e;
  VectorXd sv;
  Status s = PrincipalSubspace(centred, d, options, true, result, &e, &sv);
  if (!s.ok()) return s;
  const MatrixXd y = e.transpose() * centred;  // d×n, mean zero
  const double scale = std::sqrt(y.squaredNorm() / n);
  // Algebraic fit ŷᵀMŷ − 2wᵀŷ + k = 0 on ŷ = y/scale: null vector of the design.
  const int nq = d * (d + 1) / 2;
  const int nz = nq + d + 1;
  MatrixXd design(n, nz);
  std::vector<double> row(nq);
  for (int j = 0; j < n; ++j) {
    const VectorXd yh = y.col(j) / scale;
    QuadraticRow(yh, row.data());
    for (int k = 0; k < nq; ++k) design(j, k) = row[k];
    design.block(j, nq, 1, d) = -2.0 * yh.transpose();
    design(j, nz - 1) = 1.0;
  }
  MatrixXd r;
  if (n > nz) {
    Eigen::HouseholderQR<MatrixXd> qr(design);
    r = qr.matrixQR().topRows(nz).triangularView<Eigen::Upper>();
  } else {
    r = design;
  }
  Eigen::JacobiSVD<MatrixXd> svd(r, Eigen::ComputeFullV);
  VectorXd dsv = VectorXd::Zero(nz);
  dsv.head(svd.singularValues().size()) = svd.singularValues();
  if (dsv(nz - 2) <= 1e-10 * dsv(0)) {
    return Status::NotDeterminable(
        Reason::kPoorOrientationCoverage,
        "the positions do not determine the ellipsoid of the readings (its " +
            std::to_string(nz - 1) +
            " parameters are degenerate): the field directions lie on a cone or another quadric; " +
            kSpreadAdvice + ".");
  }
  const VectorXd z = svd.matrixV().col(nz - 1);
  MatrixXd mh = SymmetricFromVector(z.head(nq), d);
  VectorXd wh = z.segment(nq, d);
  double kh = z(nz - 1);
  Eigen::SelfAdjointEigenSolver<MatrixXd> eig0(mh);
  if (eig0.eigenvalues()(d - 1) < 0) {  // overall sign of the null vector is arbitrary
    mh = -mh;
    wh = -wh;
    kh = -kh;
  }
  Eigen::SelfAdjointEigenSolver<MatrixXd> eig1(mh);
  const VectorXd mu = eig1.eigenvalues();
  std::string not_ellipsoid =
      "the readings do not lie on an ellipsoid (algebraic fit gives a quadric that is not "
      "positive definite";
  const std::string causes =
      "): they are not those of linear sensors with constant biases in a field of constant "
      "magnitude, or there is too much noise for so few positions; record more positions, " +
      std::string(kSpreadAdvice) + ".";
  if (!(mu(0) > 1e-12 * mu(d - 1))) {
    result->g_eigenvalues = mu;
    return Status::NotDeterminable(Reason::kNotAnEllipsoid,
                                   not_ellipsoid +
                                       ", the eigenvalues of its unit-norm shape matrix " +
                                       Num(mu(0)) + " ... " + Num(mu(d - 1)) + causes);
  }
  const VectorXd y0h = mh.llt().solve(wh);
  const double rho = y0h.dot(mh * y0h) - kh;
  if (!(rho > 0)) {
    return Status::NotDeterminable(Reason::kNotAnEllipsoid,
                                   not_ellipsoid + ": an empty ellipsoid" + causes);
  }
  const MatrixXd shape = (c * c / (rho * scale * scale)) * mh;  // (y−y0)ᵀ shape (y−y0) = c²
  const VectorXd y0 = scale * y0h;
  Eigen::SelfAdjointEigenSolver<MatrixXd> eig(shape);
  const VectorXd lambda = eig.eigenvalues();
  result->g_eigenvalues = lambda;
  const MatrixXd q = eig.eigenvectors().transpose();
  const VectorXd sqrt_lambda = lambda.cwiseSqrt();
  // v = L (y − y0), L = λ^{1/2} q; m ≈ mean + e y = mean + e y0 + e L⁻¹ v.
  fit->a = sqrt_lambda.cwiseInverse().asDiagonal() * q * e.transpose();
  fit->b = mean + e * y0;
  fit->v = sqrt_lambda.asDiagonal() * q * (y.colwise() - y0);
  return Status::Ok();
}

// The Gauss-Newton step solves the reduced system of ReducedFisher with the gradient; positions
// are then re-solved exactly on the sphere (ProjectPositions).
int Refine(const MatrixXd& mm, double c, bool with_bias, int max_iterations,
           PcaInformationSolver solver_kind, Fit* fit, double* cost, const StopToken* stop) {
  const int d = static_cast<int>(fit->a.rows());
  const int m = static_cast<int>(fit->a.cols());
  const int p = with_bias ? d + 1 : d;
  int iterations = 0;
  for (int it = 0; it < max_iterations; ++it) {
    if (StopRequested(stop)) break;
    const MatrixXd res = Residuals(mm, *fit);  // m×n
    const MatrixXd g = fit->a * fit->a.transpose();
    Eigen::LLT<MatrixXd> llt(g);
    if (llt.info() != Eigen::Success) break;
    const MatrixXd gi = llt.solve(MatrixXd::Identity(d, d));
    // w_j = P_j a r_j.
    const MatrixXd ar = fit->a * res;  // d×n
    MatrixXd w(d, mm.cols());
    for (Eigen::Index j = 0; j < mm.cols(); ++j) {
      const VectorXd giu = gi * fit->v.col(j);
      const double den = fit->v.col(j).dot(giu);
      const VectorXd gir = gi * ar.col(j);
      w.col(j) = gir - giu * (giu.dot(ar.col(j)) / den);
    }
    // In the equilibrated coordinates θ' = [c·a; b] (see ReducedFisher): u = v/c, w' = w/c.
    const MatrixXd a_eq = c * fit->a;
    const MatrixXd u = fit->v / c;
    const MatrixXd vt = Regressors(u, with_bias);                                       // p×n
    const MatrixXd rhs_mat = vt * res.transpose() - (vt * (w / c).transpose()) * a_eq;  // p×m
    const ReducedFisher solver(a_eq, u, with_bias, solver_kind, stop);
    if (!solver.ok()) break;
    const VectorXd delta = solver.Solve(Eigen::Map<const VectorXd>(rhs_mat.data(), p * m));
    MatrixXd dtheta = Eigen::Map<const MatrixXd>(delta.data(), p, m);
    dtheta.topRows(d) /= c;
    bool accepted = false;
    double step = 1.0;
    for (int half = 0; half < 20; ++half, step *= 0.5) {
      if (StopRequested(stop)) return iterations;
      Fit trial;
      trial.a = fit->a + step * dtheta.topRows(d);
      trial.b = with_bias ? VectorXd(fit->b + step * dtheta.row(d).transpose()) : fit->b;
      trial.v = ProjectPositions(mm, trial.a, trial.b, c);
      const double trial_cost = Cost(mm, trial);
      if (trial_cost < *cost) {
        const double decrease = *cost - trial_cost;
        *fit = std::move(trial);
        *cost = trial_cost;
        accepted = true;
        ++iterations;
        if (decrease <= 1e-12 * trial_cost) return iterations;
        break;
      }
    }
    if (!accepted) break;
  }
  return iterations;
}

}  // namespace calibd::core::pca_internal
