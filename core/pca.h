// The `pca` calibration method: Rupniewski, "PCA-aided calibration of systems comprising multiple
// unbiased sensors" (../shared/seeds/000_cea3cc86060608ff.txt), plus an affine extension for
// unknown biases (issue #8).
//
// Model, for m single-axis sensors at n static positions under a field of constant magnitude c:
//   m_ij = a_iᵀ v_j + b_i + η_ij,   |v_j| = c,   η_ij ~ N(0, σ²)
// with a (d×m) the sensitivity vectors (axis × scale factor, one column per sensor), v (d×n) the
// field in the body frame at each position, and b (m) the biases (zero for BiasModel::kNone).
// The data determine a and v only up to a common orthogonal transform (the paper's Remark 1),
// reflections included; the result is reported in the canonical frame of the paper's Eq. 19 or,
// given nominal sensitivities, in their frame (orthogonal Procrustes allowing a reflection).
//
// Cost: O(m² n + m n d²) time for the closed form (the left SVD of the m×n readings, the quadric
// fit), O((pm)³) (dense) or O(pm · r²) (low rank, r = n(d−1) + d(d−1)/2) for the uncertainty and
// each `refine` step (at most max_refine_iterations, each with at most 20 step halvings); memory
// O(m n + (pm)²) or O(pm · r). EstimatePcaCost states both before any work and the options'
// max_memory_bytes (1 GiB) and max_flops (1e12) refuse a larger problem at once, so the worst
// case is bounded whatever the input (the job budget only bounds the readings, m·n values).
// Measured: bench/README.md "Cost of every method".
//
// Everything here is pure numerics: Eigen in, result structs out. Thread-compatible: concurrent
// calls on different objects are safe.
#ifndef CALIBD_CORE_PCA_H_
#define CALIBD_CORE_PCA_H_

#include <Eigen/Core>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/stop_token.h"

namespace calibd::core {

// The failure reasons only pca meets (base/status.h Reason; their catalog entries are in
// methods/pca/pca_method.cc FailureReasons()).
namespace pca_reason {
// Fewer sensors than the dimension d
inline constexpr Reason kTooFewSensors{"too_few_sensors"};
// No clear gap between the singular values d and d+1
inline constexpr Reason kNoRankGap{"no_rank_gap"};
// A sensor whose readings do not change with the orientation
inline constexpr Reason kDeadSensor{"dead_sensor"};
}  // namespace pca_reason

enum class BiasModel {
  kNone,      // readings are bias-free (or biases were removed beforehand): the paper's model
  kEstimate,  // unknown constant biases b_i are estimated with the sensitivities (issue #8)
};
const char* BiasModelName(BiasModel bias);  // "none" | "estimate"

// How the uncertainty (and each `refine` step) handles the reduced Fisher information S of the
// p·m sensor parameters (p = d, or d + 1 with biases), the n positions eliminated. S is the
// block-diagonal Σ_j ṽ_j ṽ_jᵀ per sensor minus a rank-n(d−1) coupling through the positions, and
// has the d(d−1)/2-dimensional rotation gauge as null space; r = n(d−1) + d(d−1)/2 below. Both
// solvers give the same σ (to rounding).
enum class PcaInformationSolver {
  kAuto,     // the cheaper of the two for the problem's size (see EstimatePcaCost)
  kDense,    // S as one dense (pm)×(pm) matrix: O((pm)³) time, O((pm)²) memory; few sensors
  kLowRank,  // block diagonal plus low rank (Woodbury): O(pm·r²) time, O(pm·r) memory; many
             // sensors, few positions
};
const char* PcaInformationSolverName(PcaInformationSolver solver);  // "auto"|"dense"|"low_rank"

// What CalibratePca will cost, estimated from the sizes alone (before any reading is looked at),
// so that a caller can refuse a problem at once. Figures are upper estimates within a small
// factor: `bytes` the peak working memory beyond the readings themselves, `flops` the
// floating-point operations of the closed form, diagnostics and uncertainty, and
// `flops_per_refine_iteration` those of one `refine` step.
struct PcaCost {
  double bytes = 0;
  double flops = 0;
  double flops_per_refine_iteration = 0;
  PcaInformationSolver solver = PcaInformationSolver::kAuto;  // the solver used (kAuto resolved)
};

// m sensors, n positions, dimension d. solver kAuto picks the one with fewer flops.
PcaCost EstimatePcaCost(int m, int n, int d, BiasModel bias,
                        PcaInformationSolver solver = PcaInformationSolver::kAuto);

struct PcaOptions {
  int dimension = 3;                // d >= 1 (at most kMaxDimension)
  std::optional<double> magnitude;  // c > 0; nullopt: unknown -> c = 1, scale factors relative
                                    // (the paper's Remark 2)
  std::optional<Eigen::MatrixXd> nominal;  // d×m nominal sensitivity vectors (columns = sensors,
                                           // like the paper's a); the result is rotated onto them
                                           // by orthogonal Procrustes allowing a reflection.
                                           // nullopt: canonical frame (Eq. 19).
  bool refine = false;                     // maximum-likelihood Gauss-Newton after the closed form
  BiasModel bias = BiasModel::kNone;       // see BiasModel
  std::optional<double> noise_std;  // σ of one (averaged) reading, > 0; nullopt: estimated from
                                    // the residuals
  int max_refine_iterations = 50;   // >= 1; Gauss-Newton iterations of `refine`
  double min_rank_gap = 3.0;        // > 1; σ_d/σ_{d+1} below this means "no clear gap"
  PcaInformationSolver information_solver = PcaInformationSolver::kAuto;  // see the enum
  // Budget: a problem whose EstimatePcaCost exceeds either limit is refused at once with
  // kNotDeterminable (field "max_memory_bytes" or "max_flops") naming the limit and the estimate.
  // 0 means no limit.
  double max_memory_bytes = 1024.0 * 1024 * 1024;  // >= 0; default 1 GiB
  double max_flops = 1e12;  // >= 0; default 1e12 (minutes on one core), counting every refine
                            // iteration allowed by max_refine_iterations

