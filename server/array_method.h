// JSON glue of the `array` method: config keys (SPEC §3) to core::ArrayOptions, a parsed recording
// to the result JSON (SPEC §4), and the simulated files of `calibd simulate array`.
#ifndef CALIBD_SERVER_ARRAY_METHOD_H_
#define CALIBD_SERVER_ARRAY_METHOD_H_

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "core/array.h"
#include "core/status.h"
#include "server/recording.h"

namespace calibd::server {

// Reads the array keys of a config object (SPEC §3): geometry {"positions": [[x,y,z], ...K],
// "reference": k (default 0)}, accel_noise (m/s²), gyro_noise (in gyro_unit), gyro_unit
// ("rad/s" default | "deg/s"), gyro_saturation (in gyro_unit), solver ("joint" | "bcd"),
// max_iterations (integer >= 0, 0 = solver default), tolerance (>= 0, < 1).
// The common keys method and device are ignored. accelerometer_calibration is recognised but not
// supported yet (kInvalidInput, issue #8). Unknown keys, missing required keys (geometry,
// accel_noise, gyro_noise) and wrong types or values are kInvalidInput with WithField(key) and a
// message naming the key. Fills geometry_part->nominal_positions and ->reference only; with
// deg/s, gyro_noise and gyro_saturation are converted to rad/s and *gyro_in_degrees is set.
Status ParseArrayConfig(const nlohmann::json& config, core::ArrayProblem* geometry_part,
                        core::ArrayOptions* options, bool* gyro_in_degrees);

// Runs the calibration on a parsed recording (gyro columns converted from deg/s when configured)
// and writes the SPEC §4 result:
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
// Metres, m/s², rad/s (gyroscope figures in the configured gyro_unit). "motion" holds at most
// 2000 points (every stride-th usable sample). No NaN/Inf (null instead). Deterministic.
// The recording's triad count must equal the geometry's (kInvalidInput naming both).
// Errors as core::CalibrateArray otherwise.
Status RunArray(const ArrayRecording& recording, const nlohmann::json& config,
                nlohmann::json* result);

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
};

// The CSV text (header t,a0_x..a31_z,g0_x..g31_z, %.17g, t = n / 100 s), the config
// ({"method":"array","geometry":{"positions": NOMINAL, "reference":0},"accel_noise",
// "gyro_noise","gyro_unit"}) and the truth ({"positions":[{"name","position"}], "seed",
// "options"}). Deterministic for a seed.
Status SimulateArrayFiles(const ArraySimulationFileOptions& options, std::string* csv,
                          nlohmann::json* config, nlohmann::json* truth);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_ARRAY_METHOD_H_
