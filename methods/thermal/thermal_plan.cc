// The plan of a thermal calibration (SPEC §10, Method::Plan; methods/thermal/thermal_method.h):
// the σ CalibrateThermal would report for a warm-up at rest from t_min to t_max °C at
// temperature_rate °C/min, what it cannot determine, and the shortest warm-up meeting the gate's
// band limits.
//
// Predicted σ: the averaging windows the method cuts from the warm-up (core/thermal.cc
// CutWindows: windows of `window` s, the remainder joining the last one when shorter than half a
// window; one static per orientation, each held for an equal part of the ramp), each window's
// temperature the ramp's mean over it and its mean's σ = noise/√n (the config's accel_noise,
// gyro_noise per sample); then the method's own weighted least squares (core::
// FitThermalPolynomial) at the floor order the method offers first (min_order, capped as the
// method caps it), on noise-free means: its crb is the covariance of the curve coefficients and
// √(vᵀ C v) the 1σ band on the method's grid. When the data favour orders above the floor, the
// method's BIC-weighted average widens the band towards the one at max_order (reported as
// `orders.band_std_at_max_order`); when the truth is of the floor's order, the floor's weight
// tends to 1 with the windows. Tested against calibrations of simulated ramps
// (tests/server/thermal_plan_test.cc).
//
// Undetermined: the bias curves when the range is below min_range (the method refuses it); the
// scale curves always: the method fits a scale curve only from opposite faces held over a common
// span of temperatures (+z warming, −z cooling), and one warm-up holds each face over its own part;
// τ with lag "estimate" (a single warm-up passes each temperature once).
//
// Suggested: the protocol's range (widened to min_range when below) at the fastest
// temperature_rate whose band meets max_accel_band_std and max_gyro_band_std (bisection on
// log rate: the band grows with the rate, as the windows get fewer), i.e. the shortest warm-up.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "methods/thermal/thermal_method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

constexpr double kSlowestRate = 0.01;  // °C/min: the slowest warm-up a suggestion considers

std::string Fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

// A warm-up protocol: range, ramp, sample rate, orientations held in turn.
struct Ramp {
  double t_min = 0, t_max = 0;
  double temperature_rate = 1;  // °C/min
  double rate = 100;            // Hz
  int orientations = 1;
  double duration() const { return (t_max - t_min) / temperature_rate * 60; }
};

// The windows of core/thermal.cc CutWindows on the ramp: per window its samples, its mean
// temperature and its orientation group.
struct PlannedWindows {
  Eigen::VectorXd temperature, samples;
  std::vector<int> group;
};

PlannedWindows CutRamp(const Ramp& ramp, double window) {
  PlannedWindows w;
  std::vector<double> temps, counts;
  const double ramp_per_s = ramp.temperature_rate / 60;
  const int64_t total = std::llround(ramp.duration() * ramp.rate);
  const int64_t per = std::max<int64_t>(3, std::llround(window * ramp.rate));
  for (int k = 0; k < ramp.orientations; ++k) {
    const int64_t first = total * k / ramp.orientations;
    const int64_t samples = total * (k + 1) / ramp.orientations - first;
    const int64_t count = std::max<int64_t>(1, (samples + per / 2) / per);
    for (int64_t j = 0; j < count; ++j) {
      const int64_t a = first + j * per;
      const int64_t b = j + 1 == count ? first + samples - 1 : a + per - 1;
      if (b - a + 1 < 3) continue;
      temps.push_back(ramp.t_min + ramp_per_s * 0.5 * static_cast<double>(a + b) / ramp.rate);
      counts.push_back(static_cast<double>(b - a + 1));
      w.group.push_back(k);
    }
  }
  w.temperature =
      Eigen::Map<Eigen::VectorXd>(temps.data(), static_cast<Eigen::Index>(temps.size()));
  w.samples = Eigen::Map<Eigen::VectorXd>(counts.data(), static_cast<Eigen::Index>(counts.size()));
  return w;
}

