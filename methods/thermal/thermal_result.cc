// The thermal result JSON (methods/thermal/thermal_method.h) of a core::ThermalResult.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>

#include "methods/thermal/thermal_method.h"

namespace calibd::server {

using nlohmann::json;

namespace {

json Vec(const Eigen::VectorXd& v) {
  json out = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) out.push_back(v(i));
  return out;
}

json Mat(const Eigen::MatrixXd& m) {
  json out = json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) out.push_back(Vec(m.row(r).transpose()));
  return out;
}

// The accelerometer's scale curves (core stage 2b: the gain's relative change d(T), reading's
// gravity part × (1 + d)), per axis null where not estimated with the reason; all null when no
// axis has one.
void AccelerometerScale(const core::ThermalImuResult& imu, json* params, json* unc, json* crb) {
  json coefficients = json::array(), orders = json::array(), reasons = json::array(),
       cov = json::array(), std = json::array(), crb_cov = json::array(), crb_std = json::array();
  int order = 0;
  bool any = false;
  for (int a = 0; a < 3; ++a) {
    const core::ThermalChannel& ch = imu.channels[static_cast<size_t>(a)];
    if (!ch.scale_estimated) {
      for (json* j : {&coefficients, &orders, &cov, &std, &crb_cov, &crb_std})
        j->push_back(nullptr);
      reasons.push_back(ch.scale_reason);
      continue;
    }
    any = true;
    order = std::max(order, ch.fit.order);
    orders.push_back(ch.fit.order);
    coefficients.push_back(Vec(ch.fit.scale_coefficients));
    reasons.push_back(nullptr);
    cov.push_back(Mat(ch.fit.scale_covariance));
    std.push_back(Vec(ch.grid_scale_std));
    crb_cov.push_back(Mat(ch.fit.scale_crb));
    crb_std.push_back(Vec(ch.grid_scale_crb_std));
  }
  if (!any) return;
  *params = {{"order", order},
             {"orders", orders},
             {"coefficients", coefficients},
             {"not_estimated", reasons}};
  *unc = {{"covariance", cov}, {"temperatures", Vec(imu.grid)}, {"std", std}};
  *crb = {{"covariance", crb_cov}, {"temperatures", Vec(imu.grid)}, {"std", crb_std}};
}

// One sensor's (accelerometer: channels 0..2, gyroscope: 3..5) bias parameters and uncertainty.
void SensorBias(const core::ThermalImuResult& imu, int first, bool gyro, json* params, json* unc,
                json* crb) {
  json coefficients = json::array(), orders = json::array(), cov = json::array(),
       std = json::array(), crb_cov = json::array(), crb_std = json::array();
  int order = 0;
  for (int a = 0; a < 3; ++a) {
    const core::ThermalChannel& ch = imu.channels[static_cast<size_t>(first + a)];
    order = std::max(order, ch.fit.order);
    orders.push_back(ch.fit.order);
    coefficients.push_back(Vec(ch.fit.coefficients));
    cov.push_back(Mat(ch.fit.covariance));
    std.push_back(Vec(ch.grid_std));
    crb_cov.push_back(Mat(ch.fit.crb));
    crb_std.push_back(Vec(ch.grid_crb_std));
  }
  json at = nullptr, at_std = nullptr;
  if (gyro && imu.gyro_at_t_ref) {
    at = Vec(*imu.gyro_at_t_ref);
    at_std = Vec(*imu.gyro_at_t_ref_std);
  }
  if (!gyro && imu.accel_at_t_ref != std::array<std::optional<double>, 3>{}) {
    at = json::array();  // per axis; null where the orientations do not determine it
    at_std = json::array();
    for (int a = 0; a < 3; ++a) {
      const size_t i = static_cast<size_t>(a);
      at.push_back(imu.accel_at_t_ref[i] ? json(*imu.accel_at_t_ref[i]) : json(nullptr));
      at_std.push_back(imu.accel_at_t_ref_std[i] ? json(*imu.accel_at_t_ref_std[i])
                                                 : json(nullptr));
    }
  }
  json scale = nullptr, scale_unc = nullptr, scale_crb = nullptr;
  if (!gyro) AccelerometerScale(imu, &scale, &scale_unc, &scale_crb);
  *params = {
      {"bias",
       {{"order", order}, {"orders", orders}, {"coefficients", coefficients}, {"at_t_ref", at}}},
      {"scale", scale}};
  *unc = {{"bias",
           {{"covariance", cov},
            {"temperatures", Vec(imu.grid)},
            {"std", std},
            {"at_t_ref_std", at_std}}},
          {"scale", scale_unc}};
  *crb = {{"bias", {{"covariance", crb_cov}, {"temperatures", Vec(imu.grid)}, {"std", crb_std}}},
          {"scale", scale_crb}};
}

