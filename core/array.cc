#include "core/array.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <thread>

#include "core/array_model.h"
#include "core/block_lm.h"
#include "core/stop_token.h"

namespace calibd::core {
namespace {

using array_model::ConstMap3X;
using array_model::Data;
using array_model::Mat3;
using array_model::MotionModel;
using array_model::MotionPass;
using array_model::MotionStates;
using array_model::MotionSums;
using array_model::PositionsProblem;
using array_model::Vec3;
using array_model::Weights;

// ----- Helpers for the result.
std::string Format(const char* fmt, double a) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, a);
  return buf;
}

std::string Fmt(double v) { return Format("%.3g", v); }

constexpr char kRecordAdvice[] =
    "record the array while twisting it by hand about all three axes (changing the rotation axis "
    "continually, fast turns and sudden stops), for at least a few seconds";

ArrayExcitation ComputeExcitation(const Mat3& AtA, double noise_floor) {
  ArrayExcitation ex;
  Eigen::SelfAdjointEigenSolver<Mat3> es(AtA);
  ex.min_eigenvalue = es.eigenvalues()(0);
  ex.max_eigenvalue = es.eigenvalues()(2);
  ex.weakest_direction = es.eigenvectors().col(0);
  if (ex.weakest_direction.cwiseAbs().maxCoeff() > 0) {
    // Deterministic sign: largest component positive.
    Eigen::Index i;
    ex.weakest_direction.cwiseAbs().maxCoeff(&i);
    if (ex.weakest_direction(i) < 0) ex.weakest_direction = -ex.weakest_direction;
  }
  ex.noise_floor = noise_floor;
  if (ex.min_eigenvalue >= 100 * noise_floor && ex.min_eigenvalue > 0)
    ex.verdict = "good";
  else if (ex.min_eigenvalue >= 3 * noise_floor && ex.min_eigenvalue > 0)
    ex.verdict = "weak";
  else
    ex.verdict = "insufficient";
  return ex;
}

double NoiseFloor(const Eigen::Matrix<double, 9, Eigen::Dynamic>& x, const MotionModel& model,
                  const ArrayOptions& o, int G) {
  const double per_sample = o.accel_noise * o.accel_noise * model.M_inv.trace();
  const double sum_w2 = x.topRows<3>().colwise().squaredNorm().sum();
  return x.cols() * per_sample + 6 * sum_w2 * o.gyro_noise * o.gyro_noise / G;
}

Status InsufficientExcitation(const ArrayExcitation& ex) {
  const Vec3& u = ex.weakest_direction;
  char dir[96];
  std::snprintf(dir, sizeof dir, "(%.2f, %.2f, %.2f)", u.x(), u.y(), u.z());
  return Status::NotDeterminable(
      array_reason::kWeakExcitation,
      "the motion does not determine the positions along the direction " + std::string(dir) +
          ": the smallest eigenvalue of sum A_n^T A_n is " + Fmt(ex.min_eigenvalue) +
          " rad^2/s^4, not above what noise alone gives (" + Fmt(ex.noise_floor) +
          " rad^2/s^4); this happens when the array rotates about one fixed axis only, or too "
          "slowly. "
          "Instead, " +
          std::string(kRecordAdvice) + ".");
}

// ----- The steps of CalibrateArray.

Status NotDeterminable(Reason reason, const std::string& why, ArrayResult* result) {
  result->usable = false;
  result->reason = why;
  return Status::NotDeterminable(reason, why);
}

