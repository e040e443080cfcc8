// Implementation notes.
//
// Closed form (kNone) — the paper's Algorithm 2: e = first d left singular vectors of m, b = eᵀm,
// g from the least squares c² = b_jᵀ g b_j, g = qᵀλq, â = λ^{-1/2} q eᵀ.
// Closed form (kEstimate) — the affine extension of issue #8: the readings lie near the
// d-dimensional affine subspace μ̄ + span(e) (PCA of the readings centred on their mean μ̄); in
// coordinates y_j = eᵀ(m_j − μ̄) they lie on the ellipsoid (y − y0)ᵀ M (y − y0) = c², found by an
// algebraic least-squares fit; with M = LᵀL, v_j = L(y_j − y0), â = L^{-T} eᵀ, b = μ̄ + e y0.
// For m = d, e is just a rotation of the readings, so the single-triad case needs nothing special.
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
//
// Scaling. CalibratePca divides the readings by a power of two near their largest magnitude
// (exact) and the Fisher information is built in the coordinates θ'_i = [c·a_i; b_i] with the
// positions on the unit sphere: one common factor on all sensitivity columns and one on all bias
// columns keeps the minimum-norm gauge, so σ are unchanged while S no longer mixes the scales
// 1 and c² (at c = 1e-6 the bias columns were 1e12 times the others and the σ came out NaN).
#include "core/pca.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace calibd::core {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

using Eigen::MatrixXd;
using Eigen::VectorXd;

std::string Fmt(const char* format, double x) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, x);
  return buf;
}
std::string Num(double x) { return Fmt("%.3g", x); }

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

// The model state: sensitivities, biases, positions.
struct Fit {
  MatrixXd a;  // d×m
  VectorXd b;  // m
  MatrixXd v;  // d×n, |v_j| = c
};

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

// S⁺ (the pseudo-inverse of the reduced information at unit noise, in the equilibrated
// coordinates θ'_i = [c·a_i; b_i], regressors ṽ_j = [u_j; 1] with u_j = v_j/c on the unit sphere)
// through M = S + κ N Nᵀ: with N an orthonormal basis of the gauge null space, S⁺ = M⁻¹ − N Nᵀ/κ.
// The equilibration scales all sensitivity columns by one factor c and the bias columns by 1, so
// the minimum-norm gauge (hence every σ) is unchanged while S no longer mixes the scales 1 and c².
// ok() false when S is singular beyond the gauge (some parameter not determined by the data).
class ReducedFisher {
 public:
  // Not ok() when `stop` asked while the dense information was built (the caller checks it).
  ReducedFisher(const MatrixXd& a, const MatrixXd& u, bool with_bias, PcaInformationSolver solver,
                const StopToken* stop = nullptr)
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
  bool ok() const { return ok_; }