json ChannelDiagnostics(const core::ThermalImuResult& imu, int c) {
  const core::ThermalChannel& ch = imu.channels[static_cast<size_t>(c)];
  json table = json::array();
  for (const core::ThermalOrderRow& row : ch.fit.table) {
    table.push_back({{"order", row.order},
                     {"chi2", row.chi2},
                     {"bic", row.bic},
                     {"weight", row.weight},
                     {"band_weight", row.band_weight}});
  }
  // The window means as deviations from the curve's value at t_ref (their orientation's
  // intercept removed), for the report's plot.
  json temps = json::array(), dev = json::array(), sd = json::array(), phase = json::array();
  for (const core::ThermalWindow& w : imu.windows) {
    const int group = c < 3 ? w.orientation : 0;
    // The intercepts are indexed by the dense groups of the fit, which follow the first
    // appearance of each orientation in time order, as the orientation indices do.
    const double intercept =
        group < ch.fit.intercepts.size() ? ch.fit.intercepts(group) : ch.fit.intercepts(0);
    temps.push_back(w.temperature);
    dev.push_back(w.mean(c) - intercept);
    sd.push_back(w.mean_std(c));
    phase.push_back(w.phase);
  }
  json hysteresis = {{"tested", ch.hysteresis_tested}};
  if (ch.hysteresis_tested) {
    hysteresis["temperatures"] = Vec(ch.hysteresis_temperatures);
    hysteresis["difference"] = Vec(ch.hysteresis_difference);
    hysteresis["z"] = Vec(ch.hysteresis_z);
    hysteresis["max_abs_z"] = ch.max_abs_z;
    hysteresis["flagged"] = ch.hysteresis_flagged;
  }
  return {{"name", ch.name},
          {"order", ch.fit.order},
          {"basis", ch.fit.basis},
          {"chi2_per_dof", ch.fit.dof > 0 ? json(ch.fit.chi2 / ch.fit.dof) : json(nullptr)},
          {"dof", ch.fit.dof},
          {"residual_rms", ch.fit.residual_rms},
          {"noise_rms", ch.fit.noise_rms},
          {"order_table", table},
          {"points", {{"temperature", temps}, {"deviation", dev}, {"std", sd}, {"phase", phase}}},
          {"curve", Vec(ch.grid_value)},
          {"hysteresis", hysteresis}};
}

json ImuDiagnostics(const core::ThermalImuResult& imu) {
  json windows = json::array(), channels = json::array();
  double rate_min = std::numeric_limits<double>::infinity(), rate_max = -rate_min;
  for (const core::ThermalWindow& w : imu.windows) {
    windows.push_back({{"start", w.start},
                       {"end", w.end},
                       {"samples", w.samples},
                       {"temperature", w.temperature},
                       {"rate", w.rate},
                       {"phase", w.phase > 0 ? "heating" : (w.phase < 0 ? "cooling" : "steady")},
                       {"orientation", w.orientation}});
    rate_min = std::min(rate_min, w.rate);
    rate_max = std::max(rate_max, w.rate);
  }
  for (int c = 0; c < 6; ++c) channels.push_back(ChannelDiagnostics(imu, c));
  json lag = {{"mode", imu.lag_std ? "estimate" : (imu.lag ? "fixed" : "none")},
              {"tau", imu.lag ? json(*imu.lag) : json(nullptr)}};
  if (imu.lag_std) {
    lag["profile"] = {{"tau", Vec(imu.lag_grid)},
                      {"minus_2_log_likelihood", Vec(imu.lag_profile)},
                      {"about",
                       "sum over the channels of n ln chi2 at each tau, relative to its minimum "
                       "(highest order offered)"}};
  }
  return {{"name", imu.name},
          {"statics", imu.statics.intervals.size()},
          {"windows", windows},
          {"orientations", imu.orientations},
          {"heating_windows", imu.heating_windows},
          {"cooling_windows", imu.cooling_windows},
          {"temperature_rate", {{"min", rate_min}, {"max", rate_max}, {"unit", "degC/s"}}},
          {"hysteresis_critical_z", imu.hysteresis_threshold_z},
          {"lag", lag},
          {"channels", channels}};
}

}  // namespace

