// The `array` method with `model: full` (SPEC §7): self-calibration of an inertial sensor array
// (Carlsson, Skog, Jaldén, "Self-calibration of inertial sensor arrays", IEEE Sensors J. 21(6),
// 2021): every triad's accelerometer and gyroscope gains, misalignments and biases together with
// the accelerometer positions, from one log holding static orientations and a dynamic phase.
//
// Model, per triad k (K triads, each one accelerometer and one gyroscope triad):
//   y_a,k = T_a,k u_a,k + b_a,k + eps_a,   y_g,k = T_g,k u_g + b_g,k + eps_g,
// general 3x3 T, bias b (reading units, SI-like: the readings are expected within a few % of
// m/s^2 and rad/s), eps white, N(0, sigma_a^2 I) and N(0, sigma_g^2 I).
//  - static interval j (from core/static_detection on the log): u_a,k = s_j with |s_j| = g (its
//    direction a 2-dof unknown on the sphere), u_g = 0. A static enters through its mean
//    readings (sufficient for white noise), weighted by its sample count.
//  - every other usable sample n (the dynamic phase and the transitions between statics):
//    u_a,k = omega_n x (omega_n x r_k) + omega_dot_n x r_k + s_n, u_g = omega_n, with
//    (omega_n, omega_dot_n, s_n) free per sample.
// Cost (the negative log-likelihood times 2 up to a constant): the sum of squared whitened
// residuals of the static means and of the dynamic samples.
//
// Gauges (what the data cannot tell, fixed by convention; result.gauge):
//  - translation: the reference triad's position is held at its nominal position;
//  - rotation: the reference triad's accelerometer T_a is upper triangular (the body frame is its
//    x axis and x-y plane);
//  - scale: with omega_dot free per sample, (omega, omega_dot, r - r_ref, T_g) -> (c omega,
//    c^2 omega_dot, (r - r_ref)/c^2, T_g/c) changes no prediction; fixed by sum_k trace T_g,k = 3K
//    (the mean gyroscope gain is 1, as the authors' code does).
// The shared unknowns are theta = per triad (T_a row-major, b_a, T_g row-major, b_g, r): 27K
// numbers, of which 27K - 7 are free. The solver works in an orthonormal basis E of the
// gauge-fixed subspace (theta = theta_0 + E delta), so the reduced Fisher information is regular
// when the recording determines everything else, and the Cramér-Rao bound of theta is
// E S^-1 E^T (zero along the fixed directions).
//
// Solver: Levenberg-Marquardt over all unknowns with core/block_lm.h. The blocks are the
// statics (a 2-dof sphere tangent) and the dynamic samples (9 dof) in one block kind of tangent
// dimension 9: a static uses the first two tangent coordinates and holds its remaining seven at
// an identity Hessian with zero gradient and zero coupling, so they never move and add nothing
// to the Schur complement (one solver pass, one reduced system, instead of two problems whose
// sums would have to be merged by hand). The block state carries a flag (static or dynamic) for
// the manifold update. Per iteration O(N K) residual work and O(N (27K)^2) for the Schur sums.
//
// Start, computed from the data: per-triad affine closed form on the static means (ellipsoid
// fit of the reference triad, which fixes the static directions s_j; every other triad then by
// linear least squares y = T s_j + b), gyroscope biases from the static means (T_g = I),
// positions from the positions-only solver (core/array.h) on the corrected readings, and the
// per-sample motion in closed form given those.
//
// Uncertainty: the Cramér-Rao bound from the reduced information at the estimate, with the
// configured (or, when not configured, the statics' within-interval) noise. When the residuals
// exceed that noise, a residual-aware "sandwich" covariance (always computed)
// sum_b t_b t_b^T, t_b = (S - I_b)^-1 s_b, over batches b of consecutive blocks (s_b: the summed
// scores of the batch, I_b its own reduced information; the (S - I_b)^-1 of the jackknife/HC3
// corrects the residuals' shrinking by the fit): every static is a batch, the dynamic samples in
// batches of robust_batch seconds (the residuals of real recordings are correlated in time, e.g.
// by sampling-time errors between the IMUs). The primary σ (report_std, theta_covariance) is the
// sandwich, with a warning, when chi^2/dof > robust_ratio or the dynamic samples were
// reweighted; else the CRB (sigma_ratio, the sandwich over the CRB, is computed either way).
// report_std_crb and theta_covariance_crb always hold the CRB.
//
// Identifiability checks: (1) rotation excitation: the eigenvalues of sum_n omega_n omega_n^T
// over the dynamic samples against what gyroscope noise alone gives (N sigma_g^2 / K): too
// little rotation about some axis leaves the gyroscope gains along it (and the positions' lever
// arms) undetermined; (2) null directions of the reduced information (after Jacobi scaling,
// eigenvalues below 1e-12 of the largest) are named by their largest components.
//
// Cost: O(I · N · 9 · (27K)^2 + I · (27K)^3) time for N samples, K triads and I LM iterations
// (max_iterations, default 50; 3 solves with dynamic_weighting kResidual), plus the residual-
// aware covariance when reported: O(N · 9 · (27K)^2 + B · 100 · (27K)^2) for B batches (the
// statics and N·Δt / robust_batch runs of dynamic samples; its Neumann series is capped at 100
// terms). Memory O(N · K) (the data and the per-sample state) + O((N / 256) · (27K)^2) (the
// per-chunk Schur sums) + O((27K)^2). The statics are blocks of the solver like the samples:
// nothing dense grows with N or with the number of statics. Worst case at the job budget's
// largest input (5.9 GiB, the default on a 2-core 23 GiB machine, 64 B per value: 8 IMUs, 49
// columns, 2.0 M rows): 0.29 ms of CPU a row at 4 iterations, ≈ 10 min, ≈ 2 h at the 50-iteration
// cap (measured to 19 k rows, linear: bench/README.md "Cost of every method"); the job's
// deadline cuts it short.
//
// Thread-safety: CalibrateArrayFull is reentrant; results do not depend on the thread count.
#ifndef CALIBD_CORE_ARRAY_FULL_H_
#define CALIBD_CORE_ARRAY_FULL_H_

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array.h"
#include "core/block_lm.h"
#include "core/static_detection.h"