// One sensor's predicted curve: coefficient covariance and band on the grid.
struct SensorPrediction {
  Eigen::MatrixXd covariance;
  Eigen::VectorXd band;       // 1σ on the grid, floor order
  double worst_band = 0;      // its largest value
  double worst_band_top = 0;  // the same at max_order (where the windows allow it)
  double intercept_std = 0;   // σ of the first group's intercept (gyroscope: at t_ref)
};

struct Prediction {
  double t_lo = 0, t_hi = 0, t_ref = 0;
  Eigen::VectorXd grid;
  int floor_order = 0, top_order = 0;
  std::array<SensorPrediction, 6> channels;  // ax ay az gx gy gz
  // The largest band (at the floor order, at max_order) of the accelerometer's (first = 0) or
  // the gyroscope's (3) axes.
  double WorstBand(int first) const {
    return std::max({channels[first].worst_band, channels[first + 1].worst_band,
                     channels[first + 2].worst_band});
  }
  double WorstBandTop(int first) const {
    return std::max({channels[first].worst_band_top, channels[first + 1].worst_band_top,
                     channels[first + 2].worst_band_top});
  }
};

// The curve's crb of one channel at orders [lowest, lowest] and [top, top], each window's mean
// with σ `sigma`.
Status PredictSensor(const PlannedWindows& w, const Eigen::VectorXd& sigma, const Prediction& p,
                     int groups, int lowest, int top, SensorPrediction* out) {
  const Eigen::VectorXd x = w.temperature.array() - p.t_ref;
  const Eigen::VectorXd y = Eigen::VectorXd::Zero(x.size());
  const double scale = 0.5 * (p.t_hi - p.t_lo);
  core::ThermalPolyFit fit;
  Status s =
      core::FitThermalPolynomial(x, y, sigma, w.group, groups, lowest, lowest, scale, 0, &fit);
  if (!s.ok()) return s;
  out->covariance = fit.crb;
  out->intercept_std = fit.intercept_std;
  out->band.resize(p.grid.size());
  for (Eigen::Index i = 0; i < p.grid.size(); ++i) {
    out->band(i) = core::ThermalCurveStd(fit.crb, p.grid(i) - p.t_ref);
  }
  out->worst_band = out->band.maxCoeff();
  out->worst_band_top = out->worst_band;
  if (top > lowest &&
      core::FitThermalPolynomial(x, y, sigma, w.group, groups, top, top, scale, 0, &fit).ok()) {
    for (Eigen::Index i = 0; i < p.grid.size(); ++i) {
      out->worst_band_top =
          std::max(out->worst_band_top, core::ThermalCurveStd(fit.crb, p.grid(i) - p.t_ref));
    }
  }
  return Status::Ok();
}

// The prediction for windows `w` (accelerometer groups: w.group, `groups` of them), each window
// mean's σ per channel sigma(c) (windows × 6); kNotDeterminable naming the range (below
// min_range) or the windows (too few for a curve).
Status PredictWindows(const core::ThermalOptions& options, const PlannedWindows& w, int groups,
                      const Eigen::MatrixXd& sigma, Prediction* p) {
  if (w.temperature.size() == 0) {
    return Status::NotDeterminable("the warm-up holds no averaging window of " +
                                   Fmt(options.window) + " s");
  }
  p->t_lo = w.temperature.minCoeff();
  p->t_hi = w.temperature.maxCoeff();
  if (p->t_hi - p->t_lo < options.min_range) {
    return Status::NotDeterminable("the windows span " + Fmt(p->t_hi - p->t_lo) + " °C (" +
                                   Fmt(p->t_lo) + " to " + Fmt(p->t_hi) + " °C), below min_range " +
                                   Fmt(options.min_range) + " °C");
  }
  p->t_ref = options.t_ref.value_or(0.5 * (p->t_lo + p->t_hi));
  p->grid.resize(options.grid_points);
  for (int i = 0; i < options.grid_points; ++i) {
    p->grid(i) = p->t_lo + (p->t_hi - p->t_lo) * i / (options.grid_points - 1);
  }
  const int m = static_cast<int>(w.temperature.size());
  for (int c = 0; c < 6; ++c) {
    const bool accel = c < 3;
    const int g = accel ? groups : 1;
    PlannedWindows windows = w;
    if (!accel) std::fill(windows.group.begin(), windows.group.end(), 0);
    const int lowest = std::max(0, std::min({options.min_order, options.max_order, m - g - 1}));
    const int top = std::max(lowest, std::min(options.max_order, m - g - 1));
    if (c == 0) p->floor_order = lowest, p->top_order = top;
    Status s = PredictSensor(windows, sigma.col(c), *p, g, lowest, top,
                             &p->channels[static_cast<size_t>(c)]);
    if (!s.ok()) {
      return Status::NotDeterminable(std::to_string(m) + " averaging windows are too few for a " +
                                     (accel ? "accelerometer" : "gyroscope") +
                                     " curve: " + s.message());
    }
  }
  return Status::Ok();
}