// Shapes and values of the input; records the reference, G and the triad names.
Status ValidateInput(const ArrayProblem& problem, const ArrayOptions& options,
                     ArrayResult* result) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput(error);
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int64_t N = problem.accel.rows();
  if (problem.accel.cols() != 3 * K)
    return Status::InvalidInput("accel has " + std::to_string(problem.accel.cols()) +
                                " columns; 3 per triad of the geometry's " + std::to_string(K) +
                                " positions means " + std::to_string(3 * K));
  if (problem.gyro.cols() % 3 != 0)
    return Status::InvalidInput("gyro has " + std::to_string(problem.gyro.cols()) +
                                " columns, not a multiple of 3");
  const int G = static_cast<int>(problem.gyro.cols() / 3);
  if (G > 0 && problem.gyro.rows() != N)
    return Status::InvalidInput("gyro has " + std::to_string(problem.gyro.rows()) +
                                " rows but accel has " + std::to_string(N));
  if (!problem.accel_names.empty() && static_cast<int>(problem.accel_names.size()) != K)
    return Status::InvalidInput("accel_names has " + std::to_string(problem.accel_names.size()) +
                                " names for " + std::to_string(K) + " triads");
  if (K > 0 && (problem.reference < 0 || problem.reference >= K))
    return Status::InvalidInput("reference " + std::to_string(problem.reference) +
                                " is not a triad index in [0, " + std::to_string(K) + ")");
  if (!problem.nominal_positions.allFinite())
    return Status::InvalidInput("nominal positions contain NaN or Inf");
  if (!problem.accel.allFinite()) return Status::InvalidInput("accel contains NaN or Inf");
  if (!problem.gyro.allFinite()) return Status::InvalidInput("gyro contains NaN or Inf");

  result->reference = problem.reference;
  result->gyro_triads = G;
  for (int k = 0; k < K; ++k)
    result->names.push_back(problem.accel_names.empty() ? "a" + std::to_string(k)
                                                        : problem.accel_names[k]);
  return Status::Ok();
}

// Structural determinability: a gyroscope, at least 3 triads, not on one line.
Status CheckGeometry(const ArrayProblem& problem, int G, ArrayResult* result) {
  const int K = static_cast<int>(problem.nominal_positions.cols());
  if (G == 0)
    return NotDeterminable(
        array_reason::kNoGyroscope,
        "no gyroscope triad: the array's angular velocity cannot be separated from the positions; "
        "record with at least one gyroscope triad (columns g0_x, g0_y, g0_z)",
        result);
  if (K < 3)
    return NotDeterminable(array_reason::kTooFewTriads,
                           "only " + std::to_string(K) +
                               " accelerometer triad(s): at least 3 triads that are not on one "
                               "line are needed to determine the motion",
                           result);
  const MotionModel model(problem.nominal_positions);
  Eigen::SelfAdjointEigenSolver<Mat3> es(model.r_tilde * model.r_tilde.transpose());
  const Eigen::Vector3d ev = es.eigenvalues();
  if (!model.ok || ev(1) <= 1e-12 * ev(2))
    return NotDeterminable(
        array_reason::kTriadsCollinear,
        "the accelerometer triads' nominal positions lie on one line: the angular acceleration "
        "about that line cannot be determined; mount at least 3 triads that span a plane",
        result);
  return Status::Ok();
}

// The samples without gyroscope saturation, laid out per sample (Data), with the gyroscope
// mean and scatter; at least 3 are needed.
Status CollectSamples(const ArrayProblem& problem, const ArrayOptions& options, Data* d,
                      ArrayResult* result) {
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int G = static_cast<int>(problem.gyro.cols() / 3);
  const int64_t N_in = problem.accel.rows();
  d->K = K;
  d->G = G;
  std::vector<int64_t> keep;
  keep.reserve(N_in);
  for (int64_t n = 0; n < N_in; ++n) {
    if (options.gyro_saturation &&
        problem.gyro.row(n).cwiseAbs().maxCoeff() >= *options.gyro_saturation)
      continue;
    if (options.accel_saturation &&
        problem.accel.row(n).cwiseAbs().maxCoeff() >= *options.accel_saturation)
      continue;
    keep.push_back(n);
  }
  d->N = static_cast<int64_t>(keep.size());
  result->samples = d->N;
  result->samples_dropped = N_in - d->N;
  if (d->N < 3) {
    std::string why = "only " + std::to_string(d->N) + " usable sample(s)";
    if (result->samples_dropped > 0) {
      // Name the limits in force (the config's or the levels found in the data), so the user
      // can tell a wrong limit from a recording turned beyond the sensors' range.
      std::string limits;
      char buf[64];
      if (options.gyro_saturation) {
        std::snprintf(buf, sizeof buf, "gyro_saturation %.6g rad/s", *options.gyro_saturation);
        limits += buf;
      }
      if (options.accel_saturation) {
        std::snprintf(buf, sizeof buf, "accel_saturation %.6g m/s^2", *options.accel_saturation);
        limits += (limits.empty() ? "" : ", ") + std::string(buf);
      }
      why += " (" + std::to_string(result->samples_dropped) +
             " dropped because a sensor reached its saturation limit: " + limits + ")";
    }
    return NotDeterminable(
        array_reason::kTooFewSamples,
        why + "; at least 3 are needed: " + kRecordAdvice +
            (result->samples_dropped > 0 ? ", turning below the gyroscopes' range" : ""),
        result);
  }
  d->ya.resize(3 * K, d->N);
  d->gbar.resize(3, d->N);
  d->gscatter.resize(d->N);
  for (int64_t i = 0; i < d->N; ++i) {
    const int64_t n = keep[i];
    d->ya.col(i) = problem.accel.row(n).transpose();
    Vec3 mean = Vec3::Zero();
    for (int j = 0; j < G; ++j) mean += problem.gyro.row(n).segment<3>(3 * j).transpose();
    mean /= G;
    double scatter = 0;
    for (int j = 0; j < G; ++j)
      scatter += (problem.gyro.row(n).segment<3>(3 * j).transpose() - mean).squaredNorm();
    d->gbar.col(i) = mean;
    d->gscatter(i) = scatter;
  }
  return Status::Ok();
}

