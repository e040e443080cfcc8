// The typed result document of the `array` method (SPEC §4 and §7), both models: the
// positions-only model (Carlsson, Skog, Jaldén: the triads' positions r_k from a free
// hand-twisted recording) and `model: full` (every triad's accelerometer and gyroscope gains,
// misalignments and biases, and its position).
//
// One struct for both models. `full` says which; the members commented "(positions)" are read
// and written only for the positions model, those commented "(full)" only for the full model,
// the rest for both. A failed run's partial diagnostics ({"method", "usable": false,
// "diagnostics", "warnings"}) read into the same struct with envelope.usable false: parameters
// and uncertainty are then absent (nullopt), and of the diagnostics only the members commented
// "[partial]" are present (the others keep their defaults and are not written).
//
// The JSON is exactly what the array adapter has always written (plus "schema_version"; the runs
// are methods/array/array_positions.cc and array_full_method.cc): ToJson(FromJson(j)) == j for
// every document the adapter writes.
//
// Results stored by an earlier calibd lack members added since. FromJson requires only what
// SPEC §4/§7 requires (commented "SPEC"); every other member (our extensions) keeps its default
// when absent: NaN for a number (shown as a dash, exported as an empty field, never as 0), an
// empty list or string, nullopt for a count or a flag whose absence must show as "unknown". A
// partial document's diagnostics members are all optional (the worker leaves out the largest
// ones over 1 MiB, or the whole diagnostics object: server/failure_reasons.h). The model is
// diagnostics.model ("full"), or, when that is absent, the presence of parameters.imus (SPEC §7).
// For the full model parameters.positions and uncertainty.positions are extensions (README
// Changelog): when absent they are derived from parameters.imus[].position and
// uncertainty.imus[].position_std, the offset from the nominal then unknown (NaN).
// ToJson writes every member it holds; an absent optional count (nullopt) is left out, except
// the SPEC's, which a usable result always has (written as 0 if a hand-built struct lacks them).
//
// Units: metres, m/s², rad/s for the positions-only model's rates; gyroscope figures in
// diagnostics.gyro_unit (the configured unit: biases in it, scales in rad/s per unit); undefined
// numbers are null (NaN here).
#ifndef CALIBD_RESULTS_ARRAY_RESULT_H_
#define CALIBD_RESULTS_ARRAY_RESULT_H_

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "results/envelope.h"
#include "results/saturation.h"
#include "results/triad.h"