// The prediction of a ramp: its windows with σ = noise/√n.
Status Predict(const core::ThermalOptions& options, const Ramp& ramp, Prediction* p) {
  const PlannedWindows w = CutRamp(ramp, options.window);
  Eigen::MatrixXd sigma(w.temperature.size(), 6);
  for (int c = 0; c < 6; ++c) {
    sigma.col(c) = (c < 3 ? *options.accel_noise : *options.gyro_noise) / w.samples.array().sqrt();
  }
  return PredictWindows(options, w, ramp.orientations, sigma, p);
}

json Vec(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

json Mat(const Eigen::MatrixXd& m) {
  json out = json::array();
  for (Eigen::Index r = 0; r < m.rows(); ++r) out.push_back(Vec(m.row(r).transpose()));
  return out;
}

// One IMU's entry of the result's uncertainty shape (methods/thermal/thermal_result.cc).
json UncertaintyImuJson(const Prediction& p, const std::string& name) {
  const auto sensor = [&p](int first) {
    json cov = json::array(), std = json::array(), at = json::array();
    for (int a = 0; a < 3; ++a) {
      const SensorPrediction& s = p.channels[static_cast<size_t>(first + a)];
      cov.push_back(Mat(s.covariance));
      std.push_back(Vec(s.band));
      at.push_back(s.intercept_std);
    }
    return json{{"bias",
                 {{"covariance", cov},
                  {"temperatures", Vec(p.grid)},
                  {"std", std},
                  {"at_t_ref_std", first == 3 ? at : json(nullptr)}}},
                {"scale", nullptr}};
  };
  return {
      {"name", name}, {"lag_std", nullptr}, {"accelerometer", sensor(0)}, {"gyroscope", sensor(3)}};
}

// The result's uncertainty shape for `imus` equal IMUs.
json UncertaintyJson(const Prediction& p, int imus) {
  json list = json::array();
  for (int i = 0; i < imus; ++i) list.push_back(UncertaintyImuJson(p, std::to_string(i)));
  return {{"basis", "crb"}, {"chi2_per_dof", nullptr}, {"imus", list}};
}

// The band limits the prediction fails (empty: it meets them).
std::vector<std::string> Unmet(const Prediction& p, const AcceptanceLimits& limits) {
  std::vector<std::string> unmet;
  const auto a = limits.Get("max_accel_band_std"), g = limits.Get("max_gyro_band_std");
  if (a && p.WorstBand(0) > *a) {
    unmet.push_back("accelerometer band " + Fmt(p.WorstBand(0)) + " m/s² above " +
                    "max_accel_band_std " + Fmt(*a));
  }
  if (g && p.WorstBand(3) > *g) {
    unmet.push_back("gyroscope band " + Fmt(p.WorstBand(3)) + " rad/s above " +
                    "max_gyro_band_std " + Fmt(*g));
  }
  return unmet;
}

json RampJson(const Ramp& r) {
  return {{"t_min", r.t_min},
          {"t_max", r.t_max},
          {"temperature_rate", r.temperature_rate},
          {"duration", r.duration()},
          {"rate", r.rate}};
}

// The ramp at `rate` °C/min, its range widened where the windows would span less than
// min_range (the windows' midpoints span the range less a window's worth of temperature).
Ramp AtRate(const core::ThermalOptions& options, Ramp ramp, double rate) {
  ramp.temperature_rate = rate;
  const double needed = options.min_range + 1.01 * options.window * rate / 60;
  ramp.t_max = std::max(ramp.t_max, ramp.t_min + needed);
  return ramp;
}

// The protocol's range (widened as AtRate) at the fastest rate meeting the band limits.
json Suggest(const core::ThermalOptions& options, const Ramp& protocol,
             const AcceptanceLimits& limits, int imus) {
  const auto meets = [&](double rate) {
    Prediction p;
    return Predict(options, AtRate(options, protocol, rate), &p).ok() && Unmet(p, limits).empty();
  };
  double rate = PlanProtocol::kMaxTemperatureRate;
  if (!meets(rate) && meets(kSlowestRate)) {
    double fast = rate, slow = kSlowestRate;  // invariant: slow meets, fast does not
    for (int i = 0; i < 40 && fast / slow > 1.001; ++i) {
      const double mid = std::sqrt(fast * slow);
      (meets(mid) ? slow : fast) = mid;
    }
    rate = slow;
  } else if (!meets(rate)) {
    rate = kSlowestRate;
  }
  const Ramp ramp = AtRate(options, protocol, rate);
  Prediction p;
  const bool predicted = Predict(options, ramp, &p).ok();
  json out = RampJson(ramp);
  out["design"] =
      "the protocol's range (at least min_range, with a window's worth of margin at the fastest "
      "rate) at the fastest temperature_rate whose 1σ band meets max_accel_band_std and "
      "max_gyro_band_std (bisection on log rate in [" +
      Fmt(kSlowestRate) + ", " + Fmt(PlanProtocol::kMaxTemperatureRate) +
      "] °C/min): the shortest warm-up";
  out["meets_limits"] = predicted && Unmet(p, limits).empty();
  out["unmet"] =
      predicted ? Unmet(p, limits) : std::vector<std::string>{"the slowest rate gives no curve"};
  out["uncertainty"] = predicted ? UncertaintyJson(p, imus) : json();
  return out;
}

}  // namespace