// What the iterations of either solver produced.
struct SolverRun {
  ArrayTermination termination = ArrayTermination::kMaxIterations;
  int iterations = 0;
};

// The paper's Algorithm 1: position update (Eq. 9) from the current motion, then the motion step
// (5) at the new positions; the profile cost is recorded after every sweep. ms: the sums of the
// motion pass at the start.
SolverRun RunBcd(const Data& d, const ArrayOptions& options, const ChunkRunner& runner,
                 const Weights& wt, int max_iterations, const std::vector<int>& free,
                 Eigen::Matrix3Xd* r, MotionStates* x, MotionSums* ms, ArrayResult* result) {
  SolverRun run;
  const double tol = options.tolerance;
  for (run.iterations = 1; run.iterations <= max_iterations; ++run.iterations) {
    const Eigen::LDLT<Mat3> C(ms->AtA);
    for (int k : free) r->col(k) = C.solve(ms->AtY.col(k));
    const double previous = ms->cost;
    MotionPass(d, *r, wt, runner, 50, x, ms, options.stop);
    if (StopRequested(options.stop)) {
      run.termination = ArrayTermination::kUserStopped;
      break;
    }
    result->cost.push_back(ms->cost);
    if (options.callback && !options.callback(run.iterations, *r)) {
      run.termination = ArrayTermination::kUserStopped;
      break;
    }
    if (tol > 0 && previous - ms->cost <= tol * ms->cost) {
      run.termination = ArrayTermination::kConvergence;
      break;
    }
  }
  run.iterations = std::min(run.iterations, max_iterations);
  return run;
}

BlockLmOptions JointSolverOptions(const ArrayOptions& options, int max_iterations, int threads) {
  BlockLmOptions o;
  o.max_iterations = max_iterations;
  o.cost_tolerance = options.tolerance;
  o.step_tolerance = options.tolerance;
  o.gradient_tolerance = 0;
  o.initial_damping = 1e-8;
  o.min_damping = 1e-15;
  o.max_damping = 1e10;
  o.threads = threads;
  o.executor = options.executor;
  o.stop = options.stop;
  return o;
}

// Joint Levenberg-Marquardt over motion and positions (core/block_lm.h). result->cost gets the
// cost of every iteration after the first entry (already there).
SolverRun RunJoint(const PositionsProblem& joint, const BlockLmOptions& lm_options,
                   const ArrayOptions& options, Eigen::Matrix3Xd* r, MotionStates* x,
                   ArrayResult* result) {
  BlockLm<PositionsProblem> solver(joint, lm_options);
  const BlockLmSummary summary = solver.Solve(x, r, options.callback);
  result->cost.insert(result->cost.end(), summary.cost.begin() + 1, summary.cost.end());
  SolverRun run;
  run.iterations = summary.iterations;
  switch (summary.termination) {
    case BlockLmTermination::kCostTolerance:
    case BlockLmTermination::kStepTolerance:
    case BlockLmTermination::kGradientTolerance:
      run.termination = ArrayTermination::kConvergence;
      break;
    case BlockLmTermination::kNoProgress:
      run.termination = ArrayTermination::kNoProgress;
      break;
    case BlockLmTermination::kUserStopped:
      run.termination = ArrayTermination::kUserStopped;
      break;
    case BlockLmTermination::kNumericalFailure:
      run.termination = ArrayTermination::kNumericalFailure;
      break;
    case BlockLmTermination::kNotRun:
    case BlockLmTermination::kMaxIterations:
      run.termination = ArrayTermination::kMaxIterations;
      break;
  }
  return run;
}

