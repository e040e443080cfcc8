#include "core/noise.h"

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <thread>
#include <utility>

namespace calibd::core {
namespace {

constexpr double kFloorFactor = 0.664;  // IEEE 952: the Allan deviation floor is 0.664 B
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kIterations = 5;  // reweighting passes of the fit
// χ² above E χ² + this many of its standard deviations: the σ are χ²-scaled.
constexpr double kChi2Deviations = 3;

std::string Format(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}
std::string Sci(double v) { return Format("%.3g", v); }

// Duration in words: "40 s", "12 min", "3.2 h", "5.1 days".
std::string Duration(double seconds) {
  if (!std::isfinite(seconds)) return "no length";
  if (seconds < 120) return Format("%.0f s", seconds);
  if (seconds < 7200) return Format("%.0f min", seconds / 60);
  if (seconds < 3 * 86400) return Format("%.1f h", seconds / 3600);
  return Format("%.1f days", seconds / 86400);
}

double Median(std::vector<double> x) {
  if (x.empty()) return kNaN;
  const size_t k = x.size() / 2;
  std::nth_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(k), x.end());
  const double upper = x[k];
  if (x.size() % 2) return upper;
  return 0.5 * (*std::max_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(k)) + upper);
}

// ----- The weighted non-negative least-squares fit of σ²(τ) = a/τ + c + d·τ.
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;

struct Fit {
  Vec3 coef = Vec3::Zero();              // (a, c, d) = (N², (0.664B)², K²/3), each >= 0
  Mat3 cov_support = Mat3::Zero();       // covariance on the support (zero rows/cols elsewhere)
  Mat3 cov_full = Mat3::Constant(kNaN);  // unconstrained covariance (all three terms)
  double chi2 = kNaN;
  // χ² the noise model predicts for the fitted points (their correlation Σ and the fit's
  // projection: E χ² = tr M, Var χ² = 2 tr M², M = W½(I−P)Σ(I−P)ᵀW½, P the weighted hat matrix
  // on the support). The points are correlated, so E χ² is not points − terms.
  double chi2_expected = kNaN;
  double chi2_expected_std = kNaN;
  std::vector<AllanNoiseType> types;  // dominant term per point of the curve
  std::vector<double> model;          // fitted σ² per point of the curve
};

Vec3 Regressors(double tau) { return Vec3(1 / tau, 1, tau); }

AllanNoiseType Dominant(const Vec3& coef, double tau) {
  const Vec3 part = coef.cwiseProduct(Regressors(tau));
  if (part(2) >= part(0) && part(2) >= part(1)) return AllanNoiseType::kRandomWalkFm;
  if (part(1) >= part(0)) return AllanNoiseType::kFlickerFm;
  return AllanNoiseType::kWhiteFm;
}

// Correlation length, in octaves of cluster size, of the overlapping Allan variances at two
// cluster times when the given term dominates: Corr(σ̂²(m), σ̂²(2m)) ≈ 0.52 for white noise and
// ≈ 0.88 for random walk (measured by simulation, 1000 seeds; flicker taken in between).
double CorrelationLength(AllanNoiseType type) {
  switch (type) {
    case AllanNoiseType::kWhiteFm:
      return 1.5;
    case AllanNoiseType::kFlickerFm:
      return 3.0;
    case AllanNoiseType::kRandomWalkFm:
      return 6.0;
  }
  return 1.5;
}

// Correlation matrix of the points (Paciorek's non-stationary exponential kernel in log2 m, which
// is positive definite for any mix of correlation lengths).
Eigen::MatrixXd Correlation(const std::vector<double>& log2m, const std::vector<double>& length) {
  const size_t k = log2m.size();
  Eigen::MatrixXd r(k, k);
  for (size_t i = 0; i < k; ++i) {
    for (size_t j = 0; j < k; ++j) {
      const double li = length[i], lj = length[j];
      const double q = 0.5 * (li * li + lj * lj);
      r(i, j) = std::sqrt(li * lj / q) * std::exp(-std::fabs(log2m[i] - log2m[j]) / std::sqrt(q));
    }
  }
  return r;
}

