// The model of CalibratePca (core/pca.h): positions on the sphere, residuals, cost, and the
// reduced Fisher information of the sensor parameters (core/pca_internal.h).
//
// Maximum likelihood / Fisher information. Per sensor parameters θ_i = [a_i; b_i] (p = d or d+1
// numbers), per position the d−1 tangent directions of v_j on the sphere. With G = a aᵀ and the
// regressor ṽ_j = [v_j; 1] (or v_j), the information of the tangent block of position j is
// T_jᵀ G T_j, and eliminating it (Schur complement) leaves, with
//   P_j = T_j (T_jᵀ G T_j)^{-1} T_jᵀ = G⁻¹ − G⁻¹u uᵀG⁻¹ / (uᵀG⁻¹u),   u = v_j,
// the reduced information (unit noise) of the sensor parameters
//   S_ik = δ_ik Σ_j ṽ_j ṽ_jᵀ − Σ_j (a_iᵀ P_j a_k) ṽ_j ṽ_jᵀ,
// assembled in O(n d² p²) through K = Σ_j vec(P_j) vec(ṽ_j ṽ_jᵀ)ᵀ. S has the d(d−1)/2-dimensional
// null space of infinitesimal rotations (θ_i → [Ω a_i; 0]); its pseudo-inverse is
// (S + κ N Nᵀ)^{-1} − N Nᵀ/κ with N an orthonormal basis of that null space. The same reduced
// system, with the gradient, gives the Gauss-Newton step of `refine`; positions are then
// re-solved exactly on the sphere (variable projection), so the cost can only go down.
//
// Cost (issue #14). S is (pm)×(pm), but only its pseudo-inverse's p×p diagonal blocks are read
// (every reported σ is per sensor). S = I ⊗ V − W C Wᵀ: block diagonal (V = Σ_j ṽ_j ṽ_jᵀ, the
// same for every sensor) minus a rank-n(d−1) coupling through the positions. kDense forms and
// factorises S (O((pm)³), O((pm)²) memory, the only way before); kLowRank applies Woodbury to
// S + κNNᵀ = D + Y Λ Yᵀ, Y = [W N] of r = n(d−1) + d(d−1)/2 columns: an r×r system and
// O(pm·r) memory, linear in the number of sensors. Both give the same S⁺, hence the same σ.
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <cmath>

#include "core/pca_internal.h"

namespace calibd::core::pca_internal {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// Least squares on the sphere: x minimising |y − aᵀx|² subject to |x| = c, given the
// eigen-decomposition of G = a aᵀ (positive definite) and r = a y. Lagrange: (G + μI)x = r with
// μ > −λ_min chosen so that |x| = c (a trust-region style secular equation, safeguarded Newton on
// 1/|x(μ)|).
class SphereSolver {
 public:
  SphereSolver(const MatrixXd& g, double c) : c_(c) {
    Eigen::SelfAdjointEigenSolver<MatrixXd> eig(g);
    lambda_ = eig.eigenvalues();
    q_ = eig.eigenvectors();
  }

  VectorXd Solve(const VectorXd& r) const {
    const int d = static_cast<int>(lambda_.size());
    const VectorXd rt = q_.transpose() * r;
    const double lam_min = lambda_(0);
    const double rnorm = rt.norm();
    if (rnorm == 0) return c_ * q_.col(0);
    double lo = -lam_min;
    double hi = rnorm / c_ - lam_min;  // |x(μ)| <= |r|/(λ_min + μ) <= c from here on
    auto norm2 = [&](double mu) {
      double s = 0;
      for (int k = 0; k < d; ++k) {
        const double t = rt(k) / (lambda_(k) + mu);
        s += t * t;
      }
      return s;
    };
    double mu = (0 > lo && 0 < hi) ? 0.0 : 0.5 * (lo + hi);
    for (int it = 0; it < 200; ++it) {
      const double s = norm2(mu);
      const double xn = std::sqrt(s);
      if (std::abs(xn - c_) <= 1e-15 * c_) break;
      if (xn > c_) {
        lo = mu;
      } else {
        hi = mu;
      }
      double s3 = 0;
      for (int k = 0; k < d; ++k) {
        const double den = lambda_(k) + mu;
        s3 += rt(k) * rt(k) / (den * den * den);
      }
      const double f = 1.0 / xn - 1.0 / c_;
      const double fp = s3 / (s * xn);
      double next = mu - f / fp;
      if (!(next > lo && next < hi) || !std::isfinite(next)) next = 0.5 * (lo + hi);
      if (next == mu || hi - lo <= 1e-16 * (std::abs(lo) + std::abs(hi))) {
        mu = next;
        break;
      }
      mu = next;
    }
    VectorXd xt(d);
    for (int k = 0; k < d; ++k) xt(k) = rt(k) / (lambda_(k) + mu);
    const double xn = xt.norm();
    if (!(xn >= c_ * (1 - 1e-8)) || !std::isfinite(xn)) {
      // Hard case (r has no component along the smallest eigenvector): μ = −λ_min and the
      // missing length goes along that eigenvector.
      xt(0) = 0;
      for (int k = 1; k < d; ++k) xt(k) = rt(k) / (lambda_(k) - lam_min);
      const double rest = xt.squaredNorm();
      xt(0) = std::sqrt(std::max(0.0, c_ * c_ - rest));
    }
    VectorXd x = q_ * xt;
    const double norm = x.norm();
    if (norm > 0) x *= c_ / norm;
    return x;
  }

