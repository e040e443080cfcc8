// JSON glue of the `noise` method (SPEC §7): an inertial log (array layout with `t`) to
// core::EstimateNoise, and its result to the typed results::NoiseResult
// (methods/noise/noise_result.h), written as the SPEC §4 / §7 result JSON:
//   {"method":"noise","schema_version":1,"model":...,
//    "parameters":{"channels":[{"name","unit","white_noise","bias_instability",
//                               "bias_instability_tau","random_walk"}]},
//    "uncertainty":{"channels":[{"name","white_noise_std","bias_instability_std",
//                                "random_walk_std"}]},
//    "diagnostics":{"rate","samples","duration","jitter","stationary","taus_per_decade",
//                   "confidence","units":{"accel_unit","gyro_unit"},
//                   "channels":[{"name","status","reason","fit_points","fit_chi2","mean"}],
//                   "allan":[{"name","tau","adev","adev_lower","adev_upper","fitted_adev"}]},
//    "warnings":[...]}
// Channels are in SI after the unit conversion: accelerometers m/s² (N in m/s²/√Hz, K in
// m/s³/√Hz), gyroscopes rad/s (N in rad/s/√Hz, K in rad/s²/√Hz) — Kalibr's units. A term the log
// is too short (or too noisy) to show is null, with a warning saying how long a log would show
// it. No NaN/Inf (null instead). Deterministic. Judge, the exports, the web report, the drift and
// the noise chain (methods/noise/noise_reference.h) read it back with results::FromJson.
// Config keys: method, device, accel_unit, gyro_unit (formats/inertial_log.h), taus_per_decade
// (0 = octaves, default; else 1..100).
#ifndef CALIBD_SERVER_NOISE_METHOD_H_
#define CALIBD_SERVER_NOISE_METHOD_H_

#include <nlohmann/json.hpp>

#include "core/noise.h"
#include "core/noise_simulation.h"
#include "methods/method.h"
#include "methods/noise/noise_result.h"

namespace calibd::server {

// The `noise` method for the registry: reads inertial logs (the array layout with `t`).
const Method& NoiseMethod();

// For `calibd simulate noise`: one IMU (a0, g0) at rest in a stationary log with known N, K and
// optionally B per sensor type; CSV `t,a0_x,..,g0_z` (%.9g), the config ({"method":"noise"}) and
// the truth ({"channels":[{"name","unit","white_noise","random_walk","bias_instability"}]}).
struct NoiseSimulationFileOptions {
  double rate = 100;                // Hz
  double seconds = 1800;            // log length
  double accel_noise = 2e-3;        // N, m/s²/√Hz
  double accel_random_walk = 1e-4;  // K, m/s³/√Hz
  double gyro_noise = 2e-4;         // N, rad/s/√Hz
  double gyro_random_walk = 2e-5;   // K, rad/s²/√Hz
  double bias_instability = 0;      // B of every channel as a fraction of N·1 s^-½ (0: none)
  uint64_t seed = 1;
};
Status SimulateNoiseFiles(const NoiseSimulationFileOptions& options, std::string* csv,
                          nlohmann::json* config, nlohmann::json* truth);

// The typed result (methods/noise/noise_result.h) of a core result, and its JSON (used by the
// method; exposed for tests). The adapter adds diagnostics.units.
results::NoiseResult NoiseResultOf(const core::NoiseResult& result, int taus_per_decade);
nlohmann::json NoiseResultToJson(const core::NoiseResult& result, int taus_per_decade);

// Exports of a noise result (methods/noise/noise_exports.cc; formats in methods/exports.h).
Status NoiseResultToCsv(const nlohmann::json& result, std::string* out);
Status NoiseResultToHeader(const nlohmann::json& result, const ExportContext& context,
                           std::string* out);
// Kalibr's imu.yaml of a noise result (format=yaml): the largest figure over the axes per sensor
// type; kNotDeterminable when a figure is null (the log could not show it).
Status NoiseResultToKalibrYaml(const nlohmann::json& result, const ExportContext& context,
                               std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_NOISE_METHOD_H_