// Generalised least squares restricted to the terms in `mask` (bit j: term j), given the
// whitened normal equations h = X̃ᵀX̃, g = X̃ᵀỹ. Columns are scaled for conditioning. Returns
// false when the reduced normal matrix is singular.
bool SolveSubset(const Mat3& h, const Vec3& g, int mask, Vec3* coef, Mat3* cov) {
  Vec3 scale = Vec3::Zero();
  for (int j = 0; j < 3; ++j) {
    if ((mask >> j & 1) && h(j, j) > 0) scale(j) = 1 / std::sqrt(h(j, j));
  }
  Mat3 reduced = scale.asDiagonal() * h * scale.asDiagonal();
  for (int j = 0; j < 3; ++j) {
    if (scale(j) == 0) {
      reduced.row(j).setZero();
      reduced.col(j).setZero();
      reduced(j, j) = 1;
    }
  }
  Eigen::FullPivLU<Mat3> lu(reduced);
  if (lu.rank() < 3 || lu.rcond() < 1e-14) return false;
  Mat3 inv = lu.inverse();
  for (int j = 0; j < 3; ++j) {
    if (scale(j) == 0) {
      inv.row(j).setZero();
      inv.col(j).setZero();
    }
  }
  *coef = scale.asDiagonal() * (inv * scale.cwiseProduct(g));
  *cov = scale.asDiagonal() * inv * scale.asDiagonal();
  return true;
}

Fit FitModel(const AllanCurve& curve, int64_t min_fit_cluster) {
  Fit fit;
  std::vector<size_t> index;
  for (size_t j = 0; j < curve.size(); ++j) {
    if (curve.cluster[j] >= min_fit_cluster && curve.avar[j] > 0) index.push_back(j);
  }
  const size_t k = index.size();
  Eigen::MatrixXd x(k, 3);
  Eigen::VectorXd y(k), model(k);
  std::vector<double> log2m(k), length(k);
  for (size_t i = 0; i < k; ++i) {
    x.row(static_cast<Eigen::Index>(i)) = Regressors(curve.tau[index[i]]).transpose();
    y(static_cast<Eigen::Index>(i)) = curve.avar[index[i]];
    log2m[i] = std::log2(static_cast<double>(curve.cluster[index[i]]));
  }
  std::vector<AllanNoiseType> types(k, AllanNoiseType::kWhiteFm);
  model = y;  // first pass: the observed values
  for (int it = 0; it < kIterations && k > 0; ++it) {
    Eigen::VectorXd sd(k);
    for (size_t i = 0; i < k; ++i) {
      const double edf = AllanEdf(types[i], curve.samples, curve.cluster[index[i]]);
      sd(static_cast<Eigen::Index>(i)) = model(static_cast<Eigen::Index>(i)) * std::sqrt(2 / edf);
      length[i] = CorrelationLength(types[i]);
    }
    // Weighted least squares with the chi-square variances (diagonal weights), covariance by the
    // sandwich with the correlated Σ: GLS with Σ itself fits below the data (the fit follows
    // the common shifts that strong correlations allow, as in Peelle's puzzle).
    const Eigen::MatrixXd sigma = sd.asDiagonal() * Correlation(log2m, length) * sd.asDiagonal();
    const Eigen::VectorXd weight = sd.array().square().inverse();
    const Eigen::MatrixXd wx = weight.asDiagonal() * x;
    const Mat3 h = x.transpose() * wx;
    const Vec3 g = wx.transpose() * y;
    const Mat3 meat = wx.transpose() * sigma * wx;
    auto chi2_of = [&](const Vec3& coef) { return (y - x * coef).cwiseAbs2().dot(weight); };
    double best = kInf;
    Mat3 best_bread = Mat3::Zero();
    for (int mask = 1; mask < 8; ++mask) {
      Vec3 coef;
      Mat3 bread;
      if (!SolveSubset(h, g, mask, &coef, &bread)) continue;
      if ((coef.array() < 0).any()) continue;
      const double chi2 = chi2_of(coef);
      if (chi2 < best) {
        best = chi2;
        fit.coef = coef;
        fit.cov_support = bread * meat * bread;
        best_bread = bread;
      }
    }
    if (std::isfinite(best)) {
      // Residual operator I − P, P = X (XᵀWX)⁻¹_support XᵀW; M = W½ (I−P) Σ (I−P)ᵀ W½.
      const Eigen::MatrixXd residual =
          Eigen::MatrixXd::Identity(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k)) -
          x * best_bread * wx.transpose();
      const Eigen::VectorXd root = weight.cwiseSqrt();
      const Eigen::MatrixXd m =
          root.asDiagonal() * residual * sigma * residual.transpose() * root.asDiagonal();
      fit.chi2_expected = m.trace();
      fit.chi2_expected_std = std::sqrt(2 * m.cwiseAbs2().sum());
    }
    Vec3 coef_full;
    Mat3 bread_full;
    if (SolveSubset(h, g, 7, &coef_full, &bread_full)) {
      fit.cov_full = bread_full * meat * bread_full;
    }
    if (!std::isfinite(best)) break;
    fit.chi2 = best;
    for (size_t i = 0; i < k; ++i) {
      model(static_cast<Eigen::Index>(i)) =
          std::max(x.row(static_cast<Eigen::Index>(i)).dot(fit.coef), 1e-300);
      types[i] = Dominant(fit.coef, curve.tau[index[i]]);
    }
  }
  fit.types.resize(curve.size());
  fit.model.resize(curve.size());
  for (size_t j = 0; j < curve.size(); ++j) {
    fit.model[j] = Regressors(curve.tau[j]).dot(fit.coef);
    fit.types[j] = Dominant(fit.coef, curve.tau[j]);
  }
  return fit;
}