namespace calibd::core {

// How the dynamic samples are weighted.
enum class ArrayFullDynamicWeighting {
  kNoise,     // by the noise (configured or the statics'): the ML estimate of the stated model
  kResidual,  // by their own residual level after a first fit (per sensor kind), then solved
              // again: when the model does not explain the motion to the noise level (real
              // hardware: sampling-time errors), the statics keep their weight in the fit
};

struct ArrayFullOptions {
  // Noise per axis of the readings: accelerometer sigma_a (m/s^2), gyroscope sigma_g (rad/s).
  // 0 (default): estimated from the statics' pooled within-interval sample std. >= 0. (The
  // server's config refuses 0: it leaves the key out for this.)
  double accel_noise = 0;
  double gyro_noise = 0;
  // |g| of the statics, m/s^2. > 0.
  double gravity = 9.80665;
  // rad/s (readings). When set (> 0), samples with any gyroscope |component| >= it are dropped
  // from the dynamic phase and never part of a static.
  std::optional<double> gyro_saturation;
  // m/s². The same for the accelerometers (methods/array/array_method.cc sets both from the data,
  // core/saturation.h).
  std::optional<double> accel_saturation;
  // Static detection (core/static_detection.h), on every triad's accelerometer and gyroscope.
  StaticDetectionOptions statics;
  // LM iterations (accepted or rejected). Reaching it is not a failure (converged = false). >= 1.
  int max_iterations = 50;
  // Converged when an accepted step decreases the cost by at most tolerance * cost or moves no
  // shared unknown by more than tolerance * (max |theta| + tolerance). >= 0, < 1.
  double tolerance = 1e-10;
  // Worker threads (0 = hardware concurrency) or an executor (core/block_lm.h). >= 0.
  int threads = 0;
  TaskExecutor executor;
  // The residual-aware covariance is the primary σ when chi^2 / dof exceeds this. >= 1.
  double robust_ratio = 1.5;
  // Length of the batches of consecutive dynamic samples whose scores are summed in the
  // sandwich covariance, seconds. > 0.
  double robust_batch = 1.0;
  // Called after every accepted LM step with the iteration number; false stops the solver
  // (termination kUserStopped: the result is not used). Optional (cancellation).
  std::function<bool(int iteration)> callback;
  // Called as each stage begins, with its name: "statics", "start" (closed forms, positions-only
  // fit, motion), "joint solver", "crb", "residual-aware sigma" (unless residual_aware_sigma is
  // false), and "done" at the end of a successful run; for benchmarks' per-stage times and
  // progress. Optional.
  std::function<void(const char* stage)> on_stage;
  // Polled (core/stop_token.h) between the stages, in the positions-only start, every LM
  // iteration and every 16 blocks of its passes, and per batch of the residual-aware covariance:
  // when it asks, CalibrateArrayFull returns core::StoppedStatus at once (termination
  // kUserStopped, not usable). Null: never stops.
  const StopToken* stop = nullptr;
  // Weighting of the dynamic samples. kResidual also reports the residual-aware σ whenever the
  // dynamic residuals exceed the noise.
  ArrayFullDynamicWeighting dynamic_weighting = ArrayFullDynamicWeighting::kNoise;
  // How warnings quote gyroscope rates (default rad/s; not the rotation excitation's (rad/s)^2).
  GyroMessageUnit gyro_message_unit;
  // Minimum number of statics (the accelerometer closed form needs 9 spanning orientations).
  int min_statics = 9;
  // Compute the residual-aware (sandwich) covariance. false: skipped (the CRB is then the
  // primary σ whatever the residuals, sigma_ratio NaN, robust_batches 0): for plans, whose
  // noise-free replays have no residuals to be aware of (methods/array/array_full_plan.cc).
  bool residual_aware_sigma = true;
  // The dynamic samples' σ is the noise times this (each weighs 1/scale² of a sample at the
  // noise; kResidual weighting raises it further). 1 (default): the stated model. A replay that
  // stands N' dynamic samples for N sets √(N'/N) (methods/array/array_full_plan.cc). > 0.
  double dynamic_noise_scale = 1;

