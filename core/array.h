// The `array` method: maximum-likelihood positions of the accelerometer triads of an inertial
// sensor array from a free-motion recording (Carlsson, Skog, Jaldén, "On-the-fly geometric
// calibration of inertial sensor arrays", seed 004).
//
// Model (the paper's Eqs. 1, 2 and 8), per time sample n, accelerometer triad k, gyro triad j:
//   y_a,n^(k) = s_n + A_n r_k + eps_a,   A_n = Omega_{omega_n}^2 + Omega_{omega_dot_n},
//   y_g,n^(j) = omega_n + eps_g,
// with eps_a ~ N(0, sigma_a^2 I3), eps_g ~ N(0, sigma_g^2 I3). Unknowns: the motion
// x_n = (omega_n, omega_dot_n, s_n) of every sample and the positions r_k of all triads but the
// reference, which is held at its nominal position (Eq. 1 does not depend on the origin).
//
// Cost minimised by both solvers (the negative log-likelihood, times 2, up to a constant):
//   C = sum_n [ sum_k |y_a,n^(k) - s_n - A_n r_k|^2 / sigma_a^2
//             + sum_j |y_g,n^(j) - omega_n|^2 / sigma_g^2 ]
// At the optimum C is close to its degrees of freedom 3(K+G)N - 9N - 3(K-1) when the configured
// noise levels are right.
//
// Solvers:
//  - kJoint (default): Levenberg-Marquardt over all 9N + 3(K-1) unknowns with the block solver
//    of core/block_lm.h. The 9x9 block of each sample is eliminated by a Schur complement onto
//    the 3(K-1) positions; since the Jacobian of a triad is affine in its position, the reduced
//    matrix is accumulated from one 12x12 sum per sample, so one iteration costs O(N K) time
//    (residuals) and O(N) for the algebra, memory O(N K) (the data) plus O(N) (motion), never a
//    (9N)^2 matrix.
//  - kBcd: the paper's Algorithm 1 (block coordinate descent): per-sample ML motion given the
//    positions, then the closed-form position update of Eq. (9). Converges linearly and slowly.
// Both start from the nominal positions and the per-sample ML motion there.
//
// Uncertainty: the inverse of the reduced (Schur) Fisher information at the estimate, i.e. the
// Cramer-Rao bound (CRB) of the positions given the configured sigma_a, sigma_g, and a
// residual-aware (HC3/jackknife-type sandwich) covariance sum_b t_b t_b^T, t_b = (S - I_b)^-1 s_b,
// over batches b of robust_batch_samples consecutive samples (s_b: the batch's reduced score of
// the positions, I_b its own reduced information, S the total). The sandwich and not the
// chi^2-scaled CRB, because the misfits of real arrays are not a uniformly larger white noise:
// noise correlated in time (which leaves chi^2/dof at 1 and the CRB too small) and sampling-time
// jitter (residuals growing with the motion) are what the batches' scores see and chi^2 does not.
// The primary position_std is the sandwich when chi^2/dof > robust_ratio or the sandwich's
// variances exceed the CRB's by robust_ratio on average (sigma_basis "sandwich"), else the CRB
// ("crb"; the sandwich is then noisier and no more right); position_std_crb is always the CRB.
//
// Cost: O(I · N · K · g) time, O(N · K) memory (the data) + O(N) (motion), for N samples, K
// accelerometer triads, I iterations (joint: max_iterations LM iterations, default 50; bcd:
// max_iterations sweeps, default 500) and g <= 50 Gauss-Newton steps of the per-sample motion
// (bcd, and the start); the reduced system is 3(K-1) square (O(K^3) per iteration). Nothing
// dense grows with N. Worst case at the job budget's largest input (5.9 GiB, the default on a
// 2-core 23 GiB machine, 24 B per value: 32 triads and 1.36 M rows): joint ≈ 27 s of CPU at its
// usual 4 iterations, ≈ 6 min at the 50-iteration cap; bcd ≈ 5 s a sweep, ≈ 45 min at its
// 500-sweep cap (measured to 262 k rows, linear: bench/README.md "Cost of every method").
//
// Thread-safety: CalibrateArray is reentrant; it uses up to options.threads worker threads and
// its result does not depend on the number of threads (fixed chunking, ordered reductions).
#ifndef CALIBD_CORE_ARRAY_H_
#define CALIBD_CORE_ARRAY_H_

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/block_lm.h"