// What a log of n samples every tau0 would give if the Allan variance were exactly the model
// `coef`: the sandwich covariance of the fitted coefficients (support = the positive terms) and
// which terms dominate at a fitted point. The same weights and Σ as FitModel at convergence.
Mat3 ModelCovariance(const Vec3& coef, int64_t n, double tau0, const NoiseOptions& options,
                     bool dominates[3]) {
  dominates[0] = dominates[1] = dominates[2] = false;
  std::vector<int64_t> m;
  for (int64_t mm : AllanClusterSizes(n, options.taus_per_decade)) {
    if (mm >= options.min_fit_cluster) m.push_back(mm);
  }
  const size_t k = m.size();
  Eigen::MatrixXd x(k, 3);
  Eigen::VectorXd sd(k);
  std::vector<double> log2m(k), length(k);
  for (size_t i = 0; i < k; ++i) {
    const double tau = static_cast<double>(m[i]) * tau0;
    const Vec3 r = Regressors(tau);
    x.row(static_cast<Eigen::Index>(i)) = r.transpose();
    const AllanNoiseType type = Dominant(coef, tau);
    dominates[static_cast<int>(type)] = true;
    sd(static_cast<Eigen::Index>(i)) =
        std::max(r.dot(coef), 1e-300) * std::sqrt(2 / AllanEdf(type, n, m[i]));
    log2m[i] = std::log2(static_cast<double>(m[i]));
    length[i] = CorrelationLength(type);
  }
  const Eigen::MatrixXd sigma = sd.asDiagonal() * Correlation(log2m, length) * sd.asDiagonal();
  const Eigen::VectorXd weight = sd.array().square().inverse();
  const Eigen::MatrixXd wx = weight.asDiagonal() * x;
  const Mat3 h = x.transpose() * wx;
  int mask = 0;
  for (int j = 0; j < 3; ++j) mask |= coef(j) > 0 ? 1 << j : 0;
  Vec3 unused;
  Mat3 bread;
  if (k < 3 || mask == 0 || !SolveSubset(h, Vec3::Zero(), mask, &unused, &bread)) {
    return Mat3::Constant(kInf);
  }
  return bread * (wx.transpose() * sigma * wx) * bread;
}

// Shortest log (seconds, searched in steps of √2 from twice `duration`) in which term j at
// coefficient coef(j) would dominate somewhere and stand (min_significance + 1) standard errors
// above zero, i.e. be reported with probability ≈ 84 %; +inf when none up to 2^30 × duration.
double NeededDuration(const Vec3& coef, int j, double duration, double tau0,
                      const NoiseOptions& options) {
  if (!(coef(j) > 0)) return kInf;
  for (int step = 2; step <= 60; ++step) {
    const double length = duration * std::pow(2.0, step / 2.0);
    const int64_t n = static_cast<int64_t>(length / tau0);
    bool dominates[3];
    const Mat3 cov = ModelCovariance(coef, n, tau0, options, dominates);
    const double sd = std::sqrt(std::max(cov(j, j), 0.0));
    if (dominates[j] && coef(j) >= (options.min_significance + 1) * sd) return length;
  }
  return kInf;
}

