// The typed result document of the `pca` method (SPEC §4, Rupniewski's PCA-aided calibration of
// m single-axis sensors in a d-dimensional field): written in one place (methods/pca/pca_method.cc,
// the adapter, through ToJson) and read in one place (FromJson) by the acceptance gate, the
// exports, the web report and the pca -> array chain.
//
// The JSON is exactly what the adapter wrote before this type existed, plus "schema_version":
//   {"method": "pca", "schema_version": 1, "model": "...",
//    "parameters": {"dimension", "magnitude", "magnitude_known", "frame", "bias",
//                   "sensors": [{"name", "sensitivity", "scale", "axis", "bias"}]},
//    "uncertainty": {"sensors": [{"name", "scale_std", "axis_std_rad", "bias_std"}], "noise_std"},
//    "diagnostics": {...PcaDiagnostics...}, "verdict": {...} (once judged), "warnings": [...]}
// A failed run's partial document is {"method", "schema_version", "usable": false,
// "diagnostics", "warnings"}: parameters and uncertainty are then nullopt (FromJson ignores them
// if a partial document has them anyway: they are not estimates; ToJson writes them only when
// present).
// Undefined numbers (an uncertainty the data cannot give, a rank gap without σ_{d+1}) are NaN in
// the struct and null in the JSON.
//
// Results stored by an earlier calibd must still read: FromJson requires only the keys SPEC
// §4 requires (the envelope; parameters dimension, magnitude, magnitude_known, frame, sensors
// [name, sensitivity, scale, axis, bias]; uncertainty.sensors [name, scale_std, axis_std_rad,
// bias_std]; diagnostics singular_values, rank_gap, positions, min_positions, g_eigenvalues,
// residual_rms, magnitude_error). Every other key (marked "extension" below) keeps the struct's
// default when absent; a partial document's diagnostics may lack any member, or be absent. ToJson
// always writes every key (a current result round-trips exactly).
#ifndef CALIBD_RESULTS_PCA_RESULT_H_
#define CALIBD_RESULTS_PCA_RESULT_H_

#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/status.h"
#include "results/envelope.h"

