// JSON glue of the `thermal` method (SPEC §8): an inertial log with temperature columns (`tempK`
// per IMU K, or one `temp`) to core::CalibrateThermal (core/thermal.h), and its result as the
// SPEC §4 / §8 result JSON (methods/thermal/thermal_result.cc):
//   parameters.imus[]: {"name", "t_ref", "t_min", "t_max", "lag" (τ in s, or null: lag none),
//     "accelerometer": {"bias": {"order" (the highest over the axes), "orders" [3],
//        "coefficients": [[c1..cp] per axis, SI per °C^k], "at_t_ref": null}, "scale": null},
//     "gyroscope": {"bias": {... "at_t_ref": [3] rad/s}, "scale": null}}
//   uncertainty: {"basis": "crb" | "chi2_scaled", "chi2_per_dof": null, "imus": [{"name",
//     "lag_std" (s; null unless estimated),
//     "accelerometer": {"bias": {"covariance": [p×p per axis], "temperatures": [grid],
//        "std": [[1σ on the grid] per axis], "at_t_ref_std": null}, "scale": null},
//     "gyroscope": {... "at_t_ref_std": [3]}, "crb": {the same keys with the white-noise bound}}]}
//   diagnostics: {"order_selection", "hysteresis_test", "imus": [{"name", "windows" [...],
//     "orientations", "heating_windows", "cooling_windows", "temperature_rate": {min, max},
//     "hysteresis_critical_z", "channels": [{"name", "order", "basis", "chi2_per_dof",
//     "residual_rms", "noise_rms", "order_table": [{order, chi2, bic, weight}], "points":
//     {"temperature", "deviation", "std"}, "hysteresis": {...}}], "lag": {"mode", "tau",
//     "profile": {"tau", "minus_2_log_likelihood"} (estimate only)}}]}
// Config keys: method, device, accel_unit, gyro_unit (formats/inertial_log.h), t_ref, max_order
// (1..8, default 5), min_order (0..8, default 3: the lowest order averaged), min_range (°C, default
// 10), lag ("none", "estimate", or τ in s: known), device_id (PX4's TC_*_ID), window (s, default
// 10), grid_points (default 21), hysteresis_alpha (default 0.01), accel_noise / gyro_noise (σ per
// sample in the reading units, or {"job": ID} of a noise job, resolved at enqueue: the windows' σ
// are then σ/√n; the result's diagnostics.noise_jobs names the jobs).
#ifndef CALIBD_METHODS_THERMAL_THERMAL_METHOD_H_
#define CALIBD_METHODS_THERMAL_THERMAL_METHOD_H_

#include <nlohmann/json.hpp>
#include <string>

#include "core/thermal.h"
#include "core/thermal_simulation.h"
#include "methods/method.h"

namespace calibd::server {

// The `thermal` method for the registry: reads inertial logs with temperature columns.
const Method& ThermalMethod();

// The result JSON of a core result (methods/thermal/thermal_result.cc; exposed for tests).
nlohmann::json ThermalResultToJson(const core::ThermalResult& result,
                                   const core::ThermalOptions& options);

// The plan of a warm-up protocol (Method::Plan; methods/thermal/thermal_plan.cc): `options` from
// the validated config. kInvalidInput naming protocol.t_min or config.accel_noise/gyro_noise
// when what the plan needs is missing.
Status PlanThermal(const core::ThermalOptions& options, const PlanProtocol& protocol,
                   const AcceptanceLimits& limits, nlohmann::json* out);

// What a job would report for the windows a recording check found (Thermal::Check, issue #27
// item 2; core::FindThermalWindows): the plan's white-noise σ (basis crb) of the bias curves on
// exactly those windows, each window mean's σ the job's own (window.mean_std), at the floor order
// the job offers first (`orders` as the plan's). {"uncertainty": null, "reason"} when the windows
// give no curve. The scale stage's extra parameters (opposite faces) are not counted.
nlohmann::json PredictThermalWindows(const core::ThermalOptions& options,
                                     const core::ThermalImuResult& found);

// `calibd simulate thermal`: CSV `t,a0_x..g0_z,temp0` (%.10g), the config and the truth
// ({"t_ref", "lag" (s), "accelerometer"/"gyroscope": {"coefficients": [[c1..cp] per axis],
// "b0": [3]}, "hysteresis": [6]}).
Status SimulateThermalFiles(const core::ThermalSimulationOptions& options, std::string* csv,
                            nlohmann::json* config, nlohmann::json* truth);

// Exports (methods/thermal/thermal_exports.cc).
Status ThermalResultToCsv(const nlohmann::json& result, std::string* out);
Status ThermalResultToHeader(const nlohmann::json& result, const ExportContext& context,
                             std::string* out);
// ArduPilot INS_TCALn_* (n from 1, at most 3 IMUs): order 3 about 35 °C, no constant term, ×1e6;
// the firmware subtracts P(T − 35) − P(T_cal − 35) from the sensor-frame reading, T clamped to
// [TMIN, TMAX] (AP_InertialSensor_tempcal.cpp correct_sensor).
Status ThermalResultToArduPilot(const nlohmann::json& result, const ExportContext& context,
                                std::string* out);
// PX4 TC_An_* / TC_Gn_* (n from 0) in QGroundControl's parameter-file lines; the firmware
// subtracts X0 + X1 dT + X2 dT² + X3 dT³, dT = clamp(T, TMIN, TMAX) − TREF
// (TemperatureCompensation::calc_thermal_offsets_3D).
Status ThermalResultToPx4(const nlohmann::json& result, const ExportContext& context,
                          std::string* out);

// A firmware's cubic fitted to a result's curve of one axis over [t_min, t_max] (least squares on
// a dense grid, free constant): coefficients a1..a3 of (T − reference)^k, the constant, and the
// largest |difference| from calibd's curve over the range (the loss of fit the files state).
struct FirmwareCubic {
  double a[3] = {0, 0, 0};
  double constant = 0;
  double max_error = 0;
};
FirmwareCubic RefitCubic(const std::vector<double>& coefficients, double t_ref, double t_min,
                         double t_max, double reference);

}  // namespace calibd::server

#endif  // CALIBD_METHODS_THERMAL_THERMAL_METHOD_H_
