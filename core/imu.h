// The `imu` calibration method (SPEC §7, issue #16): accelerometer and gyroscope of one IMU from
// a continuous hand-held log (static orientations joined by rotations), no turntable. The model
// of Tedaldi, Pretto, Menegatti (ICRA 2014, imu_tk), solved in closed form + maximum likelihood:
//   a = T_a K_a (y_a − b_a),   ω = T_g K_g (y_g − b_g)
// y readings (reading units), b biases (reading units), K diagonal scale factors (SI per reading
// unit), T_a upper triangular with unit diagonal (the body frame is the accelerometer's: x along
// its x axis, y in its x-y plane — this fixes the rotation gauge), T_g a full matrix with unit
// diagonal (the gyroscope's misalignment relative to that frame). M = T K ("matrix"):
// K_j = M_jj, T = M K⁻¹.
//
// Steps (CalibrateImus):
//  1. Static detection (core/static_detection.h) over all triads of the log, for each candidate
//     threshold multiplier (unless the caller fixed the threshold).
//  2. Accelerometer, per candidate: closed-form ellipsoid fit of the static means
//     (yᵀQy + lᵀy + c = 0 by linear least squares, centre b = −Q⁻¹l/2, M_aᵀM_a = g²Q/(bᵀQb − c),
//     M_a its upper-triangular Cholesky factor), then maximum likelihood with Levenberg-Marquardt
//     on the static means weighted by their sample counts (equivalent to all static samples for
//     white noise), the body-frame gravity direction u_j of each static a nuisance unknown:
//       ȳ_a,j = b_a + g P u_j + noise/√n_j,  P = M_a⁻¹ (upper triangular),  |u_j| = 1.
//     The candidate with the smallest χ²/dof of this fit is kept (imu_tk kept the smallest
//     cost); diagnostics list every trial.
//  3. Gyroscope bias: GyroBiasModel::kStatics (default) — the mean of all static samples (a
//     constant bias; the joint step 5 keeps the static residuals and lets the rotations refine
//     it slightly, as maximum likelihood requires); kEstimate — unknowns of the rotation fit
//     only, started at that mean, no static residuals (a bias that is not constant enough).
//  4. Gyroscope M_g: integrate the calibrated rate over each rotation between consecutive statics
//     (from the last sample of static j to the first of static j+1, at the log's own sample
//     times) with the closed-form exponential map per step,
//       R ← R Exp(M_g (½(y_k + y_{k+1}) − b_g) Δt_k),
//     i.e. the trapezoid (mean of the two samples) rate, exact for a rate linear in time about a
//     fixed axis and orthonormal by construction; RK4 on quaternions (imu_tk) has the same order
//     here because the rate is only known at the samples. Residual Rᵀu_j − u_{j+1}, weighted by
//     the integrated gyroscope noise. Levenberg-Marquardt from the nominal conversion with
//     analytic Jacobians (right-perturbation of the product of exponentials; checked against
//     finite differences when developed; a wrong Jacobian fails the Monte-Carlo σ test).
//  5. Joint maximum likelihood over all parameters (P, b_a, M_g, b_g) and all u_j with every
//     residual (accelerometer statics, gyroscope statics for kStatics, rotations). Rotation
//     residuals are weighted by 1/σ_θ, σ_θ² = tr(M_g Σ_g M_gᵀ)/3 · Σ_k c_k² (the trapezoid
//     weights c_k of each sample's white noise). Normal equations (21 + 2n unknowns for n
//     statics) kept in their block structure: the u_j part is block tridiagonal (2×2 blocks; a
//     rotation couples u_j and u_{j+1} only), eliminated by a block Cholesky factorisation onto
//     the 21 shared unknowns (Schur complement). 1σ from the inverse Fisher information at the
//     estimate (u_j marginalised: the inverse Schur complement), propagated to b, K, T.
//
// Cost: O(N · (T + I_max)) time, O(N) memory, for N samples, T threshold candidates (5) and
// I_max = 2 · max_iterations LM iterations of the stages over the rotations (each integrates every
// sample between statics once, with its Jacobian); every LM iteration also costs O(n · 21²) for
// n <= max_statics (1000) statics, and the accelerometer fits O(T · max_iterations · n · 21²).
// Nothing grows faster than N: no dense matrix over the statics (issue #20: a log whose time
// column was in ms gave ~10⁴ two-sample "statics" and a dense (21 + 2n)² LDLT per iteration,
// hours). Worst case at the job budget's largest input (the default budget on a 2-core 23 GiB
// machine, 5.9 GiB, 24 B per value, 7 columns: 37 M rows; 51 M rows at the 8 GiB maximum):
// measured 35 s of CPU and 4.1 GB for a hand-held log of 37 M rows (about 1 µs a row, linear;
// bench/README.md "Cost of every method"). Every LM stage hitting max_iterations (a log that
// does not fit the model, e.g. its time column in ms) costs up to 26 µs a row: about 16 min of
// CPU at 37 M rows, which the job's deadline (core/stop_token.h) cuts short.
//     There is no null space left: the accelerometer-defined frame (T_a upper triangular) is the
//     gauge, fixed by the parameterisation.
//
// Pure numerics: Eigen in, result structs out. Thread-compatible.
#ifndef CALIBD_CORE_IMU_H_
#define CALIBD_CORE_IMU_H_

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/static_detection.h"
#include "core/stop_token.h"