namespace calibd::results {

inline constexpr int kPcaSchemaVersion = 1;

// The frame the sensitivity vectors are expressed in (parameters.frame).
enum class PcaFrame {
  kCanonical,  // "canonical": the paper's Eq. 19 frame (h·a upper triangular); no nominal given
  kNominal,    // "nominal": the body frame of the config's nominal (orthogonal Procrustes fit)
};
// The bias model (parameters.bias, the config's "bias").
enum class PcaBias {
  kNone,      // "none": readings assumed bias-free (a raw log's removed biases still reported)
  kEstimate,  // "estimate": one constant bias per sensor estimated with the sensitivities
};
// diagnostics.coverage.verdict.
enum class PcaCoverageVerdict {
  kUnknown,  // "unknown": the fit failed before the coverage could be computed
  kGood,     // "good"
  kPoor,     // "poor": the orientations do not span the sphere well (advice says what to add)
};
const char* Name(PcaFrame frame);
const char* Name(PcaBias bias);
const char* Name(PcaCoverageVerdict verdict);
// The value Name() spells `text` as: true and *out set, else false (out untouched).
bool Parse(std::string_view text, PcaFrame* out);
bool Parse(std::string_view text, PcaBias* out);
bool Parse(std::string_view text, PcaCoverageVerdict* out);

constexpr double kPcaNaN = std::numeric_limits<double>::quiet_NaN();

// parameters.sensors[i]: sensor i's reading is r_i = a_iᵀ v + b_i.
struct PcaSensor {
  std::string name;
  std::vector<double> sensitivity;  // a_i, d components in `frame`; reading units per field unit
  double scale = kPcaNaN;           // |a_i| (relative to 1 when the magnitude is unknown)
  std::vector<double> axis;         // a_i / |a_i|, d components, unit length, unitless
  double bias = kPcaNaN;  // b_i, reading units (0 when neither estimated nor removed from a log)
};

struct PcaParameters {
  int dimension = 3;             // d, the field's components (>= 1)
  double magnitude = kPcaNaN;    // c = |v| used, field units (1 when unknown)
  bool magnitude_known = false;  // false: scale factors and the field are relative
  PcaFrame frame = PcaFrame::kCanonical;
  PcaBias bias = PcaBias::kNone;   // extension; absent: kNone (the config's default)
  std::vector<PcaSensor> sensors;  // m, in the recording's column order
};

// uncertainty.sensors[i]: one standard deviation from the Fisher information (NaN: undefined).
struct PcaSensorStd {
  std::string name;               // the same name as parameters.sensors[i] (checked on reading)
  double scale_std = kPcaNaN;     // reading units per field unit
  double axis_std_rad = kPcaNaN;  // RMS angle of the axis, radians
  double bias_std = kPcaNaN;      // reading units; 0 when the bias is zero by assumption
  // "crb": {"scale_std", "axis_std_rad", "bias_std"}, the white-noise Cramér–Rao bound at the
  // given noise_std; absent without noise_std and in results stored by an earlier calibd.
  struct Bound {
    double scale_std = kPcaNaN, axis_std_rad = kPcaNaN, bias_std = kPcaNaN;
  };
  std::optional<Bound> crb;
};

// The σ convention (SPEC §7): basis "crb" (the residuals consistent with the given noise_std),
// "chi2_scaled" (the CRB × √(χ²/dof), or without noise_std the bound at the σ the residuals
// estimate) or "crb_only" (absent: stored by an earlier calibd, its σ the bound at the σ used).
inline constexpr char kPcaBasisCrbOnly[] = "crb_only";
struct PcaUncertainty {
  std::vector<PcaSensorStd> sensors;     // m, in the order of parameters.sensors
  double noise_std = kPcaNaN;            // σ used (given or estimated), reading units; extension
  std::string basis = kPcaBasisCrbOnly;  // "crb" | "chi2_scaled" | "crb_only"
  double chi2_per_dof = kPcaNaN;         // (residual σ / given noise_std)²; null without either
};

// diagnostics.coverage: how well the positions span the sphere (directions in the result's frame).
// Every member is an extension (absent: the default here).
struct PcaCoverage {
  PcaCoverageVerdict verdict = PcaCoverageVerdict::kUnknown;
  std::vector<double> scatter_eigenvalues;  // d, ascending, sum 1 (uniform: 1/d each)
  double scatter_min = kPcaNaN;             // d × the smallest, in [0, 1]
  double design_min = kPcaNaN;              // >= 0, about 1 for a uniform sphere
  // Positions in each direction cap ("+x", "-x", "+x+y", ...); empty when unknown.
  std::map<std::string, int> positions_per_direction;
  std::string advice;  // what to add, in words; empty when good
};

// diagnostics: SPEC §4's numbers of the fit (the same keys in a usable result and a failed run's
// partial document; there the values are as far as the computation got: NaN, empty or -1, which
// are also the defaults of members a partial document lacks). The members after magnitude_error
// are extensions: absent, they keep the defaults below (NaN: unknown, shown as "—").
struct PcaDiagnostics {
  bool usable = false;  // the run's outcome (true in a usable result); extension, absent: the
                        // envelope's usable
  std::optional<std::string> reason;    // why not usable; never in stored documents (the failure's
                                        // message is stored beside the partial document)
  std::vector<double> singular_values;  // all min(m, n) of the readings, reading units
  double rank_gap = kPcaNaN;            // σ_d/σ_{d+1}; NaN (null) when there is no σ_{d+1}
  int positions = -1;                   // n
  int min_positions = -1;               // d(d+1)/2 (bias none) or d(d+3)/2 (bias estimate)
  std::vector<double> g_eigenvalues;    // ascending; all > 0 for a usable result
  std::vector<double> residual_rms;     // m: RMS over positions, reading units
  std::vector<double> magnitude_error;  // n: |v_j| - c, field units
  int degrees_of_freedom = -1;          // -1: unknown (the gate then skips its residual rule)
  // nullopt only in results stored before calibd measured the coverage (the adapter always
  // writes it, verdict "unknown" when the fit failed before): the gate then has no coverage
  // rule to apply, the report shows none.
  std::optional<PcaCoverage> coverage;
  double noise_std = kPcaNaN;    // σ used, reading units (the same value as uncertainty.noise_std)
  bool noise_std_given = false;  // absent: false (the gate's residual rule then does not apply)
  double noise_std_estimated = kPcaNaN;  // from the residual; NaN when dof <= 0
  double cost_closed_form = kPcaNaN;     // ½Σr² at the closed form, reading units²
  double cost = kPcaNaN;                 // ½Σr² at the reported estimate, reading units²
  bool refined = false;                  // the Gauss-Newton refinement's estimate is reported
  int refine_iterations = 0;
  bool reflection = false;  // nominal frame: the Procrustes fit used a reflection (det -1)
  // n position labels in order (absent only in results computed without a recording).
  std::optional<std::vector<std::string>> position_labels;
  // m biases removed from a raw log (the mean over positions of the static means), reading units;
  // present for the pca_raw layout only.
  std::optional<std::vector<double>> removed_bias;
};

struct PcaResult {
  Envelope envelope;  // method "pca"
  // Present iff envelope.usable (a partial document has none, see above).
  std::optional<PcaParameters> parameters;
  std::optional<PcaUncertainty> uncertainty;
  PcaDiagnostics diagnostics;
};

// The document above (schema_version kPcaSchemaVersion; NaN written as null).
nlohmann::json ToJson(const PcaResult& result);
// Reads a pca result document. kInvalidInput naming the path of the first problem
// ("pca result: parameters.sensors[1].scale: expected a number, found a string"; also
// Status::field()). Checks beyond the types: the envelope (results/envelope.h), a usable
// result has parameters and uncertainty, dimension >= 1, every sensitivity and axis has
// `dimension` components, uncertainty.sensors matches parameters.sensors one to one by name.
// *out is written only on success.
Status FromJson(const nlohmann::json& doc, PcaResult* out);

}  // namespace calibd::results

#endif  // CALIBD_RESULTS_PCA_RESULT_H_
