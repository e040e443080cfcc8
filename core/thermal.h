// Thermal calibration (SPEC §8 `thermal`): each IMU's accelerometer and gyroscope bias as a
// function of temperature, from a log recorded while the device warms or cools at rest (or in a few
// orientations).
//
// Stages (core/thermal.cc, core/thermal_fit.cc):
//  1. Statics: core/static_detection on the IMU's two triads; each static interval is cut into
//     consecutive averaging windows of `window` seconds (a remainder shorter than half a window
//     joins the last one). Per window: the mean of every channel, its σ = s/√n (white noise; σ/√n
//     with σ the options' accel_noise/gyro_noise where given) with s² from a variance function:
//     the windows' log sample variances, less their bias ψ(ν/2) − ln(ν/2), fitted by a quadratic
//     in the window's temperature (each window's own s² is ~6 % off: weights that noisy cost
//     ~2 % of squared error; the function keeps a noise that changes with temperature),
//     the mean temperature and the temperature rate (least squares slope of T over the window); the
//     window's phase is heating (rate > min_rate), cooling (rate < −min_rate) or steady. Windows
//     are grouped by orientation (gravity directions within `orientation_tolerance` of each other).
//  2. Per channel, weighted least squares of the window means
//       y_w = b_g(w) + Σ_{k=1..p} c_k (T_w − t_ref)^k,      weights 1/σ_w²,
//     with one intercept b_g per orientation group for accelerometers (gravity is part of it) and
//     one for gyroscopes. Solved by Householder QR on (T − t_ref)/h, h = half the range, so order 5
//     over 60 °C stays well conditioned. Every order p ∈ [p_0, P] is fitted (p_0 = min_order,
//     default 3, the flight stacks' cubic; P = max_order; both less where fewer windows leave no
//     residual degree of freedom) and the curves are averaged with BIC weights
//     w_p ∝ exp(−BIC_p/2), BIC_p = n ln(χ²_p/n) + k ln N (n the windows, k the regression
//     parameters plus the noise scale: σ_w that are uniformly too small do not favour high orders;
//     N the samples the windows average). The window means are sufficient for the samples'
//     likelihood, so its ratio between orders is the windows' and the penalty takes N: the weights
//     do not depend on `window`. BIC is consistent: a term that is absent gets a weight that
//     vanishes with N, so a curve of the floor's order pays little for the orders offered above
//     it (with ln n an absent 4th or 5th order kept ~15 % of the weight and cost up to 16 % of
//     squared error against the flight stacks' cubic when the truth is cubic); efficient
//     criteria (AIC weights, Mallows or jackknife model averaging) keep a spurious order's weight
//     at O(1) and cost 25–40 % (README, table of rules). The floor at 3 keeps a barely detectable
//     cubic term in the curve (below it every rule pays for deciding it from the data); it costs
//     nothing against the flight stacks, which fit that cubic anyway. A strict penalty also gives
//     a weak term that is there a small weight and leaves a bias: the band therefore mixes the
//     orders with the band weights v_p ∝ exp(−BIC'_p/2), BIC' with the windows' penalty k ln n (a
//     prior as broad as one window), as Σ v_p (C_p + d_p d_pᵀ), d_p the order's parameters minus
//     the curve's average (zero-padded to P): an order the curve's weights dropped but the data
//     still support widens the band. The fit's order is P (the length of the averaged
//     coefficients); the table keeps every order's χ², BIC, weight and band weight; χ², dof and
//     the basis are the heaviest order's.
//  3. Uncertainty (SPEC §7 σ convention), per order: crb = (AᵀWA)⁻¹; when χ²/dof exceeds its
//     one-sided 1 % quantile under the white-noise model (1 + 2.326 √(2/dof)), the primary is
//     chi2_scaled (crb × χ²/dof), else crb; averaged as in stage 2 (the crb without the spread).
//     The 1σ band of the curve c(T) = Σ c_k (T − t_ref)^k on a grid across [t_min, t_max] is
//     √(vᵀ C v), v_k = (T − t_ref)^k.
//  4. Hysteresis: heating and cooling windows fitted apart at the curve's order P (each with its
//     own intercepts); their difference on the grid across the temperatures both cover, z = Δ/σ_Δ,
//     flagged when |z| > Φ⁻¹(1 − α/(2 m)), m = channels × grid points (Bonferroni: the false-alarm
//     rate over all channels and temperatures is at most α, default 1 %; the grid points are
//     correlated, so it is below α).
//  5. Lag (core/thermal_lag.cc; options.lag): the sensing element's temperature T_s follows the
//     reading T_r through dT_s/dt = (T_r − T_s)/τ, integrated sample by sample from a state
//     started on a line fitted to the reading's first `lag_start` seconds (not on one noisy
//     reading); the windows' temperatures are then means of T_s. With a known τ (kFixed) that is
//     all. kEstimate needs the log to heat and cool over a common range (else kNotDeterminable:
//     a single warm-up passes each temperature once, so a lag cannot be told from another curve);
//     τ minimises the profile −2 ln L = Σ_channels n ln χ²_c(τ) over [0, lag_max] (a log grid,
//     then golden section), each channel at its order P. Its σ and the curves' extra σ come from
//     the Gauss–Newton information with τ as a parameter shared by the six channels: with M_c the
//     channel's information and b_c = Aᵀ W ∂y/∂τ, S = Σ_c (d_c − b_cᵀ M_c⁻¹ b_c)/s_c,
//     σ_τ² = 1/S and C_c += h_c h_cᵀ/S, h_c = M_c⁻¹ b_c (s_c the channel's χ² scale, 1 for crb).
//  2b. Accelerometer scale and bias at t_ref (several orientations). Per axis a, the intercepts
//     are the reading at t_ref: I_g = b0_a + S_a n_{g,a}, n_g the group's unit gravity direction,
//     S_a = |g| (1 + k0_a) the gravity part's magnitude. Assumption: one gravity (magnitude and
//     direction fixed while a group is held), and groups within 60° of the axis whose directions
//     differ along it by at least scale_min_spread — antipodal faces (+a and −a) ideally, where
//     b0_a = (I_+ + I_−)/2 exactly. The faces of both signs must share a temperature span of at
//     least min_range (else the curves rest on extrapolation: null, with the spans found).
//     Otherwise the directions n_g = normalize((I_g − b0) / S) are iterated with (b0_a, S_a) from
//     the least squares of the intercepts on [1, n_g,a] weighted by their variances (σ from their
//     full covariance, A Σ Aᵀ), which is exact for faces along the axes and second order in b0/|g|
//     for others (S_a is off by |b_⊥|²/(2|g|) where the other axes' b0 are not determined). The
//     window means are then fitted as
//       y_w = I_g + Σ c_k x^k + G_g Σ d_k x^k,   G_g = S_a n_{g,a},
//     the bias curve c and the gain's relative change d (reading's gravity part × (1 + d(x)))
//     separated because G_g differs between groups; same orders, BIC average and σ convention as
//     stage 2 with twice the curve columns. G_g is taken from the fit's own intercepts (not the
//     raw group means, which carry the bias and the curves' average): the two steps alternate
//     until b0 changes by less than 1e-12 |g| (Aitken's Δ² every third round where it creeps), so
//     the fixed point is the bilinear model's least squares and noise-free data are recovered
//     exactly. G_g's own error (σ of I_g, ~1e-5 of |g|) scales d by that relative amount and is
//     not propagated. Not estimated (null, the channel says why): one orientation, groups that do
//     not differ along the axis, or lag = estimate (the lag's profile models bias curves only;
//     the bias at t_ref is still given there, from stage 2's intercepts, its σ without τ's).
//
// Pure numerics, thread-compatible. Units: SI readings (m/s², rad/s), °C, s.
#ifndef CALIBD_CORE_THERMAL_H_
#define CALIBD_CORE_THERMAL_H_

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "core/static_detection.h"