 private:
  double c_;
  VectorXd lambda_;
  MatrixXd q_;
};

// Reduced (Schur-complement) information of θ = vec([a; bᵀ]) at unit noise, positions eliminated.
// False when G = a aᵀ is singular.
// False when a·aᵀ is singular or `stop` asked (polled per sensor row of S).
bool ReducedInformation(const MatrixXd& a, const MatrixXd& v, bool with_bias, MatrixXd* s,
                        const StopToken* stop) {
  const int d = static_cast<int>(a.rows());
  const int m = static_cast<int>(a.cols());
  const int n = static_cast<int>(v.cols());
  const int p = with_bias ? d + 1 : d;
  Eigen::LLT<MatrixXd> llt(a * a.transpose());
  if (llt.info() != Eigen::Success) return false;
  const MatrixXd gi = llt.solve(MatrixXd::Identity(d, d));
  MatrixXd vv = MatrixXd::Zero(p, p);
  MatrixXd k = MatrixXd::Zero(d * d, p * p);
  VectorXd vt(p);
  MatrixXd pj(d, d);
  MatrixXd outer(p, p);
  for (int j = 0; j < n; ++j) {
    vt.head(d) = v.col(j);
    if (with_bias) vt(d) = 1;
    const VectorXd giu = gi * v.col(j);
    const double den = v.col(j).dot(giu);
    pj = gi - giu * giu.transpose() / den;
    outer.noalias() = vt * vt.transpose();
    vv += outer;
    k.noalias() += Eigen::Map<const VectorXd>(pj.data(), d * d) *
                   Eigen::Map<const VectorXd>(outer.data(), p * p).transpose();
  }
  s->setZero(p * m, p * m);
  VectorXd w(d * d);
  for (int i = 0; i < m; ++i) {
    if (StopRequested(stop)) return false;
    for (int kk = i; kk < m; ++kk) {
      // w = vec(a_k a_iᵀ)? P(r,s) is stored at r + s*d; a_iᵀ P a_k = Σ a(r,i) a(s,k) P(r,s).
      for (int ss = 0; ss < d; ++ss) {
        for (int rr = 0; rr < d; ++rr) w(rr + ss * d) = a(rr, i) * a(ss, kk);
      }
      const VectorXd block = -(k.transpose() * w);  // p², column-major p×p
      for (int q2 = 0; q2 < p; ++q2) {
        for (int q1 = 0; q1 < p; ++q1) {
          double x = block(q1 + q2 * p);
          if (i == kk) x += vv(q1, q2);
          (*s)(i * p + q1, kk * p + q2) = x;
          (*s)(kk * p + q2, i * p + q1) = x;
        }
      }
    }
  }
  return true;
}

// Orthonormal basis (p·m × d(d−1)/2) of the rotation gauge: θ_i → [Ω a_i; 0].
MatrixXd GaugeBasis(const MatrixXd& a, bool with_bias) {
  const int d = static_cast<int>(a.rows());
  const int m = static_cast<int>(a.cols());
  const int p = with_bias ? d + 1 : d;
  const int ng = d * (d - 1) / 2;
  MatrixXd nb = MatrixXd::Zero(p * m, ng);
  int col = 0;
  for (int r = 0; r < d; ++r) {
    for (int s = r + 1; s < d; ++s, ++col) {
      for (int i = 0; i < m; ++i) {
        nb(i * p + r, col) = a(s, i);
        nb(i * p + s, col) = -a(r, i);
      }
    }
  }
  if (ng == 0) return nb;
  Eigen::HouseholderQR<MatrixXd> qr(nb);
  return qr.householderQ() * MatrixXd::Identity(p * m, ng);
}

}  // namespace

// Optimal positions on the sphere for given a and b.
MatrixXd ProjectPositions(const MatrixXd& m, const MatrixXd& a, const VectorXd& b, double c) {
  const SphereSolver solver(a * a.transpose(), c);
  MatrixXd r = a * (m.colwise() - b);  // d×n
  MatrixXd v(a.rows(), m.cols());
  for (Eigen::Index j = 0; j < m.cols(); ++j) v.col(j) = solver.Solve(r.col(j));
  return v;
}

