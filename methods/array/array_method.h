// JSON glue of the `array` method: config keys (SPEC §3) to core::ArrayOptions, a parsed recording
// to the result JSON (SPEC §4), and the simulated files of `calibd simulate array`.
#ifndef CALIBD_SERVER_ARRAY_METHOD_H_
#define CALIBD_SERVER_ARRAY_METHOD_H_

#include <atomic>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/array.h"
#include "core/array_full.h"
#include "core/stop_token.h"
#include "formats/recording.h"
#include "methods/method.h"

namespace calibd::server {

// The `array` method for the registry (methods/method.h): reads the array layout.
const Method& ArrayMethod();

// Its references to other jobs (Method::ResolveReferences): `accel_noise` / `gyro_noise` as
// {"job": ID} of a succeeded noise job (methods/noise/noise_reference.h), and the accelerometer
// calibration of a succeeded, accepted pca job: {"accelerometer_calibration": {"job": ID}} becomes
// {"job": ID, "result": {...}} before the job is stored.
Status ResolveArrayReferences(storage::Store* store, nlohmann::json* config);

// The accelerometer calibration an array fit uses (SPEC §3 `accelerometer_calibration`, issue #8).
struct ArrayAccelerometerCalibration {
  bool present = false;  // the config has (a valid) accelerometer_calibration
  nlohmann::json job;    // the pca job's id when given as {"job": ID, "result": {...}}, else null
  std::string frame;     // the pca result's parameters.frame ("nominal")
  std::string bias;      // its parameters.bias ("estimate" | "none"; "" when absent)
  double magnitude = 0;  // its parameters.magnitude (m/s^2 expected)
  int sensors = 0;       // sensors used: 3K (a0_x ... a{K-1}_z)
  double max_condition_number = 0;                    // over the K sensitivity blocks
  std::vector<core::AccelerometerTriadModel> triads;  // K, triad order (a0, a1, ...)
  std::vector<std::string> warnings;                  // for the result's warnings