namespace calibd::core {

// SPEC §8 `lag`: none (the reading is the sensor's temperature), a known τ, or τ estimated.
enum class ThermalLagMode { kNone, kFixed, kEstimate };

struct ThermalOptions {
  double window = 10;  // s, > 0: averaging window inside the statics
  int max_order = 5;   // in [1, 8]: highest polynomial order offered
  // In [0, 8]: lowest order offered (capped at max_order and at what the windows support). 3,
  // the flight stacks' cubic: the data decide only the orders above it (see stage 2).
  int min_order = 3;
  std::optional<double> t_ref;     // °C; nullopt: the middle of [t_min, t_max]
  double min_range = 10;           // °C, >= 0: a smaller range of window temperatures is refused
  double min_rate = 0.001;         // °C/s, >= 0: |rate| above it is heating or cooling
  int grid_points = 21;            // >= 2: band and hysteresis grid across [t_min, t_max]
  double hysteresis_alpha = 0.01;  // in (0, 1): false-alarm rate over all channels
  double orientation_tolerance = 0.17453;  // rad (10°): same orientation group
  // In (0, 2]: an accelerometer axis gets a scale curve and its bias at t_ref only when the
  // orientation groups' unit gravity directions differ along it by at least this (2: antipodal).
  double scale_min_spread = 0.5;
  StaticDetectionOptions statics;  // static detection (stop token included)
  ThermalLagMode lag = ThermalLagMode::kNone;
  double lag_seconds = 0;  // s, > 0 with kFixed: the known τ
  double lag_max = 1800;   // s, > 0: kEstimate searches τ in [0, lag_max]
  double lag_start = 10;   // s, > 0: the lag state starts on a line fitted to these first seconds
  // White noise per sample (σ, SI, > 0) of the accelerometers and gyroscopes, e.g. from a noise
  // job: a window's σ is then σ/√n. nullopt: each window's σ from its own samples.
  std::optional<double> accel_noise, gyro_noise;