namespace calibd::core {

// The failure reasons only imu meets (base/status.h Reason; their catalog entries are in
// methods/imu/imu_method.cc FailureReasons()).
namespace imu_reason {
// Too few rotations between statics for the gyroscope
inline constexpr Reason kTooFewRotations{"too_few_rotations"};
}  // namespace imu_reason

inline constexpr double kImuStandardGravity = 9.80665;  // m/s²

// WGS-84 normal gravity (Somigliana's formula with the free-air correction to second order in
// height), m/s². latitude in degrees [-90, 90], height above the ellipsoid in metres.
double Wgs84NormalGravity(double latitude_deg, double height_m);

enum class GyroBiasModel {
  kStatics,   // b_g from every static interval (constant bias); SPEC `gyro_bias: statics`
  kEstimate,  // b_g unknowns of the rotation fit (bias not constant enough); `estimate`
};
const char* GyroBiasModelName(GyroBiasModel model);  // "statics" | "estimate"

struct ImuOptions {
  double accel_unit = 1;                 // nominal SI (m/s²) per accelerometer reading unit, > 0
  double gyro_unit = 1;                  // nominal SI (rad/s) per gyroscope reading unit, > 0
  double gravity = kImuStandardGravity;  // local |g|, m/s², > 0 (see Wgs84NormalGravity)
  GyroBiasModel gyro_bias = GyroBiasModel::kStatics;
  // The "before calibration" reference of the diagnostics: nominal unit, identity misalignment
  // and these biases (reading units; e.g. 32768 for offset-binary counts). Not a starting guess.
  double nominal_accel_bias = 0;
  double nominal_gyro_bias = 0;
  StaticDetectionOptions detection;  // window, min_static, overrides (see static_detection.h)
  // Multipliers tried when no threshold override is given; the best accelerometer fit wins.
  // Empty: only detection.threshold_multiplier.
  std::vector<double> threshold_multipliers = {2, 3, 4, 6, 8};
  int min_statics = 9;           // >= 9: the accelerometer's 9 unknowns need 9 statics
  int recommended_statics = 15;  // fewer gives a warning
  // >= min_statics: when the detection finds more, the fits take the max_statics longest (in
  // time order) and a warning says so: bounds the cost whatever the log (a time column in ms
  // gives one "static" every few samples). Real hand-held logs have tens to a few hundred.
  int max_statics = 1000;
  // Accelerometer and gyroscope saturation limits, reading units (samples at or beyond dropped).
  double accel_saturation_low = -std::numeric_limits<double>::infinity();
  double accel_saturation_high = std::numeric_limits<double>::infinity();
  double gyro_saturation_low = -std::numeric_limits<double>::infinity();
  double gyro_saturation_high = std::numeric_limits<double>::infinity();
  // White-noise σ per axis of one sample in SI; nullopt: pooled within-static std of the log.
  std::optional<double> accel_noise;
  std::optional<double> gyro_noise;
  bool joint_refinement = true;  // step 5; false: stop after the separate fits (σ still joint)
  int max_iterations = 100;      // >= 1, per Levenberg-Marquardt stage
  double max_scale_deviation = 0.25;  // > 0: |K/unit − 1| above this is implausible (units?)
  // > 0 rad: an RMS gravity-direction error per rotation above this after calibration means the
  // gyroscope model does not explain the rotations (wrong gyro_unit aliasing whole turns,
  // saturation, a time base error): implausible.
  double max_direction_error = 0.05;
  // Polled (core/stop_token.h) between the stages, in every LM iteration, per rotation and every
  // 65 536 integration steps: when it asks, CalibrateImus returns core::StoppedStatus at once
  // (termination kStopped, the results filled as far as they got). Null: never stops.
  const StopToken* stop = nullptr;