  bool IsValid(std::string* error) const;
};

struct ArrayFullProblem {
  Eigen::Matrix3Xd nominal_positions;  // 3 x K, metres (start of the positions-only fit)
  int reference = 0;                   // reference triad (gauges)
  Eigen::VectorXd t;                   // N sample times, s, strictly increasing
  Eigen::MatrixXd accel;               // N x 3K (a0_x a0_y a0_z a1_x ...), ~m/s^2
  Eigen::MatrixXd gyro;                // N x 3K, ~rad/s; triad k is the IMU of accelerometer k
  std::vector<std::string> names;      // K names; empty: "0", "1", ...
};

// One triad's parameters in the paper's convention (T maps the physical quantity to readings).
struct ArrayFullTriad {
  Eigen::Matrix3d accel_T = Eigen::Matrix3d::Identity();
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();
  Eigen::Matrix3d gyro_T = Eigen::Matrix3d::Identity();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
};
inline constexpr int kArrayFullTriadParameters = 27;  // T_a (9), b_a, T_g (9), b_g, r
// theta layout of one triad: T_a row-major at 0, b_a at 9, T_g row-major at 12, b_g at 21, r 24.
Eigen::Matrix<double, 27, 1> PackArrayFullTriad(const ArrayFullTriad& triad);
ArrayFullTriad UnpackArrayFullTriad(const Eigen::Matrix<double, 27, 1>& theta);

// A sensor triad as SPEC §7 `imu` reports it: matrix = T^-1 (bias-free reading to SI), scale =
// diag(matrix), misalignment = matrix diag(scale)^-1 (unit diagonal), bias (reading units).
struct ArrayFullSensorReport {
  Eigen::Vector3d bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale = Eigen::Vector3d::Zero();
  Eigen::Matrix3d misalignment = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Zero();
};
struct ArrayFullSensorStd {  // 1 sigma of the reported quantities (matrix entries not reported)
  Eigen::Vector3d bias_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d scale_std = Eigen::Vector3d::Zero();
  Eigen::Matrix3d misalignment_std = Eigen::Matrix3d::Zero();
};
struct ArrayFullTriadReport {
  std::string name;
  ArrayFullSensorReport accelerometer, gyroscope;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
};
struct ArrayFullTriadStd {
  std::string name;
  ArrayFullSensorStd accelerometer, gyroscope;
  Eigen::Vector3d position_std = Eigen::Vector3d::Zero();
};
// The reported quantities of one triad, and their 1 sigma from a 27 x 27 covariance of theta
// (first-order propagation; central differences of the map).
ArrayFullTriadReport ReportArrayFullTriad(const ArrayFullTriad& triad);
ArrayFullTriadStd ReportArrayFullTriadStd(const ArrayFullTriad& triad,
                                          const Eigen::Matrix<double, 27, 27>& covariance);

struct ArrayFullResidualStats {  // per triad, rms of the residual components (m/s², rad/s)
  double static_accel = 0, static_gyro = 0;  // of the static means (a mean's noise: σ/√samples)
  double dynamic_accel = 0, dynamic_gyro = 0;  // of the dynamic samples
};

// One static interval the fit used, and its means' residuals over all triads.
struct ArrayFullStatic {
  double start = 0, end = 0;  // s (the recording's t)
  int64_t samples = 0;
  double accel_rms = 0, gyro_rms = 0;  // RMS of the static means' residual components, m/s², rad/s
};

struct ArrayFullResult {
  bool usable = false;
  std::string reason;

  std::vector<std::string> names;
  int reference = 0;
  std::vector<ArrayFullTriad> triads;  // estimates (paper convention)
  std::vector<ArrayFullTriadReport> report;
  std::vector<ArrayFullTriadStd> report_std;      // the primary σ (sigma_basis)
  std::vector<ArrayFullTriadStd> report_std_crb;  // the Cramér-Rao bound
  std::string sigma_basis = "crb";                // "crb" | "sandwich"
  // sqrt(mean over the free parameters of sandwich variance / CRB variance).
  double sigma_ratio = 1;
  Eigen::VectorXd theta;                 // 27K, the estimate
  Eigen::MatrixXd theta_covariance;      // 27K x 27K, primary (singular along the gauges)
  Eigen::MatrixXd theta_covariance_crb;  // 27K x 27K, CRB
  int64_t robust_batches = 0;            // batches of the sandwich
  Eigen::MatrixXd gauge_basis;           // E, 27K x (27K - 7), orthonormal columns
  std::string gauge;                     // "sum_trace_gyroscope" (sum_k trace T_g,k = 3K)
  std::string gauge_description;