  bool IsValid(std::string* error) const;
};

// One IMU's log. Non-owning: the arrays must outlive the call.
struct ThermalImuInput {
  std::string name;                         // e.g. "0"
  const Eigen::MatrixX3d* accel = nullptr;  // N×3, m/s²
  const Eigen::MatrixX3d* gyro = nullptr;   // N×3, rad/s
  const Eigen::VectorXd* temp = nullptr;    // N, °C
};

// One averaging window (stage 1).
struct ThermalWindow {
  double start = 0, end = 0;  // s
  int64_t samples = 0;
  double temperature = 0;                // °C, mean
  double rate = 0;                       // °C/s
  int phase = 0;                         // +1 heating, −1 cooling, 0 steady
  int orientation = 0;                   // group index
  Eigen::Matrix<double, 6, 1> mean;      // ax ay az gx gy gz, SI
  Eigen::Matrix<double, 6, 1> mean_std;  // σ of the mean, SI
};

// One row of the order table (stage 2).
struct ThermalOrderRow {
  int order = 0;
  double chi2 = 0;
  double bic = 0;          // with the samples' penalty k ln N (stage 2)
  double weight = 0;       // in [0, 1], summing to 1 over the table: the order's share of the curve
  double band_weight = 0;  // in [0, 1], summing to 1: its share of the band (penalty k ln n)
};

// One weighted polynomial fit (one channel, one set of windows).
struct ThermalPolyFit {
  int order = 0;
  Eigen::VectorXd coefficients;  // c_1..c_p, SI per °C^k
  Eigen::VectorXd intercepts;    // per orientation group (gyro: one), SI
  Eigen::MatrixXd covariance;    // p×p, primary
  Eigen::MatrixXd crb;           // p×p, white-noise bound
  // With a scale column block (FitThermalPolynomial's gravity given): d_1..d_p (dimensionless gain
  // change per °C^k) and their primary and white-noise covariances; empty otherwise.
  Eigen::VectorXd scale_coefficients;
  Eigen::MatrixXd scale_covariance, scale_crb;
  // (groups + p)², or (groups + 2p)² with scale, primary: intercepts, c_1..c_p, then d_1..d_p.
  Eigen::MatrixXd full_covariance;
  double intercept_std = 0;  // primary σ of intercepts(0)
  double chi2 = 0;
  int dof = 0;
  std::string basis;        // "crb" | "chi2_scaled"
  double residual_rms = 0;  // SI, unweighted
  double noise_rms = 0;     // SI, RMS of the windows' σ of the mean
  std::vector<ThermalOrderRow> table;
};

struct ThermalChannel {
  std::string name;  // "accelerometer.x" ... "gyroscope.z"
  ThermalPolyFit fit;
  Eigen::VectorXd grid_value;  // curve on the grid, SI
  Eigen::VectorXd grid_std;    // primary 1σ on the grid
  Eigen::VectorXd grid_crb_std;
  // Accelerometer scale curve (stage 2b): fit.scale_* hold it when estimated; else the reason.
  bool scale_estimated = false;
  std::string scale_reason;
  Eigen::VectorXd grid_scale_value, grid_scale_std, grid_scale_crb_std;  // dimensionless
  // Hysteresis (empty when heating or cooling has too few windows).
  bool hysteresis_tested = false;
  Eigen::VectorXd hysteresis_temperatures;
  Eigen::VectorXd hysteresis_difference;  // heating − cooling, SI
  Eigen::VectorXd hysteresis_z;
  double max_abs_z = 0;
  bool hysteresis_flagged = false;
};

struct ThermalImuResult {
  std::string name;
  double t_ref = 0, t_min = 0, t_max = 0;
  std::vector<ThermalWindow> windows;
  int orientations = 0;
  Eigen::VectorXd grid;                  // °C
  std::vector<ThermalChannel> channels;  // 6: accelerometer x,y,z, gyroscope x,y,z
  std::optional<Eigen::Vector3d> gyro_at_t_ref, gyro_at_t_ref_std;  // rad/s
  // Stage 2b, per accelerometer axis (nullopt where the orientations do not determine it, the
  // channel's scale_reason says why): the bias at t_ref (m/s²), its primary σ, and the gravity
  // part's magnitude S_a = |g| (1 + k0_a) at t_ref (m/s²).
  std::array<std::optional<double>, 3> accel_at_t_ref, accel_at_t_ref_std, accel_gravity;
  int heating_windows = 0, cooling_windows = 0;
  double hysteresis_threshold_z = 0;  // Bonferroni critical |z|
  // Stage 5: τ in s (nullopt: lag none); its primary σ and white-noise bound where estimated.
  std::optional<double> lag, lag_std, lag_crb_std;
  // kEstimate: the profile −2 ln L (relative to its minimum) on the τ grid searched.
  Eigen::VectorXd lag_grid, lag_profile;
  StaticDetection statics;
};

struct ThermalResult {
  std::vector<ThermalImuResult> imus;
  std::vector<std::string> warnings;
};

// kInvalidInput: options invalid, arrays of different lengths, non-finite values (names IMU and
// sample). kNotDeterminable: too few statics/windows (names what was found) or a temperature range
// below min_range (names the range found). kStopped when options.statics.stop asked for a stop.
Status CalibrateThermal(const Eigen::VectorXd& t, const std::vector<ThermalImuInput>& imus,
                        const ThermalOptions& options, ThermalResult* out);

// Stages 1 and 5 alone, for one IMU (what the recording check shows before a fit, issue #27): its
// statics, the averaging windows with their temperatures, phases and orientation groups, t_min,
// t_max and the phase counts, and the lag where options ask for one, written into *out exactly as
// CalibrateThermal finds them. The same errors as CalibrateThermal for these stages
// (kNotDeterminable: too few windows, a range below min_range, a lag not determinable), with *out
// filled as far as it got. No channel fit.
Status FindThermalWindows(const Eigen::VectorXd& t, const ThermalImuInput& imu,
                          const ThermalOptions& options, ThermalImuResult* out);

// Stage 2 and 3 for one channel, exposed for tests: x = T − t_ref (°C), group per window (in
// [0, groups)), the orders min_order..max_order averaged (equal: a fixed order). `scale` (> 0)
// is the unit of x the design uses internally (half the range). `samples` (>= the windows; 0:
// the windows) the samples the window means reduce, whose count BIC's penalty takes. `gravity`
// non-empty (one per window, SI): the model y = I_g + Σ c_k x^k + G_w Σ d_k x^k, both curves of
// the same order.
Status FitThermalPolynomial(const Eigen::VectorXd& x, const Eigen::VectorXd& y,
                            const Eigen::VectorXd& sigma, const std::vector<int>& group, int groups,
                            int min_order, int max_order, double scale, int64_t samples,
                            ThermalPolyFit* out,
                            const Eigen::VectorXd& gravity = Eigen::VectorXd());

// The curve Σ c_k x^k and its 1σ √(vᵀ C v) at x = T − t_ref.
double ThermalCurve(const Eigen::VectorXd& coefficients, double x);
double ThermalCurveStd(const Eigen::MatrixXd& covariance, double x);

// Φ⁻¹(1 − α/(2m)): the two-sided Bonferroni critical |z| for m tests at family rate α.
double BonferroniCriticalZ(double alpha, int tests);

}  // namespace calibd::core

#endif  // CALIBD_CORE_THERMAL_H_
