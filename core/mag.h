// The `mag` calibration numerics (SPEC §8, issue #26): a magnetometer's hard and soft iron from a
// log turned by hand through many orientations, its rotation to the accelerometer frame and the
// field's dip from the log's still holds, each with 1σ.
//
// Model (Vasconcelos, Elkaim, Silvestre, Oliveira, Cardeira, IEEE TAES 2011, "Geometric approach
// to strapdown magnetometer calibration in sensor frame"; alignment as Kok & Schön, IFAC 2016):
//   m_i = S (y_i − h),   |m_i| = F,   S = R P,
// y_i the readings (reading units), h the hard iron (reading units), P symmetric positive definite
// (the soft iron in the magnetometer's own axes, with the scale to µT), R the rotation of the
// magnetometer frame to the accelerometer frame, F the local field (µT; 1 when unknown). The
// readings are y_i = h + A u_i + ε_i with A = F P⁻¹ (symmetric) and u_i the field's direction in
// the magnetometer frame, a unit-vector nuisance per sample; ε_i white, isotropic, σ unknown.
//
// Steps (CalibrateMag):
//  1. Start: the algebraic ellipsoid fit yᵀQy + lᵀy + c = 0 (the singular vector of the design
//     matrix with the smallest singular value, the readings centred and scaled first), centre
//     h = −Q⁻¹l/2, A = (Q/k)^(-1/2) with k = hᵀQh − c; u_i = A⁻¹(y_i − h) normalised. Q not
//     definite: the readings lie on no ellipsoid (kNotAnEllipsoid).
//  2. Maximum likelihood: Levenberg-Marquardt over (h, the 6 entries of A) and every u_i (2
//     tangent unknowns each), the u_i blocks eliminated per sample (Schur complement onto the 9
//     shared unknowns): O(N) per iteration. Robust passes (iteratively reweighted): Cauchy
//     weights w_i = 1/(1 + (|e_i|/(c σ̂))²) on each sample's residual norm, σ̂ from the median
//     residual, so that spans disturbed by nearby iron weigh little; samples with w_i below
//     `disturbed_weight` are reported as disturbed spans.
//  2b. Errors in variables: each u_i is fitted to the noise too (Neyman-Scott), so a reading's
//     distance to the fitted ellipsoid along its outward normal n_i has the mean (σ²/2) κ_i, κ_i
//     the sum of the principal curvatures at the foot point (2/radius on a sphere), and plain
//     maximum likelihood returns an ellipsoid too large by about σ²/radius (relative (σ/radius)²:
//     several σ of P at a noisy sensor's 5 % of the field). The fit is repeated, robust passes
//     and all, on the readings less (σ̂²/2) κ_i n_i (σ̂ from the median residual, κ_i and n_i at
//     the first fit's foot points); the weights then come from zero-mean distances too. The
//     uncertainty (step 3) is that of the corrected fit.
//  3. Uncertainty: the white-noise bound σ̂² (Σ w J̃ᵀJ̃)⁻¹ (J̃ the reduced Jacobian, σ̂ from the
//     weighted residuals) and the residual-aware sandwich over batches of consecutive samples
//     (`batch_seconds`), Newey-West with lag one batch: H⁻¹ M H⁻¹ · n_b/(n_b − 9),
//     M = Σ_b s_b s_bᵀ + ½ Σ_b (s_b s_{b−1}ᵀ + s_{b−1} s_bᵀ), s_b the batch's reduced score;
//     again over batches 2, 4, 8... times as long while `min_batches` remain, the largest kept
//     (the blocking method: residuals correlated over longer than a batch, as a hand-held log's
//     misfit is, make the short batches' sandwich too small; halves of a real log showed it).
//     The sandwich holds when the noise is coloured (a hand-held log's disturbances and
//     vibration are) or the weights matter; the primary σ is the sandwich where it exceeds the
//     white-noise bound by more than `sandwich_margin` (RMS over the parameters' σ ratios),
//     else the bound (SPEC §7's uncertainty rule; basis named in the result). A sandwich primary
//     is the largest over batches down to `min_long_batches` (noisier; they do not decide the
//     basis, so white noise keeps the bound): the public logs' blocking reaches no plateau (the
//     QMC5883L sphere's σ ratio grows 1.9, 2.2, 2.6, 3.1, 4.5 over 2-32 s batches, its x and z
//     offsets wandering at every time scale from 5 s up; CK-Explorer's 8.5, 10, 14 over 2-8 s),
//     and its halves, each with 24 batches at most, disagreed at z RMS 2.08 and 1.68 (1.50 and
//     1.45 with 15). The result's `blocking` lists the curve; where σ is the sandwich and the
//     curve reaches no plateau (`plateau_growth`) a warning names it.
//  3c. Offset wander (no plateau, sandwich primary): a sensor whose offsets wander (an AMR's
//     1/f offset noise, warm-up) gives each log its own average hard iron, which no σ about
//     that average covers (halves of the public logs disagreed by 1.5σ RMS). The primary σ then
//     predicts the next log as long as this one: the white-noise bound at σ̂_d (the residuals'
//     sample-to-sample noise, which the wander does not reach; every sandwich counts the
//     wander's level in its batches and would count it twice) plus the wander's share of
//     ½ E (θ̂ − θ̂')(θ̂ − θ̂')ᵀ, under a random walk of the hard iron (rate per
//     axis from the hard irons of `wander_segments` consecutive segments, A held at the fit, each
//     sample weighted 1 unless disturbed, less their own noise) carried through the fit's linear
//     response to every reading (so the soft iron's share too; the alignment carries the
//     sandwich alone: its statics' scatter holds the wander within the log). For the hard iron that
//     share is q T / 3, the offset's Allan variance at the log's length T. A random walk is the
//     model that grows fastest of those a flat or falling Allan deviation would allow (flicker:
//     flat); for 1/f offsets it is conservative.
//  4. Alignment (with accelerometer statics): the down direction d_j (−specific force, unit) and
//     the calibrated field direction n_j = P(ȳ_j − h)/|·| of each static satisfy
//     d_jᵀ R n_j = sin δ (δ the dip, positive down); Gauss-Newton over R (left perturbation) and
//     sin δ, 1σ from the residual scatter (as a Student-t's standard deviation: ν/(ν − 2) times
//     the scatter's variance, ν = statics − 4) plus the ellipsoid's σ carried through. Too few
//     statics, or statics about one axis only: not estimated, with the reason in
//     `alignment_note`.
//  5. Coverage of orientations: the calibrated field directions' scatter (3/N) Σ u_i u_iᵀ and the
//     magnetometer axes (±x, ±y, ±z) the field never came within 45° of (SPEC §8: "judged as for
//     imu"). Readings close to a plane (turned about one axis only: the smallest eigenvalue of
//     their covariance under `min_coverage_eigenvalue` / 10 of the largest, checked first) do not
//     determine the ellipsoid: kPoorOrientationCoverage naming the axis to bring along the field.
//
// Cost: O(N · iterations) time, O(N) memory (24 doubles a sample). `options.stop` is polled
// every iteration. Pure numerics: Eigen in, result structs out. Thread-compatible.
#ifndef CALIBD_CORE_MAG_H_
#define CALIBD_CORE_MAG_H_