// ----- Stationarity: windows' variances and the jumps of their means.
void CheckStationarity(const float* y, int64_t n, double tau0, const NoiseOptions& options,
                       NoiseStationarity* st) {
  const int64_t w = std::max<int64_t>(16, std::llround(options.stationarity_window / tau0));
  const int64_t windows = n / w;
  st->window_samples = w;
  st->windows = windows;
  if (windows < 8) return;  // checked = false
  st->checked = true;
  std::vector<double> mean(static_cast<size_t>(windows)), var(static_cast<size_t>(windows));
  for (int64_t j = 0; j < windows; ++j) {
    const float* p = y + j * w;
    double s = 0;
    for (int64_t i = 0; i < w; ++i) s += p[i];
    const double mu = s / static_cast<double>(w);
    double ss = 0;
    for (int64_t i = 0; i < w; ++i) ss += (p[i] - mu) * (p[i] - mu);
    mean[static_cast<size_t>(j)] = mu;
    var[static_cast<size_t>(j)] = ss / static_cast<double>(w - 1);
  }
  double reference = Median(var);
  if (!(reference > 0)) {
    double total = 0;
    for (double v : var) total += v;
    reference = total / static_cast<double>(windows);
  }
  st->max_variance_ratio = 0;
  if (reference > 0) {
    for (int64_t j = 0; j < windows; ++j) {
      const double ratio = var[static_cast<size_t>(j)] / reference;
      if (ratio > st->max_variance_ratio) {
        st->max_variance_ratio = ratio;
        st->max_variance_time = static_cast<double>(j * w) * tau0;
      }
    }
  }
  std::vector<double> jump(static_cast<size_t>(windows - 1));
  for (size_t j = 0; j + 1 < mean.size(); ++j) jump[j] = mean[j + 1] - mean[j];
  const double centre = Median(jump);
  std::vector<double> deviation(jump.size());
  for (size_t j = 0; j < jump.size(); ++j) deviation[j] = std::fabs(jump[j] - centre);
  const double spread =
      std::max(1.4826 * Median(deviation), std::sqrt(2 * reference / static_cast<double>(w)));
  st->max_jump_ratio = 0;
  if (spread > 0) {
    for (size_t j = 0; j < deviation.size(); ++j) {
      const double ratio = deviation[j] / spread;
      if (ratio > st->max_jump_ratio) {
        st->max_jump_ratio = ratio;
        st->max_jump_time = static_cast<double>((static_cast<int64_t>(j) + 1) * w) * tau0;
      }
    }
  }
  st->stationary = st->max_variance_ratio <= options.max_variance_ratio &&
                   st->max_jump_ratio <= options.max_jump_ratio;
}