namespace calibd::core {

// The failure reasons only array meets (base/status.h Reason; their catalog entries are in
// methods/array/array_method.cc FailureReasons()).
namespace array_reason {
// No gyroscope triad
inline constexpr Reason kNoGyroscope{"no_gyroscope"};
// Fewer than 3 accelerometer triads
inline constexpr Reason kTooFewTriads{"too_few_triads"};
// The triads lie on one line
inline constexpr Reason kTriadsCollinear{"triads_collinear"};
// Fewer usable samples than needed
inline constexpr Reason kTooFewSamples{"too_few_samples"};
// The motion does not excite every direction
inline constexpr Reason kWeakExcitation{"weak_excitation"};
// No motion after the statics (full model)
inline constexpr Reason kNoDynamicPhase{"no_dynamic_phase"};
}  // namespace array_reason

// The unit in which messages quote a gyroscope rate (the numerics never read it): the array
// methods pass the config's gyro_unit, so that warnings and diagnostics speak one unit.
struct GyroMessageUnit {
  std::string name = "rad/s";  // non-empty
  double rad_per_unit = 1;     // rad/s in one `name`: finite, > 0
  // "0.0566 deg/s" for a rate in rad/s (3 significant digits).
  std::string Quote(double rad_per_s) const;
  bool IsValid(std::string* error) const;
};

enum class ArraySolver { kJoint, kBcd };
const char* ArraySolverName(ArraySolver solver);  // "joint" | "bcd"

struct ArrayOptions {
  // Accelerometer noise sigma_a, m/s^2, per axis. Required, > 0.
  double accel_noise = 0;
  // Gyroscope noise sigma_g, rad/s, per axis. Required, > 0.
  double gyro_noise = 0;
  // How warnings quote gyroscope rates (default rad/s).
  GyroMessageUnit gyro_message_unit;
  // rad/s. When set (> 0), samples with any gyroscope |component| >= it are dropped and counted.
  std::optional<double> gyro_saturation;
  // m/s². When set (> 0), samples with any accelerometer |component| >= it are dropped and
  // counted with the gyroscope's (methods/array/array_method.cc sets both from the data,
  // core/saturation.h).
  std::optional<double> accel_saturation;
  // Which optimiser. Default: joint Levenberg-Marquardt with Schur complement.
  ArraySolver solver = ArraySolver::kJoint;
  // Iteration limit (LM iterations for joint, sweeps of Algorithm 1 for bcd). 0 = solver default:
  // kDefaultJointIterations (50) or kDefaultBcdIterations (500). Reaching it is not a failure:
  // the result is kept with converged = false and a warning. >= 0.
  int max_iterations = 0;
  static constexpr int kDefaultJointIterations = 50;
  static constexpr int kDefaultBcdIterations = 500;
  // Converged when an iteration decreases the cost by at most tolerance * cost, or (joint) moves
  // no position by more than tolerance * (largest |position| + tolerance). 0 = never stop early
  // (only max_iterations, or no representable progress, ends the run). >= 0, < 1.
  double tolerance = 1e-10;
  // Worker threads; 0 = std::thread::hardware_concurrency(). >= 0.
  int threads = 0;
  // The residual-aware σ becomes the primary when chi^2/dof, or the mean ratio of its variances
  // to the CRB's, exceeds this. >= 1.
  double robust_ratio = 1.5;
  // Consecutive samples per batch of the residual-aware σ (longer than the residuals'
  // correlation time; the array method sets 1 s of samples when it knows the rate). >= 1.
  int64_t robust_batch_samples = 100;
  // Optional: runs the solver's parallel chunks instead of `threads` new threads (e.g. a pool
  // shared by all jobs; core/block_lm.h). The result does not depend on it.
  TaskExecutor executor;
  // Called after every BCD sweep or accepted joint step with the iteration number (1-based) and
  // the current positions (3 x K); returning false stops the solver (termination kUserStopped,
  // converged = false).
  // Optional; used by benchmarks to stop when a target accuracy is reached.
  std::function<bool(int iteration, const Eigen::Matrix3Xd& positions)> callback;
  // Polled (core/stop_token.h) every BCD sweep and LM iteration and every 16 samples of every
  // pass over the samples: when it asks, CalibrateArray returns core::StoppedStatus at once
  // (termination kUserStopped, not usable). Null: never stops.
  const StopToken* stop = nullptr;

