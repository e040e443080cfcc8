// The typed result of the `imu` method (SPEC §4, §7): what methods/imu/imu_method.cc writes and
// what Judge, the exports (CSV, C header, OpenVINS yaml), the web report and the drift tables read.
// ToJson writes exactly the document the adapter has always written (plus "schema_version");
// FromJson reads it back, naming the path of the first problem
// ("imu result: diagnostics.imus[0].coverage.sufficient: expected a boolean, found a string").
//
// Model: a = T_a K_a (y_a − b_a), ω = T_g K_g (y_g − b_g) per IMU (results::ImuTriads). Units:
// biases in reading units, scales in SI per reading unit, misalignment angles in radians, times
// in seconds, gravity and accelerometer residuals in m/s², gyroscope direction errors in rad.
// NaN is written as null.
//
// Members marked "optional" were added after the first imu results were stored (the reading units
// and rate, gaps, saturation, noise jobs): absent in those, and written only when present, so an
// old stored result reads and writes back unchanged.
//
// Keys SPEC §4/§7 requires are required by FromJson: the envelope, parameters.imus[] and
// uncertainty.imus[] (results/triad.h), diagnostics.statics[] (start, end, samples),
// diagnostics.threshold_choice (the threshold used), and per IMU in diagnostics.imus[] its statics
// (start, end, samples, accel/gyro mean and std), rotations (angle, direction errors before and
// after), coverage.verdict and residuals. Every other key is an extension (marked "ext." below):
// when absent (a result stored by an earlier calibd) the member keeps the default given here —
// NaN for a number (shown as a dash, never exported as 0), empty for a list or text. ToJson
// writes them all. In a partial document every diagnostics member, and the diagnostics
// themselves, are optional.
//
// A failed run's partial document ({"method", "usable": false, "diagnostics", "warnings"}) reads
// with envelope.usable == false: `parameters` and `uncertainty` are then absent (nullopt); the
// diagnostics are as far as the calibration got.
#ifndef CALIBD_RESULTS_IMU_RESULT_H_
#define CALIBD_RESULTS_IMU_RESULT_H_

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "results/envelope.h"
#include "results/json_reader.h"
#include "results/saturation.h"
#include "results/triad.h"