// ----- One channel.
// `scale` (>= 1) multiplies the model's covariance (√(χ²/E χ²) when the residuals exceed the
// noise model, else 1): visibility, upper bounds and the primary σ use the scaled one, the
// model's own σ stays in NoiseTerm::crb_std.
void ReadTerms(const Fit& fit, const AllanCurve& curve, const NoiseOptions& options,
               double duration, double tau0, double scale, NoiseChannelResult* ch) {
  const Vec3& coef = fit.coef;
  Vec3 std_support, std_full;
  for (int j = 0; j < 3; ++j) {
    std_support(j) = scale * std::sqrt(std::max(fit.cov_support(j, j), 0.0));
    std_full(j) = scale * std::sqrt(std::max(fit.cov_full(j, j), 0.0));
    if (!std::isfinite(std_full(j))) std_full(j) = std_support(j);
  }
  // Which term dominates where, over the fitted points.
  bool dominates[3] = {false, false, false};
  double tau_min = kInf, tau_max = 0;
  for (size_t j = 0; j < curve.size(); ++j) {
    if (curve.cluster[j] < options.min_fit_cluster || !(curve.avar[j] > 0)) continue;
    tau_min = std::min(tau_min, curve.tau[j]);
    tau_max = std::max(tau_max, curve.tau[j]);
    dominates[static_cast<int>(fit.types[j])] = true;
  }
  NoiseTerm* terms[3] = {&ch->white_noise, &ch->bias_instability, &ch->random_walk};
  // value = g(coefficient): N = √a, B = √c / 0.664, K = √(3d).
  const double factor[3] = {1.0, 1 / kFloorFactor, std::sqrt(3.0)};
  for (int j = 0; j < 3; ++j) {
    NoiseTerm& t = *terms[j];
    t.coefficient = coef(j);
    t.coefficient_std = std_support(j) > 0 ? std_support(j) : std_full(j);
    const double upper = std::max(coef(j), 0.0) + 2 * std_full(j);
    t.upper_bound = factor[j] * std::sqrt(std::max(upper, 0.0));
    const bool significant =
        coef(j) > 0 && std_support(j) > 0 && coef(j) >= options.min_significance * std_support(j);
    if (dominates[j] && significant) {
      const double value = factor[j] * std::sqrt(coef(j));
      t.value = value;
      t.std = factor[j] * std_support(j) / (2 * std::sqrt(coef(j)));
      t.crb_std = *t.std / scale;
    }
  }
  const double a = coef(0), c = coef(1), d = coef(2);
  // Bias instability τ: the minimum of the fitted curve, within the fitted range.
  if (ch->bias_instability.value) {
    double tau = d > 0 ? std::sqrt(a / d) : tau_max;
    if (a <= 0) tau = tau_min;
    ch->bias_instability_tau = std::clamp(tau, tau_min, tau_max);
  }
  const std::string& unit = ch->unit;
  const std::string name = ch->name;
  // Not visible: the log length that would show it if it were at its 2σ upper bound, the other
  // terms as fitted (NeededDuration).
  auto with = [&coef](int j, double value) {
    Vec3 v = coef.cwiseMax(0.0);
    v(j) = value;
    return v;
  };
  if (!ch->random_walk.value) {
    NoiseTerm& t = ch->random_walk;
    t.needed =
        NeededDuration(with(2, t.upper_bound * t.upper_bound / 3), 2, duration, tau0, options);
    ch->warnings.push_back(name + ": random_walk not visible in this " + Duration(duration) +
                           " log (K < " + Sci(t.upper_bound) + " " + unit + "/s/√Hz at 2σ); " +
                           (std::isfinite(t.needed)
                                ? "a log of " + Duration(t.needed) +
                                      " would show it if K were at that bound, " +
                                      "a longer one if it is smaller"
                                : std::string("no log length would show it")));
  }
  if (!ch->bias_instability.value) {
    NoiseTerm& t = ch->bias_instability;
    t.needed = NeededDuration(with(1, std::pow(kFloorFactor * t.upper_bound, 2)), 1, duration, tau0,
                              options);
    ch->warnings.push_back(
        name + ": bias_instability not visible (B < " + Sci(t.upper_bound) + " " + unit +
        " at 2σ); " +
        (std::isfinite(t.needed)
             ? "a log of " + Duration(t.needed) + " would show it if B were at that bound"
             : std::string("white noise and random walk hide it at every τ, whatever the "
                           "length")));
  }
  if (!ch->white_noise.value) {
    NoiseTerm& t = ch->white_noise;
    const double au = t.upper_bound * t.upper_bound;
    double tau_x = kInf;
    if (c > 0) tau_x = std::min(tau_x, au / c);
    if (d > 0) tau_x = std::min(tau_x, std::sqrt(au / d));
    // Sample period at which the shortest fitted cluster reaches half of τ_x.
    t.needed = au > 0 ? tau_x / (2.0 * static_cast<double>(options.min_fit_cluster)) : 0;
    ch->warnings.push_back(name + ": white_noise not visible (N < " + Sci(t.upper_bound) + " " +
                           unit + "/√Hz at 2σ); " +
                           (t.needed > 0 && std::isfinite(t.needed)
                                ? "a sample rate of at least " + Format("%.3g", 1 / t.needed) +
                                      " Hz would show it if N were at that bound"
                                : std::string("no sample rate would show it")));
  }
}