  // Polled (core/stop_token.h) between the stages, at every `refine` step and step halving, and
  // per sensor row of the dense information: when it asks, CalibratePca returns
  // core::StoppedStatus at once. A single factorisation is not interrupted: max_flops bounds it.
  // Null: never stops.
  const StopToken* stop = nullptr;

  static constexpr int kMaxDimension = 32;

  // True when every field is in range; otherwise false and *error names the violated constraint.
  bool IsValid(std::string* error) const;
};

struct PcaProblem {
  Eigen::MatrixXd m;                         // m×n readings (sensors × positions); for the raw
                                             // layout with biases already removed
  std::vector<std::string> sensor_names;     // m (may be empty: then "s0", "s1", ...)
  std::vector<std::string> position_labels;  // n (may be empty)
  Eigen::VectorXd removed_bias;              // m, bias removed from a static/moving log (empty or
                                             // zeros if none); reported as each sensor's bias
  Eigen::VectorXd removed_bias_std;          // m, its standard deviation (empty if none)
};

// How well the static positions span the sphere: the field directions u_j = v_j/|v_j| of the
// estimate, in the result's frame. Two numbers, both 1 for orientations spread uniformly at random
// over the sphere (in expectation) and 0 for a degenerate set:
//  - scatter: the eigenvalues of Σ u_j u_jᵀ / n (ascending, sum 1); scatter_min = d × the smallest
//    (0: all positions in a plane, e.g. turned about one axis only);
//  - design_min: the smallest eigenvalue of the quadric fit's design Σ f_j f_jᵀ / n relative to
//    its uniform-sphere expectation, f_j = the quadratic terms u_k u_l (and with bias estimation
//    the linear terms u_k): what the sensitivity matrix's shape (scale factors, angles between
//    axes) and the biases are estimated from. The six faces of a box, for instance, leave the
//    u_k u_l terms (k ≠ l), the angles between axes, to the other positions alone.
// For d = 3 the positions are also counted in 18 caps (overlapping): within 60° of each of the 6
// axis directions ±x, ±y, ±z, and within 30° of each of the 12 edge directions such as +x+y (45°
// between two axes); the advice names, in the axes of the result's frame, the missing directions
// that matter: axis directions with no position near them (both signs where both are missing),
// the sparse direction of the scatter, pairs of axes with no position in between.
enum class PcaCoverageVerdict {
  kUnknown,  // not computed (no estimate)
  kGood,
  kPoor,  // scatter_min < kMinScatter or design_min < kMinDesign: add the advised positions
};
const char* PcaCoverageVerdictName(PcaCoverageVerdict verdict);  // "unknown" | "good" | "poor"

// The frame the sensitivities are reported in.
enum class PcaFrame {
  kNone,       // not reached (the fit failed before the frame was chosen)
  kCanonical,  // the paper's Eq. 19 frame (h·a upper triangular): no nominal given
  kNominal,    // the nominal sensitivities' body frame (orthogonal Procrustes fit)
};
const char* PcaFrameName(PcaFrame frame);  // "" | "canonical" | "nominal"

struct PcaCoverage {
  // Thresholds of a poor verdict. For 30 random orientations (biases estimated) the 1 % quantiles
  // are about 0.48 (scatter_min) and 0.08 (design_min); for the 6 faces of a box plus 4 positions
  // near faces, design_min is about 0.01.
  static constexpr double kMinScatter = 0.3;
  static constexpr double kMinDesign = 0.05;