  // The start (closed forms + positions-only fit), for "what the full model changed".
  std::vector<ArrayFullTriad> initial;
  bool initial_positions_from_array = false;  // positions-only fit succeeded
  // 1 sigma (CRB) of initial[k].position from that fit, 3 x K (0 for the reference); empty when
  // the fit failed (the start is then the nominal geometry).
  Eigen::Matrix3Xd initial_position_std;

  BlockLmTermination termination = BlockLmTermination::kNotRun;
  int iterations = 0;
  bool converged = false;
  std::vector<double> cost;
  int64_t statics = 0;
  std::vector<ArrayFullStatic> static_intervals;  // time order, `statics` of them
  int64_t static_samples = 0;
  int64_t dynamic_samples = 0;
  int64_t samples_dropped = 0;  // saturation (gyroscope or accelerometer)
  int64_t dof = 0;              // residuals - block unknowns - free shared unknowns
  double chi2_per_dof = 0;      // final cost / dof
  // χ² of the static means alone (each weighted by its σ/√samples) / their degrees of freedom
  // 6KJ − 2J − 15K (J statics; the accelerometers and gyroscope biases are what they fix): noise
  // correlated in time inflates it by the static means' variance ratio while the dynamic samples
  // keep chi2_per_dof near 1. Above robust_ratio the sandwich is the primary σ. 0: none.
  double static_chi2_per_dof = 0;
  double accel_noise = 0, gyro_noise = 0;  // sigma used
  bool noise_estimated = false;            // from the statics (not configured)
  // Sigma used for the dynamic samples (= accel_noise, gyro_noise unless kResidual raised it).
  double dynamic_accel_noise = 0, dynamic_gyro_noise = 0;
  std::vector<ArrayFullResidualStats> residuals;
  double dynamic_rms_accel = 0, dynamic_rms_gyro = 0;    // over all triads
  double static_noise_accel = 0, static_noise_gyro = 0;  // pooled within-static std

  // Diagnostic of sampling-time errors between the IMUs (not part of the model): per IMU, the
  // offset delta_k (s, relative to the mean of all) whose delta_k T_g,k omega_dot best explains
  // its gyroscope residual in the dynamic phase, and the fraction of the gyroscope residual sum
  // of squares such offsets explain (~0 when the model fits).
  Eigen::VectorXd time_offsets;
  double time_offset_explained = 0;
  // The same with an offset free per sample and IMU (timing jitter): the fraction of the
  // gyroscope residual along T_g,k omega_dot, and the rms offset it implies (s), weighted by
  // |T_g,k omega_dot|^2.
  double jitter_explained = 0;
  double jitter_rms = 0;
  // Rotation excitation: eigenvalues (ascending) of sum omega omega^T over dynamic samples,
  // (rad/s)^2, the noise floor N sigma_g^2 / K, the least excited body axis and a verdict "good"
  // (>= 100 floor), "weak" (>= 3 floor: warning), "insufficient" (not determinable).
  Eigen::Vector3d rotation_eigenvalues = Eigen::Vector3d::Zero();
  double rotation_noise_floor = 0;
  Eigen::Vector3d weakest_rotation_axis = Eigen::Vector3d::Zero();
  std::string rotation_verdict = "insufficient";
  // Null directions of the information (each: its largest components, named).
  std::vector<std::string> null_directions;

  std::vector<std::string> warnings;
  std::string BriefReport() const;
};

// Name of theta component i (e.g. "3.gyroscope.T[2][2]", "0.position.z").
std::string ArrayFullParameterName(const std::vector<std::string>& names, int i);

// Errors:
//  - kInvalidInput: options not valid, shapes inconsistent (accel/gyro N x 3K, t N, positions
//    3 x K, K >= 3), reference out of range, non-finite values.
//  - kNotDeterminable (message says what to record): fewer than min_statics statics, statics
//    that do not determine the accelerometers (ellipsoid fit fails), fewer than 10 dynamic
//    samples, too little rotation about some axis (names it), null directions of the
//    information (names the parameters), LM numerical failure. *result then carries the
//    diagnostics computed so far (usable = false).
Status CalibrateArrayFull(const ArrayFullProblem& problem, const ArrayFullOptions& options,
                          ArrayFullResult* result);

}  // namespace calibd::core

#endif  // CALIBD_CORE_ARRAY_FULL_H_