namespace calibd::results {

inline constexpr int kArraySchemaVersion = 1;

namespace array_internal {
inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline const Eigen::Vector3d kNaN3 = Eigen::Vector3d::Constant(kNaN);
}  // namespace array_internal

// ---- parameters / uncertainty ----

// parameters.positions[]: {"name", "position", "offset"}.
struct ArrayPosition {
  std::string name;                                  // triad name ("a0", or "0" for full)
  Eigen::Vector3d position = array_internal::kNaN3;  // r_k, metres, nominal geometry frame
  Eigen::Vector3d offset = array_internal::kNaN3;    // r_k − nominal, metres
};

// uncertainty.positions[]: {"name", "std", "crb": {"std"}}.
struct ArrayPositionStd {
  std::string name;
  Eigen::Vector3d std = array_internal::kNaN3;  // 1σ per axis (uncertainty.basis), metres
  // The white-noise Cramér–Rao bound of the same; absent in results stored by an earlier calibd.
  std::optional<Eigen::Vector3d> crb;
};

// parameters.imus[] (full): the two triads and the accelerometer's position.
struct ArrayImu {
  ImuTriads triads;                                  // "name", "accelerometer", "gyroscope"
  Eigen::Vector3d position = array_internal::kNaN3;  // metres
};

// uncertainty.imus[].crb (full): the white-noise Cramér–Rao bound of the same entries.
struct ArrayImuCrbStd {
  SensorTriadStd accelerometer;
  SensorTriadStd gyroscope;
  Eigen::Vector3d position_std = array_internal::kNaN3;  // metres
};

// uncertainty.imus[] (full).
struct ArrayImuStd {
  ImuTriadsStd triads;                                   // "name", "accelerometer", "gyroscope"
  Eigen::Vector3d position_std = array_internal::kNaN3;  // metres
  // The Cramér–Rao bound; absent in results stored by an earlier calibd (whose "robust" member,
  // the residual-aware σ, is not read: it is what the primary σ now is when basis is "sandwich").
  std::optional<ArrayImuCrbStd> crb;
};

struct ArrayParameters {
  int reference = 0;  // SPEC index of the reference triad, held at its nominal position
  std::vector<ArrayPosition> positions;  // SPEC (positions); (full) derived when absent, see above
  std::vector<ArrayImu> imus;            // SPEC (full)
};

// What the primary σ is (SPEC §7 "Uncertainty, every method", README changelog): "crb" (the
// residuals match the noise model), "sandwich" (residual-aware), or "crb_only" (absent: a
// result stored by an earlier calibd, whose σ is the Cramér–Rao bound whatever the residuals).
inline constexpr char kArrayBasisCrbOnly[] = "crb_only";

struct ArrayUncertainty {
  std::string basis = kArrayBasisCrbOnly;      // "crb" | "sandwich" | "crb_only"
  double chi2_per_dof = array_internal::kNaN;  // the fit's χ²/dof; NaN when absent
  std::vector<ArrayPositionStd> positions;     // SPEC (positions); (full) as parameters.positions
  double std_rms = array_internal::kNaN;  // (positions) RMS of the K−1 free triads' σ, metres
  std::vector<ArrayImuStd> imus;          // SPEC (full)
};

// ---- diagnostics ----

// {"accelerometer", "gyroscope"}: one figure per sensor type (m/s², gyro_unit).
struct SensorFigures {
  double accelerometer = array_internal::kNaN;
  double gyroscope = array_internal::kNaN;
};

// diagnostics.excitation (positions): the Fisher information of the rotation (SPEC §4).
struct ArrayExcitation {
  double min_eigenvalue = array_internal::kNaN;
  double max_eigenvalue = array_internal::kNaN;
  double noise_floor = array_internal::kNaN;
  Eigen::Vector3d weakest_direction = array_internal::kNaN3;
  std::string verdict;  // "" when the solver did not get that far (partial documents)
};

// diagnostics.motion (positions): |ω| and |ω̇| at every stride-th usable sample (≤ 2000 points).
struct ArrayMotion {
  int64_t stride = 1;
  std::vector<double> omega_norm;      // rad/s
  std::vector<double> omega_dot_norm;  // rad/s²
  // "units": {"omega_norm", "omega_dot_norm"}
  std::string omega_norm_unit = "rad/s";
  std::string omega_dot_norm_unit = "rad/s^2";
};

// diagnostics.noise_jobs (positions): the noise jobs the configured σ came from (null: a number).
struct ArrayNoiseJobs {
  std::optional<int64_t> accelerometer;
  std::optional<int64_t> gyroscope;
};

// diagnostics.accelerometer_calibration (positions), when the config had one (SPEC §3).
struct ArrayCalibrationUsed {
  std::optional<int64_t> job;       // the pca job, when given as {"job": ID}
  int sensors = 0;                  // accelerometer axes corrected (3K)
  std::string frame;                // the pca result's frame ("nominal")
  std::optional<std::string> bias;  // "estimate" | "none"; null when the pca result had none
  double magnitude = array_internal::kNaN;             // m/s² expected
  double max_condition_number = array_internal::kNaN;  // over the K sensitivity blocks
};

// The diagnostics of the positions model.
struct ArrayPositionsDiagnostics {
  std::string solver;                      // [partial] SPEC "joint" | "bcd"
  std::string termination;                 // [partial] "" when absent
  std::optional<int> iterations;           // [partial] SPEC LM iterations / BCD sweeps
  std::optional<int64_t> samples;          // [partial] SPEC usable samples N
  std::optional<int64_t> samples_dropped;  // [partial] SPEC dropped for gyroscope saturation
  std::optional<int> gyro_triads;          // [partial] G
  std::string gyro_unit;                   // [partial] "rad/s" | "deg/s"; "" when absent
  // [partial] SPEC: min_eigenvalue and verdict (the others are extensions).
  ArrayExcitation excitation;
  bool converged = false;          // SPEC
  std::vector<double> cost;        // SPEC before the first and after every iteration
  SensorFigures residual_rms;      // SPEC m/s², gyro_unit
  SensorFigures noise_estimate;    // SPEC from the residuals, m/s², gyro_unit
  ArrayNoiseJobs noise_jobs;       // both nullopt when absent
  SensorFigures noise_configured;  // accel_noise, gyro_noise (m/s², gyro_unit)
  double parallel_fraction = array_internal::kNaN;
  ArrayMotion motion;                                             // no points when absent
  std::optional<ArrayCalibrationUsed> accelerometer_calibration;  // null without one (or absent)
  std::optional<SaturationDiagnostics> saturation;  // results/saturation.h; absent: none pinned
};

// diagnostics.gauge (full).
struct ArrayGauge {
  std::string scale;  // SPEC §7 (which gauge was used): "sum_trace_gyroscope"
  int reference = 0;  // the triad whose position and lower-triangle misalignment are held
  std::string description;
};

// diagnostics.noise (full): the σ the fit used.
struct ArrayFullNoise {
  double accelerometer = array_internal::kNaN;          // m/s²
  double gyroscope = array_internal::kNaN;              // gyro_unit
  std::string source;                                   // "statics" | "configured"
  std::string dynamic_weighting;                        // "noise" | "residual"
  double dynamic_accelerometer = array_internal::kNaN;  // m/s²
  double dynamic_gyroscope = array_internal::kNaN;      // gyro_unit
};

// diagnostics.residual_rms.imus[] (full).
struct ArrayImuResiduals {
  std::string name;
  SensorFigures static_rms;   // "static": the static means' residuals × √samples
  SensorFigures dynamic_rms;  // "dynamic": over the dynamic samples
};

// diagnostics.rotation_excitation (full; "rotation" in a partial document, without "units").
struct ArrayRotationExcitation {
  Eigen::Vector3d eigenvalues = array_internal::kNaN3;
  double noise_floor = array_internal::kNaN;
  Eigen::Vector3d weakest_axis = array_internal::kNaN3;
  std::string verdict;
  std::string units = "(rad/s)^2";  // written in usable results only
};

// diagnostics.time_offsets (full; diagnostic, not part of the model).
struct ArrayTimeOffset {
  std::string name;
  double offset = array_internal::kNaN;  // ms, relative to the IMUs' mean
};
struct ArrayTimeOffsets {
  std::vector<ArrayTimeOffset> offsets_ms;
  double explained_fraction = array_internal::kNaN;
  double per_sample_rms_ms = array_internal::kNaN;
  double per_sample_explained_fraction = array_internal::kNaN;
  std::string note;
};

// diagnostics.robust (full): the residual-aware σ.
struct ArrayRobust {
  bool used = false;  // it is the primary σ (uncertainty.basis "sandwich")
  int64_t batches = 0;
  double batch_seconds = array_internal::kNaN;
  double ratio = array_internal::kNaN;
};

// diagnostics.changed_from_positions_only[] (full).
struct ArrayPositionChange {
  std::string name;
  Eigen::Vector3d positions_only = array_internal::kNaN3;   // the start's position, metres
  std::optional<Eigen::Vector3d> positions_only_std;        // its CRB; absent when that fit failed
  Eigen::Vector3d position_change = array_internal::kNaN3;  // metres
  double position_change_norm = array_internal::kNaN;
  Eigen::Vector3d position_change_sigma = array_internal::kNaN3;  // change / σ; null: reference
};

// diagnostics.static_intervals[] (full): a static the fit used, with its means' residuals.
struct ArrayFullStaticInterval {
  double start = array_internal::kNaN, end = array_internal::kNaN;  // s
  int64_t samples = 0;
  // RMS over every triad's three components of the static mean's residual: m/s², gyro_unit.
  double accel_residual_rms = array_internal::kNaN, gyro_residual_rms = array_internal::kNaN;
};

// The diagnostics of the full model.
struct ArrayFullDiagnostics {
  std::string termination;                      // [partial]
  std::optional<int> iterations;                // [partial] SPEC (§4)
  std::optional<int64_t> statics;               // [partial]
  std::optional<int64_t> static_samples;        // [partial]
  std::optional<int64_t> dynamic_samples;       // [partial]
  ArrayRotationExcitation rotation_excitation;  // [partial] (as "rotation")
  std::vector<std::string> null_directions;     // [partial]
  ArrayGauge gauge;                             // SPEC §7 (gauge.scale)
  std::string solver;                           // SPEC (§4) "joint"
  bool converged = false;                       // SPEC (§4)
  std::vector<double> cost;                     // SPEC (§4)
  int64_t samples_dropped = 0;                  // SPEC (§4)
  std::optional<int64_t> dof;
  double chi2_per_dof = array_internal::kNaN;
  std::string gyro_unit;
  ArrayFullNoise noise;
  SensorFigures static_noise;  // pooled within-static σ
  // The statics in time order. Empty in results stored by an earlier calibd, whose
  // residual_rms.imus[].static figures were the means' residuals × √samples (now: the means'
  // residuals, m/s² and gyro_unit).
  std::vector<ArrayFullStaticInterval> static_intervals;
  SensorFigures residual_rms_dynamic;                // residual_rms.dynamic, over all triads
  std::vector<ArrayImuResiduals> residual_rms_imus;  // residual_rms.imus
  ArrayTimeOffsets time_offsets;
  ArrayRobust robust;
  // The start came from a positions-only fit (false: from the nominal geometry); nullopt when
  // absent.
  std::optional<bool> positions_only_start;
  std::vector<ArrayPositionChange> changed_from_positions_only;
  std::optional<SaturationDiagnostics> saturation;  // results/saturation.h; absent: none pinned
};

struct ArrayResult {
  Envelope envelope;  // method "array"
  bool full = false;  // model full: diagnostics.model (and parameters.model) "full"
  // Absent when envelope.usable is false.
  std::optional<ArrayParameters> parameters;
  std::optional<ArrayUncertainty> uncertainty;
  ArrayPositionsDiagnostics diagnostics;  // (positions)
  ArrayFullDiagnostics full_diagnostics;  // (full)
};

nlohmann::json ToJson(const ArrayResult& r);
// kInvalidInput naming the path of the first problem ("array result: parameters.positions[1]
// .offset: ..."); *out untouched then.
Status FromJson(const nlohmann::json& doc, ArrayResult* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_ARRAY_RESULT_H_