// The residual-aware (HC3/jackknife-type sandwich) covariance of the free positions (core/array.h)
// over batches of options.robust_batch_samples consecutive samples. Per sample the reduced score
// is g_r - H_rx H_xx^-1 g_x and the reduced information H_rr - H_rx H_xx^-1 H_xr, with
// H_xr = wa C lift (core/array_model.h), so a batch needs only its 12-vector sum_n C^T H^-1 g,
// its 12x12 sum_n C^T H^-1 C and its sums of A^T e and A^T A. Each batch score s_b is mapped by
// (S - I_b)^-1 (Neumann series t = Cov s + Cov I_b t) to undo the fit's shrinking of the batch's
// residuals. *not_converged counts batches whose series did not converge (leverage ~ 1).
Eigen::MatrixXd PositionsSandwich(const Data& d, const PositionsProblem& joint, double wa,
                                  const std::vector<int>& free, const Eigen::Matrix3Xd& r,
                                  const MotionStates& x, int64_t batch_samples,
                                  const Eigen::MatrixXd& crb, const StopToken* stop,
                                  int64_t* batches, int* not_converged) {
  const int m = static_cast<int>(free.size());
  const PositionsProblem::Context ctx = joint.MakeContext(r);
  Eigen::MatrixXd lift = Eigen::MatrixXd::Zero(12, 3 * m);
  for (int j = 0; j < m; ++j)
    for (int a = 0; a < 4; ++a)
      lift.block<3, 3>(3 * a, 3 * j) = ctx.c(a, free[j]) * Mat3::Identity();
  Eigen::MatrixXd sandwich = Eigen::MatrixXd::Zero(3 * m, 3 * m);
  *batches = 0;
  *not_converged = 0;
  PositionsProblem::Normal b;
  for (int64_t start = 0; start < d.N; start += batch_samples) {
    if (StopRequested(stop)) return sandwich;
    PositionsProblem::Sums sums = joint.MakeSums();
    Eigen::Matrix<double, 12, 1> v = Eigen::Matrix<double, 12, 1>::Zero();
    Eigen::Matrix<double, 12, 12> w = Eigen::Matrix<double, 12, 12>::Zero();
    for (int64_t n = start; n < std::min(d.N, start + batch_samples); ++n) {
      joint.Linearize(n, x.col(n), ctx, &b, &sums);
      const Eigen::LLT<Eigen::Matrix<double, 9, 9>> llt(b.H);
      v.noalias() += b.C.transpose() * llt.solve(b.g);
      w.noalias() += b.C.transpose() * llt.solve(b.C);
    }
    Eigen::VectorXd score = -wa * (lift.transpose() * v);
    Eigen::MatrixXd info = -wa * wa * (lift.transpose() * w * lift);
    for (int j = 0; j < m; ++j) {
      score.segment<3>(3 * j) += wa * sums.br.col(free[j]);
      info.block<3, 3>(3 * j, 3 * j) += wa * sums.AtA;
    }
    const Eigen::VectorXd t0 = crb * score;
    Eigen::VectorXd t = t0;
    bool done = false;
    for (int it = 0; it < 100 && !done; ++it) {
      const Eigen::VectorXd next = t0 + crb * (info * t);
      done = (next - t).norm() <= 1e-10 * next.norm();
      t = next;
    }
    if (!done || !t.allFinite()) {
      ++*not_converged;
      t = t0;
    }
    sandwich.selfadjointView<Eigen::Lower>().rankUpdate(t);
    ++*batches;
  }
  return sandwich.selfadjointView<Eigen::Lower>();
}