#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/stop_token.h"

namespace calibd::core {

struct MagOptions {
  // Local field magnitude F, µT (the readings' unit scaled by `microtesla_per_unit`); 0: unknown,
  // then |m| = 1 and the result's field_estimate gives F from the data. >= 0.
  double field = 0;
  // µT per reading unit (the caller's mag_unit). > 0.
  double microtesla_per_unit = 1;
  // Levenberg-Marquardt iterations per robust pass. >= 1.
  int max_iterations = 100;
  // Relative cost decrease under which a pass has converged. > 0.
  double tolerance = 1e-8;
  // Cauchy scale c of the robust weights, in σ̂; 0: plain maximum likelihood (no reweighting).
  // >= 0 (values under 2 down-weight clean samples too).
  double robust_scale = 3;
  // Reweighting passes after the first (unweighted) fit. >= 0.
  int robust_passes = 3;
  // Remove the fit's errors-in-variables bias (step 2b): refit on the readings less each one's
  // expected distance to the ellipsoid, (σ̂²/2) × the sum of the principal curvatures along the
  // normal. false: plain maximum likelihood (the ellipsoid too large by about σ²/radius).
  bool errors_in_variables = true;
  // A sample weighs less than this: it is counted as disturbed. In (0, 1).
  double disturbed_weight = 0.25;
  // More than this fraction of samples disturbed: kFieldDisturbed. In (0, 1].
  double max_disturbed_fraction = 0.3;
  // Length of the sandwich's batches of consecutive samples, s (several correlation times of the
  // disturbances a hand-held log holds). > 0.
  double batch_seconds = 2;
  // The sandwich is also computed over batches of 2, 4, 8... × batch_seconds while at least this
  // many batches remain, and the largest kept (residuals correlated longer than a batch). > 9.
  int min_batches = 24;
  // Once the sandwich is the primary (see sandwich_margin), batches down to this many also
  // count (the largest kept; step 3): residuals correlated longer than the batches that leave
  // min_batches. In (9, min_batches].
  int min_long_batches = 15;
  // Disturbed samples closer than this merge into one span, s. >= 0.
  double span_merge_seconds = 0.5;
  // The sandwich becomes the primary σ when the RMS of its σ over the bound's exceeds this. >= 1.
  double sandwich_margin = 1.15;
  // Where σ is the sandwich: the blocking reaches no plateau (a warning; step 3c) when its σ
  // ratio (RMS over the parameters, sandwich over bound) at the longest batches exceeds the one at
  // batches half as long by more than this factor (measured at about 16 batches: white-noise and
  // AR(1) logs 1.1-1.3, the small-sample factor lifting it over 1; a random-walk offset 1.4-1.5;
  // README, mag section). > 1.
  double plateau_growth = 1.3;
  // Where the blocking reaches no plateau and σ is the sandwich: add the hard iron's wander to
  // the primary σ (step 3c), a random walk whose rate comes from the hard irons of consecutive
  // segments, carried through the fit to the next log as long as this one. false: σ stays the
  // sandwich (a lower bound there, as the warning says).
  bool offset_wander = true;
  // The wander's segments: the log in this many, each at least wander_min_seconds long (then
  // fewer). >= 4; wander_min_seconds >= 4 × batch_seconds (each segment's noise is a sandwich
  // over its batches).
  int wander_segments = 12;
  double wander_min_seconds = 8;
  // Coverage: the smallest eigenvalue of (3/N) Σ u uᵀ for a "good" verdict (all 1 when the field
  // directions are spread evenly). In (0, 1].
  double min_coverage_eigenvalue = 0.2;
  // Alignment: at least this many statics. >= 7: the rotation and the dip (4 unknowns) take their
  // σ from the statics' scatter, whose Student-t variance ν/(ν − 2) needs ν = statics − 4 >= 3.
  int min_alignment_statics = 7;
  // Asks the fit to stop early (kStopped). May be null.
  const StopToken* stop = nullptr;