Status AnalyseChannel(const NoiseChannelInput& in, int64_t n, double tau0,
                      const NoiseOptions& options, NoiseChannelResult* ch) {
  ch->name = in.name;
  ch->unit = in.unit;
  const float* y = in.data;
  long double total = 0;
  float lo = y[0], hi = y[0];
  for (int64_t i = 0; i < n; ++i) {
    if (!std::isfinite(y[i])) {
      return Status::InvalidInput(
          Reason::kInvalidRecording,
          "channel " + in.name + ": sample " + std::to_string(i) + " is not a finite number");
    }
    total += y[i];
    lo = std::min(lo, y[i]);
    hi = std::max(hi, y[i]);
  }
  ch->mean = static_cast<double>(total / static_cast<long double>(n));
  AllanOptions ao;
  ao.taus_per_decade = options.taus_per_decade;
  ao.confidence = options.confidence;
  ao.threads = options.threads;
  ao.executor = options.executor;
  ao.stop = options.stop;
  Status s = ComputeAllanDeviation(y, n, tau0, ao, &ch->allan);
  if (s.code() == StatusCode::kStopped) {
    return StoppedStatus(*options.stop, "noise: Allan deviation of channel " + in.name);
  }
  if (!s.ok()) return s;
  if (lo == hi) {
    ch->status = NoiseChannelStatus::kConstant;
    ch->reason =
        "every sample is " + Sci(lo) + " " + in.unit + ": a dead or saturated sensor has no noise";
    ch->warnings.push_back(ch->name + ": " + ch->reason);
    return Status::Ok();
  }
  CheckStationarity(y, n, tau0, options, &ch->stationarity);
  const Fit fit = FitModel(ch->allan, options.min_fit_cluster);
  SetAllanConfidence(fit.types, options.confidence, &ch->allan);
  ch->fit_chi2 = fit.chi2;
  ch->fit_points = 0;
  for (size_t j = 0; j < ch->allan.size(); ++j) {
    ch->fitted_adev.push_back(std::sqrt(std::max(fit.model[j], 0.0)));
    if (ch->allan.cluster[j] >= options.min_fit_cluster && ch->allan.avar[j] > 0) ++ch->fit_points;
  }
  // The σ convention (SPEC §4/§7, issue 28): the model's σ where χ² is within 3 standard
  // deviations of what the noise model predicts, else that σ × √(χ²/E χ²).
  ch->chi2_expected = fit.chi2_expected;
  ch->chi2_per_dof = fit.chi2 / fit.chi2_expected;
  double scale = 1;
  if (fit.chi2_expected > 0 &&
      fit.chi2 > fit.chi2_expected + kChi2Deviations * fit.chi2_expected_std) {
    scale = std::sqrt(ch->chi2_per_dof);
    ch->uncertainty_basis = "chi2_scaled";
  }
  ReadTerms(fit, ch->allan, options, static_cast<double>(n) * tau0, tau0, scale, ch);
  if (scale > 1) {
    ch->warnings.push_back(
        ch->name + ": the N/B/K model fits the Allan curve worse than its noise allows (χ² = " +
        Format("%.1f", fit.chi2) + " where " + Format("%.1f", fit.chi2_expected) + " ± " +
        Format("%.1f", fit.chi2_expected_std) + " is expected): the σ are scaled by " +
        Format("%.2f", scale) +
        "; look at the plot for quantisation, a sinusoid, a rate ramp or a correlated bump");
  }
  const NoiseStationarity& st = ch->stationarity;
  if (!st.checked) {
    ch->warnings.push_back(ch->name + ": stationarity not checked (fewer than 8 windows of " +
                           std::to_string(st.window_samples) + " samples)");
  } else if (!st.stationary) {
    ch->status = NoiseChannelStatus::kNotStationary;
    if (st.max_variance_ratio > options.max_variance_ratio) {
      ch->reason = "the sensor moved: the window at t = " + Format("%.1f", st.max_variance_time) +
                   " s has " + Format("%.0f", st.max_variance_ratio) +
                   " times the median window variance";
    } else {
      ch->reason = "the sensor moved: the mean jumps at t = " + Format("%.1f", st.max_jump_time) +
                   " s by " + Format("%.0f", st.max_jump_ratio) +
                   " times the spread of window means";
    }
    ch->reason += "; the Allan curve of a log that is not at rest is meaningless";
    return Status::Ok();
  }
  ch->status = NoiseChannelStatus::kOk;
  return Status::Ok();
}

Status Fail(Status s, NoiseResult* result) {
  result->usable = false;
  result->reason = s.message();
  return s;
}

}  // namespace