// Chooses the primary σ (core/array.h): the sandwich when chi^2/dof or its mean variance ratio
// to the CRB exceeds options.robust_ratio, and says so in a warning.
void ChooseSigma(const ArrayOptions& options, const std::vector<int>& free,
                 const Eigen::MatrixXd& sandwich, int not_converged, ArrayResult* result) {
  double ratio2 = 0;
  int counted = 0;
  for (Eigen::Index i = 0; i < sandwich.rows(); ++i)
    if (result->position_covariance_crb(i, i) > 0) {
      ratio2 += sandwich(i, i) / result->position_covariance_crb(i, i);
      ++counted;
    }
  result->sigma_ratio = counted > 0 ? std::sqrt(ratio2 / counted) : 1;
  if (!(result->chi2_per_dof > options.robust_ratio) &&
      !(result->sigma_ratio * result->sigma_ratio > options.robust_ratio))
    return;
  result->sigma_basis = "sandwich";
  result->position_covariance = sandwich;
  for (size_t j = 0; j < free.size(); ++j)
    result->position_std.col(free[j]) =
        sandwich.diagonal().segment<3>(3 * j).cwiseMax(0).cwiseSqrt();
  result->warnings.push_back(
      "σ is the residual-aware sandwich, " + Format("%.2g", result->sigma_ratio) +
      "× the white-noise bound (uncertainty.positions[].crb): the residuals exceed the noise "
      "model (χ²/dof " +
      Format("%.3g", result->chi2_per_dof) +
      (result->chi2_per_dof > options.robust_ratio
           ? ")"
           : "; the residuals are correlated in time, so χ² alone does not show it)"));
  if (not_converged > 0)
    result->warnings.push_back(std::to_string(not_converged) +
                               " batches of the residual-aware σ alone determine some position "
                               "(leverage ~ 1): their scores are not leverage-corrected");
}

// Everything the result reports at the estimate (r, x) except warnings: motion summaries,
// residuals, noise estimates, excitation and the CRB of the positions from the reduced Fisher
// information.
Status Diagnose(const ArrayProblem& problem, const ArrayOptions& options, const Data& d,
                const PositionsProblem& joint, const BlockLmOptions& lm_options,
                const std::vector<int>& free, const Eigen::Matrix3Xd& r, const MotionStates& x,
                double* gyro_dof, ArrayResult* result) {
  const int K = d.K;
  BlockLm<PositionsProblem> solver(joint, lm_options);
  BlockLmInformation info;
  PositionsProblem::Sums L;
  solver.ComputeSharedInformation(x, r, &info, &L);
  const MotionModel model(r);
  result->excitation = ComputeExcitation(L.AtA, NoiseFloor(x, model, options, d.G));

  result->positions = r;
  result->offsets = r - problem.nominal_positions;
  result->position_std = Eigen::Matrix3Xd::Zero(3, K);
  result->omega_norm = x.topRows<3>().colwise().norm().transpose();
  result->omega_dot_norm = x.middleRows<3>(3).colwise().norm().transpose();
  int64_t parallel = 0;
  for (int64_t n = 0; n < d.N; ++n) {
    const Vec3 w = x.col(n).head<3>(), wd = x.col(n).segment<3>(3);
    if (w.cross(wd).norm() < 0.1 * w.norm() * wd.norm()) ++parallel;
  }
  result->parallel_fraction = static_cast<double>(parallel) / d.N;

  const double n_accel = 3.0 * K * d.N, n_gyro = 3.0 * d.G * d.N;
  result->residual_rms_accel = std::sqrt(L.ssr_a / n_accel);
  result->residual_rms_gyro = std::sqrt(L.ssr_g / n_gyro);
  const double dof_g = n_gyro - L.lev_g;
  *gyro_dof = dof_g;
  const double dof_a = n_accel - 9.0 * d.N - 3.0 * (K - 1) + L.lev_g;
  result->noise_estimate_accel = dof_a > 0 ? std::sqrt(L.ssr_a / dof_a) : 0;
  result->noise_estimate_gyro = dof_g > 0 ? std::sqrt(L.ssr_g / dof_g) : 0;

  if (result->excitation.verdict == "insufficient") {
    const Status s = InsufficientExcitation(result->excitation);
    result->reason = s.message();
    return s;
  }
  if (!InvertInformation(info.information, &result->position_covariance))
    return NotDeterminable(
        Reason::kSingularInformation,
        "the Fisher information of the positions is singular at the estimate: the recording "
        "does not determine every position; " +
            std::string(kRecordAdvice),
        result);
  for (size_t j = 0; j < free.size(); ++j)
    result->position_std.col(free[j]) =
        result->position_covariance.diagonal().segment<3>(3 * j).cwiseMax(0).cwiseSqrt();
  result->position_std_crb = result->position_std;
  result->position_covariance_crb = result->position_covariance;
  const double dof = n_accel + n_gyro - 9.0 * d.N - 3.0 * (K - 1);
  result->chi2_per_dof = dof > 0 ? (L.ssr_a / (options.accel_noise * options.accel_noise) +
                                    L.ssr_g / (options.gyro_noise * options.gyro_noise)) /
                                       dof
                                 : 0;
  int not_converged = 0;
  const Eigen::MatrixXd sandwich =
      PositionsSandwich(d, joint, 1 / (options.accel_noise * options.accel_noise), free, r, x,
                        options.robust_batch_samples, result->position_covariance_crb, options.stop,
                        &result->sigma_batches, &not_converged);
  ChooseSigma(options, free, sandwich, not_converged, result);
  return Status::Ok();
}