  // kInvalidInput naming the violated constraint.
  Status Validate() const;
};

// A still hold of the device (found by the caller's static detection on the accelerometer).
struct MagStatic {
  int64_t first = 0;  // first and last sample index of the hold, into MagProblem::y
  int64_t last = 0;
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();  // accelerometer mean, any unit
};

struct MagProblem {
  Eigen::VectorXd t;               // sample times, s, increasing (N)
  Eigen::Matrix3Xd y;              // magnetometer readings, reading units (3×N)
  std::vector<MagStatic> statics;  // for the alignment; empty: not estimated
};

struct MagCoverage {
  Eigen::Vector3d eigenvalues = Eigen::Vector3d::Zero();  // ascending, of (3/N) Σ u uᵀ
  Eigen::Vector3d least_covered_direction = Eigen::Vector3d::Zero();
  std::vector<std::string> missing;  // magnetometer axes the field never came within 45° of
  bool sufficient = false;
  std::string verdict;  // "good: ..." or what to add
};

// A time span of disturbed samples.
struct MagSpan {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
  double max_residual = 0;  // µT, the largest residual norm in the span
};

// One step of the sandwich's blocking (core/mag.h step 3): batches of `seconds`, `batches` of
// them, the RMS over the parameters of σ(sandwich) / σ(bound).
struct MagBlockingStep {
  double seconds = 0;
  int64_t batches = 0;
  double ratio = 0;
};

// The σ of every parameter, in the result's units (see MagResult).
struct MagStd {
  Eigen::Vector3d hard_iron = Eigen::Vector3d::Zero();
  Eigen::Matrix3d soft_iron = Eigen::Matrix3d::Zero();
  Eigen::Vector3d alignment = Eigen::Vector3d::Zero();    // rad, small angles about the accel axes
  double dip = std::numeric_limits<double>::quiet_NaN();  // degrees
};

struct MagResult {
  Eigen::Vector3d hard_iron = Eigen::Vector3d::Zero();  // h, reading units
  // S = R P (µT per reading unit when F is known, else unit field per reading unit).
  Eigen::Matrix3d soft_iron = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d soft_iron_symmetric = Eigen::Matrix3d::Identity();  // P
  std::optional<Eigen::Matrix3d> alignment;  // R; nullopt: not estimated (alignment_note says why)
  std::optional<double> dip;                 // degrees, positive down
  std::string alignment_note;
  double field = 1;           // F the model used: options.field, or 1
  double field_estimate = 0;  // µT: the ellipsoid's geometric-mean radius × µT per unit