const char* NoiseChannelStatusName(NoiseChannelStatus status) {
  switch (status) {
    case NoiseChannelStatus::kNotRun:
      return "not_run";
    case NoiseChannelStatus::kOk:
      return "ok";
    case NoiseChannelStatus::kNotStationary:
      return "not_stationary";
    case NoiseChannelStatus::kConstant:
      return "constant";
  }
  return "?";
}

bool NoiseOptions::IsValid(std::string* error) const {
  auto fail = [error](const char* what) {
    if (error != nullptr) *error = what;
    return false;
  };
  const auto finite = [](double v) { return std::isfinite(v); };
  if (taus_per_decade < 0 || taus_per_decade > 100) {
    return fail("taus_per_decade must be between 0 (octaves) and 100");
  }
  if (!(confidence > 0 && confidence < 1)) return fail("confidence must be in (0, 1)");
  if (min_samples < 16) return fail("min_samples must be >= 16");
  if (min_fit_cluster < 1) return fail("min_fit_cluster must be >= 1");
  if (!(min_significance >= 0) || !finite(min_significance)) {
    return fail("min_significance must be a finite number >= 0");
  }
  if (sample_period && !(*sample_period > 0 && finite(*sample_period))) {
    return fail("sample_period must be a finite number > 0");
  }
  if (!(jitter_warning >= 0) || !(max_jitter >= jitter_warning) || !finite(max_jitter)) {
    return fail("jitter limits must satisfy 0 <= jitter_warning <= max_jitter (finite)");
  }
  if (!(stationarity_window > 0) || !finite(stationarity_window)) {
    return fail("stationarity_window must be a finite number > 0");
  }
  if (!(max_variance_ratio > 1) || !finite(max_variance_ratio)) {
    return fail("max_variance_ratio must be a finite number > 1");
  }
  if (!(max_jump_ratio > 1) || !finite(max_jump_ratio)) {
    return fail("max_jump_ratio must be a finite number > 1");
  }
  if (threads < 0) return fail("threads must be >= 0");
  return true;
}

std::string NoiseResult::BriefReport() const {
  std::string out = std::string(usable ? "usable" : "not usable: " + reason) + "; " +
                    std::to_string(samples) + " samples at " + Format("%.6g", rate) + " Hz (" +
                    Duration(duration) + ")\n";
  auto term = [](const NoiseTerm& t) {
    return t.value ? Sci(*t.value) + " ± " + Sci(t.std.value_or(kNaN)) : std::string("-");
  };
  for (const NoiseChannelResult& c : channels) {
    out += c.name + " [" + NoiseChannelStatusName(c.status) + "]: N " + term(c.white_noise) +
           ", B " + term(c.bias_instability) + ", K " + term(c.random_walk) + "\n";
  }
  return out;
}