// gyro_dof: degrees of freedom of the gyroscope residuals (from Diagnose).
void AddWarnings(const ArrayOptions& options, int64_t samples_in, int max_iterations,
                 double gyro_dof, ArrayResult* result) {
  auto& warnings = result->warnings;
  if (result->samples_dropped > 0)
    warnings.push_back(
        std::to_string(result->samples_dropped) + " of " + std::to_string(samples_in) +
        " samples dropped because a sensor reached its saturation limit (" +
        (options.gyro_saturation
             ? "gyroscopes " + options.gyro_message_unit.Quote(*options.gyro_saturation)
             : std::string("gyroscopes none")) +
        (options.accel_saturation ? ", accelerometers " + Fmt(*options.accel_saturation) + " m/s^2"
                                  : std::string()) +
        ")");
  if (result->termination == ArrayTermination::kMaxIterations)
    warnings.push_back("reached max_iterations (" + std::to_string(max_iterations) +
                       ") before the tolerance was met: the positions are usable but not fully "
                       "converged; raise max_iterations" +
                       (options.solver == ArraySolver::kBcd ? " or use solver \"joint\"" : ""));
  if (result->termination == ArrayTermination::kUserStopped)
    warnings.push_back("stopped by the caller before convergence");
  // quote: a value (in SI) with its unit.
  auto check_noise = [&](const char* what, double estimate, double configured, auto quote) {
    if (estimate > 2 * configured || estimate < configured / 2)
      warnings.push_back(std::string(what) + " noise estimated from the residuals (" +
                         quote(estimate) + ") differs from the configured " + quote(configured) +
                         " by more than 2x: " +
                         (result->sigma_basis == "sandwich"
                              ? "the reported σ is the residual-aware one; "
                              : "the reported uncertainties assume the configured value; ") +
                         "check the noise setting, the units and the sensors");
  };
  check_noise("accelerometer", result->noise_estimate_accel, options.accel_noise,
              [](double v) { return Fmt(v) + " m/s^2"; });
  if (gyro_dof > 0.5)
    check_noise("gyroscope", result->noise_estimate_gyro, options.gyro_noise,
                [&](double v) { return options.gyro_message_unit.Quote(v); });
  if (result->excitation.verdict == "weak")
    warnings.push_back(
        "weak excitation: the smallest eigenvalue of sum A_n^T A_n (" +
        Fmt(result->excitation.min_eigenvalue) +
        " rad^2/s^4) is less than 100x what noise "
        "alone gives (" +
        Fmt(result->excitation.noise_floor) +
        " rad^2/s^4); positions along the weakest direction are poorly determined; " +
        kRecordAdvice);
  if (result->parallel_fraction > 0.5)
    warnings.push_back(
        Format("omega and omega_dot are nearly parallel in %.0f%% of the samples "
               "(each A_n then has rank 2, the paper's Lemma 1): vary the rotation "
               "axis while turning",
               100 * result->parallel_fraction));
}

}  // namespace

const char* ArraySolverName(ArraySolver solver) {
  return solver == ArraySolver::kBcd ? "bcd" : "joint";
}

const char* ArrayTerminationName(ArrayTermination t) {
  switch (t) {
    case ArrayTermination::kNotRun:
      return "not_run";
    case ArrayTermination::kConvergence:
      return "convergence";
    case ArrayTermination::kNoProgress:
      return "no_progress";
    case ArrayTermination::kMaxIterations:
      return "max_iterations";
    case ArrayTermination::kUserStopped:
      return "user_stopped";
    case ArrayTermination::kNumericalFailure:
      return "numerical_failure";
  }
  return "unknown";
}

std::string GyroMessageUnit::Quote(double rad_per_s) const {
  return Fmt(rad_per_s / rad_per_unit) + " " + name;
}