  PcaCoverageVerdict verdict = PcaCoverageVerdict::kUnknown;
  Eigen::VectorXd scatter_eigenvalues;  // d, ascending, sum 1 (uniform: 1/d each)
  double scatter_min = std::numeric_limits<double>::quiet_NaN();  // d × smallest, in [0, 1]
  double design_min = std::numeric_limits<double>::quiet_NaN();   // >= 0 (uniform: about 1)
  std::vector<std::string> cap_names;  // d = 3: "+x", "-x", ..., "-z", "+x+y", "+x-y", ... (18)
  std::vector<int> cap_positions;      // positions in each cap (same order)
  std::string advice;  // what to add, in words ("add positions with the -y axis up"); empty when
                       // good
};

// One sensor's calibration. Frame-free quantities (scale, the *_std) do not depend on the frame.
struct PcaSensorEstimate {
  std::string name;
  Eigen::VectorXd sensitivity;  // a_i (d), in the result's frame
  double scale = 0;             // |a_i| (relative when the magnitude is unknown)
  Eigen::VectorXd axis;         // a_i / |a_i| (d, unit length)
  double bias = 0;              // estimated (kEstimate) or removed from a static/moving log, else 0
  // One standard deviation, from the Fisher information at the estimate; NaN when undefined (the
  // noise level can be neither given nor estimated, or the information matrix is singular).
  double scale_std = std::numeric_limits<double>::quiet_NaN();
  // RMS angle (radians) between the estimated and the true axis after the rotation that best
  // aligns all axes (the pseudo-inverse gauge, equivalent to a Procrustes fit onto the truth).
  double axis_std_rad = std::numeric_limits<double>::quiet_NaN();
  // 0 when the bias is neither estimated nor removed (it is then zero by assumption); NaN when
  // estimated but undefined.
  double bias_std = 0;
  // The white-noise Cramér–Rao bound of the three σ above (σ of a reading = the given noise_std);
  // absent when noise_std was not given (there is then no bound apart from the residuals).
  struct Bound {
    double scale_std, axis_std_rad, bias_std;
  };
  std::optional<Bound> crb;
};

// Fields start at sentinel values (NaN / empty / -1) and are filled as far as the computation got:
// on a kNotDeterminable failure the diagnostics computed before the failure are still there.
// A usable result has finite parameters (a, v, b, scale, axis, bias); an uncertainty is either
// finite or NaN (undefined, with a warning saying why), never a made-up 0 or an infinity.
struct PcaResult {
  bool usable = false;  // true iff CalibratePca returned OK: the parameters may be used
  std::string reason;   // why not usable (the failure message); empty when usable
  PcaFrame frame = PcaFrame::kNone;
  bool reflection = false;  // nominal frame: the Procrustes fit used a reflection (det = -1)
  int dimension = 0;        // d
  double magnitude = std::numeric_limits<double>::quiet_NaN();  // c used (1 when unknown)
  bool magnitude_known = false;
  BiasModel bias_model = BiasModel::kNone;
  Eigen::MatrixXd a;                       // d×m sensitivities in `frame`
  Eigen::MatrixXd v;                       // d×n field per position in `frame`, |v_j| = c
  Eigen::VectorXd b;                       // m biases (estimated, removed from the log, or zeros)
  std::vector<PcaSensorEstimate> sensors;  // m