Status EstimateNoise(const NoiseProblem& problem, const NoiseOptions& options,
                     NoiseResult* result) {
  *result = NoiseResult();
  std::string error;
  if (!options.IsValid(&error))
    return Fail(Status::InvalidInput(Reason::kInvalidConfig, "noise options: " + error), result);
  const int64_t n = problem.samples;
  result->samples = n;
  if (problem.channels.empty()) {
    return Fail(
        Status::InvalidInput(Reason::kInvalidRecording, "the log has no channel to analyse"),
        result);
  }
  for (const NoiseChannelInput& c : problem.channels) {
    if (c.data == nullptr && n > 0) {
      return Fail(
          Status::InvalidInput(Reason::kInvalidRecording, "channel " + c.name + " has no data"),
          result);
    }
  }
  if (n < options.min_samples) {
    return Fail(Status::NotDeterminable(
                    Reason::kLogTooShort,
                    "the log has " + std::to_string(n) +
                        " samples; the noise method needs at "
                        "least " +
                        std::to_string(options.min_samples) +
                        " (the longest cluster time is a quarter of the log): record the sensor at "
                        "rest for an hour or more"),
                result);
  }
  // Sample period: median Δt of the timestamps, or the configured period.
  double tau0 = options.sample_period.value_or(kNaN);
  if (problem.times != nullptr) {
    const double* t = problem.times;
    std::vector<double> dt(static_cast<size_t>(n - 1));
    for (int64_t i = 0; i < n; ++i) {
      if ((i & 0xFFFF) == 0 && StopRequested(options.stop)) {  // ~0.1 ms of work between polls
        return Fail(StoppedStatus(*options.stop, "noise: sample times"), result);
      }
      if (!std::isfinite(t[i])) {
        return Fail(Status::InvalidInput(
                        Reason::kInvalidRecording,
                        "timestamp of sample " + std::to_string(i) + " is not a finite number"),
                    result);
      }
      if (i > 0) {
        if (!(t[i] > t[i - 1])) {
          return Fail(Status::InvalidInput(
                          Reason::kInvalidRecording,
                          "timestamps must be strictly increasing: sample " + std::to_string(i) +
                              " (t = " + Format("%.9g", t[i]) +
                              " s) does not follow t = " + Format("%.9g", t[i - 1]) + " s"),
                      result);
        }
        dt[static_cast<size_t>(i - 1)] = t[i] - t[i - 1];
      }
    }
    tau0 = Median(std::move(dt));  // no copy: one double per sample at a time
    double worst = 0;
    int64_t worst_index = 1;
    if (StopRequested(options.stop)) {  // after the median (one nth_element over n values)
      return Fail(StoppedStatus(*options.stop, "noise: sample times"), result);
    }
    for (int64_t i = 1; i < n; ++i) {
      const double jitter = std::fabs(t[i] - t[i - 1] - tau0) / tau0;
      if (jitter > worst) {
        worst = jitter;
        worst_index = i;
      }
    }
    result->timestamps = true;
    result->jitter = worst;
    result->jitter_index = worst_index;
    const double dt_worst = t[worst_index] - t[worst_index - 1];
    const std::string where = "sample " + std::to_string(worst_index) +
                              " (t = " + Format("%.6g", t[worst_index]) + " s) comes " +
                              Format("%.4g", dt_worst * 1e3) +
                              " ms after the previous one, the "
                              "median interval is " +
                              Format("%.4g", tau0 * 1e3) + " ms";
    if (worst > options.max_jitter) {
      result->rate = 1 / tau0;
      result->sample_period = tau0;
      return Fail(
          Status::NotDeterminable(
              noise_reason::kIrregularSampling,
              "irregular sample times: " + where + " (jitter " + Format("%.0f", 100 * worst) +
                  "% of the period, at most " + Format("%.0f", 100 * options.max_jitter) +
                  "% is accepted); the Allan deviation needs uniform sampling: split the log "
                  "at gaps or resample it"),
          result);
    }
    if (worst > options.jitter_warning) {
      result->warnings.push_back("timestamps jitter by up to " + Format("%.1f", 100 * worst) +
                                 "% of the sample period (" + where +
                                 "); the analysis assumes the samples are uniformly spaced");
    }
  } else if (!options.sample_period) {
    return Fail(Status::InvalidInput(Reason::kInvalidConfig,
                                     "no timestamps and no sample_period: the rate is unknown"),
                result);
  }
  result->sample_period = tau0;
  result->rate = 1 / tau0;
  result->duration = static_cast<double>(n) * tau0;

  // Channels one at a time, so that one cumulative sum (8 bytes a sample) is held at a time;
  // each channel's Allan variance runs on the threads (bit-identical for any number).
  const size_t count = problem.channels.size();
  result->channels.resize(count);
  for (size_t c = 0; c < count; ++c) {
    if (StopRequested(options.stop)) {
      return Fail(StoppedStatus(*options.stop, "noise: channel " + problem.channels[c].name),
                  result);
    }
    Status s = AnalyseChannel(problem.channels[c], n, tau0, options, &result->channels[c]);
    if (!s.ok()) return Fail(s, result);
  }
  result->stationary = true;
  std::string moved;
  for (const NoiseChannelResult& c : result->channels) {
    result->warnings.insert(result->warnings.end(), c.warnings.begin(), c.warnings.end());
    if (c.status == NoiseChannelStatus::kNotStationary) {
      result->stationary = false;
      if (moved.empty()) moved = c.name + ": " + c.reason;
    }
  }
  if (!result->stationary) {
    return Fail(Status::NotDeterminable(noise_reason::kNotStationary,
                                        "the log is not stationary (" + moved +
                                            "); record the sensor at rest, untouched"),
                result);
  }
  result->usable = true;
  return Status::Ok();
}

}  // namespace calibd::core
