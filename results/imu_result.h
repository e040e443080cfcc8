// The typed result of the `imu` method (SPEC §4, §7): what server/imu_method.cc writes and what
// Judge, the exports (CSV, C header, OpenVINS yaml), the web report and the drift tables read.
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
#include "results/triad.h"

namespace calibd::results {

inline constexpr int kImuSchemaVersion = 1;

struct ImuParameters {
  double gravity = std::numeric_limits<double>::quiet_NaN();  // m/s², used by the fit
  std::string gyro_bias;                                      // "statics" | "estimate"
  // The nominal SI per reading unit the log was read with (optional, see above).
  std::optional<double> accel_unit, gyro_unit;
  std::vector<ImuTriads> imus;  // one per IMU, in the log's order
};

struct ImuUncertainty {
  std::vector<ImuTriadsStd> imus;  // the same IMUs in the same order
};

// diagnostics.statics[] (the shared detection) : one static interval.
struct ImuInterval {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
};

// diagnostics.gaps[]: a gap in t.
struct ImuGap {
  int64_t index = -1;         // first sample after the gap
  double start = 0, end = 0;  // s
};

// diagnostics.noise_model.{accelerometer,gyroscope}: Kalibr's figures of the noise job a config
// named ({"job": ID}), SI, the largest axis.
struct ImuNoiseModel {
  std::optional<int64_t> job;
  double white_noise = std::numeric_limits<double>::quiet_NaN();  // unit/√Hz
  double random_walk = std::numeric_limits<double>::quiet_NaN();  // unit/s/√Hz; NaN: not shown
};

// One static of one IMU (diagnostics.imus[].statics[]).
struct ImuStatic {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
  Eigen::Vector3d accel_mean = Eigen::Vector3d::Zero(), accel_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_mean = Eigen::Vector3d::Zero(), gyro_std = Eigen::Vector3d::Zero();
  Eigen::Vector3d gravity_direction = Eigen::Vector3d::Zero();  // body frame, unit
  double norm_residual_before = 0, norm_residual_after = 0;     // |a| − g, m/s²
};

// One rotation between statics `from` and `to` (diagnostics.imus[].rotations[]).
struct ImuRotation {
  int64_t from = -1, to = -1;
  double start = 0, end = 0;                                     // s
  double angle = 0;                                              // rad
  double direction_error_before = 0, direction_error_after = 0;  // rad
  bool used = true;
  std::string excluded;  // why not used ("" when used)
};

// How well the orientations and rotations cover the directions (diagnostics.imus[].coverage).
struct ImuCoverage {
  Eigen::Vector3d gravity_eigenvalues = Eigen::Vector3d::Zero();
  double min_eigenvalue = 0;
  Eigen::Vector3d least_covered_direction = Eigen::Vector3d::Zero();
  std::vector<std::string> missing_up;                          // "+x", "-y", ...
  Eigen::Vector3d rotation_per_axis = Eigen::Vector3d::Zero();  // rad
  std::vector<std::string> weak_axes;
  bool sufficient = false;
  std::string verdict;  // in words
};

struct ImuThresholdTrial {
  double multiplier = 0;
  int64_t statics = 0;
  double accel_chi2_per_dof = std::numeric_limits<double>::quiet_NaN();  // NaN: not fitted
  bool chosen = false;
};

// diagnostics.imus[]: how the fit of one IMU went.
struct ImuFitDiagnostics {
  std::string name;
  bool usable = false;
  std::string termination;  // core::ImuTerminationName: "converged", "too_few_statics", ...
  std::string reason;       // why not usable; "" when usable
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  int64_t degrees_of_freedom = -1;
  int64_t accel_iterations = 0, gyro_iterations = 0, joint_iterations = 0;  // "iterations"
  Eigen::Vector3d accel_noise = Eigen::Vector3d::Zero();  // "noise": σ per sample, SI
  Eigen::Vector3d gyro_noise = Eigen::Vector3d::Zero();
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
  std::optional<int64_t> saturated_samples;                         // optional
  double static_window = std::numeric_limits<double>::quiet_NaN();  // s
  double min_static = std::numeric_limits<double>::quiet_NaN();     // s
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
  // members it dropped, which are null in JSON and left at their defaults here ("diagnostics"
  // itself when all were dropped). Empty for every other document.
  std::optional<nlohmann::json> trimmed;
  std::vector<std::string> dropped;
};

nlohmann::json ToJson(const ImuResult& r);
// kInvalidInput naming the path of the first problem (what = "imu result").
Status FromJson(const nlohmann::json& doc, ImuResult* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_IMU_RESULT_H_
