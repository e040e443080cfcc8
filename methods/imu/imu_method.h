// JSON glue of the `imu` method (SPEC §7): an inertial log (array layout with `t`; triad K of the
// accelerometers and of the gyroscopes belong to IMU K) to core::CalibrateImus, and its results to
// the typed results::ImuResult (methods/imu/imu_result.h, every key typed there), written as the
// SPEC §4 / §7 result JSON:
//   {"method":"imu","schema_version":1,"model":...,
//    "parameters":{"gravity","gyro_bias","accel_unit","gyro_unit","imus":[{"name",
//        "accelerometer":{"bias":[3],"scale":[3],"misalignment":[[3]x3],"matrix":[[3]x3]},
//        "gyroscope":{same}}]},
//    "uncertainty":{"imus":[{"name","accelerometer":{"bias_std","scale_std","misalignment_std"},
//                            "gyroscope":{same}}]},
//    "diagnostics":{"statics":[{"start","end","samples"}],"rate","gaps","noise_jobs",
//        "noise_model","saturated_samples","static_window","min_static","threshold_choice",
//        "imus":[{"name","usable","termination","reason","chi2_per_dof","degrees_of_freedom",
//                 "iterations","noise",
//                 "residuals":{"accel_norm_rms_before","accel_norm_rms_after",
//                              "gyro_direction_rms_before","gyro_direction_rms_after"},
//                 "statics":[...],"rotations":[...],"coverage":{...},
//                 "threshold_trials":[...],"threshold_choice","cost"}]},
//    "warnings":[...]}
// Judge, the exports, the web report and the drift read it back with results::FromJson.
// Biases in reading units, scales in SI per reading unit, misalignment angles in radians. No
// NaN/Inf (null instead). Deterministic.
// Config keys: method, device, accel_unit, gyro_unit (formats/inertial_log.h), gravity (m/s²) or
// latitude (deg) and height (m) for WGS-84 normal gravity (default 9.80665), gyro_bias
// ("statics" default | "estimate"), static_window (s, default 1), min_static (s, default 1),
// static_threshold ({"accelerometer": x, "gyroscope": y}, window spread in reading units,
// overriding the threshold found from the noise floor), accel_noise / gyro_noise (σ per sample,
// SI; default: from the statics), nominal_accel_bias / nominal_gyro_bias (reading units, e.g.
// 32768 for offset-binary counts: the "before calibration" reference of the diagnostics).
#ifndef CALIBD_SERVER_IMU_METHOD_H_
#define CALIBD_SERVER_IMU_METHOD_H_

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/imu.h"
#include "core/imu_simulation.h"
#include "methods/method.h"
#include "results/triad.h"

namespace calibd::server {

class HeaderWriter;  // methods/export_util.h

// The `imu` method for the registry: reads inertial logs (the array layout with `t`).
const Method& ImuMethod();

// The imu config keys (SPEC §7) as core options; errors name the key. Also used for the static
// detection keys of GET /recordings/{id}/segments (server/recording_segments.h).
Status ParseImuOptions(const nlohmann::json& config, core::ImuOptions* options);

// For `calibd simulate imu`: one IMU placed by hand in `statics` orientations; CSV
// `t,a0_x,..,g0_z` (%.10g), the config ({"method":"imu", units, gravity}) and the truth
// ({"accelerometer"/"gyroscope": {"bias","scale","misalignment","matrix"}}).
Status SimulateImuFiles(const core::ImuSimulationOptions& options, std::string* csv,
                        nlohmann::json* config, nlohmann::json* truth);

// Sets *sim to the nominal IMU `options` describe (gravity, units, offsets) without sensor
// errors: what the plan and the check's prediction simulate. Motion and noise are left as they are.
void SetNominalImu(const core::ImuOptions& options, core::ImuSimulationOptions* sim);

// Method::Plan of imu (methods/imu/imu_plan.cc): needs the config's accel_noise and gyro_noise.
Status PlanImu(const nlohmann::json& config, const PlanProtocol& protocol,
               const AcceptanceLimits& limits, nlohmann::json* out);
// The result the imu method reports for the log of `protocol` simulated with a nominal IMU and
// the config's noise figures (deterministic); errors as Run's.
Status PredictImu(const nlohmann::json& config, const PlanProtocol& protocol,
                  nlohmann::json* result);

// Exports of a imu result (methods/imu/imu_exports.cc; formats in methods/exports.h).
Status ImuResultToCsv(const nlohmann::json& result, std::string* out);
Status ImuResultToHeader(const nlohmann::json& result, const ExportContext& context,
                         std::string* out);
// The per-IMU part of the C header (macros prefixed `sub`): per IMU a = MATRIX (y - BIAS) for
// both triads; also written for an array result of the full model (sub "IMU_").
// The json form (for an array full result) reads name, bias and matrix of parameters.imus[] and
// bias_std, scale_std of uncertainty.imus[] (uncertainties that do not read are left out, as
// undefined ones are); kInternal naming the path when the IMUs do not read.
Status ImuHeader(const nlohmann::json& params, const nlohmann::json& unc, const std::string& sub,
                 HeaderWriter* w);
Status ImuHeader(const std::vector<results::ImuTriads>& imus,
                 const std::vector<results::ImuTriadsStd>& stds, const std::string& sub,
                 HeaderWriter* w);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_IMU_METHOD_H_