  // {"job": ID or null, "sensors", "frame", "bias", "magnitude", "max_condition_number"}, or
  // null when !present: the array result's diagnostics.accelerometer_calibration.
  nlohmann::json ToJson() const;
};

// Reads an accelerometer_calibration value for an array of `triads` accelerometer triads named
// a0 ... a{triads-1}. Accepted: a pca result object (SPEC §4, "method": "pca"), or
// {"job": ID, "result": {pca result}} (what the server makes of the user's {"job": ID}).
// Convention, from the pca model m_i = a_iᵀ v + b_i (parameters.sensors[i].sensitivity = a_i,
// .bias = b_i): triad k's block A_k = [a_x a_y a_z] (sensitivity vectors of aK_x, aK_y, aK_z as
// columns), readings y = A_kᵀ f + b_k, corrected f = A_k⁻ᵀ (y − b_k)
// (core::AccelerometerTriadModel). Errors, all kInvalidInput with
// WithField("accelerometer_calibration") and a message starting "config key
// 'accelerometer_calibration': ": not an object (a string path is resolved only by `calibd
// calibrate`); a bare {"job": ID} (only resolvable over HTTP); not a pca result; dimension
// != 3; frame not "nominal" (a canonical-frame result's axes do not line up with the gyroscopes);
// magnitude unknown; sensors malformed, duplicated or missing (the missing names are listed);
// a triad's 3×3 block singular or ill-conditioned (condition number >
// core::kMaxAccelerometerConditionNumber). Sensors other than aK_x/y/z are ignored (warning).
// Warnings (not errors): magnitude far from 9.80665 (units), bias "none" with every bias 0 (biases
// not corrected; nonzero biases are applied whatever parameters.bias says).
// The pca nominal frame is the best orthogonal fit of all the triads' axes onto the nominal; the
// array fit assumes it is the gyroscopes' frame (a common accelerometer-to-gyroscope rotation is
// not observable from static data and is not estimated).
Status ParseAccelerometerCalibration(const nlohmann::json& value, int triads,
                                     ArrayAccelerometerCalibration* out);

// Reads the array keys of a config object (SPEC §3): geometry {"positions": [[x,y,z], ...K],
// "reference": k (default 0)}, accel_noise (m/s²), gyro_noise (in gyro_unit), gyro_unit
// ("rad/s" default | "deg/s"), gyro_saturation (in gyro_unit), accel_saturation (m/s²; both
// default: the clip levels found in the data, core/saturation.h, less 0.2 %; what is pinned is
// reported in diagnostics.saturation and a warning), solver ("joint" | "bcd"),
// max_iterations (integer >= 0, 0 = solver default), tolerance (>= 0, < 1).
// accelerometer_calibration (optional, see ParseAccelerometerCalibration; checked against the
// geometry's triad count). The common keys method and device are ignored. Unknown keys, missing
// required keys (geometry, accel_noise, gyro_noise) and wrong types or values are kInvalidInput
// with WithField(key) and a message naming the key. Fills geometry_part->nominal_positions and
// ->reference only; with deg/s, gyro_noise and gyro_saturation are converted to rad/s and
// *gyro_in_degrees is set. calibration may be null (validation only); otherwise it is reset and
// filled (present = false without the key).
Status ParseArrayConfig(const nlohmann::json& config, core::ArrayProblem* geometry_part,
                        core::ArrayOptions* options, bool* gyro_in_degrees,
                        ArrayAccelerometerCalibration* calibration = nullptr);

// Runs the calibration on a parsed recording (gyro columns converted from deg/s when configured)
// and writes the SPEC §4 result, built as a results::ArrayResult (methods/array/array_result.h, the
// typed schema every reader of the result uses) and written with its ToJson (so it also carries
// "schema_version"; the failed run's partial document too):
//   {"method":"array",
//    "parameters":{"reference", "positions":[{"name","position":[x,y,z],"offset":[dx,dy,dz]}]},
//    "uncertainty":{"positions":[{"name","std":[sx,sy,sz]}]},
//    "diagnostics":{"solver","iterations","converged","termination","cost":[...],"samples",
//                   "samples_dropped","gyro_triads",
//                   "residual_rms":{"accelerometer","gyroscope"},
//                   "noise_estimate":{"accelerometer","gyroscope"},
//                   "noise_configured":{"accelerometer","gyroscope"},
//                   "excitation":{"min_eigenvalue","max_eigenvalue","noise_floor",
//                                 "weakest_direction","verdict"},
//                   "parallel_fraction",
//                   "motion":{"stride","omega_norm":[...],"omega_dot_norm":[...]}},
//    "warnings":[...]}
//                   "accelerometer_calibration": null | {"job", "sensors", "frame", "bias",
//                                                        "magnitude", "max_condition_number"}},
// With an accelerometer_calibration, each triad's readings are corrected (f = A_k⁻ᵀ(y − b_k))
// before the fit; accel_noise stays the σ_a of the raw readings (the correction changes it by
// the scale errors, ~1%, which the isotropic model ignores).
// Metres, m/s², rad/s (gyroscope figures in the configured gyro_unit); diagnostics name them
// (accel_unit, gyro_unit, excitation.units, units: methods/array/array_result.cc). "motion" holds
// at most 2000 points (every stride-th usable sample). No NaN/Inf (null instead). Deterministic.
// The recording's triad count must equal the geometry's (kInvalidInput naming both).
// Errors as core::CalibrateArray otherwise.
// `stop` (optional): the solver stops at its next iteration once it asks to.
// `executor` (optional): runs the solver's parallel work (e.g. the server's shared pool);
// without one the solver starts its own threads.
// The recording is taken by value: pass it with std::move where it is not needed afterwards
// (the samples are then never copied).
Status RunArray(ArrayRecording recording, const nlohmann::json& config, nlohmann::json* result,
                const core::StopToken* stop = nullptr, core::TaskExecutor executor = {});

// The plan of a free-motion protocol for the positions model (Method::Plan; methods/array/
// array_plan.cc): `geometry` (nominal_positions, reference) and `options` (noises in rad/s etc.)
// as ParseArrayConfig fills them. kInvalidInput naming protocol.angular_rate when the protocol
// gives no motion.
Status PlanArray(const core::ArrayProblem& geometry, const core::ArrayOptions& options,
                 const PlanProtocol& protocol, const AcceptanceLimits& limits, nlohmann::json* out);

// The plan of a statics-then-motion protocol for the full model (Method::Plan; methods/array/
// array_full_plan.cc): `config` a full-model config whose accel_noise and gyro_noise are given
// (kInvalidInput naming the missing one); the protocol's orientations (the statics) and
// angular_rate (the dynamic phase) are required. kInvalidInput also for a protocol too long to
// replay (naming protocol.duration).
Status PlanArrayFull(const nlohmann::json& config, const PlanProtocol& protocol,
                     const AcceptanceLimits& limits, nlohmann::json* out);

// The acceptance gate of an array result (Method::Judge), read typed (results::FromJson; a result
// that does not read is rejected with the reader's message): every triad but the reference within
// max_offset of its nominal position and its 1 sigma within max_position_std
// (parameters.positions and uncertainty.positions, both models; an offset the result does not
// give, as a full-model result stored without parameters.positions, is taken against the config's
// geometry), the solver converged, for the positions model the residual RMS against the
// configured accel_noise / gyro_noise (max_chi2 on the squared ratio), and for model full each
// triad's gains, misalignments and biases as for imu (JudgeImuTriads; nominal units from
// accel_unit, gyro_unit).
void JudgeArray(const nlohmann::json& result, const nlohmann::json& config,
                const AcceptanceLimits& limits, Verdict* verdict);

// model "full" (SPEC §7): the keys geometry (as above), accel_noise (m/s², optional: default
// from the statics), gyro_noise (gyro_unit, optional: from the statics), gyro_unit,
// gyro_saturation, accel_saturation (as for positions), gravity (m/s², default 9.80665),
// max_iterations (>= 1), tolerance,
// static_window and min_static (s, static detection), robust_batch (s, the residual-aware σ's
// batches), dynamic_weighting ("noise" default | "residual": the dynamic samples weighted by
// their own residual level, core::ArrayFullDynamicWeighting), model, method, device. solver and
// accelerometer_calibration are rejected (the full model estimates the accelerometers with its own
// joint solver). Errors as ParseArrayConfig. RunArray dispatches on "model": with "full" it runs
// core::CalibrateArrayFull on the recording (which needs a `t` column and one gyroscope triad per
// accelerometer triad) and writes
//   parameters: {"model":"full","reference","imus":[{"name","accelerometer":{"bias","scale",
//                "misalignment","matrix"},"gyroscope":{same},"position"}],"positions":[as the
//                positions model]},
//   uncertainty: {"imus":[{"name","accelerometer":{"bias_std","scale_std","misalignment_std"},
//                 "gyroscope":{same},"position_std","robust":{same keys, when the residuals
//                 exceed the noise}}],"positions":[{"name","std"}]},
//   diagnostics: {"model","gauge":{"scale","reference","description"},"iterations",
//                 "converged","termination","cost","statics","static_samples",
//                 "dynamic_samples","samples_dropped","dof","chi2_per_dof","noise",
//                 "static_noise","residual_rms":{"dynamic","imus":[{"name","static",
//                 "dynamic"}]},"rotation_excitation","null_directions","robust",
//                 "positions_only_start","changed_from_positions_only":[{"name",
//                 "positions_only" (the fit the full model starts from), "positions_only_std"
//                 (its CRB; absent when that fit failed), "position_change",
//                 "position_change_norm", "position_change_sigma" (change / the full model's
//                 position_std per axis; null for the reference), "unit"}], "accel_unit",
//                 "units"}; "model": the equation.
// Gyroscope figures in the configured gyro_unit (bias in it, scale in rad/s per unit).
Status ParseArrayFullConfig(const nlohmann::json& config, core::ArrayFullProblem* geometry_part,
                            core::ArrayFullOptions* options, bool* gyro_in_degrees);

// For `calibd simulate array`.
struct ArraySimulationFileOptions {
  int64_t samples = 1000;                // N
  double omega_norm_dps = 2000;          // |omega|, deg/s
  double omega_dot_norm_dps2 = 2000;     // |omega_dot|, deg/s²
  double accel_noise = 0.04;             // sigma_a, m/s²
  double gyro_noise_dps = 0.06;          // sigma_g, deg/s
  double position_perturbation = 0.001;  // sigma_r, m
  uint64_t seed = 1;
  std::string gyro_unit = "rad/s";  // unit of the gyro columns and config ("rad/s" | "deg/s")
  // Per-triad accelerometer errors (core::ArraySimulationOptions, SimulateAccelerometerModels):
  // the same board (seed) in SimulateArrayFiles and SimulateArrayStaticFiles. Default 0: ideal.
  double accel_bias = 0;          // sigma of each bias, m/s²
  double accel_scale_error = 0;   // sigma of each relative scale-factor error
  double accel_misalignment = 0;  // sigma of each axis tilt, rad
  // Static recording (SimulateArrayStaticFiles): readings averaged over this many samples per
  // position, so the noise is accel_noise / sqrt(static_samples). >= 1.
  int64_t static_samples = 1000;
  // `--model full` (SimulateArrayFullFiles): the board ("mimu4444": 8 IMUs, "paper32": the 32 of
  // the seed) with per-triad accelerometer and gyroscope errors (core/array_full_simulation.h
  // defaults: gains 1 %, misalignment 10 mrad, biases 0.1 m/s² and 1 °/s), 20 statics of
  // 1.5 s, then `samples` dynamic samples, at 100 Hz.
  std::string board = "mimu4444";
};

// The CSV text (header t,a0_x..a31_z,g0_x..g31_z, %.17g, t = n / 100 s), the config
// ({"method":"array","geometry":{"positions": NOMINAL, "reference":0},"accel_noise",
// "gyro_noise","gyro_unit"}) and the truth ({"positions":[{"name","position"}], "seed",
// "options"}). Deterministic for a seed. With accelerometer errors, truth also has
// "accelerometer_sensors": [{"name": "a0_x", "sensitivity": [3], "bias"}, ...] (the pca truth
// format, body frame) and options records accel_bias, accel_scale_error, accel_misalignment.
Status SimulateArrayFiles(const ArraySimulationFileOptions& options, std::string* csv,
                          nlohmann::json* config, nlohmann::json* truth);

// The static multi-orientation recording of the SAME simulated board (same seed-derived
// accelerometer errors) for a `pca` calibration with unknown biases: CSV in the pca averaged
// layout "position,a0_x,...,a31_z" (rows p1..pn, %.17g), gravity 9.80665 m/s² in `positions`
// random orientations, noise accel_noise / sqrt(static_samples); config {"method":"pca",
// "magnitude":9.80665,"bias":"estimate","nominal": identity block per triad (96 rows)}.
// Its pca result (frame nominal) is an accelerometer_calibration for SimulateArrayFiles' config.
// kInvalidInput for positions < 1, static_samples < 1 or invalid options.
Status SimulateArrayStaticFiles(const ArraySimulationFileOptions& options, int positions,
                                std::string* csv, nlohmann::json* config);

// `calibd simulate array --model full`: CSV (t,a0_x..,g0_x.., %.17g), config ({"method":
// "array","model":"full","geometry","accel_noise","gyro_noise","gyro_unit","static_window":0.25,
// "min_static":0.5}) and truth ({"method","model":"full","reference","imus":[as the result's
// parameters.imus],"seed","options"}). kInvalidInput for an unknown board or unit.
Status SimulateArrayFullFiles(const ArraySimulationFileOptions& options, std::string* csv,
                              nlohmann::json* config, nlohmann::json* truth);

// Exports of a array result (methods/array/array_exports.cc; formats in methods/exports.h), read
// typed (results::FromJson): a result that does not read is kInternal with the reader's message. An
// offset the result does not give (a full-model result stored without parameters.positions) is
// an empty CSV field, and the header leaves OFFSET out saying so.
Status ArrayResultToCsv(const nlohmann::json& result, std::string* out);
Status ArrayResultToHeader(const nlohmann::json& result, const ExportContext& context,
                           std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_ARRAY_METHOD_H_