  MagStd std;         // primary σ (basis says which)
  MagStd crb;         // the white-noise bound
  std::string basis;  // "crb" or "sandwich"
  // RMS over the parameters of σ(sandwich) / σ(bound): about 1 for white noise; the primary's
  // sandwich (down to min_long_batches) when the basis is "sandwich". (No χ²/dof: σ̂ comes from
  // the residuals themselves.)
  double sandwich_ratio = std::numeric_limits<double>::quiet_NaN();
  double noise_std = 0;  // σ̂, reading units (white, from the residuals)
  // The sandwich over every batch length tried (2, 4, 8... × batch_seconds while at least
  // min_long_batches remain); `plateau` false when σ is the sandwich and the longest grew by
  // more than plateau_growth over the one before (residuals correlated longer than the log's
  // blocking can show; a warning says so, and step 3c adds the wander). True with fewer than two
  // steps or where σ is the bound.
  std::vector<MagBlockingStep> blocking;
  bool plateau = true;
  // Step 3c (no plateau, sandwich primary, MagOptions::offset_wander): the hard iron's random
  // walk, √q per axis (reading units/√s), from `wander_segments` segments of
  // `wander_segment_seconds`; `wander_included`: the primary σ holds its share.
  Eigen::Vector3d wander_rate = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  int wander_segments = 0;
  double wander_segment_seconds = 0;
  bool wander_included = false;

  // |m| − F over all samples, µT (RMS): the nominal (identity, no offset) and calibrated.
  double residual_rms_before = 0;
  double residual_rms_after = 0;  // unweighted, all samples
  double residual_rms_clean = 0;  // samples not disturbed
  int64_t samples = 0;
  int64_t disturbed_samples = 0;
  std::vector<MagSpan> disturbed_spans;
  MagCoverage coverage;
  int iterations = 0;
  std::vector<std::string> warnings;
};

// kInvalidInput: options invalid, y not finite, t not increasing or sizes that differ, fewer than
// 20 samples; kNotDeterminable: kNotAnEllipsoid, kPoorOrientationCoverage, Reason::kFieldDisturbed,
// kIllConditioned; kStopped when options.stop asked. On failure `result` holds what was found.
Status CalibrateMag(const MagProblem& problem, const MagOptions& options, MagResult* result);

// Step 5's check made first (before any fit): kNotDeterminable (kPoorOrientationCoverage) with
// CalibrateMag's message when the readings lie close to a plane; Ok otherwise. For checks before
// fitting (Method::Check).
Status CheckMagReadingsNotPlanar(const Eigen::Matrix3Xd& y, const MagOptions& options);

}  // namespace calibd::core

#endif  // CALIBD_CORE_MAG_H_