  // S⁺ rhs (the minimum-norm solution of S x = rhs).
  VectorXd Solve(const VectorXd& rhs) const {
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

  // The p×p diagonal blocks of S⁺, one per sensor: all that the reported σ need.
  std::vector<MatrixXd> DiagonalBlocks() const {
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

 private:
  void InitDense(const MatrixXd& a, const MatrixXd& u, bool with_bias) {
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
  void InitLowRank(const MatrixXd& a, const MatrixXd& u, bool with_bias) {
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

  const StopToken* stop_ = nullptr;
  int d_, m_, n_, p_;
  MatrixXd nb_;
  double kappa_ = 0;
  bool ok_ = false;
  bool low_rank_ = false;
  Eigen::LLT<MatrixXd> llt_;  // dense: M
  MatrixXd vi_;               // low rank: V⁻¹
  MatrixXd b_;                // low rank: D⁻¹ Y (pm × r)
  VectorXd lambda_;           // low rank: eigenvalues of K
  MatrixXd q_;                // low rank: eigenvectors of K
};

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
                                       Num(sv(d - 1) / s1) + " of the largest)." + what_instead);
  }
  if (result->rank_gap < options.min_rank_gap) {
    return Status::NotDeterminable(
        Reason::kNoRankGap,
        "no clear gap between singular values " + std::to_string(d) + " and " +
            std::to_string(d + 1) + " of " + readings + " (ratio " + Num(result->rank_gap) +
            ", at least " + Num(options.min_rank_gap) +
            " needed): the field is not seen in d clearly independent directions above the noise." +
            what_instead + " If the field is too weak for the noise, average longer per position.");
  }
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

// The paper's Algorithm 2. Fills fit (a, b = 0, v unconstrained) and diagnostics.
Status ClosedFormBiasFree(const MatrixXd& mm, int d, double c, const PcaOptions& options,
                          PcaResult* result, Fit* fit) {
  const int m = static_cast<int>(mm.rows());
  const int n = static_cast<int>(mm.cols());
  MatrixXd e_all;
  VectorXd sv;
  LeftSvd(mm, &e_all, &sv);
  Status s = CheckRank(sv, d, options, false, result);
  if (!s.ok()) return s;
  const MatrixXd e = e_all.leftCols(d);
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
        "g is not positive definite (eigenvalues " + Num(lambda(0)) + " ... " + Num(lambda(d - 1)) +
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
  MatrixXd e_all;
  VectorXd sv;
  LeftSvd(centred, &e_all, &sv);
  Status s = CheckRank(sv, d, options, true, result);
  if (!s.ok()) return s;
  const MatrixXd e = e_all.leftCols(d);
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
    return Status::NotDeterminable(
        Reason::kNotAnEllipsoid,
        not_ellipsoid + ", eigenvalues " + Num(mu(0)) + " ... " + Num(mu(d - 1)) + causes);
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

// Maximum-likelihood Gauss-Newton (variable projection over positions). Only accepted steps
// lower the cost, so the result is never worse than the start.
// At most max_iterations Gauss-Newton steps of at most 20 step halvings each; polls `stop` at
// every step and halving (returns at once, *fit the last accepted estimate).
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

// Caps of PcaCoverage: within 60° of an axis direction, within 30° of an edge direction.
constexpr double kAxisCapCos = 0.5;
constexpr double kEdgeCapCos = 0.8660254037844386;

// Coverage of the sphere by the field directions (see PcaCoverage). v: d×n in the result's frame;
// frame_note names the frame's axes for the advice.
PcaCoverage Coverage(const MatrixXd& v, bool with_bias, const std::string& frame_note) {
  PcaCoverage cov;
  const int d = static_cast<int>(v.rows());
  const int n = static_cast<int>(v.cols());
  if (n < 1 || d < 1 || !v.allFinite()) return cov;
  MatrixXd u = v;
  for (int j = 0; j < n; ++j) {
    const double norm = u.col(j).norm();
    if (!(norm > 0)) return cov;
    u.col(j) /= norm;
  }
  Eigen::SelfAdjointEigenSolver<MatrixXd> scatter(u * u.transpose() / n);
  cov.scatter_eigenvalues = scatter.eigenvalues();
  cov.scatter_min = d * std::max(0.0, cov.scatter_eigenvalues(0));
  // Design of the quadric fit: f = [u_k u_l (×√2 for k < l); u_k with biases].
  const int nq = d * (d + 1) / 2;
  const int nf = nq + (with_bias ? d : 0);
  MatrixXd f(nf, n);
  for (int j = 0; j < n; ++j) {
    int idx = 0;
    for (int k = 0; k < d; ++k) {
      for (int l = k; l < d; ++l) f(idx++, j) = (k == l ? 1.0 : std::sqrt(2.0)) * u(k, j) * u(l, j);
    }
    if (with_bias) f.col(j).tail(d) = u.col(j);
  }
  MatrixXd design = MatrixXd::Zero(nf, nf);
  design.selfadjointView<Eigen::Lower>().rankUpdate(f, 1.0 / n);
  design = design.selfadjointView<Eigen::Lower>();
  // Its expectation for uniform directions: E u_k⁴ = 3/(d(d+2)), E u_k²u_l² = 1/(d(d+2)),
  // E u_k² = 1/d, odd moments 0.
  MatrixXd uniform = MatrixXd::Zero(nf, nf);
  const double q = 1.0 / (d * (d + 2.0));
  std::vector<int> diag_index;
  int idx = 0;
  for (int k = 0; k < d; ++k) {
    for (int l = k; l < d; ++l, ++idx) {
      if (k == l) {
        diag_index.push_back(idx);
      } else {
        uniform(idx, idx) = 2 * q;
      }
    }
  }
  for (int k : diag_index) {
    for (int l : diag_index) uniform(k, l) = (k == l ? 3 : 1) * q;
  }
  if (with_bias) uniform.bottomRightCorner(d, d).diagonal().setConstant(1.0 / d);
  const Eigen::LLT<MatrixXd> llt(uniform);
  const MatrixXd li = llt.matrixL().solve(MatrixXd::Identity(nf, nf));
  Eigen::SelfAdjointEigenSolver<MatrixXd> relative(li * design * li.transpose());
  cov.design_min = std::max(0.0, relative.eigenvalues()(0));
  const bool poor_scatter = cov.scatter_min < PcaCoverage::kMinScatter;
  const bool poor_design = cov.design_min < PcaCoverage::kMinDesign;
  cov.verdict = poor_scatter || poor_design ? PcaCoverageVerdict::kPoor : PcaCoverageVerdict::kGood;
  if (d != 3) {
    if (cov.verdict == PcaCoverageVerdict::kPoor) {
      cov.advice =
          "add positions with the field in directions between and opposite to those recorded, "
          "spread over the whole sphere";
    }
    return cov;
  }
  // d = 3: positions near each axis direction and between each pair of axes.
  const char* axis_name[3] = {"x", "y", "z"};
  std::vector<Eigen::Vector3d> dirs;
  for (int k = 0; k < 3; ++k) {
    for (int sgn : {1, -1}) {
      cov.cap_names.push_back(std::string(sgn > 0 ? "+" : "-") + axis_name[k]);
      dirs.push_back(sgn * Eigen::Vector3d::Unit(k));
    }
  }
  const int pairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (const auto& pr : pairs) {
    for (int s1 : {1, -1}) {
      for (int s2 : {1, -1}) {
        cov.cap_names.push_back(std::string(s1 > 0 ? "+" : "-") + axis_name[pr[0]] +
                                (s2 > 0 ? "+" : "-") + axis_name[pr[1]]);
        dirs.push_back((s1 * Eigen::Vector3d::Unit(pr[0]) + s2 * Eigen::Vector3d::Unit(pr[1])) /
                       std::sqrt(2.0));
      }
    }
  }
  cov.cap_positions.assign(dirs.size(), 0);
  for (int j = 0; j < n; ++j) {
    for (size_t c = 0; c < dirs.size(); ++c) {
      const double cos_angle = u.col(j).dot(dirs[c]);
      if (cos_angle >= (c < 6 ? kAxisCapCos : kEdgeCapCos)) ++cov.cap_positions[c];
    }
  }
  if (cov.verdict != PcaCoverageVerdict::kPoor) return cov;
  std::vector<std::string> parts;
  std::vector<bool> named(6, false);
  auto name_axis = [&](int k, int sign_index) {  // sign_index 0: +, 1: −
    if (named[2 * k + sign_index]) return;
    named[2 * k + sign_index] = true;
    parts.push_back(std::string("with the ") + (sign_index == 0 ? "+" : "-") + axis_name[k] +
                    " axis up");
  };
  // Axis directions with no position near them, both signs together where both are missing.
  for (int k = 0; k < 3; ++k) {
    const bool plus = cov.cap_positions[2 * k] == 0, minus = cov.cap_positions[2 * k + 1] == 0;
    if (plus && minus) {
      named[2 * k] = named[2 * k + 1] = true;
      parts.push_back(std::string("with the +") + axis_name[k] + " and with the -" + axis_name[k] +
                      " axis up");
    } else if (plus || minus) {
      name_axis(k, plus ? 0 : 1);
    }
  }
  // The sparser side of an axis: the one with fewer positions near it.
  auto sparse_side = [&](int k) {
    return cov.cap_positions[2 * k] <= cov.cap_positions[2 * k + 1] ? 0 : 1;
  };
  if (poor_scatter) {
    // The sparse direction is the eigenvector of the smallest scatter eigenvalue.
    Eigen::Index k;
    scatter.eigenvectors().col(0).cwiseAbs().maxCoeff(&k);
    if (!named[2 * k] && !named[2 * k + 1]) {
      named[2 * k] = named[2 * k + 1] = true;
      parts.push_back(std::string("with the +") + axis_name[k] + " and with the -" + axis_name[k] +
                      " axis up");
    }
  }
  if (poor_design) {
    // Pairs of axes with (almost) no position in between: the information on their u_k u_l term
    // (the angle between the axes), Σ_j 2 u_k² u_l² / n, below 0.3 of its uniform expectation
    // 2/15.
    std::vector<int> empty_pairs;
    for (int pi = 0; pi < 3; ++pi) {
      const auto uk = u.row(pairs[pi][0]).array(), ul = u.row(pairs[pi][1]).array();
      const double info = 2 * (uk * uk * ul * ul).sum() / n;
      if (info < 0.3 * 2.0 / 15.0) empty_pairs.push_back(pi);
    }
    if (empty_pairs.empty()) {
      // The weakest direction of the design: its largest term names what is missing.
      const VectorXd w = li.transpose() * relative.eigenvectors().col(0);
      Eigen::Index k;
      w.cwiseAbs().maxCoeff(&k);
      if (k >= nq) {  // a linear term (bias): the sparse side of that axis
        name_axis(static_cast<int>(k - nq), sparse_side(static_cast<int>(k - nq)));
      } else {
        int fidx = 0;
        for (int a = 0; a < 3; ++a) {
          for (int b = a; b < 3; ++b, ++fidx) {
            if (fidx != k) continue;
            if (a == b) {
              name_axis(a, sparse_side(a));
            } else {
              for (int pi = 0; pi < 3; ++pi) {
                if (pairs[pi][0] == a && pairs[pi][1] == b) empty_pairs.push_back(pi);
              }
            }
          }
        }
      }
    }
    if (!empty_pairs.empty()) {
      std::string list;
      for (size_t i = 0; i < empty_pairs.size(); ++i) {
        const int pi = empty_pairs[i];
        list += std::string(i == 0                        ? ""
                            : i + 1 == empty_pairs.size() ? " and "
                                                          : ", ") +
                "the " + axis_name[pairs[pi][0]] + " and " + axis_name[pairs[pi][1]] + " axes";
      }
      const int p0 = empty_pairs[0];
      parts.push_back("tilted about 45 degrees between " + list + " (e.g. with the +" +
                      axis_name[pairs[p0][0]] + "+" + axis_name[pairs[p0][1]] + " direction up)");
    }
  }
  if (parts.empty()) parts.push_back("spread over the whole sphere");
  cov.advice = "add positions ";
  for (size_t i = 0; i < parts.size(); ++i) {
    cov.advice += (i == 0 ? "" : i + 1 == parts.size() ? ", and " : ", ") + parts[i];
  }
  cov.advice += " (" + frame_note + ")";
  return cov;
}

Status Fail(Status s, PcaResult* result) {
  result->usable = false;
  result->reason = s.message();
  return s;
}

}  // namespace

const char* BiasModelName(BiasModel bias) {
  return bias == BiasModel::kEstimate ? "estimate" : "none";
}

const char* PcaInformationSolverName(PcaInformationSolver solver) {
  switch (solver) {
    case PcaInformationSolver::kDense:
      return "dense";
    case PcaInformationSolver::kLowRank:
      return "low_rank";
    default:
      return "auto";
  }
}

const char* PcaCoverageVerdictName(PcaCoverageVerdict verdict) {
  switch (verdict) {
    case PcaCoverageVerdict::kGood:
      return "good";
    case PcaCoverageVerdict::kPoor:
      return "poor";
    default:
      return "unknown";
  }
}

const char* PcaFrameName(PcaFrame frame) {
  switch (frame) {
    case PcaFrame::kCanonical:
      return "canonical";
    case PcaFrame::kNominal:
      return "nominal";
    default:
      return "";
  }
}

std::string PcaResult::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "pca: %s%s; d %d, %zu sensors, %d positions (min %d), bias %s, frame %s, rank gap "
                "%.4g, cost %.6g -> %.6g (%s, %d iterations)",
                usable ? "usable" : "not usable: ", usable ? "" : reason.c_str(), dimension,
                sensors.size(), positions, min_positions, BiasModelName(bias_model),
                frame == PcaFrame::kNone ? "-" : PcaFrameName(frame), rank_gap, cost_closed_form,
                cost, refined ? "refined" : "closed form", refine_iterations);
  return buf;
}

