// Implementation notes.
//
// The closed forms and the refinement are in core/pca_fit.cc, the maximum likelihood and Fisher
// information in core/pca_fisher.cc, the coverage in core/pca_coverage.cc; CalibrateScaled below
// runs the stages of core/pca_stages.h.
//
// Scaling. CalibratePca divides the readings by a power of two near their largest magnitude
// (exact) and the Fisher information is built in the coordinates θ'_i = [c·a_i; b_i] with the
// positions on the unit sphere: one common factor on all sensitivity columns and one on all bias
// columns keeps the minimum-norm gauge, so σ are unchanged while S no longer mixes the scales
// 1 and c² (at c = 1e-6 the bias columns were 1e12 times the others and the σ came out NaN).

#include "core/pca.h"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>

#include "core/pca_internal.h"
#include "core/pca_stages.h"

namespace calibd::core {

using Eigen::MatrixXd;
using Eigen::VectorXd;

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

using pca_internal::Fail;

// CalibratePca on readings divided by `unit` (a power of two, so exactly): every number of the
// result is in those units until CalibratePca multiplies it back. Messages quote readings in the
// caller's units. The stages (core/pca_stages.h) in order; each one that fails has already
// marked the result unusable.
Status CalibrateScaled(const PcaProblem& problem, const PcaOptions& options, double unit,
                       PcaResult* result) {
  namespace pi = pca_internal;
  const pi::PcaSetup setup(problem, options, unit);
  Status s = pi::ValidateProblem(setup, result);
  if (s.ok()) s = pi::CheckBudget(setup, result);
  pi::Fit fit;
  if (s.ok()) s = pi::FitModel(setup, result, &fit);
  if (!s.ok()) return s;
  const pi::OutlierReport outliers = pi::Diagnose(setup, fit, result);
  std::vector<MatrixXd> cov_blocks;
  s = pi::EstimateUncertainty(setup, fit, result, &cov_blocks);
  if (!s.ok()) return s;
  const std::string frame_note = pi::ExpressInFrame(setup, fit, result);
  pi::ReportSensors(setup, fit, cov_blocks, result);
  pi::ApplySigmaBasis(setup, result);
  if (StopRequested(options.stop)) return pi::Stopped(setup, "uncertainty", result);
  pi::AssessCoverage(setup, frame_note, outliers, result);
  return pi::CheckFinite(result);
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
    if (se.crb) {
      se.crb->scale_std *= unit;
      se.crb->bias_std *= unit;
    }
  }
  return s;
}

}  // namespace calibd::core
