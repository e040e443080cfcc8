// JSON glue of the `mag` method (SPEC §8, issue #26): per magnetometer triad `mK_x,mK_y,mK_z` of
// an inertial log to core::CalibrateMag (core/mag.h), the statics for the alignment found on the
// accelerometer triad aK (else a0) by the raw-log methods' static detection, and its result as
// the SPEC §4 / §8 result JSON (methods/mag/mag_result.cc):
//   parameters.mags[]: {"name", "hard_iron" [3] reading units, "soft_iron" S = R P (3×3, µT per
//     reading unit with `field`, else unit field per reading unit), "soft_iron_symmetric" P,
//     "alignment" R (3×3) or null, "dip" (degrees, positive down) or null, "field" (µT) or null,
//     "field_estimate" (µT), "mag_unit", "microtesla_per_unit"}
//   uncertainty: {"basis": "crb" | "sandwich", "chi2_per_dof": null, "mags": [{"name",
//     "hard_iron_std" [3], "soft_iron_std" 3×3, "alignment_std" [3] rad or null, "dip_std" or
//     null, "crb": {the same keys with the white-noise bound}}]}
//   diagnostics.mags[]: {"name", "samples", "disturbed_samples", "disturbed_fraction",
//     "disturbed_spans" [{start, end, samples, max_residual}], "noise_std" (reading units),
//     "sample_noise_std" (µT per axis, from second differences of consecutive samples), "chi2"
//     (residual_rms_clean² / sample_noise_std²), "residual_rms_before", "residual_rms_after",
//     "residual_rms_clean" (µT), "sandwich_ratio", "blocking" [{seconds, batches, ratio: the
//     sandwich's σ over the bound's, RMS over the 9 ellipsoid parameters}] (every batch length
//     tried), "plateau" (false: σ grew over the last doubling, a lower bound), "iterations",
//     "statics" (count),
//     "accelerometer" (the triad used, or null), "alignment_note", "coverage": {"eigenvalues",
//     "least_covered_direction", "missing", "sufficient", "verdict"}, "plot": {"t", "raw" [3][n],
//     "calibrated" [3][n], "residual" [n], "disturbed" [n] (0/1)} (at most kMagPlotPoints samples)}
// Config keys: method, device, mag_unit ("uT" default, "gauss", "mG", "nT", or µT per reading
// unit), field (µT, > 0; absent: unknown, |m| = 1), mag_noise (σ per sample and axis in
// mag_unit) and dip (degrees, positive down, default 60): read by the plan only (a job estimates
// both from its log), static_window and min_static (s, default 0.5:
// hand-held holds are short), device_id (the firmware's device id of m0, or an array of them for
// m0, m1, ...: written as PX4's CAL_MAGn_ID and ArduPilot's COMPASS_DEV_IDn; absent, the files say
// it must be set).
#ifndef CALIBD_METHODS_MAG_MAG_METHOD_H_
#define CALIBD_METHODS_MAG_MAG_METHOD_H_

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/mag.h"
#include "core/mag_simulation.h"
#include "methods/method.h"

namespace calibd::server {

// The `mag` method for the registry: reads inertial logs with magnetometer columns.
const Method& MagMethod();

// What the plan reads of a mag config (methods/mag/mag_plan.cc).
struct MagPlanConfig {
  double field = 0;                // µT; 0: not given
  double microtesla_per_unit = 1;  // of mag_unit
  std::optional<double> noise;     // mag_noise: σ per sample and axis, reading units
  double dip = 60;                 // degrees, positive down
};
// kInvalidInput naming the key, as ValidateConfig.
Status ReadMagPlanConfig(const nlohmann::json& config, MagPlanConfig* out);

// Method::Plan of mag (methods/mag/mag_plan.cc): see there.
Status PlanMag(const nlohmann::json& config, const PlanProtocol& protocol,
               const AcceptanceLimits& limits, nlohmann::json* out);

// Samples of each triad's plot in diagnostics (evenly spaced over the log).
inline constexpr int kMagPlotPoints = 800;

// One magnetometer's run, for the result JSON.
struct MagRun {
  std::string name;                   // "m0"
  std::string accelerometer;          // the triad whose statics were used ("" none)
  int statics = 0;                    // statics found on it
  double sample_noise_std = NAN;      // µT per axis, from consecutive samples (SampleNoise)
  int64_t device_id = -1;             // the firmware's device id, -1 unknown (SetDeviceId)
  std::string device_id_source;       // "config", "log" or "" (unknown)
  std::vector<std::string> warnings;  // the method's own (besides the numerics')
  const core::MagProblem* problem;    // the readings (not owned)
  core::MagResult result;
};

// The result JSON of the runs (methods/mag/mag_result.cc; exposed for tests). `unit_text` and
// `microtesla_per_unit` as configured; `field` the config's (0: unknown).
nlohmann::json MagResultToJson(const std::vector<MagRun>& runs, const std::string& unit_text,
                               double microtesla_per_unit, double field);
// The diagnostics of one run (also the partial diagnostics of a failed run); `unit_text` the
// configured mag_unit (the wander's rate is in it per √s).
nlohmann::json MagDiagnostics(const MagRun& run, const std::string& unit_text);

// `calibd simulate mag`: CSV `t,a0_x,a0_y,a0_z,m0_x,m0_y,m0_z` (%.10g), the config (with the
// field) and the truth ({"hard_iron", "soft_iron", "soft_iron_symmetric", "alignment", "dip",
// "field", "seed"}).
Status SimulateMagFiles(const core::MagSimulationOptions& options, std::string* csv,
                        nlohmann::json* config, nlohmann::json* truth);

// Exports (methods/mag/mag_exports.cc). The firmware files carry the symmetric P as a
// dimensionless matrix M = P · k / µT-per-unit (k = 1 with a field, P then being in µT per
// reading unit; else field_estimate), so that M (raw − h) is the field in the reading's unit.
Status MagResultToCsv(const nlohmann::json& result, std::string* out);
Status MagResultToHeader(const nlohmann::json& result, const ExportContext& context,
                         std::string* out);
// ArduPilot COMPASS_OFS*, _DIA*, _ODI* (instances 1..3: no suffix, 2, 3), milligauss; the
// firmware adds the offsets and multiplies by the matrix: mag = M (raw + OFS)
// (AP_Compass_Backend.cpp correct_field), so OFS = −h.
Status MagResultToArduPilot(const nlohmann::json& result, const ExportContext& context,
                            std::string* out);
// PX4 CAL_MAGn_{X,Y,Z}OFF, _SCALE, _ODIAG (n from 0), gauss; the firmware computes
// mag = M (raw − OFF) (sensor_calibration/Magnetometer.hpp Correct), so OFF = h.
Status MagResultToPx4(const nlohmann::json& result, const ExportContext& context, std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_METHODS_MAG_MAG_METHOD_H_