PcaCost EstimatePcaCost(int m, int n, int d, BiasModel bias, PcaInformationSolver solver) {
  const double mm = std::max(m, 0), nn = std::max(n, 0), dd = std::max(d, 1);
  const double p = bias == BiasModel::kEstimate ? dd + 1 : dd;
  const double np = p * mm;
  const double ng = dd * (dd - 1) / 2;
  const double r = nn * (dd - 1) + ng;
  const double k = std::min(mm, nn);
  const double nq = dd * (dd + 1) / 2 + dd + 1;
  // Shared: SVD of the readings (QR + small SVD), the quadric fit, positions on the sphere,
  // residuals, diagnostics, the gauge basis; a handful of m×n copies of the readings.
  const double shared_flops = 4 * mm * nn * k + 30 * k * k * k + 2 * nn * nq * nq +
                              60 * mm * nn * dd + 4 * np * ng * ng + 200 * nn * dd * dd;
  const double shared_bytes = 8 * (6 * mm * nn + mm * k + 2 * np * ng + nn * nq);
  const double step_shared = 20 * mm * nn * dd;  // residuals, gradient, one projection
  // Dense: assemble S (m² blocks), Cholesky, p·m solves for the diagonal blocks.
  const double dense_flops = mm * mm * dd * dd * p * p + np * np * ng * 2 + np * np * np / 3;
  const double dense_bytes = 8 * (2 * np * np + dd * dd * p * p);
  // Low rank: Y and D⁻¹Y, K = Λ⁻¹ + Yᵀ D⁻¹ Y, its eigen-decomposition.
  const double low_flops = 2 * np * r * r + 9 * r * r * r + 4 * np * r * p;
  const double low_bytes = 8 * (2 * np * r + 4 * r * r);
  PcaCost cost;
  cost.solver = solver;
  if (solver == PcaInformationSolver::kAuto) {
    cost.solver = low_flops + 2 * np * r * r < dense_flops + 2 * np * np * np
                      ? PcaInformationSolver::kLowRank
                      : PcaInformationSolver::kDense;
  }
  if (cost.solver == PcaInformationSolver::kLowRank) {
    cost.flops = shared_flops + low_flops + 2 * np * r * r;  // + B·Q for the blocks
    cost.flops_per_refine_iteration = step_shared + low_flops;
    cost.bytes = shared_bytes + low_bytes;
  } else {
    cost.flops = shared_flops + dense_flops + 2 * np * np * np;  // + the block solves
    cost.flops_per_refine_iteration = step_shared + dense_flops;
    cost.bytes = shared_bytes + dense_bytes;
  }
  return cost;
}