bool GyroMessageUnit::IsValid(std::string* error) const {
  if (!name.empty() && rad_per_unit > 0 && std::isfinite(rad_per_unit)) return true;
  if (error) *error = "gyro_message_unit needs a name and a finite rad_per_unit > 0";
  return false;
}

bool ArrayOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!gyro_message_unit.IsValid(error)) return false;
  if (!(accel_noise > 0) || !std::isfinite(accel_noise))
    return fail("accel_noise must be a finite number > 0 (m/s^2)");
  if (!(gyro_noise > 0) || !std::isfinite(gyro_noise))
    return fail("gyro_noise must be a finite number > 0 (rad/s)");
  if (gyro_saturation && (!(*gyro_saturation > 0) || !std::isfinite(*gyro_saturation)))
    return fail("gyro_saturation must be a finite number > 0 (rad/s)");
  if (accel_saturation && (!(*accel_saturation > 0) || !std::isfinite(*accel_saturation)))
    return fail("accel_saturation must be a finite number > 0 (m/s^2)");
  if (max_iterations < 0) return fail("max_iterations must be >= 0 (0: solver default)");
  if (!(tolerance >= 0 && tolerance < 1)) return fail("tolerance must be >= 0 and < 1");
  if (threads < 0) return fail("threads must be >= 0 (0: hardware concurrency)");
  if (!(robust_ratio >= 1) || !std::isfinite(robust_ratio))
    return fail("robust_ratio must be >= 1");
  if (robust_batch_samples < 1) return fail("robust_batch_samples must be >= 1");
  return true;
}

std::string ArrayResult::BriefReport() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "array: %s, solver %s, termination %s, %d iterations, cost %.6g -> %.6g, "
                "%lld samples (%lld dropped)",
                usable ? "usable" : "not usable", ArraySolverName(solver),
                ArrayTerminationName(termination), iterations, cost.empty() ? 0.0 : cost.front(),
                cost.empty() ? 0.0 : cost.back(), static_cast<long long>(samples),
                static_cast<long long>(samples_dropped));
  return buf;
}

Status CalibrateArray(const ArrayProblem& problem, const ArrayOptions& options,
                      ArrayResult* result) {
  *result = ArrayResult();
  result->solver = options.solver;
  if (Status s = ValidateInput(problem, options, result); !s.ok()) return s;
  if (Status s = CheckGeometry(problem, result->gyro_triads, result); !s.ok()) return s;
  Data d;
  if (Status s = CollectSamples(problem, options, &d, result); !s.ok()) return s;

  const int threads = options.threads > 0
                          ? options.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  const ChunkRunner runner(threads, options.executor);
  const Weights wt{1 / (options.accel_noise * options.accel_noise),
                   1 / (options.gyro_noise * options.gyro_noise)};
  const int max_iterations =
      options.max_iterations > 0
          ? options.max_iterations
          : (options.solver == ArraySolver::kJoint ? ArrayOptions::kDefaultJointIterations
                                                   : ArrayOptions::kDefaultBcdIterations);
  std::vector<int> free;
  for (int k = 0; k < d.K; ++k)
    if (k != problem.reference) free.push_back(k);

  // Start: nominal positions, per-sample ML motion from the gyroscope mean.
  Eigen::Matrix3Xd r = problem.nominal_positions;
  MotionStates x = MotionStates::Zero(9, d.N);
  x.topRows<3>() = d.gbar;
  auto stopped = [&](const std::string& stage) {
    result->termination = ArrayTermination::kUserStopped;
    result->usable = false;
    const Status s = StoppedStatus(*options.stop, "array: " + stage);
    result->reason = s.message();
    return s;
  };
  MotionSums ms;
  MotionPass(d, r, wt, runner, 50, &x, &ms, options.stop);
  if (StopRequested(options.stop)) return stopped("start");
  result->cost.push_back(ms.cost);
  const ArrayExcitation start =
      ComputeExcitation(ms.AtA, NoiseFloor(x, MotionModel(r), options, d.G));
  if (start.verdict == "insufficient") {
    result->excitation = start;
    const Status s = InsufficientExcitation(start);
    result->reason = s.message();
    return s;
  }

  const PositionsProblem joint(d, wt, free);
  const BlockLmOptions lm_options = JointSolverOptions(options, max_iterations, threads);
  const SolverRun run =
      options.solver == ArraySolver::kBcd
          ? RunBcd(d, options, runner, wt, max_iterations, free, &r, &x, &ms, result)
          : RunJoint(joint, lm_options, options, &r, &x, result);
  result->iterations = run.iterations;
  result->termination = run.termination;
  if (StopRequested(options.stop)) {
    return stopped(options.solver == ArraySolver::kBcd ? "bcd solver" : "joint solver");
  }
  result->converged = run.termination == ArrayTermination::kConvergence ||
                      run.termination == ArrayTermination::kNoProgress;
  if (run.termination == ArrayTermination::kNumericalFailure)
    return NotDeterminable(
        Reason::kNumericalFailure,
        "the joint solver found no step with a finite cost (numerical failure): the recording "
        "or the noise settings are degenerate; " +
            std::string(kRecordAdvice),
        result);

  double gyro_dof = 0;
  const auto sigma_warnings_from = static_cast<std::ptrdiff_t>(result->warnings.size());
  if (Status s = Diagnose(problem, options, d, joint, lm_options, free, r, x, &gyro_dof, result);
      !s.ok())
    return StopRequested(options.stop) ? stopped("uncertainty") : s;
  if (StopRequested(options.stop)) return stopped("uncertainty");
  const auto sigma_warnings_to = static_cast<std::ptrdiff_t>(result->warnings.size());
  AddWarnings(options, problem.accel.rows(), max_iterations, gyro_dof, result);
  // The σ warnings (Diagnose) after the others, which say first what happened to the run.
  std::rotate(result->warnings.begin() + sigma_warnings_from,
              result->warnings.begin() + sigma_warnings_to, result->warnings.end());
  result->usable = true;
  result->reason = result->converged
                       ? std::string("converged (") + ArrayTerminationName(run.termination) + ")"
                       : std::string("not converged (") + ArrayTerminationName(run.termination) +
                             "): positions usable, see warnings";
  return Status::Ok();
}