MatrixXd Residuals(const MatrixXd& m, const Fit& fit) {
  MatrixXd r = m - fit.a.transpose() * fit.v;
  r.colwise() -= fit.b;
  return r;
}

double Cost(const MatrixXd& m, const Fit& fit) { return 0.5 * Residuals(m, fit).squaredNorm(); }

// Regressor of sensor parameters θ_i: ṽ_j = [v_j; 1] (with bias) or v_j.
MatrixXd Regressors(const MatrixXd& v, bool with_bias) {
  if (!with_bias) return v;
  MatrixXd vt(v.rows() + 1, v.cols());
  vt.topRows(v.rows()) = v;
  vt.row(v.rows()).setOnes();
  return vt;
}

ReducedFisher::ReducedFisher(const MatrixXd& a, const MatrixXd& u, bool with_bias,
                             PcaInformationSolver solver, const StopToken* stop)
    : stop_(stop),
      d_(static_cast<int>(a.rows())),
      m_(static_cast<int>(a.cols())),
      n_(static_cast<int>(u.cols())),
      p_(with_bias ? d_ + 1 : d_) {
  nb_ = GaugeBasis(a, with_bias);
  if (solver == PcaInformationSolver::kLowRank) {
    InitLowRank(a, u, with_bias);
  } else {
    InitDense(a, u, with_bias);
  }
}

VectorXd ReducedFisher::Solve(const VectorXd& rhs) const {
  VectorXd x;
  if (low_rank_) {
    x.resize(rhs.size());
    for (int i = 0; i < m_; ++i) x.segment(i * p_, p_) = vi_ * rhs.segment(i * p_, p_);
    const VectorXd t = q_.transpose() * (b_.transpose() * rhs);
    x -= b_ * (q_ * t.cwiseQuotient(lambda_));
  } else {
    x = llt_.solve(rhs);
  }
  return x - nb_ * (nb_.transpose() * x);
}

std::vector<MatrixXd> ReducedFisher::DiagonalBlocks() const {
  std::vector<MatrixXd> blocks(m_);
  const int np = p_ * m_;
  if (low_rank_ && q_.cols() == 0) {
    // r = 0 (d = 1: no tangent directions, no rotation gauge): no low-rank correction. (A
    // block of an empty (pm)×0 matrix would offset a null pointer.)
    for (int i = 0; i < m_; ++i) blocks[i] = vi_;
  } else if (low_rank_) {
    const MatrixXd bq = b_ * q_;  // (pm)×r
    const VectorXd inv = lambda_.cwiseInverse();
    for (int i = 0; i < m_; ++i) {
      const auto bqi = bq.middleRows(i * p_, p_);
      blocks[i] = vi_ - bqi * inv.asDiagonal() * bqi.transpose();
    }
  } else {
    MatrixXd e = MatrixXd::Zero(np, p_);
    for (int i = 0; i < m_; ++i) {
      e.middleRows(i * p_, p_).setIdentity();
      blocks[i] = llt_.solve(e).middleRows(i * p_, p_);
      e.middleRows(i * p_, p_).setZero();
    }
  }
  for (int i = 0; i < m_; ++i) {
    if (nb_.cols() > 0) {  // d = 1 has no rotation gauge (and nb_ no columns)
      const auto ni = nb_.middleRows(i * p_, p_);
      blocks[i] -= ni * ni.transpose() / kappa_;
    }
    blocks[i] = 0.5 * (blocks[i] + blocks[i].transpose()).eval();
  }
  return blocks;
}

void ReducedFisher::InitDense(const MatrixXd& a, const MatrixXd& u, bool with_bias) {
  MatrixXd s;
  if (!ReducedInformation(a, u, with_bias, &s, stop_)) return;
  kappa_ = s.trace() / static_cast<double>(s.rows());
  if (!(kappa_ > 0) || !std::isfinite(kappa_)) return;
  s.noalias() += kappa_ * nb_ * nb_.transpose();
  llt_.compute(s);
  ok_ = llt_.info() == Eigen::Success && llt_.rcond() > 1e-13;
}