bool PcaOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& what) {
    if (error != nullptr) *error = what;
    return false;
  };
  if (dimension < 1 || dimension > kMaxDimension) {
    return fail("dimension must be between 1 and " + std::to_string(kMaxDimension));
  }
  if (magnitude && !(*magnitude > 0 && std::isfinite(*magnitude))) {
    return fail("magnitude must be a finite number > 0");
  }
  if (noise_std && !(*noise_std > 0 && std::isfinite(*noise_std))) {
    return fail("noise_std must be a finite number > 0");
  }
  if (nominal) {
    if (nominal->rows() != dimension) {
      return fail("nominal must have dimension = " + std::to_string(dimension) +
                  " numbers per sensor, not " + std::to_string(nominal->rows()));
    }
    if (nominal->cols() < 1) return fail("nominal must have at least one sensor");
    if (!nominal->allFinite()) return fail("nominal must contain finite numbers only");
  }
  if (max_refine_iterations < 1) return fail("max_refine_iterations must be >= 1");
  if (!(max_memory_bytes >= 0) || !std::isfinite(max_memory_bytes)) {
    return fail("max_memory_bytes must be a finite number >= 0 (0: no limit)");
  }
  if (!(max_flops >= 0) || !std::isfinite(max_flops)) {
    return fail("max_flops must be a finite number >= 0 (0: no limit)");
  }
  if (!(min_rank_gap > 1) || !std::isfinite(min_rank_gap)) {
    return fail("min_rank_gap must be a finite number > 1");
  }
  return true;
}

Eigen::MatrixXd CanonicalFrame(const Eigen::MatrixXd& a) {
  const Eigen::Index d = a.rows();
  Eigen::HouseholderQR<MatrixXd> qr(a);
  const MatrixXd q = qr.householderQ() * MatrixXd::Identity(d, d);
  MatrixXd h = q.transpose();
  const Eigen::Index k = std::min(d, a.cols());
  for (Eigen::Index i = 0; i < k; ++i) {
    if (qr.matrixQR()(i, i) < 0) h.row(i) *= -1;
  }
  return h;
}

