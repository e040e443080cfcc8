#include "core/mag.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/mag_internal.h"

namespace calibd::core {
namespace {

using Eigen::Matrix3d;
using Eigen::MatrixXd;
using Eigen::Vector3d;
using Eigen::VectorXd;
using mag_internal::Ellipsoid;
using mag_internal::Matrix9d;
using mag_internal::Sym;
using mag_internal::Vector6d;
using mag_internal::Vector9d;

std::string Fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

Status Invalid(const std::string& what) { return Status::InvalidInput("mag: " + what); }

// An orthonormal basis (columns) of the plane orthogonal to the unit vector u.
Eigen::Matrix<double, 3, 2> Tangent(const Vector3d& u) {
  const Vector3d a = std::abs(u.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
  const Vector3d b1 = u.cross(a).normalized();
  Eigen::Matrix<double, 3, 2> b;
  b << b1, u.cross(b1);
  return b;
}

// Stage 1: the algebraic ellipsoid fit (see core/mag.h), on readings centred on their mean and
// scaled by their RMS spread so that the design matrix is well conditioned.
Status StartFit(const Eigen::Matrix3Xd& y, Ellipsoid* e) {
  const Vector3d mean = y.rowwise().mean();
  const double scale = std::sqrt((y.colwise() - mean).squaredNorm() / y.cols());
  if (!(scale > 0)) {
    return Status::NotDeterminable(Reason::kNoSignal, "mag: all magnetometer readings are equal");
  }
  Eigen::Matrix<double, 10, 10> dtd = Eigen::Matrix<double, 10, 10>::Zero();
  for (Eigen::Index i = 0; i < y.cols(); ++i) {
    const Vector3d z = (y.col(i) - mean) / scale;
    Eigen::Matrix<double, 10, 1> row;
    row << z.x() * z.x(), z.y() * z.y(), z.z() * z.z(), 2 * z.x() * z.y(), 2 * z.x() * z.z(),
        2 * z.y() * z.z(), z.x(), z.y(), z.z(), 1;
    dtd.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  dtd = dtd.selfadjointView<Eigen::Lower>();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 10, 10>> es(dtd);
  const Eigen::Matrix<double, 10, 1> v = es.eigenvectors().col(0);
  Matrix3d q;
  q << v(0), v(3), v(4), v(3), v(1), v(5), v(4), v(5), v(2);
  const Vector3d l = v.segment<3>(6);
  Eigen::SelfAdjointEigenSolver<Matrix3d> qe(q);
  if (qe.eigenvalues()(0) * qe.eigenvalues()(2) <= 0) {
    return Status::NotDeterminable(
        Reason::kNotAnEllipsoid,
        "mag: the magnetometer readings lie on no ellipsoid (the field changed while recording, "
        "or the device was not turned through enough orientations)");
  }
  const Vector3d hz = -0.5 * q.ldlt().solve(l);
  const double k = hz.dot(q * hz) - v(9);
  const Matrix3d m = q / k;  // (z − hz)ᵀ m (z − hz) = 1
  Eigen::SelfAdjointEigenSolver<Matrix3d> me(m);
  if (!(me.eigenvalues()(0) > 0)) {
    return Status::NotDeterminable(Reason::kNotAnEllipsoid,
                                   "mag: the magnetometer readings lie on no ellipsoid");
  }
  const Matrix3d a_z = me.eigenvectors() *
                       me.eigenvalues().cwiseSqrt().cwiseInverse().asDiagonal() *
                       me.eigenvectors().transpose();
  e->h = mean + scale * hz;
  e->a = scale * a_z;
  const Matrix3d a_inv = e->a.inverse();
  e->u.resize(3, y.cols());
  for (Eigen::Index i = 0; i < y.cols(); ++i)
    e->u.col(i) = (a_inv * (y.col(i) - e->h)).normalized();
  return Status::Ok();
}

// ∂r/∂θ of a sample whose field direction is u: −I for h, −E_k u for the entries a_k of A (E_k
// the symmetric basis matrices). Linear in (one, u): the sample's Jacobian is ThetaJacobian(1, u).
Eigen::Matrix<double, 3, 9> ThetaJacobian(double one, const Vector3d& u) {
  Eigen::Matrix<double, 3, 9> jt;
  jt << -one, 0, 0, -u(0), -u(1), -u(2), 0, 0, 0,  //
      0, -one, 0, 0, -u(0), 0, -u(1), -u(2), 0,    //
      0, 0, -one, 0, 0, -u(0), 0, -u(1), -u(2);
  return jt;
}

// The per-sample pieces of one linearisation (see MaximumLikelihood). Reused from one
// linearisation to the next (no reallocation).
struct Linearized {
  std::vector<Eigen::Matrix2d> huu;
  std::vector<Eigen::Matrix<double, 2, 9>> hut;
  std::vector<Eigen::Vector2d> gu;
  std::vector<Eigen::Matrix<double, 3, 2>> tangent;
  std::vector<Vector9d> score;  // w Jθᵀ r per sample (for the sandwich; empty unless asked)
  Matrix9d htt = Matrix9d::Zero();
  Vector9d gt = Vector9d::Zero();
};

// Linearises the cost at `e`; `with_scores`: also each sample's score (l->score).
void Linearize(const Eigen::Matrix3Xd& y, const VectorXd& w, const Ellipsoid& e, bool with_scores,
               Linearized* l) {
  const Eigen::Index n = y.cols();
  l->huu.resize(n);
  l->hut.resize(n);
  l->gu.resize(n);
  l->tangent.resize(n);
  l->score.resize(with_scores ? n : 0);
  l->gt.setZero();
  // Σ w Jθᵀ Jθ from the moments Σ w φ φᵀ of φ = (1, u), Jθ being linear in φ.
  Eigen::Matrix4d moments = Eigen::Matrix4d::Zero();
  for (Eigen::Index i = 0; i < n; ++i) {
    const Vector3d u = e.u.col(i);
    const Vector3d r = y.col(i) - e.h - e.a * u;
    const Eigen::Matrix<double, 3, 9> jt = ThetaJacobian(1, u);
    l->tangent[i] = Tangent(u);
    const Eigen::Matrix<double, 3, 2> ju = -e.a * l->tangent[i];
    const Eigen::Matrix<double, 3, 2> wju = w(i) * ju;
    // Products with a dimension of 9 written as lazy (coefficient-wise) products: Eigen would
    // send them to its blocked large-matrix kernel, several times slower at these sizes.
    l->huu[i].noalias() = wju.transpose() * ju;
    l->hut[i].noalias() = wju.transpose().lazyProduct(jt);
    l->gu[i].noalias() = wju.transpose() * r;
    const Vector9d score = jt.transpose().lazyProduct(w(i) * r);
    if (with_scores) l->score[i] = score;
    l->gt += score;
    Eigen::Vector4d phi;
    phi << 1, u;
    moments.noalias() += w(i) * phi * phi.transpose();
  }
  std::array<Eigen::Matrix<double, 3, 9>, 4> basis;  // Jθ = Σ_p φ_p basis[p]
  basis[0] = ThetaJacobian(1, Vector3d::Zero());
  for (int k = 0; k < 3; ++k) basis[1 + k] = ThetaJacobian(0, Vector3d::Unit(k));
  l->htt.setZero();
  for (int p = 0; p < 4; ++p) {
    for (int q = 0; q < 4; ++q) {
      l->htt.noalias() += moments(p, q) * basis[p].transpose().lazyProduct(basis[q]);
    }
  }
}

double Cost(const Eigen::Matrix3Xd& y, const VectorXd& w, const Ellipsoid& e) {
  double c = 0;
  for (Eigen::Index i = 0; i < y.cols(); ++i) {
    c += w(i) * (y.col(i) - e.h - e.a * e.u.col(i)).squaredNorm();
  }
  return c;
}

// The reduced (Schur) system of a linearisation with Marquardt damping λ on every block.
void Reduce(const Linearized& l, double lambda, Matrix9d* h, Vector9d* g) {
  *h = l.htt;
  h->diagonal() *= 1 + lambda;
  *g = l.gt;
  for (size_t i = 0; i < l.huu.size(); ++i) {
    Eigen::Matrix2d huu = l.huu[i];
    huu.diagonal() *= 1 + lambda;
    const Eigen::Matrix<double, 2, 9> inv_hut = huu.inverse() * l.hut[i];
    h->noalias() -= l.hut[i].transpose().lazyProduct(inv_hut);
    g->noalias() -= inv_hut.transpose().lazyProduct(l.gu[i]);
  }
}

// Stage 2: Levenberg-Marquardt with the weights w. Returns the iterations used.
Status MaximumLikelihood(const Eigen::Matrix3Xd& y, const VectorXd& w, const MagOptions& options,
                         int max_iterations, Linearized* workspace, Ellipsoid* e, int* iterations) {
  Linearized& l = *workspace;
  double lambda = 1e-6;
  double cost = Cost(y, w, *e);
  for (int it = 0; it < max_iterations; ++it) {
    if (StopRequested(options.stop)) return StoppedStatus(*options.stop, "mag: fit");
    ++*iterations;
    Linearize(y, w, *e, /*with_scores=*/false, &l);
    bool accepted = false;
    while (!accepted && lambda < 1e12) {
      Matrix9d h;
      Vector9d g;
      Reduce(l, lambda, &h, &g);
      const Vector9d dt = -h.ldlt().solve(g);
      if (!dt.allFinite()) {
        lambda *= 10;
        continue;
      }
      Ellipsoid next = *e;
      next.h += dt.head<3>();
      next.a += Sym(dt.tail<6>());
      for (Eigen::Index i = 0; i < y.cols(); ++i) {
        Eigen::Matrix2d huu = l.huu[i];
        huu.diagonal() *= 1 + lambda;
        const Eigen::Vector2d du = -huu.inverse() * (l.gu[i] + l.hut[i].lazyProduct(dt));
        next.u.col(i) = (e->u.col(i) + l.tangent[i] * du).normalized();
      }
      const double next_cost = Cost(y, w, next);
      if (next_cost < cost) {
        const double decrease = (cost - next_cost) / std::max(cost, 1e-300);
        *e = std::move(next);
        cost = next_cost;
        lambda = std::max(lambda / 3, 1e-12);
        accepted = true;
        if (decrease < options.tolerance) return Status::Ok();
      } else {
        lambda *= 4;
      }
    }
    if (!accepted) return Status::Ok();  // no step lowers the cost: a minimum
  }
  return Status::Ok();
}

VectorXd ResidualNorms(const Eigen::Matrix3Xd& y, const Ellipsoid& e) {
  VectorXd r(y.cols());
  for (Eigen::Index i = 0; i < y.cols(); ++i) r(i) = (y.col(i) - e.h - e.a * e.u.col(i)).norm();
  return r;
}

double Median(VectorXd v) {
  if (v.size() == 0) return 0;
  const Eigen::Index mid = v.size() / 2;
  std::nth_element(v.data(), v.data() + mid, v.data() + v.size());
  return v(mid);
}

// Stage 2 on the readings y, from `e`: Levenberg-Marquardt with the weights w, then
// options.robust_passes reweightings (Cauchy weights from the residual norms, σ̂ from their
// median), each followed by a fit. `reweight_first`: weigh by e's residuals before the first fit
// (e already fits y closely). A fit whose weights the next replaces runs at most kPassIterations
// (enough for the residuals the weights come from: a log with disturbances converges only
// linearly before it is weighted); the last runs to convergence.
Status RobustFit(const Eigen::Matrix3Xd& y, const MagOptions& options, bool reweight_first,
                 Linearized* workspace, Ellipsoid* e, VectorXd* w, int* iterations) {
  constexpr int kPassIterations = 5;
  const int passes = options.robust_scale > 0 ? options.robust_passes : 0;
  // Cauchy weights from e's residuals; false when they are rounding only (a noise-free log).
  auto reweight = [&] {
    const VectorXd r = ResidualNorms(y, *e);
    const double sigma = Median(r) / 0.6745;
    if (!(sigma > 1e-9 * e->a.norm())) return false;
    for (Eigen::Index i = 0; i < y.cols(); ++i) {
      const double z = r(i) / (options.robust_scale * sigma);
      (*w)(i) = 1 / (1 + z * z);
    }
    return true;
  };
  int pass = 0;
  if (reweight_first && passes > 0 && !reweight()) pass = passes;
  for (;; ++pass) {
    const int cap =
        pass < passes ? std::min(kPassIterations, options.max_iterations) : options.max_iterations;
    if (Status s = MaximumLikelihood(y, *w, options, cap, workspace, e, iterations); !s.ok()) {
      return s;
    }
    if (pass >= passes) return Status::Ok();
    // Weighting ends early on a noise-free log: the next fit converges as weighted so far.
    if (!reweight()) pass = passes - 1;
  }
}

// The errors-in-variables offsets (stage 2b): a reading's distance to the ellipsoid along the
// outward normal n has the mean (σ²/2) κ (κ the sum of the principal curvatures at the foot
// point), not 0 (the foot point is fitted to the noise too: Neyman-Scott), so plain maximum
// likelihood returns an ellipsoid too large by about σ²/radius. Returns the columns (σ²/2) κ_i n_i
// at e's foot points; the readings minus them have a zero-mean distance. For the surface
// pᵀ M p = 1, M = A⁻², p = A u: n = M p / |M p|, κ = (tr M |M p|² − (M p)ᵀ M (M p)) / |M p|³.
Eigen::Matrix3Xd CurvatureOffsets(const Ellipsoid& e, double sigma) {
  const Matrix3d a_inv = e.a.inverse();
  const Matrix3d m = a_inv * a_inv;
  const double trace = m.trace();
  Eigen::Matrix3Xd c(3, e.u.cols());
  for (Eigen::Index i = 0; i < e.u.cols(); ++i) {
    const Vector3d g = m * (e.a * e.u.col(i));
    const double g_norm = g.norm();
    const double kappa = (trace * g_norm * g_norm - g.dot(m * g)) / (g_norm * g_norm * g_norm);
    c.col(i) = 0.5 * sigma * sigma * kappa * g / g_norm;
  }
  return c;
}

// Newey-West over batches of `seconds` of consecutive samples, lag one batch (Bartlett weight ½:
// noise correlated across a batch boundary counts too; positive semi-definite by construction):
// M = Σ_b s_b s_bᵀ + ½ Σ_b (s_b s_{b−1}ᵀ + s_{b−1} s_bᵀ), s_b the sum of the batch's `score`.
Matrix9d BatchMeat(const std::vector<Vector9d>& score, const VectorXd& t, double seconds,
                   int64_t* batches) {
  Matrix9d meat = Matrix9d::Zero();
  *batches = 0;
  Vector9d s = Vector9d::Zero(), previous = Vector9d::Zero();
  double batch_start = t.size() ? t(0) : 0;
  auto close_batch = [&] {
    meat += s * s.transpose() + 0.5 * (s * previous.transpose() + previous * s.transpose());
    ++*batches;
    previous = s;
    s.setZero();
  };
  for (size_t i = 0; i < score.size(); ++i) {
    if (t(i) - batch_start >= seconds) {
      close_batch();
      batch_start = t(i);
    }
    s += score[i];
  }
  close_batch();
  return meat;
}

// The two covariances of θ = (h, a) (stage 3).
struct Covariances {
  Matrix9d h_inv = Matrix9d::Zero();  // the reduced information's inverse (σ̂² h_inv = crb)
  Matrix9d crb = Matrix9d::Zero();
  Matrix9d sandwich = Matrix9d::Zero();       // over batches that leave min_batches
  Matrix9d sandwich_long = Matrix9d::Zero();  // also over those that leave min_long_batches
  double sigma = 0;                           // σ̂, reading units
  std::vector<MagBlockingStep> blocking;      // every batch length tried
  bool ok = false;
};

Covariances Uncertainty(const Eigen::Matrix3Xd& y, const VectorXd& t, const VectorXd& w,
                        const Ellipsoid& e, const MagOptions& options, Linearized* workspace) {
  Covariances c;
  Linearized& l = *workspace;
  Linearize(y, w, e, /*with_scores=*/true, &l);
  Matrix9d h;
  Vector9d g;
  Reduce(l, 0, &h, &g);
  Eigen::LDLT<Matrix9d> ldlt(h);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return c;
  const Matrix9d h_inv = ldlt.solve(Matrix9d::Identity());
  c.h_inv = h_inv;
  const double weight_sum = w.sum();
  c.sigma = std::sqrt(Cost(y, w, e) / std::max(weight_sum - 9, 1.0));
  c.crb = c.sigma * c.sigma * h_inv;
  // Each sample's reduced score (its share of the Schur-reduced gradient).
  std::vector<Vector9d> score(y.cols());
  for (Eigen::Index i = 0; i < y.cols(); ++i) {
    score[i] = l.score[i] - l.hut[i].transpose().lazyProduct(l.huu[i].inverse() * l.gu[i]);
  }
  // Batches of `options.batch_seconds`, then twice, four times... as long as at least
  // `options.min_batches` remain (the blocking method): residuals correlated longer than a batch
  // (a hand-held log's slow disturbances, drift, orientation-dependent misfit) make the sandwich
  // grow with the batch length until the batches outlast the correlation; the largest is kept.
  // Batches down to `options.min_long_batches` (noisier) count only for `sandwich_long`, the
  // primary once the sandwich is (see ChoosePrimary): a hand-held log's misfit can stay
  // correlated longer than the batches that leave `min_batches` (no plateau yet).
  c.sandwich = c.sandwich_long = c.crb;  // too few batches for a sandwich: the bound alone
  double largest = 0, largest_long = 0;
  for (double seconds = options.batch_seconds;; seconds *= 2) {
    int64_t batches = 0;
    const Matrix9d meat = BatchMeat(score, t, seconds, &batches);
    if (batches <= 9 || (seconds > options.batch_seconds && batches < options.min_long_batches)) {
      break;
    }
    const Matrix9d sandwich = h_inv * meat * h_inv * (static_cast<double>(batches) / (batches - 9));
    const double size = (sandwich.diagonal().array() / c.crb.diagonal().array()).sum();
    c.blocking.push_back({seconds, batches, std::sqrt(size / 9)});
    if (size > largest && (seconds == options.batch_seconds || batches >= options.min_batches)) {
      largest = size;
      c.sandwich = sandwich;
    }
    if (size > largest_long) {
      largest_long = size;
      c.sandwich_long = sandwich;
    }
  }
  c.ok = c.crb.allFinite() && c.sandwich.allFinite() && c.sandwich_long.allFinite();
  return c;
}

// Sample i's w_i J̃_iᵀ (9×3): the reduced Jacobian's transpose, w_i jtᵀ (I − Π_i), Π_i the
// projection onto the span of ∂r/∂u_i (the direction's two tangent unknowns). −h_inv times it is
// the fit's response to a change of reading i (a change of the hard iron at that sample).
Eigen::Matrix<double, 9, 3> ReducedJacobianT(const Ellipsoid& e, const Linearized& l, double w,
                                             Eigen::Index i) {
  const Eigen::Matrix<double, 3, 2> ju = -e.a * l.tangent[i];
  const Matrix3d projection = ju * (ju.transpose() * ju).inverse() * ju.transpose();
  const Eigen::Matrix<double, 3, 9> jt = ThetaJacobian(1, e.u.col(i));
  return w * jt.transpose() * (Matrix3d::Identity() - projection);
}

// Stage 3c: the hard iron's wander (see MagOptions::offset_wander). The log is cut into
// segments; each one's hard iron with A held at the fit is h + δ_k, δ_k = −G_k⁻¹ b_k (G_k the
// segment's reduced hard-iron information, b_k its reduced score), its noise C_k = σ̂_d² G_k⁻¹
// with σ̂_d² = Σ w |r_i − r_{i−1}|² / (2 Σ w) (coloured noise counts as wander: conservative).
// Consecutive differences d_k = δ_{k+1} − δ_k of a random walk of rate q (per axis) have E d_k² =
// C_k + C_{k+1} + q (τ_k + τ_{k+1})/3 (τ the segments' lengths): q by weighted moments, weights
// 1/(E d_k²)², iterated. The covariance returned is the wander's share of ½ E (θ̂ − θ̂')(θ̂ − θ̂')ᵀ, θ̂'
// the fit of the next log as long, made the same way: θ̂ − θ̂' = Σ_i L_i (w(t_i) − w(t_i + T)), L_i =
// −h_inv w_i J̃_iᵀ, whose covariance under the random walk is Σ_k Δt_k (head_k Q head_kᵀ + tail_k Q
// tail_kᵀ) (head and tail the sums of L_i before and after the k-th interval). Σ L_i is exactly the
// hard iron's selector (a constant offset moves h alone), so for the hard iron it is q T/3, the
// offset's Allan variance at T.
struct Wander {
  Vector3d rate = Vector3d::Zero();  // q per axis, reading units² / s
  Matrix9d cov = Matrix9d::Zero();
  int segments = 0;
  double segment_seconds = 0;
  double noise_variance = 0;  // σ̂_d², reading units²
  bool ok = false;
};

Wander EstimateWander(const Eigen::Matrix3Xd& y, const VectorXd& t, const VectorXd& w,
                      const Ellipsoid& e, const Covariances& c, const Linearized& l,
                      const MagOptions& options) {
  Wander out;
  const Eigen::Index n = y.cols();
  if (n < 2 || l.tangent.size() != static_cast<size_t>(n)) return out;
  const double length = t(n - 1) - t(0);
  const double dt = length / static_cast<double>(n - 1);
  out.segment_seconds = std::max(length / options.wander_segments, options.wander_min_seconds);
  // Per segment: G_k and b_k; the noise from the residuals' successive differences, which a
  // slow wander does not reach (a sandwich over the segment's batches would count the wander
  // inside the segment as noise and take it out of the differences: the rate then read 0.56×
  // the simulated walk's).
  struct Segment {
    double start = 0;
    Matrix3d g = Matrix3d::Zero();
    Vector3d b = Vector3d::Zero();
  };
  std::vector<Segment> segments;
  using Matrix93 = Eigen::Matrix<double, 9, 3>;
  Matrix93 total = Matrix93::Zero();  // Σ M_i, M_i = w_i J̃_iᵀ, for the propagation below
  double diff_sum = 0, diff_weight = 0;
  Vector3d previous = Vector3d::Zero();
  for (Eigen::Index i = 0; i < n; ++i) {
    if (segments.empty() || t(i) - segments.back().start >= out.segment_seconds) {
      segments.push_back({t(i), Matrix3d::Zero(), Vector3d::Zero()});
    }
    // Each sample counts fully unless disturbed: the robust weights fall with the residual, so
    // they would pull each segment's hard iron towards the fit's (the rate then reads low).
    const double weight = w(i) >= options.disturbed_weight ? 1.0 : 0.0;
    const Eigen::Matrix<double, 9, 3> unit = ReducedJacobianT(e, l, 1, i);  // linear in w
    total += w(i) * unit;
    const Eigen::Matrix<double, 9, 3> jr = weight * unit;
    const Vector3d r = y.col(i) - e.h - e.a * e.u.col(i);
    // The hard-iron rows: jt_h = −I, so −w (I − Π) r is the score and w (I − Π) the information.
    segments.back().g -= jr.topRows<3>();
    segments.back().b += jr.topRows<3>() * r;
    if (i > 0) {
      diff_sum += weight * (r - previous).squaredNorm();
      diff_weight += weight;
    }
    previous = r;
  }
  const double noise_variance = diff_weight > 0 ? diff_sum / (2 * diff_weight) : 0;
  out.noise_variance = noise_variance;
  // A last segment shorter than half the others joins the one before.
  if (segments.size() > 1 && (t(n - 1) - segments.back().start) < 0.5 * out.segment_seconds) {
    segments[segments.size() - 2].g += segments.back().g;
    segments[segments.size() - 2].b += segments.back().b;
    segments.pop_back();
  }
  std::vector<Vector3d> delta;
  std::vector<Vector3d> noise;  // diag C_k
  std::vector<double> tau;
  for (size_t k = 0; k < segments.size(); ++k) {
    const double end = k + 1 < segments.size() ? segments[k + 1].start : t(n - 1) + dt;
    Eigen::LDLT<Matrix3d> ldlt(segments[k].g);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) continue;
    const Matrix3d g_inv = ldlt.solve(Matrix3d::Identity());
    delta.push_back(-g_inv * segments[k].b);
    noise.push_back(noise_variance * g_inv.diagonal());
    tau.push_back(end - segments[k].start);
  }
  out.segments = static_cast<int>(delta.size());
  if (delta.size() < 3) return out;
  for (int a = 0; a < 3; ++a) {
    double q = 0;
    for (int iteration = 0; iteration < 20; ++iteration) {
      double num = 0, den = 0;
      for (size_t k = 0; k + 1 < delta.size(); ++k) {
        const double d2 = std::pow(delta[k + 1](a) - delta[k](a), 2);
        const double cn = noise[k](a) + noise[k + 1](a);
        const double ell = (tau[k] + tau[k + 1]) / 3;
        const double weight = 1 / std::pow(cn + q * ell, 2);
        num += weight * (d2 - cn);
        den += weight * ell;
      }
      const double next = den > 0 ? std::max(num / den, 0.0) : 0;
      if (std::abs(next - q) <= 1e-6 * std::max(next, 1e-300)) {
        q = next;
        break;
      }
      q = next;
    }
    out.rate(a) = q;
  }
  // The propagation: heads and tails of the M_i (their total from the first pass).
  const Matrix3d q = out.rate.asDiagonal();
  Matrix9d sum = Matrix9d::Zero();
  Matrix93 head = Matrix93::Zero();
  for (Eigen::Index i = 0; i < n; ++i) {
    head += ReducedJacobianT(e, l, w(i), i);
    const double step = i + 1 < n ? t(i + 1) - t(i) : dt;  // the last: up to the next log's start
    const Matrix93 tail = total - head;                    // the samples after this interval
    sum += step * (head * q * head.transpose() + tail * q * tail.transpose());
  }
  out.cov = 0.5 * c.h_inv * sum * c.h_inv;
  out.ok = out.cov.allFinite();
  return out;
}

// ∂P/∂a_k for P = F A⁻¹ (k < 6).
std::vector<Matrix3d> SoftIronDirections(const Matrix3d& a, double field) {
  const Matrix3d a_inv = a.inverse();
  std::vector<Matrix3d> d(6);
  for (int k = 0; k < 6; ++k) {
    Vector6d ek = Vector6d::Zero();
    ek(k) = 1;
    d[k] = -field * a_inv * Sym(ek) * a_inv;
  }
  return d;
}

MagStd StdOf(const Matrix9d& cov, const std::vector<Matrix3d>& dp) {
  MagStd s;
  s.hard_iron = cov.diagonal().head<3>().cwiseMax(0).cwiseSqrt();
  s.soft_iron = mag_internal::EntryStd(dp, cov.bottomRightCorner<6, 6>());
  return s;
}

// Residual norms in µT (|m_i| − F) for the RMS figures.
double FieldResidualRms(const Eigen::Matrix3Xd& y, const Eigen::Vector3d& h, const Matrix3d& s,
                        double field, double scale_ut, const VectorXd* mask) {
  double sum = 0;
  int64_t n = 0;
  for (Eigen::Index i = 0; i < y.cols(); ++i) {
    if (mask != nullptr && (*mask)(i) == 0) continue;
    const double d = ((s * (y.col(i) - h)).norm() - field) * scale_ut;
    sum += d * d;
    ++n;
  }
  return n ? std::sqrt(sum / n) : 0;
}

Status CheckProblem(const MagProblem& p) {
  if (p.y.cols() < 20) return Invalid("fewer than 20 magnetometer samples");
  if (p.t.size() != p.y.cols())
    return Invalid("the time and magnetometer columns differ in length");
  if (!p.y.allFinite()) return Invalid("a magnetometer reading is not finite");
  for (Eigen::Index i = 1; i < p.t.size(); ++i) {
    if (!(p.t(i) > p.t(i - 1))) return Invalid("sample times do not increase");
  }
  for (const MagStatic& s : p.statics) {
    if (s.first < 0 || s.last < s.first || s.last >= p.y.cols()) {
      return Invalid("a static's sample range lies outside the log");
    }
  }
  return Status::Ok();
}

// Readings on a plane (a circle: the device turned about one axis only, e.g. flat on a table) do
// not determine an ellipsoid: kPoorOrientationCoverage naming the axis to bring along the field.
// The spread across the plane against along it, from the readings' covariance (its smallest over
// its largest eigenvalue: about 1 for a sphere's worth of orientations, 0 for a circle).
Status CheckNotPlanar(const Eigen::Matrix3Xd& y, const MagOptions& options) {
  const Eigen::Matrix3Xd c = y.colwise() - y.rowwise().mean();
  Eigen::SelfAdjointEigenSolver<Matrix3d> es(c * c.transpose() / static_cast<double>(y.cols()));
  const double ratio = es.eigenvalues()(0) / std::max(es.eigenvalues()(2), 1e-300);
  if (ratio >= options.min_coverage_eigenvalue / 10) return Status::Ok();
  int axis = 0;
  es.eigenvectors().col(0).cwiseAbs().maxCoeff(&axis);
  const std::string a(1, "xyz"[axis]);
  return Status::NotDeterminable(
      Reason::kPoorOrientationCoverage,
      "mag: the readings lie close to a plane (spread across it " + Fmt("%.2g", std::sqrt(ratio)) +
          " of the spread along it): the device was turned about its " + a +
          " axis only, which does not determine the soft iron; tilt it and turn it over so that "
          "the field also comes along its +" +
          a + " and -" + a + " axes");
}

// RMS over θ of σ(sandwich) / σ(bound).
double SandwichRatio(const Matrix9d& sandwich, const Matrix9d& crb) {
  double sum = 0;
  for (int k = 0; k < 9; ++k) sum += sandwich(k, k) / std::max(crb(k, k), 1e-300);
  return std::sqrt(sum / 9);
}

// The primary σ (stage 3's rule: the basis decided on the sandwich over batches that leave
// min_batches; a sandwich primary also over those that leave min_long_batches) and its warning.
void ChoosePrimary(const Covariances& c, const std::vector<Matrix3d>& dp, const MagOptions& options,
                   MagResult* r) {
  r->crb = StdOf(c.crb, dp);
  r->sandwich_ratio = SandwichRatio(c.sandwich, c.crb);
  if (r->sandwich_ratio > options.sandwich_margin) {
    r->basis = "sandwich";
    r->std = StdOf(c.sandwich_long, dp);
    r->sandwich_ratio = SandwichRatio(c.sandwich_long, c.crb);
    r->warnings.push_back("σ is the residual-aware sandwich, " + Fmt("%.2g", r->sandwich_ratio) +
                          "× the white-noise bound: the residuals are correlated in time "
                          "(disturbances, vibration or a model error)");
  } else {
    r->basis = "crb";
    r->std = r->crb;
  }
}

// The blocking's plateau check (MagResult::plateau) and its warning: only where σ is the
// sandwich (the residuals are correlated at all). Where the bound is the primary, a growth at the
// last step alone is that step's noise: its 15 or so batches' small-sample factor n_b/(n_b − 9)
// is 2.5, and 1 of 6 short white-noise logs grew 1.42× there (tests/methods/mag_method_test.cc).
void CheckPlateau(const Covariances& c, const MagOptions& options, MagResult* r) {
  r->blocking = c.blocking;
  const size_t k = c.blocking.size();
  if (k < 2 || r->basis != "sandwich") return;
  const double growth = c.blocking[k - 1].ratio / c.blocking[k - 2].ratio;
  if (growth <= options.plateau_growth) return;
  r->plateau = false;
  r->warnings.push_back(
      "the sandwich's blocking reaches no plateau: its σ grew " + Fmt("%.2f", growth) + "× from " +
      Fmt("%.0f", c.blocking[k - 2].seconds) + " s to " + Fmt("%.0f", c.blocking[k - 1].seconds) +
      " s batches (the longest the log allows): the residuals (offsets) wander over longer than "
      "that, and σ is a lower bound");
}

}  // namespace

Status CheckMagReadingsNotPlanar(const Eigen::Matrix3Xd& y, const MagOptions& options) {
  return CheckNotPlanar(y, options);
}

Status MagOptions::Validate() const {
  if (!(field >= 0) || !std::isfinite(field)) return Invalid("field must be >= 0 µT");
  if (!(microtesla_per_unit > 0) || !std::isfinite(microtesla_per_unit)) {
    return Invalid("microtesla_per_unit must be > 0");
  }
  if (max_iterations < 1) return Invalid("max_iterations must be >= 1");
  if (!(tolerance > 0)) return Invalid("tolerance must be > 0");
  if (!(robust_scale >= 0)) return Invalid("robust_scale must be >= 0");
  if (robust_passes < 0) return Invalid("robust_passes must be >= 0");
  if (!(disturbed_weight > 0 && disturbed_weight < 1)) {
    return Invalid("disturbed_weight must lie in (0, 1)");
  }
  if (!(max_disturbed_fraction > 0 && max_disturbed_fraction <= 1)) {
    return Invalid("max_disturbed_fraction must lie in (0, 1]");
  }
  if (!(batch_seconds > 0)) return Invalid("batch_seconds must be > 0");
  if (min_batches <= 9) return Invalid("min_batches must be > 9");
  if (min_long_batches <= 9 || min_long_batches > min_batches) {
    return Invalid("min_long_batches must be > 9 and <= min_batches");
  }
  if (!(span_merge_seconds >= 0)) return Invalid("span_merge_seconds must be >= 0");
  if (!(sandwich_margin >= 1)) return Invalid("sandwich_margin must be >= 1");
  if (!(plateau_growth > 1)) return Invalid("plateau_growth must be > 1");
  if (wander_segments < 4) return Invalid("wander_segments must be >= 4");
  if (!(wander_min_seconds >= 4 * batch_seconds)) {
    return Invalid("wander_min_seconds must be >= 4 × batch_seconds");
  }
  if (!(min_coverage_eigenvalue > 0 && min_coverage_eigenvalue <= 1)) {
    return Invalid("min_coverage_eigenvalue must lie in (0, 1]");
  }
  if (min_alignment_statics < 7) {
    return Invalid(
        "min_alignment_statics must be >= 7 (the alignment's σ from the statics' scatter needs 3 "
        "degrees of freedom over its 4 unknowns)");
  }
  return Status::Ok();
}

Status CalibrateMag(const MagProblem& problem, const MagOptions& options, MagResult* result) {
  *result = MagResult();
  if (Status s = options.Validate(); !s.ok()) return s;
  if (Status s = CheckProblem(problem); !s.ok()) return s;
  const Eigen::Matrix3Xd& y = problem.y;
  const Eigen::Index n = y.cols();
  result->samples = n;
  if (Status s = CheckNotPlanar(y, options); !s.ok()) return s;
  Ellipsoid e;
  if (Status s = StartFit(y, &e); !s.ok()) return s;
  VectorXd w = VectorXd::Ones(n);
  Linearized workspace;  // the per-sample pieces, reused by every fit
  if (Status s =
          RobustFit(y, options, /*reweight_first=*/false, &workspace, &e, &w, &result->iterations);
      !s.ok()) {
    return s;
  }
  // Stage 2b: the errors-in-variables correction, one round (the offsets move the fit by
  // O(σ²/radius), which changes the offsets only at the next order).
  Eigen::Matrix3Xd y_corrected;
  if (options.errors_in_variables) {
    const double sigma = Median(ResidualNorms(y, e)) / 0.6745;
    if (sigma > 1e-9 * e.a.norm()) {
      y_corrected = y - CurvatureOffsets(e, sigma);
      if (Status s = RobustFit(y_corrected, options, /*reweight_first=*/true, &workspace, &e, &w,
                               &result->iterations);
          !s.ok()) {
        return s;
      }
    }
  }
  const Eigen::Matrix3Xd& y_fit = y_corrected.size() ? y_corrected : y;
  const VectorXd residual = ResidualNorms(y_fit, e) * options.microtesla_per_unit;
  result->disturbed_spans = mag_internal::DisturbedSpans(problem.t, w, residual, options);
  for (const MagSpan& s : result->disturbed_spans) result->disturbed_samples += s.samples;
  result->coverage = mag_internal::AssessCoverage(e.u, w, options);
  // The model's parameters.
  result->field = options.field > 0 ? options.field : 1;
  result->field_estimate = std::cbrt(e.a.determinant()) * options.microtesla_per_unit;
  result->hard_iron = e.h;
  result->soft_iron_symmetric = result->field * e.a.inverse();
  result->soft_iron = result->soft_iron_symmetric;
  if (!result->soft_iron.allFinite() || !e.h.allFinite()) {
    return Status::NotDeterminable(
        Reason::kIllConditioned, "mag: the fit's values are not finite (check the readings' unit)");
  }
  // Stage 3.
  const Covariances c = Uncertainty(y_fit, problem.t, w, e, options, &workspace);
  if (!c.ok) {
    return Status::NotDeterminable(Reason::kSingularInformation,
                                   "mag: the log does not determine every soft-iron entry");
  }
  result->noise_std = c.sigma;
  const std::vector<Matrix3d> dp = SoftIronDirections(e.a, result->field);
  ChoosePrimary(c, dp, options, result);
  CheckPlateau(c, options, result);
  // The ellipsoid's covariance behind the primary σ (the alignment carries it through).
  Matrix9d primary = result->basis == "sandwich" ? c.sandwich_long : c.crb;
  const Matrix9d without_wander = primary;
  if (!result->plateau && result->basis == "sandwich" && options.offset_wander) {
    const Wander wander = EstimateWander(y_fit, problem.t, w, e, c, workspace, options);
    result->wander_segments = wander.segments;
    result->wander_segment_seconds = wander.segment_seconds;
    if (wander.ok) {
      result->wander_rate = wander.rate.cwiseSqrt();
      result->wander_included = true;
      // The noise's share: the white-noise bound with σ̂_d, which the wander does not reach.
      // Every sandwich counts the wander's level in its batches' scores, so with it the wander
      // would count twice (the 2 s batches': simulated halves' soft iron z RMS 0.73; the
      // longest: 0.65; this: 0.90, and a fixed log under 30 walks 0.94).
      primary = wander.noise_variance * c.h_inv + wander.cov;
      result->std = StdOf(primary, dp);
      const double length = problem.t(n - 1) - problem.t(0);
      // The plateau warning's last clause ("σ is a lower bound") becomes what σ now holds.
      std::string& warning = result->warnings.back();
      warning.erase(std::min(warning.size(), warning.rfind(", and σ is a lower bound")));
      warning += "; σ predicts the next log as long as this one (" + Fmt("%.0f", length) +
                 " s): the white-noise bound at the sample-to-sample noise plus the hard "
                 "iron's wander, a random walk of " +
                 Fmt("%.3g", result->wander_rate(0)) + ", " + Fmt("%.3g", result->wander_rate(1)) +
                 ", " + Fmt("%.3g", result->wander_rate(2)) +
                 " reading units/√s (x, y, z) from the hard irons of " +
                 std::to_string(wander.segments) + " segments of " +
                 Fmt("%.0f", wander.segment_seconds) + " s";
    }
  }
  // Residual RMS before (identity, no offset, against the data's own field) and after.
  const double f_ut = options.field > 0 ? options.field : result->field_estimate;
  result->residual_rms_before =
      FieldResidualRms(y, Vector3d::Zero(), Matrix3d::Identity(),
                       f_ut / options.microtesla_per_unit, options.microtesla_per_unit, nullptr);
  const double to_ut = options.field > 0 ? 1 : result->field_estimate;
  result->residual_rms_after =
      FieldResidualRms(y, e.h, result->soft_iron_symmetric, result->field, to_ut, nullptr);
  const VectorXd clean = (w.array() >= options.disturbed_weight).cast<double>();
  result->residual_rms_clean =
      FieldResidualRms(y, e.h, result->soft_iron_symmetric, result->field, to_ut, &clean);
  // Stage 4.
  const Eigen::MatrixXd primary_dynamic = primary;
  mag_internal::EstimateAlignment(problem, options, e, without_wander, c.crb, result,
                                  &primary_dynamic);
  const double disturbed = static_cast<double>(result->disturbed_samples) / n;
  if (disturbed > options.max_disturbed_fraction) {
    return Status::NotDeterminable(Reason::kFieldDisturbed,
                                   "mag: " + Fmt("%.0f", 100 * disturbed) +
                                       " % of the samples are disturbed (over " +
                                       Fmt("%.0f", 100 * options.max_disturbed_fraction) +
                                       " %): record again away from iron, motors and cables");
  }
  if (result->disturbed_samples > 0) {
    result->warnings.push_back(std::to_string(result->disturbed_spans.size()) +
                               " disturbed span(s), " + std::to_string(result->disturbed_samples) +
                               " samples, were down-weighted (diagnostics list them)");
  }
  return Status::Ok();
}

}  // namespace calibd::core