  bool IsValid(std::string* error) const;
};

struct ArrayProblem {
  Eigen::Matrix3Xd nominal_positions;    // 3 x K, metres; the solvers' starting point
  int reference = 0;                     // triad held fixed at its nominal position
  Eigen::MatrixXd accel;                 // N x 3K (a0_x a0_y a0_z a1_x ...) m/s^2
  Eigen::MatrixXd gyro;                  // N x 3G rad/s (all G triads measure the same omega)
  std::vector<std::string> accel_names;  // K names ("a0"...); empty: "a<k>" is used
};

enum class ArrayTermination {
  kNotRun,            // sentinel: CalibrateArray failed before solving
  kConvergence,       // tolerance met
  kNoProgress,        // joint: no step decreased the cost any more (numerical optimum)
  kMaxIterations,     // iteration limit reached: usable, converged = false
  kUserStopped,       // the callback returned false, or options.stop asked (then not usable)
  kNumericalFailure,  // joint: no trial point had a finite cost (CalibrateArray: kNotDeterminable)
};
const char* ArrayTerminationName(ArrayTermination termination);

struct ArrayExcitation {
  // Eigenvalues of sum_n A_n^T A_n at the estimate ((rad/s)^4 scale), ascending.
  double min_eigenvalue = 0;
  double max_eigenvalue = 0;
  // What noise alone would contribute to min_eigenvalue: sum_n sigma_a^2 tr(M^-1)
  // + 6 |omega_n|^2 sigma_g^2 / G, M = sum_k [r~_k]x^T [r~_k]x (centred positions).
  double noise_floor = 0;
  // Unit direction of the least excited position component (eigenvector of min_eigenvalue).
  Eigen::Vector3d weakest_direction = Eigen::Vector3d::Zero();
  // "good" (min_eigenvalue >= 100 noise_floor), "weak" (>= 3 noise_floor: warning),
  // "insufficient" (kNotDeterminable).
  std::string verdict = "insufficient";
};

struct ArrayResult {
  // Whether positions may be used, and why (or why not).
  bool usable = false;
  std::string reason;

  int reference = 0;
  std::vector<std::string> names;  // K triad names
  Eigen::Matrix3Xd positions;      // 3 x K estimates, metres (reference = nominal)
  Eigen::Matrix3Xd offsets;        // positions - nominal
  // The primary σ (sigma_basis: the sandwich or the CRB): 3 x K, 0 for the reference, and its
  // 3(K-1) square covariance, triads in order without the reference.
  Eigen::Matrix3Xd position_std;
  Eigen::MatrixXd position_covariance;
  Eigen::Matrix3Xd position_std_crb;        // the Cramér-Rao bound, same layout
  Eigen::MatrixXd position_covariance_crb;  // CRB
  std::string sigma_basis = "crb";          // "crb" | "sandwich"
  double chi2_per_dof = 0;                  // final cost / (residuals - unknowns)
  // sqrt(mean over the free coordinates of sandwich variance / CRB variance).
  double sigma_ratio = 1;
  int64_t sigma_batches = 0;  // batches of the sandwich