double CalibrationError(const Eigen::MatrixXd& a_true, const Eigen::MatrixXd& a_hat) {
  return (CanonicalFrame(a_true) * a_true - CanonicalFrame(a_hat) * a_hat).norm();
}

Eigen::MatrixXd ProcrustesRotation(const Eigen::MatrixXd& from, const Eigen::MatrixXd& to,
                                   bool allow_reflection) {
  Eigen::JacobiSVD<MatrixXd> svd(to * from.transpose(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  MatrixXd u = svd.matrixU();
  const MatrixXd& v = svd.matrixV();
  if (!allow_reflection && (u * v.transpose()).determinant() < 0) {
    u.col(u.cols() - 1) *= -1;
  }
  return u * v.transpose();
}

namespace {

// The coverage of positions the fit failed on, seen through the nominal sensitivities (d×m):
// each position's field is the least-squares v_j = (N Nᵀ)⁻¹ N m_j of its readings (biases, when
// unknown, are ignored: a guide to which orientations are missing, not an estimate). Leaves the
// coverage unknown without a nominal or when the nominal axes do not span d dimensions.
void CoverageFromNominal(const MatrixXd& mm, const PcaOptions& options, PcaResult* result) {
  if (!options.nominal || options.nominal->cols() != mm.rows() || mm.cols() < 1) return;
  const MatrixXd& nom = *options.nominal;
  const Eigen::LDLT<MatrixXd> gram(nom * nom.transpose());
  if (gram.info() != Eigen::Success || !(gram.rcond() > 1e-12)) return;
  const MatrixXd v = gram.solve(nom * mm);
  result->coverage = Coverage(v, options.bias == BiasModel::kEstimate,
                              "axes of the nominal frame, through the nominal sensitivities");
}

// CalibratePca on readings divided by `unit` (a power of two, so exactly): every number of the
// result is in those units until CalibratePca multiplies it back. Messages quote readings in the
// caller's units.
Status CalibrateScaled(const PcaProblem& problem, const PcaOptions& options, double unit,
                       PcaResult* result) {
  const MatrixXd& mm = problem.m;
  const int d = options.dimension;
  const int m = static_cast<int>(mm.rows());
  const int n = static_cast<int>(mm.cols());
  const bool affine = options.bias == BiasModel::kEstimate;
  const int p = affine ? d + 1 : d;
  result->dimension = d;
  result->bias_model = options.bias;
  result->positions = n;
  result->min_positions = affine ? d * (d + 3) / 2 : d * (d + 1) / 2;
  result->magnitude_known = options.magnitude.has_value();
  const double c = options.magnitude.value_or(1.0);
  result->magnitude = c;
  result->noise_std_given = options.noise_std.has_value();

  if (m < 1 || n < 1) {
    return Fail(Status::InvalidInput(Reason::kInvalidRecording,
                                     "the recording has no readings (" + std::to_string(m) +
                                         " sensors, " + std::to_string(n) + " positions)"),
                result);
  }
  if (!mm.allFinite()) {
    return Fail(Status::InvalidInput(Reason::kInvalidRecording, "readings must be finite numbers"),
                result);
  }
  if (!problem.sensor_names.empty() && static_cast<int>(problem.sensor_names.size()) != m) {
    return Fail(
        Status::InvalidInput("sensor_names has " + std::to_string(problem.sensor_names.size()) +
                             " names for " + std::to_string(m) + " sensors"),
        result);
  }
  if (!problem.position_labels.empty() && static_cast<int>(problem.position_labels.size()) != n) {
    return Fail(Status::InvalidInput("position_labels has " +
                                     std::to_string(problem.position_labels.size()) +
                                     " labels for " + std::to_string(n) + " positions"),
                result);
  }
  for (const VectorXd* x : {&problem.removed_bias, &problem.removed_bias_std}) {
    if (x->size() != 0 && (x->size() != m || !x->allFinite())) {
      return Fail(Status::InvalidInput("removed bias (and its std) must have one finite value "
                                       "per sensor"),
                  result);
    }
  }
  if (options.nominal && options.nominal->cols() != m) {
    return Fail(Status::InvalidInput("nominal has " + std::to_string(options.nominal->cols()) +
                                     " sensors but the recording has " + std::to_string(m))
                    .WithField("nominal"),
                result);
  }
  if (m < d) {
    return Fail(Status::NotDeterminable(
                    Reason::kTooFewSensors,
                    std::to_string(m) + " sensor" + (m == 1 ? "" : "s") + " cannot determine " +
                        std::to_string(d) +
                        "-dimensional sensitivity vectors: at least d = " + std::to_string(d) +
                        " sensors are needed (the paper's inequality 17); record with at "
                        "least " +
                        std::to_string(d) + " sensors, or set dimension to " + std::to_string(m) +
                        " if the field only has that many components"),
                result);
  }
  if (n < result->min_positions) {
    CoverageFromNominal(mm, options, result);
    return Fail(
        Status::NotDeterminable(
            Reason::kTooFewPositions,
            std::to_string(n) + " position" + (n == 1 ? "" : "s") + " recorded, but dimension " +
                std::to_string(d) + (affine ? " with unknown biases" : "") + " needs at least " +
                std::to_string(result->min_positions) + " (" + (affine ? "d(d+3)/2" : "d(d+1)/2") +
                "); record at least " + std::to_string(result->min_positions) +
                " positions with orientations spread over the sphere (more is better: the error "
                "falls as 1/sqrt(n))"),
        result);
  }

  // Budget, before any work.
  result->cost_estimate = EstimatePcaCost(m, n, d, options.bias, options.information_solver);
  {
    const PcaCost& cost = result->cost_estimate;
    const double flops =
        cost.flops +
        (options.refine ? options.max_refine_iterations * cost.flops_per_refine_iteration : 0.0);
    const std::string size = std::to_string(m) + " sensors × " + std::to_string(n) +
                             " positions (dimension " + std::to_string(d) +
                             (affine ? ", biases estimated" : "") + ")";
    if (options.max_memory_bytes > 0 && cost.bytes > options.max_memory_bytes) {
      return Fail(
          Status::NotDeterminable(
              Reason::kProblemTooLarge,
              "the problem is too large: " + size + " needs about " +
                  Num(cost.bytes / (1024.0 * 1024)) +
                  " MiB of working memory, more than "
                  "the limit max_memory_bytes = " +
                  Num(options.max_memory_bytes / (1024.0 * 1024)) +
                  " MiB; split the sensors into smaller groups (each with the same positions) "
                  "or record fewer positions")
              .WithField("max_memory_bytes"),
          result);
    }
    if (options.max_flops > 0 && flops > options.max_flops) {
      return Fail(Status::NotDeterminable(
                      Reason::kProblemTooLarge,
                      "the problem is too large: " + size + " needs about " + Num(flops) +
                          " floating-point operations" +
                          (options.refine ? " (with max_refine_iterations = " +
                                                std::to_string(options.max_refine_iterations) + ")"
                                          : std::string()) +
                          ", more than the limit max_flops = " + Num(options.max_flops) +
                          "; split the sensors into smaller groups (each with the same positions), "
                          "record fewer positions, or refine with fewer iterations")
                      .WithField("max_flops"),
                  result);
    }
  }

  auto stopped = [&](const std::string& stage) {
    return Fail(StoppedStatus(*options.stop, "pca: " + stage), result);
  };
  if (StopRequested(options.stop)) return stopped("closed form");

  // Closed form.
  Fit fit;
  Status s = affine ? ClosedFormAffine(mm, d, c, options, result, &fit)
                    : ClosedFormBiasFree(mm, d, c, options, result, &fit);
  if (StopRequested(options.stop)) return stopped("closed form");
  if (!s.ok()) {
    CoverageFromNominal(mm, options, result);
    return Fail(s, result);
  }
  fit.v = ProjectPositions(mm, fit.a, fit.b, c);
  result->cost_closed_form = Cost(mm, fit);
  result->cost = result->cost_closed_form;
  if (options.refine) {
    result->refine_iterations =
        Refine(mm, c, affine, options.max_refine_iterations, result->cost_estimate.solver, &fit,
               &result->cost, options.stop);
    if (StopRequested(options.stop)) return stopped("refinement");
    result->refined = result->cost < result->cost_closed_form;
    if (!result->refined) {
      result->warnings.push_back(
          "The maximum-likelihood refinement did not lower the cost; the closed-form estimate is "
          "reported.");
    }
  }

  // Diagnostics at the estimate.
  const MatrixXd res = Residuals(mm, fit);
  result->residual_rms = (res.rowwise().squaredNorm() / n).cwiseSqrt();
  {
    const MatrixXd g = fit.a * fit.a.transpose();
    const MatrixXd v_free = g.llt().solve(fit.a * (mm.colwise() - fit.b));
    result->magnitude_error = v_free.colwise().norm().transpose().array() - c;
  }
  result->degrees_of_freedom = m * n - (p * m + (d - 1) * n - d * (d - 1) / 2);
  if (result->degrees_of_freedom > 0) {
    result->noise_std_estimated = std::sqrt(2 * result->cost / result->degrees_of_freedom);
  }
  result->noise_std = options.noise_std.value_or(result->noise_std_estimated);
  if (!options.noise_std && result->degrees_of_freedom <= 0) {
    result->warnings.push_back(
        "The noise level cannot be estimated: with " + std::to_string(n) + " positions and " +
        std::to_string(m) + " sensors there is no redundancy (degrees of freedom " +
        std::to_string(result->degrees_of_freedom) +
        "), so the uncertainties are undefined; give noise_std or record more positions.");
  }
  if (options.noise_std && result->degrees_of_freedom >= 20 &&
      (result->noise_std_estimated > 2 * *options.noise_std ||
       result->noise_std_estimated < 0.5 * *options.noise_std)) {
    result->warnings.push_back("The residuals suggest a noise level of " +
                               Num(unit * result->noise_std_estimated) +
                               ", not the given noise_std " + Num(unit * *options.noise_std) +
                               ": the uncertainties use the given value; check it.");
  }
  std::string outlier_warning;
  int outlier_count = 0;
  {
    // Outlying positions: |v_j| far from c compared with the spread of the others (robust:
    // median absolute deviation), e.g. the device moved while a reading was averaged.
    const VectorXd& err = result->magnitude_error;
    std::vector<double> sorted(err.data(), err.data() + n);
    std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
    const double med = sorted[n / 2];
    for (double& x : sorted) x = std::abs(x - med);
    std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
    const double spread = 1.4826 * sorted[n / 2];
    std::string outliers;
    int count = 0;
    for (int j = 0; j < n && n >= 10; ++j) {
      if (std::abs(err(j) - med) > 6 * spread && std::abs(err(j)) > 1e-9 * c) {
        if (++count <= 10) {
          outliers += (outliers.empty() ? "" : ", ") + (problem.position_labels.empty()
                                                            ? std::to_string(j + 1)
                                                            : problem.position_labels[j]);
        }
      }
    }
    if (count > 0) {
      // Pushed after the coverage is known (a poorly spread set also leaves positions off).
      outlier_warning = std::to_string(count) + " position" + (count == 1 ? "" : "s") + " (" +
                        outliers + (count > 10 ? ", ..." : "") +
                        ") disagree with a field of constant magnitude far more than the others "
                        "(see magnitude_error): ";
      outlier_count = count;
    }
  }
  if (result->rank_gap < 10 * options.min_rank_gap) {
    result->warnings.push_back(
        "The gap between singular values " + std::to_string(d) + " and " + std::to_string(d + 1) +
        " is small (" + Num(result->rank_gap) + "): the positions barely span " +
        std::to_string(d) +
        " dimensions above the noise; the estimate may be poor. Record more orientations spread "
        "over the sphere.");
  }

  // Uncertainty (frame-free), at unit noise then scaled; the p×p diagonal blocks of S⁺ in the
  // equilibrated coordinates θ'_i = [c·a_i; b_i] (see ReducedFisher).
  std::vector<MatrixXd> cov_blocks;
  if (std::isfinite(result->noise_std)) {
    const ReducedFisher solver(c * fit.a, fit.v / c, affine, result->cost_estimate.solver,
                               options.stop);
    if (StopRequested(options.stop)) return stopped("uncertainty");
    if (solver.ok()) {
      cov_blocks = solver.DiagonalBlocks();
      VectorXd unscale = VectorXd::Constant(p, 1.0 / c);
      if (affine) unscale(d) = 1;
      const double var = result->noise_std * result->noise_std;
      for (MatrixXd& blk : cov_blocks)
        blk = var * unscale.asDiagonal() * blk * unscale.asDiagonal();
    } else {
      result->warnings.push_back(
          "The Fisher information is singular beyond the rotation gauge: some parameters are not "
          "determined by these positions, so uncertainties are undefined.");
    }
  }
  const bool have_cov = !cov_blocks.empty();

  // Frame.
  MatrixXd h;
  std::string frame_note;
  if (options.nominal) {
    result->frame = PcaFrame::kNominal;
    h = ProcrustesRotation(fit.a, *options.nominal, true);
    result->reflection = h.determinant() < 0;
    frame_note = "axes of the nominal frame";
  } else {
    result->frame = PcaFrame::kCanonical;
    h = CanonicalFrame(fit.a);
    frame_note =
        "axes of the canonical frame: x along the first sensor's axis, y in the plane of "
        "the first two";
  }
  result->a = h * fit.a;
  result->v = h * fit.v;
  result->b = fit.b;
  if (problem.removed_bias.size() == m) result->b += problem.removed_bias;

  if (!result->magnitude_known) {
    result->warnings.push_back(
        "The field magnitude was not given: scale factors are relative (the magnitude is taken as "
        "1, the paper's Remark 2), and scale_std describes those relative scale factors.");
  }
  std::string undefined_std;  // sensors whose variance came out negative or not finite
  int undefined_count = 0;
  // sqrt of a variance; NaN (never 0) when it is not a finite number >= 0 up to rounding.
  auto std_of = [&](double variance, double scale, const std::string& name) {
    if (std::isfinite(variance) && variance >= -1e-10 * scale)
      return std::sqrt(std::max(0.0, variance));
    if (++undefined_count <= 5) undefined_std += (undefined_std.empty() ? "" : ", ") + name;
    return kNaN;
  };
  result->sensors.resize(m);
  for (int i = 0; i < m; ++i) {
    PcaSensorEstimate& se = result->sensors[i];
    se.name = problem.sensor_names.empty() ? "s" + std::to_string(i) : problem.sensor_names[i];
    se.sensitivity = result->a.col(i);
    se.scale = se.sensitivity.norm();
    se.axis = se.sensitivity / se.scale;
    se.bias = result->b(i);
    double bias_var = 0;
    if (problem.removed_bias_std.size() == m) {
      bias_var += problem.removed_bias_std(i) * problem.removed_bias_std(i);
    }
    if (have_cov) {
      const MatrixXd& blk = cov_blocks[i];
      const MatrixXd ca = blk.topLeftCorner(d, d);
      const double norm = fit.a.col(i).norm();
      const VectorXd u = fit.a.col(i) / norm;
      const double tr = std::abs(ca.trace());
      se.scale_std = std_of(u.dot(ca * u), tr, se.name);
      const MatrixXd proj = MatrixXd::Identity(d, d) - u * u.transpose();
      se.axis_std_rad = std_of((proj * ca * proj).trace(), tr, se.name) / norm;
      if (affine) {
        bias_var += blk(d, d);
        se.bias_std = std_of(bias_var, std::abs(blk(d, d)), se.name);
      } else {
        se.bias_std = std::sqrt(bias_var);
      }
    } else if (affine) {
      se.bias_std = kNaN;
    } else {
      se.bias_std = std::sqrt(bias_var);
    }
    if (options.nominal) {
      const VectorXd nom = options.nominal->col(i);
      const double cosang = nom.norm() > 0 ? se.axis.dot(nom) / nom.norm() : 1.0;
      const double deg = std::acos(std::clamp(cosang, -1.0, 1.0)) * 180.0 / M_PI;
      if (deg > 10) {
        result->warnings.push_back("Sensor " + se.name + "'s axis is " + Fmt("%.1f", deg) +
                                   " degrees from its nominal direction: check the nominal "
                                   "sensitivities and the sensor order.");
      }
    }
  }
  if (undefined_count > 0) {
    result->warnings.push_back(
        "The uncertainty of " + std::to_string(undefined_count) + " sensor" +
        (undefined_count == 1 ? "" : "s") + " (" + undefined_std +
        (undefined_count > 5 ? ", ..." : "") +
        ") is undefined: the Fisher information is numerically singular for them (a variance "
        "came out negative or not finite); their *_std are NaN.");
  }

  if (StopRequested(options.stop)) return stopped("uncertainty");
  // Coverage of the sphere, in the result's frame.
  result->coverage = Coverage(result->v, affine, frame_note);
  if (result->coverage.verdict == PcaCoverageVerdict::kPoor) {
    result->warnings.push_back(
        "The orientations are poorly spread over the sphere (coverage: scatter_min " +
        Num(result->coverage.scatter_min) + ", design_min " + Num(result->coverage.design_min) +
        ", 1 for a uniform spread): some parameters rest on very few positions, so a small error "
        "there moves the estimate far; " +
        result->coverage.advice + ".");
  }
  if (!outlier_warning.empty()) {
    const bool poor = result->coverage.verdict == PcaCoverageVerdict::kPoor;
    result->warnings.push_back(
        outlier_warning +
        (poor ? "the orientations are poorly spread (see the coverage warning), so a few "
                "positions decide the fit and the others cannot agree with it; or was the device "
                "moving, or the field disturbed, while averaging? Add the advised positions "
                "before removing any."
              : "was the device moving, or the field disturbed, while averaging? Consider "
                "re-recording or removing " +
                    std::string(outlier_count == 1 ? "it." : "them.")));
  }

  // Guards: a usable result has finite parameters.
  std::string non_finite;
  if (!result->a.allFinite())
    non_finite = "sensitivity";
  else if (!result->b.allFinite())
    non_finite = "bias";
  else if (!result->v.allFinite())
    non_finite = "field per position";
  else if (!result->residual_rms.allFinite())
    non_finite = "residual";
  else if (!std::isfinite(result->cost))
    non_finite = "cost";
  if (non_finite.empty()) {
    for (const PcaSensorEstimate& se : result->sensors) {
      if (!(std::isfinite(se.scale) && se.scale > 0) || !se.axis.allFinite()) {
        return Fail(
            Status::NotDeterminable(
                Reason::kDeadSensor,
                "sensor " + se.name + "'s axis is undefined: its sensitivity is " + Num(se.scale) +
                    " (its readings do not change with the orientation: a dead or "
                    "disconnected sensor?); check it, or remove it from the recording"),
            result);
      }
    }
  }
  if (!non_finite.empty()) {
    return Fail(Status::NotDeterminable(
                    Reason::kIllConditioned,
                    "the computed " + non_finite +
                        " is not a finite number: the readings are too ill-conditioned for double "
                        "precision (check their units and range, and that the field was applied)"),
                result);
  }
  result->usable = true;
  return Status::Ok();
}

}  // namespace

Status CalibratePca(const PcaProblem& problem, const PcaOptions& options, PcaResult* result) {
  *result = PcaResult();
  std::string error;
  if (!options.IsValid(&error))
    return Fail(Status::InvalidInput(Reason::kInvalidConfig, "pca options: " + error), result);
  // Equilibrate the readings: divide them by the power of two nearest their largest magnitude,
  // exactly, so that neither squares nor products of readings overflow or underflow and every
  // tolerance below is relative. The result is multiplied back at the end.
  const double largest =
      problem.m.size() > 0 && problem.m.allFinite() ? problem.m.cwiseAbs().maxCoeff() : 0.0;
  if (!(largest > 0) || !std::isfinite(largest))
    return CalibrateScaled(problem, options, 1.0, result);
  const double unit = std::ldexp(1.0, std::ilogb(largest));
  PcaProblem scaled;
  scaled.m = problem.m / unit;
  scaled.sensor_names = problem.sensor_names;
  scaled.position_labels = problem.position_labels;
  scaled.removed_bias = problem.removed_bias / unit;
  scaled.removed_bias_std = problem.removed_bias_std / unit;
  PcaOptions scaled_options = options;
  if (options.noise_std) scaled_options.noise_std = *options.noise_std / unit;
  const Status s = CalibrateScaled(scaled, scaled_options, unit, result);
  // Back to the caller's units: sensitivities, biases, noise and costs scale with the readings;
  // g (and the ellipsoid's shape) with their inverse square; the field and angles not at all.
  PcaResult& r = *result;
  r.a *= unit;
  r.b *= unit;
  r.singular_values *= unit;
  r.g_eigenvalues /= unit * unit;
  r.residual_rms *= unit;
  r.noise_std *= unit;
  r.noise_std_estimated *= unit;
  r.cost_closed_form *= unit * unit;
  r.cost *= unit * unit;
  for (PcaSensorEstimate& se : r.sensors) {
    se.sensitivity *= unit;
    se.scale *= unit;
    se.bias *= unit;
    se.scale_std *= unit;
    se.bias_std *= unit;
  }
  return s;
}

}  // namespace calibd::core