double AccelerometerConditionNumber(const AccelerometerTriadModel& model) {
  if (!model.sensitivity.allFinite()) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Mat3>(model.sensitivity).singularValues();
  if (!(sv(2) > 0)) return std::numeric_limits<double>::infinity();
  return sv(0) / sv(2);
}

Status CorrectAccelerometerReadings(const std::vector<AccelerometerTriadModel>& models,
                                    const std::vector<std::string>& names, Eigen::MatrixXd* accel) {
  const int K = static_cast<int>(models.size());
  if (accel->cols() != 3 * K)
    return Status::InvalidInput("accelerometer calibration: " + std::to_string(K) +
                                " triad models for " + std::to_string(accel->cols()) +
                                " accelerometer columns (3 per triad)");
  std::vector<Mat3> inverse_transpose(K);
  for (int k = 0; k < K; ++k) {
    const std::string name =
        static_cast<int>(names.size()) == K ? names[k] : "a" + std::to_string(k);
    const AccelerometerTriadModel& m = models[k];
    if (!m.sensitivity.allFinite() || !m.bias.allFinite())
      return Status::InvalidInput("accelerometer calibration of triad " + name +
                                  ": sensitivities and biases must be finite numbers");
    const double cond = AccelerometerConditionNumber(m);
    if (!(cond <= kMaxAccelerometerConditionNumber)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.3g", cond);
      return Status::InvalidInput(
          "accelerometer calibration of triad " + name + ": its 3x3 sensitivity block (" + name +
          "_x, " + name + "_y, " + name + "_z) is " +
          (std::isfinite(cond) ? "ill-conditioned (condition number " + std::string(buf) + " > " +
                                     "1000): its three axes are nearly coplanar"
                               : std::string("singular: its three axes do not span space")) +
          "; the readings cannot be corrected (recalibrate the triad)");
    }
    inverse_transpose[k] = m.sensitivity.transpose().inverse();
  }
  const Eigen::Index N = accel->rows();
  for (int k = 0; k < K; ++k) {
    const Mat3& t = inverse_transpose[k];
    const Vec3 b = models[k].bias;
    for (Eigen::Index n = 0; n < N; ++n) {
      const Vec3 y(((*accel)(n, 3 * k)), (*accel)(n, 3 * k + 1), (*accel)(n, 3 * k + 2));
      const Vec3 f = t * (y - b);
      for (int i = 0; i < 3; ++i) (*accel)(n, 3 * k + i) = f(i);
    }
  }
  return Status::Ok();
}

}  // namespace calibd::core