Status PlanThermal(const core::ThermalOptions& options, const PlanProtocol& protocol,
                   const AcceptanceLimits& limits, json* out) {
  if (!protocol.t_min) {
    return Status::InvalidInput(
               "protocol.t_min: a thermal plan needs the warm-up's range t_min, t_max (°C) and "
               "its temperature_rate (°C/min)")
        .WithField("protocol.t_min");
  }
  for (const auto& [key, value] :
       {std::pair<const char*, const std::optional<double>*>{"accel_noise", &options.accel_noise},
        {"gyro_noise", &options.gyro_noise}}) {
    if (!*value) {
      return Status::InvalidInput(std::string("config.") + key +
                                  ": the plan needs the white noise per sample (a number in the "
                                  "reading units, or {\"job\": ID} of a noise job)")
          .WithField(std::string("config.") + key);
    }
  }
  Ramp ramp{*protocol.t_min, *protocol.t_max, protocol.temperature_rate, protocol.rate,
            std::max<int>(1, static_cast<int>(protocol.orientations.size()))};
  json& o = *out;
  o = {{"method", "thermal"},
       {"protocol", RampJson(ramp)},
       {"undetermined", json::array()},
       {"notes",
        {"σ is the white-noise bound of the method's weighted least squares on the averaging "
         "windows of this warm-up (each window's mean σ = noise/√n), at the floor order the "
         "method offers first; when the data favour higher orders the method's BIC-weighted "
         "average widens the band towards orders.band_std_at_max_order"}}};
  o["protocol"]["imus"] = protocol.imus;
  o["protocol"]["orientations"] = OrientationsJson(protocol.orientations, protocol.labels);
  Prediction p;
  const Status s = Predict(options, ramp, &p);
  if (s.ok()) {
    o["uncertainty"] = UncertaintyJson(p, protocol.imus);
    o["orders"] = {{"planned", p.floor_order},
                   {"max", p.top_order},
                   {"band_std_at_max_order",
                    {{"accelerometer", p.WorstBandTop(0)}, {"gyroscope", p.WorstBandTop(3)}}}};
  } else {
    o["uncertainty"] = nullptr;
    o["undetermined"].push_back(
        {{"parameters", {"imus[].accelerometer.bias", "imus[].gyroscope.bias"}},
         {"missing", {s.message()}}});
  }
  // A single ramp holds each face over its own part of the range; the method's scale stage needs
  // opposite faces over a common span (core/thermal.h stage 2b), i.e. a warm-up and a cool-down.
  std::vector<std::string> scale_missing = {
      "opposite faces (+a and −a of each axis) held over a common span of at least min_range, "
      "e.g. +z through a warm-up and −z through a cool-down; a single warm-up holds each face "
      "over its own part of the range"};
  if (ramp.orientations < 2) {
    scale_missing.push_back(
        "one orientation: a scale curve needs the field along each axis in turn, both ways");
  }
  o["undetermined"].push_back(
      {{"parameters", {"imus[].accelerometer.scale"}}, {"missing", scale_missing}});
  o["undetermined"].push_back(
      {{"parameters", {"imus[].gyroscope.scale"}},
       {"missing",
        {"a rate input: at rest a gyroscope sees only the Earth's rate (7.3e-5 rad/s), so the "
         "method never estimates its scale curves"}}});
  if (options.lag == core::ThermalLagMode::kEstimate) {
    o["undetermined"].push_back(
        {{"parameters", {"imus[].lag"}},
         {"missing",
          {"a cool-down over the warm-up's range: a single warm-up passes each temperature once, "
           "so a lag cannot be told from another curve"}}});
  }
  if (options.lag == core::ThermalLagMode::kFixed) {
    o["notes"].push_back(
        "a known lag shifts the windows' temperatures by about τ × the rate; "
        "the σ is planned on the reading's temperatures");
  }
  o["suggested"] = Suggest(options, ramp, limits, protocol.imus);
  return Status::Ok();
}

