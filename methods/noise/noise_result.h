// The typed result of the `noise` method (SPEC §4, §7): what methods/noise/noise_method.cc writes
// and what Judge, the exports, the web report, the drift tables and the noise chain
// (methods/noise/noise_reference.h) read. ToJson writes exactly the document the adapter has always
// written (plus "schema_version"); FromJson reads it back, naming the path of the first problem
// ("noise result: parameters.channels[2].white_noise: expected a number, found a string").
//
// Units (SI after the unit conversion, Kalibr's): per channel `unit` is "m/s^2" (accelerometer
// channels, names a*) or "rad/s" (gyroscope channels, names g*); N in unit/√Hz, B in unit, K in
// unit/s/√Hz, τ in seconds. A term the log does not show is NaN (written as null).
//
// Keys SPEC §4/§7 requires are required by FromJson: the envelope, parameters.channels[] and
// uncertainty.channels[] with every member, and diagnostics rate, samples and allan[] (name, tau,
// adev, adev_lower, adev_upper). Every other key is an extension (marked "ext." below): when
// absent (a result stored by an earlier calibd) the member keeps the default given here — NaN
// for a number (shown as a dash, never exported as 0), empty for a list or text. ToJson writes
// them all. In a partial document every diagnostics member, and the diagnostics themselves, are
// optional.
//
// A failed run's partial document ({"method", "usable": false, "diagnostics", "warnings"}) reads
// with envelope.usable == false: `parameters` and `uncertainty` are then empty (absent in JSON);
// the diagnostics are as far as the analysis got.
#ifndef CALIBD_RESULTS_NOISE_RESULT_H_
#define CALIBD_RESULTS_NOISE_RESULT_H_

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

namespace calibd::results {

inline constexpr int kNoiseSchemaVersion = 1;

// parameters.channels[]: the fitted Allan-variance terms of one channel (IEEE Std 952).
struct NoiseChannelParameters {
  std::string name;  // "a0_x", "g1_z": a* accelerometer, g* gyroscope
  std::string unit;  // "m/s^2" | "rad/s"
  double white_noise = std::numeric_limits<double>::quiet_NaN();           // N, unit/√Hz
  double bias_instability = std::numeric_limits<double>::quiet_NaN();      // B, unit
  double bias_instability_tau = std::numeric_limits<double>::quiet_NaN();  // τ of B's floor, s
  double random_walk = std::numeric_limits<double>::quiet_NaN();           // K, unit/s/√Hz
};

// The σ convention (issue 28, SPEC §4/§7 in README's changelog): per channel basis "crb" (the
// noise model's σ: the Allan curve follows N/B/K within its chi-square intervals) or
// "chi2_scaled" (that σ × √chi2_per_dof, warned); "crb_only": absent, a result stored by an
// earlier calibd, whose σ are the model's whatever the fit.
inline constexpr char kNoiseBasisCrbOnly[] = "crb_only";

// The three terms' σ (uncertainty.channels[].crb: the noise model's own, ext.).
struct NoiseTermStds {
  double white_noise_std = std::numeric_limits<double>::quiet_NaN();
  double bias_instability_std = std::numeric_limits<double>::quiet_NaN();
  double random_walk_std = std::numeric_limits<double>::quiet_NaN();
};

// uncertainty.channels[]: one standard deviation of each term (NaN: undefined or not shown),
// the primary σ of the basis.
struct NoiseChannelUncertainty {
  std::string name;
  double white_noise_std = std::numeric_limits<double>::quiet_NaN();
  double bias_instability_std = std::numeric_limits<double>::quiet_NaN();
  double random_walk_std = std::numeric_limits<double>::quiet_NaN();
  std::string basis = kNoiseBasisCrbOnly;  // ext.: "crb" | "chi2_scaled" | "crb_only"
  // ext.: the fit's χ² / the χ² the noise model predicts for the correlated Allan points.
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  std::optional<NoiseTermStds> crb;  // ext.: absent with crb_only
};

// diagnostics.channels[]: how the fit of one channel went (ext., every member).
struct NoiseChannelDiagnostics {
  std::string name;
  std::string status;      // core::NoiseChannelStatusName: "ok", "not_stationary", ...
  std::string reason;      // in words, "" when ok
  int64_t fit_points = 0;  // cluster times the fit used
  double fit_chi2 = std::numeric_limits<double>::quiet_NaN();
  double mean = std::numeric_limits<double>::quiet_NaN();  // of the samples, unit
  std::string unit;  // ext.: the channel's SI unit, of mean and of its allan[] curve ("": absent)
};

// diagnostics.allan[]: one channel's overlapping Allan deviation, its confidence bounds and the
// fitted model, all per cluster time τ (same lengths; unit as the channel's).
struct NoiseAllanCurve {
  std::string name;
  std::vector<double> tau;  // s
  std::vector<double> adev, adev_lower, adev_upper;
  std::vector<double> fitted_adev;  // ext. (empty when absent: the plot leaves the model out)
  std::string unit;  // ext.: of adev, its bounds and fitted_adev, the channel's ("": absent)
};

// diagnostics.units: the units the log was read with, as the config gave them (ext.).
struct NoiseUnits {
  std::string accel_unit;
  std::string gyro_unit;
};

struct NoiseDiagnostics {
  double rate = std::numeric_limits<double>::quiet_NaN();      // Hz
  int64_t samples = 0;                                         // per channel
  double duration = std::numeric_limits<double>::quiet_NaN();  // s (ext.)
  double jitter = std::numeric_limits<double>::quiet_NaN();  // max |Δt − median| / median (ext.)
  // ext.; absent: true (Judge then does not reject on it; results were accepted as stationary).
  bool stationary = true;
  int taus_per_decade = 0;  // 0: octave spacing, the default (ext.)
  // Of the Allan deviation's bounds (e.g. 0.683); NaN (null) when there are no channels (ext.).
  double confidence = std::numeric_limits<double>::quiet_NaN();
  std::vector<NoiseChannelDiagnostics> channels;  // ext. (empty when absent)
  std::vector<NoiseAllanCurve> allan;
  std::optional<NoiseUnits> units;                  // written by the server's adapter
  std::optional<SaturationDiagnostics> saturation;  // results/saturation.h; absent: none pinned
};

struct NoiseResult {
  Envelope envelope;  // method "noise"
  // parameters.channels and uncertainty.channels, in the same order (empty when not usable).
  std::vector<NoiseChannelParameters> channels;
  std::vector<NoiseChannelUncertainty> channel_stds;
  // uncertainty.basis (ext.): "chi2_scaled" when any channel's is, else "crb"; "crb_only" when
  // absent. uncertainty.chi2_per_dof (ext.): the largest of the channels' (NaN when absent).
  std::string basis = kNoiseBasisCrbOnly;
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  NoiseDiagnostics diagnostics;
  // A partial document the server trimmed to fit the store (server/failure_reasons.h,
  // PartialDiagnosticsText): its "trimmed" note as stored (open shape) and the diagnostics
  // members it dropped, which are absent from the JSON and left at their defaults here
  // ("diagnostics" itself when all were dropped). Empty for every other document.
  std::optional<nlohmann::json> trimmed;
  std::vector<std::string> dropped;
};

nlohmann::json ToJson(const NoiseResult& r);
// kInvalidInput naming the path of the first problem (what = "noise result").
Status FromJson(const nlohmann::json& doc, NoiseResult* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_NOISE_RESULT_H_