  ArraySolver solver = ArraySolver::kJoint;
  ArrayTermination termination = ArrayTermination::kNotRun;
  int iterations = 0;  // LM iterations (accepted or not) / BCD sweeps
  bool converged = false;
  std::vector<double> cost;  // cost C before the first and after every iteration

  int64_t samples = 0;          // usable samples N
  int64_t samples_dropped = 0;  // dropped for saturation (gyroscope or accelerometer)
  int gyro_triads = 0;          // G

  double residual_rms_accel = 0;  // sqrt(mean of squared accel residual components)
  double residual_rms_gyro = 0;
  double noise_estimate_accel = 0;  // from residuals, corrected for degrees of freedom
  double noise_estimate_gyro = 0;

  ArrayExcitation excitation;
  // Fraction of samples with |omega x omega_dot| < 0.1 |omega||omega_dot| (Lemma 1: A_n rank 2).
  double parallel_fraction = 0;

  Eigen::VectorXd omega_norm;      // N, |omega_n| rad/s (estimates, for plots)
  Eigen::VectorXd omega_dot_norm;  // N, |omega_dot_n| rad/s^2

  std::vector<std::string> warnings;

  // One line: usable, solver, termination, iterations, cost, samples.
  std::string BriefReport() const;
};

// Affine model of one accelerometer triad, as a `pca` calibration with `bias: estimate` in the
// body (nominal) frame reports it: reading_i = a_i^T f + b_i for the axes i = x, y, z, with f the
// specific force in the body frame (m/s^2). `sensitivity` holds the sensitivity vectors a_x, a_y,
// a_z as COLUMNS (A = [a_x a_y a_z]), so the readings are y = A^T f + b and the corrected specific
// force is f = A^-T (y - b). An ideal triad has A = I, b = 0.
struct AccelerometerTriadModel {
  Eigen::Matrix3d sensitivity = Eigen::Matrix3d::Identity();  // A, columns a_x, a_y, a_z
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();             // b, m/s^2
};

// Largest condition number (sigma_max / sigma_min of A) accepted by CorrectAccelerometerReadings.
// A real triad is close to 1; beyond this the three axes are nearly coplanar.
inline constexpr double kMaxAccelerometerConditionNumber = 1e3;

// Condition number sigma_max / sigma_min of a triad's sensitivity block; +inf when it is singular
// or not finite.
double AccelerometerConditionNumber(const AccelerometerTriadModel& model);

// Replaces the raw readings of every triad k by f = A_k^-T (y - b_k), in place. accel is N x 3K
// (a0_x a0_y a0_z a1_x ...), models has K entries. kInvalidInput when the counts disagree, or when
// a model is not finite or its condition number exceeds kMaxAccelerometerConditionNumber (message
// names the triad by names[k] when names has K entries, else "a<k>"). On error accel is unchanged.
// The noise of the corrected readings is A_k^-T eps: for |A_k - I| << 1 still ~ sigma_a, so the
// array fit keeps its isotropic model.
Status CorrectAccelerometerReadings(const std::vector<AccelerometerTriadModel>& models,
                                    const std::vector<std::string>& names, Eigen::MatrixXd* accel);

// Estimates the triad positions. Errors:
//  - kInvalidInput: options not valid, shapes inconsistent, reference out of range, NaN/Inf.
//  - kNotDeterminable (message says why and what motion to record): fewer than 3 usable samples,
//    fewer than 3 triads or triads on one line, no gyroscope triad, sum A_n^T A_n not exceeding
//    the noise floor in some direction (e.g. rotation about one fixed axis only).
// On kNotDeterminable, *result still carries whatever diagnostics were computed (usable = false).
Status CalibrateArray(const ArrayProblem& problem, const ArrayOptions& options,
                      ArrayResult* result);

}  // namespace calibd::core

#endif  // CALIBD_CORE_ARRAY_H_