json PredictThermalWindows(const core::ThermalOptions& options,
                           const core::ThermalImuResult& found) {
  PlannedWindows w;
  const auto m = static_cast<Eigen::Index>(found.windows.size());
  w.temperature.resize(m);
  w.samples.resize(m);
  Eigen::MatrixXd sigma(m, 6);
  int groups = 1;
  for (Eigen::Index i = 0; i < m; ++i) {
    const core::ThermalWindow& window = found.windows[static_cast<size_t>(i)];
    w.temperature(i) = window.temperature;
    w.samples(i) = static_cast<double>(window.samples);
    w.group.push_back(window.orientation);
    groups = std::max(groups, window.orientation + 1);
    sigma.row(i) = window.mean_std.transpose();
  }
  Prediction p;
  const Status s = PredictWindows(options, w, groups, sigma, &p);
  if (!s.ok()) return {{"uncertainty", nullptr}, {"reason", s.message()}};
  return {{"basis", "crb"},
          {"uncertainty", UncertaintyImuJson(p, found.name)},
          {"orders",
           {{"planned", p.floor_order},
            {"max", p.top_order},
            {"band_std_at_max_order",
             {{"accelerometer", p.WorstBandTop(0)}, {"gyroscope", p.WorstBandTop(3)}}}}}};
}

}  // namespace calibd::server