  bool IsValid(std::string* error) const;
};

// One IMU of the log. Non-owning: the matrices must outlive the call.
struct ImuReadings {
  std::string name = "0";
  const Eigen::MatrixX3d* accel = nullptr;  // N×3, reading units
  const Eigen::MatrixX3d* gyro = nullptr;   // N×3, reading units
};

// One triad's calibration: value = matrix (y − bias), matrix = misalignment · diag(scale).
struct TriadCalibration {
  Eigen::Vector3d bias = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d scale = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Matrix3d misalignment =
      Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
  // 1σ (ImuResult::uncertainty_basis); 0 for entries fixed by the model (T diagonal, T_a
  // below the diagonal). misalignment_std in radians (T's entries are small angles).
  Eigen::Vector3d bias_std = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d scale_std = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Matrix3d misalignment_std =
      Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
};

enum class ImuTermination {
  kNotRun,           // sentinel
  kConverged,        // usable
  kMaxIterations,    // usable, with a warning: the last LM stage hit max_iterations
  kInvalidInput,     // bad options or readings (Status kInvalidInput)
  kTooFewStatics,    // fewer than min_statics static intervals (kNotDeterminable)
  kTooFewRotations,  // fewer than 5 usable rotations for the gyroscope's 9 unknowns
  kDegenerate,       // statics do not determine the ellipsoid / singular information
  kImplausible,      // a scale far from the nominal unit (wrong accel_unit / gyro_unit?)
  kStopped,          // options.stop asked (StatusCode::kStopped): nothing usable
};
const char* ImuTerminationName(ImuTermination t);  // "converged", "max_iterations", ...

struct ImuStaticDiagnostics {
  double start = 0, end = 0;      // s
  int64_t first = -1, last = -1;  // sample indices
  int64_t samples = 0;
  Eigen::Vector3d accel_mean, accel_std, gyro_mean, gyro_std;  // reading units
  Eigen::Vector3d gravity_direction;  // u_j, body frame, unit (after calibration)
  double norm_residual_before = 0;    // |a| − g with the nominal conversion, m/s²
  double norm_residual_after = 0;     // |a| − g calibrated, m/s²
};

struct ImuRotationDiagnostics {
  int from = -1, to = -1;             // static indices j, j+1
  double start = 0, end = 0;          // s (last sample of static j, first of static j+1)
  double angle = 0;                   // rad, calibrated integrated rotation
  double direction_error_before = 0;  // rad, angle(Rᵀu_j, u_{j+1}) with the nominal conversion
  double direction_error_after = 0;   // rad, calibrated
  bool used = true;                   // in the gyroscope fit
  std::string excluded;               // why not ("gap in t", "saturated samples")
};

struct ImuCoverage {
  // Eigenvalues (ascending) of (3/n) Σ u_j u_jᵀ: all 1 for orientations spread evenly on the
  // sphere; min_eigenvalue near 0 means the statics lie near a plane or a line.
  Eigen::Vector3d gravity_eigenvalues = Eigen::Vector3d::Zero();
  double min_eigenvalue = 0;
  Eigen::Vector3d least_covered_direction = Eigen::Vector3d::Zero();  // its eigenvector
  std::vector<std::string> missing_up;  // body axes ("+x", "-y", ...) never within 45° of up
  // Rotation excitation: Σ over used rotations of ∫|ω_i| dt per body axis, rad.
  Eigen::Vector3d rotation_per_axis = Eigen::Vector3d::Zero();
  std::vector<std::string> weak_axes;  // axes turned less than 20 % of the most turned one
  bool sufficient = false;
  std::string verdict;  // in words, e.g. "add orientations with the board's -y axis up"
};

struct ImuThresholdTrial {
  double multiplier = 0;
  int statics = 0;
  double accel_chi2_per_dof = std::numeric_limits<double>::quiet_NaN();  // NaN: not fitted
  bool chosen = false;
};

struct ImuResult {
  std::string name;
  bool usable = false;  // the parameters may be used
  ImuTermination termination = ImuTermination::kNotRun;
  std::string reason;  // why not usable; empty when usable
  double gravity = std::numeric_limits<double>::quiet_NaN();
  GyroBiasModel gyro_bias_model = GyroBiasModel::kStatics;
  TriadCalibration accelerometer, gyroscope;