// M = D + Y Λ Yᵀ with D = I ⊗ V, V = Σ_j ṽ_j ṽ_jᵀ; Y = [W N], W's column block j the p·m × (d−1)
// matrix with sensor rows ṽ_j (a_iᵀ T_j) (T_j an orthonormal basis of the tangent space at u_j),
// Λ = diag(−(T_jᵀ G T_j)⁻¹ ..., κ I). Woodbury: M⁻¹ = D⁻¹ − B K⁻¹ Bᵀ, B = D⁻¹ Y,
// K = Λ⁻¹ + Yᵀ D⁻¹ Y (r×r, symmetric indefinite, factorised by its eigen-decomposition). Y's
// columns are scaled to unit norm first (the same M), which equilibrates K. M is positive
// definite iff K has exactly n(d−1) negative and d(d−1)/2 positive eigenvalues (Haynsworth
// inertia additivity), and det M = det D det Λ det K, so K's conditioning stands for M's.
void ReducedFisher::InitLowRank(const MatrixXd& a, const MatrixXd& u, bool with_bias) {
  low_rank_ = true;
  const int d = d_, m = m_, n = n_, p = p_;
  const int nt = n * (d - 1);
  const int ng = d * (d - 1) / 2;
  const int r = nt + ng;
  const int np = p * m;
  const MatrixXd g = a * a.transpose();
  MatrixXd vv = MatrixXd::Zero(p, p);
  VectorXd vt(p);
  double vt_sq = 0;
  for (int j = 0; j < n; ++j) {
    vt.head(d) = u.col(j);
    if (with_bias) vt(d) = 1;
    vv.noalias() += vt * vt.transpose();
    vt_sq += vt.squaredNorm();
  }
  Eigen::LLT<MatrixXd> vllt(vv);
  if (vllt.info() != Eigen::Success) return;
  vi_ = vllt.solve(MatrixXd::Identity(p, p));
  // trace S = m trace V − Σ_j trace(P_j G) |ṽ_j|², trace(P_j G) = d − 1.
  kappa_ = (m * vv.trace() - (d - 1) * vt_sq) / static_cast<double>(np);
  if (!(kappa_ > 0) || !std::isfinite(kappa_)) return;
  if (r == 0) {  // d = 1: no positions to eliminate, no gauge; M = D
    b_.setZero(np, 0);
    q_.setZero(0, 0);
    ok_ = true;
    return;
  }
  MatrixXd y(np, r);
  MatrixXd lambda_inv = MatrixXd::Zero(r, r);
  for (int j = 0; j < n && d > 1; ++j) {
    Eigen::HouseholderQR<MatrixXd> qr(u.col(j));
    const MatrixXd t = (qr.householderQ() * MatrixXd::Identity(d, d)).rightCols(d - 1);
    const MatrixXd at = a.transpose() * t;  // m×(d−1): a_iᵀ T_j
    vt.head(d) = u.col(j);
    if (with_bias) vt(d) = 1;
    for (int i = 0; i < m; ++i) {
      y.block(i * p, j * (d - 1), p, d - 1).noalias() = vt * at.row(i);
    }
    lambda_inv.block(j * (d - 1), j * (d - 1), d - 1, d - 1) = -t.transpose() * g * t;
  }
  y.rightCols(ng) = nb_;
  lambda_inv.bottomRightCorner(ng, ng).diagonal().setConstant(1.0 / kappa_);
  VectorXd e = y.colwise().norm().transpose();
  for (int k = 0; k < r; ++k) e(k) = e(k) > 0 ? 1.0 / e(k) : 1.0;
  y = y * e.asDiagonal();
  lambda_inv = e.asDiagonal() * lambda_inv * e.asDiagonal();
  b_.resize(np, r);
  for (int i = 0; i < m; ++i) b_.middleRows(i * p, p).noalias() = vi_ * y.middleRows(i * p, p);
  MatrixXd k = lambda_inv;
  k.noalias() += y.transpose() * b_;
  y.resize(0, 0);
  Eigen::SelfAdjointEigenSolver<MatrixXd> eig(0.5 * (k + k.transpose()));
  if (eig.info() != Eigen::Success) return;
  lambda_ = eig.eigenvalues();
  q_ = eig.eigenvectors();
  const double largest = lambda_.cwiseAbs().maxCoeff();
  int negative = 0;
  for (int kk = 0; kk < r; ++kk) {
    if (!(std::abs(lambda_(kk)) > 1e-13 * largest)) return;
    if (lambda_(kk) < 0) ++negative;
  }
  ok_ = negative == nt && std::isfinite(largest);
}

}  // namespace calibd::core::pca_internal

namespace calibd::core {

Status ComputePcaInformation(const Eigen::MatrixXd& a, const Eigen::MatrixXd& u, BiasModel bias,
                             PcaInformation* out) {
  if (a.rows() < 1 || a.cols() < 1 || u.rows() != a.rows()) {
    return Status::InvalidInput("pca information: a is d×m and u d×n");
  }
  const bool with_bias = bias == BiasModel::kEstimate;
  if (!pca_internal::ReducedInformation(a, u, with_bias, &out->s, nullptr)) {
    return Status::InvalidInput("pca information: the sensitivities do not span the dimension");
  }
  out->gauge = pca_internal::GaugeBasis(a, with_bias);
  return Status::Ok();
}

}  // namespace calibd::core