json ThermalResultToJson(const core::ThermalResult& r, const core::ThermalOptions& options) {
  json p_imus = json::array(), u_imus = json::array(), d_imus = json::array();
  bool scaled = false;
  double worst = 1;
  for (const core::ThermalImuResult& imu : r.imus) {
    json pa, ua, ca, pg, ug, cg;
    SensorBias(imu, 0, false, &pa, &ua, &ca);
    SensorBias(imu, 3, true, &pg, &ug, &cg);
    p_imus.push_back({{"name", imu.name},
                      {"t_ref", imu.t_ref},
                      {"t_min", imu.t_min},
                      {"t_max", imu.t_max},
                      {"lag", imu.lag ? json(*imu.lag) : json(nullptr)},
                      {"accelerometer", pa},
                      {"gyroscope", pg}});
    const auto opt = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
    u_imus.push_back(
        {{"name", imu.name},
         {"lag_std", opt(imu.lag_std)},
         {"accelerometer", ua},
         {"gyroscope", ug},
         {"crb", {{"lag_std", opt(imu.lag_crb_std)}, {"accelerometer", ca}, {"gyroscope", cg}}}});
    d_imus.push_back(ImuDiagnostics(imu));
    for (const core::ThermalChannel& ch : imu.channels) {
      if (ch.fit.basis == "chi2_scaled") {
        scaled = true;
        worst = std::max(worst, ch.fit.chi2 / ch.fit.dof);
      }
    }
  }
  json warnings = r.warnings;
  if (scaled) {
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "σ is the χ²-scaled bound, up to %.2g× the white-noise bound: the window means "
                  "scatter more than their own noise (χ²/dof up to %.3g; see "
                  "diagnostics.imus[].channels[].basis)",
                  std::sqrt(worst), worst);
    warnings.push_back(buf);
  }
  return {
      {"method", "thermal"},
      {"model",
       "per IMU and axis, bias(T) = bias(t_ref) + sum_k c_k (T - t_ref)^k, T in degC clamped to "
       "[t_min, t_max]; corrected reading = reading - (bias(T) - bias(t_ref)) in the sensor frame, "
       "before the room-temperature calibration; where accelerometer.scale is given, the reading's "
       "gravity part is (1 + sum_k d_k (T - t_ref)^k) times its value at t_ref (divide it out)"},
      {"parameters", {{"imus", p_imus}}},
      {"uncertainty",
       {{"basis", scaled ? "chi2_scaled" : "crb"}, {"chi2_per_dof", nullptr}, {"imus", u_imus}}},
      {"diagnostics",
       {{"order_selection",
         "curves of orders " + std::to_string(std::min(options.min_order, options.max_order)) +
             ".." + std::to_string(options.max_order) +
             " (min_order..max_order, fewer where the windows leave no residual degree of "
             "freedom) averaged with BIC weights exp(-BIC/2), BIC = n ln(chi2/n) + k ln N (n "
             "windows, N the samples they average, noise scale estimated): "
             "order_table[].weight; the band mixes the orders with the weights of the penalty k "
             "ln n: order_table[].band_weight"},
        {"hysteresis_test",
         {{"method",
           "heating and cooling windows fitted apart at the curve's order; |z| of their difference "
           "on a grid over the common range against the Bonferroni bound over 6 channels x grid "
           "points (family-wise false-alarm rate at most alpha per IMU)"},
          {"alpha", options.hysteresis_alpha},
          {"grid_points", options.grid_points}}},
        {"window", options.window},
        {"imus", d_imus}}},
      {"warnings", warnings}};
}

}  // namespace calibd::server