  // Diagnostics.
  StaticDetection detection;                        // the chosen detection (all triads of the log)
  std::vector<ImuThresholdTrial> threshold_trials;  // multipliers tried (empty if overridden)
  std::string threshold_choice;                     // in words, how the threshold was chosen
  std::vector<ImuStaticDiagnostics> statics;
  std::vector<ImuRotationDiagnostics> rotations;
  ImuCoverage coverage;
  Eigen::Vector3d accel_noise = Eigen::Vector3d::Zero();       // σ per axis per sample, SI, used
  Eigen::Vector3d gyro_noise = Eigen::Vector3d::Zero();        // σ per axis per sample, SI, used
  double accel_norm_rms_before = 0, accel_norm_rms_after = 0;  // RMS of |a| − g over statics
  double gyro_direction_rms_before = 0, gyro_direction_rms_after = 0;  // rad, used rotations
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();      // joint fit, whitened
  int degrees_of_freedom = -1;
  int accel_iterations = 0, gyro_iterations = 0, joint_iterations = 0;
  std::vector<double> cost;  // ½χ² (whitened) at the start and after each accepted iteration
                             // of the last stage run (joint, or the gyroscope fit)
  // Covariance of the 21 reported parameters, in order b_a(3), K_a(3), T_a01, T_a02, T_a12,
  // b_g(3), K_g(3), T_g01, T_g02, T_g10, T_g12, T_g20, T_g21: the primary one (uncertainty_basis),
  // from which accelerometer/gyroscope *_std come.
  Eigen::MatrixXd covariance;
  // "crb": the white-noise Cramér–Rao bound (inverse Fisher information), χ²/dof consistent with
  // the noise model; "chi2_scaled": the CRB × crb_scale² where χ²/dof exceeds it significantly
  // (the residuals are the static means and rotation ends, so bias wander, coloured noise and an
  // understated noise inflate them and the σ with them).
  std::string uncertainty_basis = "crb";
  double crb_scale = 1;  // primary σ / CRB σ (√(χ²/dof) when chi2_scaled, else 1)
  // The CRB's σ in the *_std members (the other members unset).
  TriadCalibration accelerometer_crb, gyroscope_crb;
  std::vector<std::string> warnings;

  // One line for logs and tests, in the style of every method's result: usable (or why not),
  // termination, statics and rotations used, iterations per stage, χ²/dof, the residuals before
  // and after calibration.
  std::string BriefReport() const;
};

// Calibrates every IMU of a log with one shared static detection. kInvalidInput: bad options or
// readings (names what). kNotDeterminable: too few statics or rotations, degenerate orientations,
// implausible scales — the message says how many statics were found, how many are needed and
// which orientations to add. `results` gets one entry per IMU, filled as far as the computation
// got, even on failure.
Status CalibrateImus(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                     const ImuOptions& options, std::vector<ImuResult>* results);

// Steps 1-2 of CalibrateImus alone, the same code (what GET /recordings/{id}/check shows before
// fitting, server/recording_check.h): the static detection at every candidate multiplier, the
// accelerometer fits that choose among them, and per IMU its detection, threshold_trials,
// threshold_choice and warnings as CalibrateImus leaves them, and the coverage of the chosen
// statics' gravity directions read with the nominal conversion (CalibrateImus reports the
// calibrated one). No gyroscope fit: cost O(N × triads × multipliers). The status as CalibrateImus
// would return it at that point (kNotDeterminable for too few statics, the results then failed).
Status FindImuStatics(const Eigen::VectorXd& t, const std::vector<ImuReadings>& imus,
                      const ImuOptions& options, std::vector<ImuResult>* results);

// One IMU.
Status CalibrateImu(const Eigen::VectorXd& t, const Eigen::MatrixX3d& accel,
                    const Eigen::MatrixX3d& gyro, const ImuOptions& options, ImuResult* result);

// The rotation of the body over samples [first, last] (body at `last` → body at `first`) from the
// calibrated rate, as the gyroscope fit integrates it. Exposed for tests and reports.
Eigen::Matrix3d IntegrateRotation(const Eigen::VectorXd& t, const Eigen::MatrixX3d& gyro,
                                  const Eigen::Matrix3d& matrix, const Eigen::Vector3d& bias,
                                  int64_t first, int64_t last);

// Pooled within-static σ per axis (reading units) of triad `tri` of a detection (2k: IMU k's
// accelerometer, 2k + 1 its gyroscope): the noise CalibrateImus uses when the options give none.
Eigen::Vector3d PooledStd(const StaticDetection& d, int tri);

}  // namespace calibd::core

#endif  // CALIBD_CORE_IMU_H_