namespace calibd::results {

inline constexpr int kImuSchemaVersion = 1;

namespace imu_result_internal {
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}

struct ImuParameters {
  double gravity = std::numeric_limits<double>::quiet_NaN();  // m/s², used by the fit (ext.)
  std::string gyro_bias;  // "statics" | "estimate" (ext.; "" when absent)
  // The nominal SI per reading unit the log was read with (optional, see above).
  std::optional<double> accel_unit, gyro_unit;
  std::vector<ImuTriads> imus;  // one per IMU, in the log's order
};

// uncertainty: {"basis", "chi2_per_dof", "imus": [{"name", "accelerometer", "gyroscope",
// "crb": {"accelerometer", "gyroscope"}}]}. The *_std of each entry are the primary σ, named by
// basis; crb holds the white-noise Cramér–Rao bound's.
struct ImuUncertainty {
  // "crb" (every IMU's residuals consistent with its noise), "chi2_scaled" (at least one IMU's σ
  // is its CRB × √(χ²/dof); its warning says by how much) or "crb_only" (read from a result of an
  // earlier calibd, without basis: the σ are the CRB, nothing known of the residuals).
  std::string basis = "crb_only";
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();  // largest over the IMUs
  std::vector<ImuTriadsStd> imus;  // the same IMUs in the same order
  std::vector<ImuTriadsStd> crb;   // per IMU (same order), the CRB; empty when crb_only
};

// diagnostics.statics[] (the shared detection) : one static interval.
struct ImuInterval {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
};

// diagnostics.gaps[]: a gap in t.
struct ImuGap {
  int64_t index = -1;                                       // first sample after the gap (ext.)
  double start = std::numeric_limits<double>::quiet_NaN();  // s (ext.)
  double end = std::numeric_limits<double>::quiet_NaN();    // s (ext.)
};

// diagnostics.noise_model.{accelerometer,gyroscope}: Kalibr's figures of the noise job a config
// named ({"job": ID}), SI, the largest axis.
struct ImuNoiseModel {
  std::optional<int64_t> job;
  double white_noise = std::numeric_limits<double>::quiet_NaN();  // unit/√Hz (ext.)
  double random_walk =
      std::numeric_limits<double>::quiet_NaN();  // unit/s/√Hz; NaN: not shown (ext.)
};

// One static of one IMU (diagnostics.imus[].statics[]).
struct ImuStatic {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
  Eigen::Vector3d accel_mean = Eigen::Vector3d::Zero(), accel_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_mean = Eigen::Vector3d::Zero(), gyro_std = Eigen::Vector3d::Zero();
  // Body frame, unit (ext.; NaN when absent).
  Eigen::Vector3d gravity_direction = Eigen::Vector3d::Constant(imu_result_internal::kNaN);
  // |a| − g, m/s² (ext.; NaN when absent: the plots leave the point out).
  double norm_residual_before = imu_result_internal::kNaN,
         norm_residual_after = imu_result_internal::kNaN;
};

// One rotation between statics `from` and `to` (diagnostics.imus[].rotations[]).
struct ImuRotation {
  int64_t from = -1, to = -1;  // ext. (-1 when absent)
  double start = imu_result_internal::kNaN, end = imu_result_internal::kNaN;  // s (ext.)
  double angle = 0;                                                           // rad
  double direction_error_before = 0, direction_error_after = 0;               // rad
  bool used = true;                                                           // ext. (absent: used)
  std::string excluded;  // why not used ("" when used) (ext.)
};

// How well the orientations and rotations cover the directions (diagnostics.imus[].coverage).
// All but `verdict` are extensions: numbers NaN and lists empty when absent.
struct ImuCoverage {
  Eigen::Vector3d gravity_eigenvalues = Eigen::Vector3d::Constant(imu_result_internal::kNaN);
  double min_eigenvalue = imu_result_internal::kNaN;
  Eigen::Vector3d least_covered_direction = Eigen::Vector3d::Constant(imu_result_internal::kNaN);
  std::vector<std::string> missing_up;  // "+x", "-y", ...
  Eigen::Vector3d rotation_per_axis = Eigen::Vector3d::Constant(imu_result_internal::kNaN);  // rad
  std::vector<std::string> weak_axes;
  // Absent (an earlier calibd): true, i.e. Judge does not reject on it; the verdict in words,
  // which SPEC requires, still says how the orientations covered the sphere.
  bool sufficient = true;
  std::string verdict;  // in words
};

// ext., every member.
struct ImuThresholdTrial {
  double multiplier = imu_result_internal::kNaN;
  int64_t statics = 0;
  double accel_chi2_per_dof = std::numeric_limits<double>::quiet_NaN();  // NaN: not fitted
  bool chosen = false;
};

// diagnostics.imus[]: how the fit of one IMU went.
// name, usable, termination, reason, chi2_per_dof, degrees_of_freedom, iterations, noise,
// threshold_trials, threshold_choice and cost are extensions.
struct ImuFitDiagnostics {
  // Absent: the parameters' name of the IMU at the same index (else the index).
  std::string name;
  bool usable = false;      // absent: the document's usable
  std::string termination;  // core::ImuTerminationName: "converged", "too_few_statics", ...
  std::string reason;       // why not usable; "" when usable
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  int64_t degrees_of_freedom = -1;
  int64_t accel_iterations = 0, gyro_iterations = 0, joint_iterations = 0;  // "iterations"
  // "noise": σ per sample, SI (NaN when absent: the OpenVINS export then gives no density from
  // the statics).
  Eigen::Vector3d accel_noise = Eigen::Vector3d::Constant(imu_result_internal::kNaN);
  Eigen::Vector3d gyro_noise = Eigen::Vector3d::Constant(imu_result_internal::kNaN);
  // "residuals": RMS of |a| − g over the statics (m/s²) and of the gravity-direction error per
  // rotation (rad), with the nominal conversion and calibrated.
  double accel_norm_rms_before = 0, accel_norm_rms_after = 0;
  double gyro_direction_rms_before = 0, gyro_direction_rms_after = 0;
  std::vector<ImuStatic> statics;
  std::vector<ImuRotation> rotations;
  ImuCoverage coverage;
  std::vector<ImuThresholdTrial> threshold_trials;
  std::string threshold_choice;
  std::vector<double> cost;  // ½χ² at the start and after each accepted iteration
};

struct ImuDiagnostics {
  std::vector<ImuInterval> statics;
  std::optional<double> rate;               // Hz, mean over the log (optional)
  std::optional<std::vector<ImuGap>> gaps;  // optional
  // Noise jobs the config's accel_noise / gyro_noise came from (optional block; each nullopt when
  // the config gave a number or nothing, written as null).
  struct NoiseJobs {
    std::optional<int64_t> accelerometer, gyroscope;
  };
  std::optional<NoiseJobs> noise_jobs;
  // Their figures (optional block; each nullopt = null).
  struct NoiseModels {
    std::optional<ImuNoiseModel> accelerometer, gyroscope;
  };
  std::optional<NoiseModels> noise_model;
  std::optional<int64_t> saturated_samples;         // optional
  std::optional<SaturationDiagnostics> saturation;  // results/saturation.h; absent: none pinned
  double static_window = std::numeric_limits<double>::quiet_NaN();  // s (ext.)
  double min_static = std::numeric_limits<double>::quiet_NaN();     // s (ext.)
  std::string threshold_choice;
  std::vector<ImuFitDiagnostics> imus;
};

struct ImuResult {
  Envelope envelope;                          // method "imu"
  std::optional<ImuParameters> parameters;    // nullopt exactly when not usable
  std::optional<ImuUncertainty> uncertainty;  // nullopt exactly when not usable
  ImuDiagnostics diagnostics;
  // A partial document the server trimmed to fit the store (server/failure_reasons.h,
  // PartialDiagnosticsText): its "trimmed" note as stored (open shape) and the diagnostics
  // members it dropped, which are absent from the JSON and left at their defaults here
  // ("diagnostics" itself when all were dropped). Empty for every other document.
  std::optional<nlohmann::json> trimmed;
  std::vector<std::string> dropped;
};

nlohmann::json ToJson(const ImuResult& r);
// kInvalidInput naming the path of the first problem (what = "imu result").
Status FromJson(const nlohmann::json& doc, ImuResult* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_IMU_RESULT_H_
