// The stages of CalibratePca (core/pca_stages.h).
#include "core/pca_stages.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace calibd::core::pca_internal {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// Outlying positions: |v_j| far from c compared with the spread of the others (robust: median
// absolute deviation), e.g. the device moved while a reading was averaged. Reads
// result->magnitude_error.
OutlierReport FindOutliers(const PcaSetup& setup, const PcaResult* result) {
  const PcaProblem& problem = setup.problem;
  const int n = setup.n;
  const double c = setup.c;
  OutlierReport report;
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
        outliers +=
            (outliers.empty() ? "" : ", ") +
            (problem.position_labels.empty() ? std::to_string(j + 1) : problem.position_labels[j]);
      }
    }
  }
  if (count > 0) {
    // Pushed after the coverage is known (a poorly spread set also leaves positions off).
    report.warning = std::to_string(count) + " position" + (count == 1 ? "" : "s") + " (" +
                     outliers + (count > 10 ? ", ..." : "") +
                     ") disagree with a field of constant magnitude far more than the others "
                     "(see magnitude_error): ";
    report.count = count;
  }
  return report;
}

}  // namespace

PcaSetup::PcaSetup(const PcaProblem& problem, const PcaOptions& options, double unit)
    : problem(problem),
      options(options),
      unit(unit),
      d(options.dimension),
      m(static_cast<int>(problem.m.rows())),
      n(static_cast<int>(problem.m.cols())),
      affine(options.bias == BiasModel::kEstimate),
      p(affine ? d + 1 : d),
      c(options.magnitude.value_or(1.0)) {}

Status Fail(Status s, PcaResult* result) {
  result->usable = false;
  result->reason = s.message();
  return s;
}

Status Stopped(const PcaSetup& setup, const std::string& stage, PcaResult* result) {
  return Fail(StoppedStatus(*setup.options.stop, "pca: " + stage), result);
}

Status ValidateProblem(const PcaSetup& setup, PcaResult* result) {
  const PcaProblem& problem = setup.problem;
  const PcaOptions& options = setup.options;
  const MatrixXd& mm = problem.m;
  const int d = setup.d, m = setup.m, n = setup.n;
  const bool affine = setup.affine;
  result->dimension = d;
  result->bias_model = options.bias;
  result->positions = n;
  result->min_positions = affine ? d * (d + 3) / 2 : d * (d + 1) / 2;
  result->magnitude_known = options.magnitude.has_value();
  result->magnitude = setup.c;
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
                    pca_reason::kTooFewSensors,
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
  return Status::Ok();
}

Status CheckBudget(const PcaSetup& setup, PcaResult* result) {
  const PcaOptions& options = setup.options;
  const int d = setup.d, m = setup.m, n = setup.n;
  const bool affine = setup.affine;
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
  return Status::Ok();
}

Status FitModel(const PcaSetup& setup, PcaResult* result, Fit* fit_out) {
  const PcaOptions& options = setup.options;
  const MatrixXd& mm = setup.problem.m;
  const int d = setup.d;
  const bool affine = setup.affine;
  const double c = setup.c;
  Fit& fit = *fit_out;
  if (StopRequested(options.stop)) return Stopped(setup, "closed form", result);

  // Closed form.
  Status s = affine ? ClosedFormAffine(mm, d, c, options, result, &fit)
                    : ClosedFormBiasFree(mm, d, c, options, result, &fit);
  if (StopRequested(options.stop)) return Stopped(setup, "closed form", result);
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
    if (StopRequested(options.stop)) return Stopped(setup, "refinement", result);
    result->refined = result->cost < result->cost_closed_form;
    if (!result->refined) {
      result->warnings.push_back(
          "The maximum-likelihood refinement did not lower the cost; the closed-form estimate is "
          "reported.");
    }
  }
  return Status::Ok();
}

OutlierReport Diagnose(const PcaSetup& setup, const Fit& fit, PcaResult* result) {
  const PcaOptions& options = setup.options;
  const MatrixXd& mm = setup.problem.m;
  const int d = setup.d, m = setup.m, n = setup.n, p = setup.p;
  const double c = setup.c, unit = setup.unit;
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
  // (Residuals above the given noise_std scale the σ instead: ApplySigmaBasis.)
  if (options.noise_std && result->degrees_of_freedom >= 20 &&
      result->noise_std_estimated < 0.5 * *options.noise_std) {
    result->warnings.push_back(
        "The residuals suggest a noise level of " + Num(unit * result->noise_std_estimated) +
        " reading units, not the given noise_std " + Num(unit * *options.noise_std) +
        " reading units: the uncertainties use the given value; check it.");
  }
  OutlierReport outliers = FindOutliers(setup, result);
  if (result->rank_gap < 10 * options.min_rank_gap) {
    result->warnings.push_back(
        "The gap between singular values " + std::to_string(d) + " and " + std::to_string(d + 1) +
        " is small (their ratio " + Num(result->rank_gap) + "): the positions barely span " +
        std::to_string(d) +
        " dimensions above the noise; the estimate may be poor. Record more orientations spread "
        "over the sphere.");
  }
  return outliers;
}