  // Diagnostics (SPEC §4).
  Eigen::VectorXd singular_values;  // all min(m,n) singular values of the readings (kEstimate:
                                    // of the readings minus their mean over positions)
  double rank_gap = std::numeric_limits<double>::quiet_NaN();  // σ_d/σ_{d+1}; +inf when there
                                                               // is no σ_{d+1} (e.g. m = d)
  int positions = -1;                                          // n
  int min_positions = -1;           // d(d+1)/2 (kNone) or d(d+3)/2 (kEstimate)
  Eigen::VectorXd g_eigenvalues;    // eigenvalues of g (kNone) or of the ellipsoid shape
                                    // (kEstimate), ascending; all > 0 for a usable result
  Eigen::VectorXd residual_rms;     // m: RMS over positions of m_ij - a_iᵀv_j - b_i
  Eigen::VectorXd magnitude_error;  // n: |v_j| - c with v_j the unconstrained least-squares field
                                    // given a and b (how far each position is off the sphere)
  int degrees_of_freedom = -1;      // mn - (p·m + (d-1)n - d(d-1)/2), p = d or d+1
  double noise_std = std::numeric_limits<double>::quiet_NaN();  // σ used for the uncertainty
  bool noise_std_given = false;
  double noise_std_estimated = std::numeric_limits<double>::quiet_NaN();  // NaN if dof <= 0
  // What the sensors' σ are (the σ convention, SPEC §7): "crb" — noise_std given and the
  // residuals consistent with it (χ²/dof within 3·√(2/dof) of 1) or no redundancy to judge;
  // "chi2_scaled" — the CRB × √(χ²/dof), the residuals exceeding the given noise_std (a warning
  // says by how much), or, without noise_std, the bound at the σ the residuals estimate
  // (√(2·cost/dof): χ²-scaled by construction).
  std::string uncertainty_basis = "crb";
  // (noise_std_estimated / noise_std)²; NaN without a given noise_std or redundancy.
  double chi2_per_dof = std::numeric_limits<double>::quiet_NaN();
  double cost_closed_form = std::numeric_limits<double>::quiet_NaN();  // ½Σr² at the closed form
  double cost = std::numeric_limits<double>::quiet_NaN();  // ½Σr² at the reported estimate
  bool refined = false;       // the refinement was run and its estimate is reported
  int refine_iterations = 0;  // Gauss-Newton iterations taken (0 when not run)
  PcaCost cost_estimate;      // EstimatePcaCost of this problem (solver resolved)
  // How well the positions span the sphere. When the fit fails (too few positions, or the
  // closed form) and a nominal is given, from the fields seen through the nominal sensitivities
  // (a guide to the orientations to add); else unknown on failure.
  PcaCoverage coverage;
  std::vector<std::string> warnings;  // plain words, for people

  // One line for logs and tests, in the style of every method's result: usable (or why not),
  // the problem's size, the frame, the rank gap, the costs and the refinement's iterations.
  std::string BriefReport() const;
};

// Runs the calibration. kInvalidInput: bad options or problem (shapes, non-finite numbers, nominal
// with the wrong size). kNotDeterminable: the data cannot determine the parameters (the message
// says why and what to record instead), a computed value is not finite (the message names it), or
// the problem exceeds the options' budget (field "max_memory_bytes" or "max_flops"; nothing is
// computed). `result` is always written (see PcaResult). Cost: O(m·n·d² + m·p·r²) time and
// O(m·n + m·p·r) memory with the low-rank solver (r = n(d−1) + d(d−1)/2), so linear in the number
// of sensors for a fixed number of positions.
Status CalibratePca(const PcaProblem& problem, const PcaOptions& options, PcaResult* result);

// The Fisher information CalibratePca's uncertainty is computed from, for experiment design
// (the plan, SPEC §10): the reduced information S (unit noise) of the sensor parameters
// θ_i = [c·a_i; b_i] (p = d, or d + 1 with biases; sensor-major, p·m rows), the positions
// eliminated, at sensitivities `a` (d×m) and field directions `u` (d×n, unit length); and an
// orthonormal basis of its rotation gauge (p·m × d(d−1)/2), a null space of S by construction.
// S is singular beyond the gauge exactly when the positions cannot determine some parameter.
struct PcaInformation {
  Eigen::MatrixXd s;
  Eigen::MatrixXd gauge;
};
// kInvalidInput when the shapes disagree or a·aᵀ is singular (the sensors do not span d).
Status ComputePcaInformation(const Eigen::MatrixXd& a, const Eigen::MatrixXd& u, BiasModel bias,
                             PcaInformation* out);

// The paper's Eq. 19 canonical frame: the orthogonal h (d×d) such that h·a is upper triangular
// with a non-negative diagonal (QR of a, d×m). Requires a.rows() >= 1.
Eigen::MatrixXd CanonicalFrame(const Eigen::MatrixXd& a);

// The paper's Eq. 19 calibration error ε = |h·a_true − k·a_hat|_F, both in their canonical frames.
double CalibrationError(const Eigen::MatrixXd& a_true, const Eigen::MatrixXd& a_hat);

// Orthogonal r (d×d) minimising |r·from − to|_F (orthogonal Procrustes). allow_reflection: any
// orthogonal r (det ±1, what the data justify); false: a proper rotation (det +1).
Eigen::MatrixXd ProcrustesRotation(const Eigen::MatrixXd& from, const Eigen::MatrixXd& to,
                                   bool allow_reflection);

}  // namespace calibd::core

#endif  // CALIBD_CORE_PCA_H_