Status EstimateUncertainty(const PcaSetup& setup, const Fit& fit, PcaResult* result,
                           std::vector<MatrixXd>* cov_blocks_out) {
  const PcaOptions& options = setup.options;
  const int d = setup.d, p = setup.p;
  const bool affine = setup.affine;
  const double c = setup.c;
  std::vector<MatrixXd>& cov_blocks = *cov_blocks_out;
  // Uncertainty (frame-free), at unit noise then scaled; the p×p diagonal blocks of S⁺ in the
  // equilibrated coordinates θ'_i = [c·a_i; b_i] (see ReducedFisher).
  if (std::isfinite(result->noise_std)) {
    const ReducedFisher solver(c * fit.a, fit.v / c, affine, result->cost_estimate.solver,
                               options.stop);
    if (StopRequested(options.stop)) return Stopped(setup, "uncertainty", result);
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
  return Status::Ok();
}

std::string ExpressInFrame(const PcaSetup& setup, const Fit& fit, PcaResult* result) {
  const PcaProblem& problem = setup.problem;
  const PcaOptions& options = setup.options;
  const int m = setup.m;
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
  return frame_note;
}

void ReportSensors(const PcaSetup& setup, const Fit& fit, const std::vector<MatrixXd>& cov_blocks,
                   PcaResult* result) {
  const PcaProblem& problem = setup.problem;
  const PcaOptions& options = setup.options;
  const int d = setup.d, m = setup.m;
  const bool affine = setup.affine;
  const bool have_cov = !cov_blocks.empty();
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
}

void ApplySigmaBasis(const PcaSetup& setup, PcaResult* result) {
  const PcaOptions& options = setup.options;
  const int dof = result->degrees_of_freedom;
  if (!options.noise_std) {
    // σ of a reading from the residuals themselves: no white-noise bound apart from them.
    result->uncertainty_basis = "chi2_scaled";
    return;
  }
  for (PcaSensorEstimate& se : result->sensors)
    se.crb = PcaSensorEstimate::Bound{se.scale_std, se.axis_std_rad, se.bias_std};
  result->uncertainty_basis = "crb";
  if (dof <= 0 || !(result->noise_std_estimated >= 0)) return;
  const double ratio = result->noise_std_estimated / *options.noise_std;
  result->chi2_per_dof = ratio * ratio;
  // χ²/dof of consistent residuals is within 3·√(2/dof) of 1 (its σ is √(2/dof)).
  if (result->chi2_per_dof <= 1 + 3 * std::sqrt(2.0 / dof)) return;
  result->uncertainty_basis = "chi2_scaled";
  const bool estimated_bias = setup.affine;
  for (PcaSensorEstimate& se : result->sensors) {
    se.scale_std *= ratio;
    se.axis_std_rad *= ratio;
    if (estimated_bias) se.bias_std *= ratio;  // a removed bias keeps its own measurement's σ
  }
  result->warnings.push_back(
      "The residuals are " + Fmt("%.2f", ratio) + " times the given noise_std (chi2/dof " +
      Fmt("%.3g", result->chi2_per_dof) + " over " + std::to_string(dof) +
      " degrees of freedom): the sensors' σ are the Cramér–Rao bound × " + Fmt("%.2f", ratio) +
      " (χ²-scaled); the bound itself is in uncertainty.sensors[].crb. Check noise_std, or what "
      "disturbed the positions.");
}

void AssessCoverage(const PcaSetup& setup, const std::string& frame_note,
                    const OutlierReport& outliers, PcaResult* result) {
  const bool affine = setup.affine;
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
  if (!outliers.warning.empty()) {
    const bool poor = result->coverage.verdict == PcaCoverageVerdict::kPoor;
    result->warnings.push_back(
        outliers.warning +
        (poor ? "the orientations are poorly spread (see the coverage warning), so a few "
                "positions decide the fit and the others cannot agree with it; or was the device "
                "moving, or the field disturbed, while averaging? Add the advised positions "
                "before removing any."
              : "was the device moving, or the field disturbed, while averaging? Consider "
                "re-recording or removing " +
                    std::string(outliers.count == 1 ? "it." : "them.")));
  }
}

Status CheckFinite(PcaResult* result) {
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
                pca_reason::kDeadSensor,
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

}  // namespace calibd::core::pca_internal
