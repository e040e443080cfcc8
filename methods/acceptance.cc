#include "methods/acceptance.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "methods/method.h"
#include "methods/registry.h"
#include "results/json_text.h"

namespace calibd::server {

using nlohmann::json;

namespace {

std::string KeyList(const std::vector<AcceptanceKey>& keys) {
  std::string out;
  for (const AcceptanceKey& k : keys) out += (out.empty() ? "" : ", ") + std::string(k.name);
  return out;
}

// "pca, array, imu or noise": the registry's methods, unquoted.
std::string MethodNameList() {
  const std::vector<const Method*>& methods = AllMethods();
  std::string out;
  for (size_t i = 0; i < methods.size(); ++i) {
    if (i > 0) out += i + 1 == methods.size() ? " or " : ", ";
    out += methods[i]->name();
  }
  return out;
}

}  // namespace

const std::vector<AcceptanceKey>& AcceptanceKeys(const std::string& method) {
  static const std::vector<AcceptanceKey>& kNone = *new std::vector<AcceptanceKey>();
  static std::mutex& mu = *new std::mutex;
  static auto& cache = *new std::map<std::string, std::vector<AcceptanceKey>>;
  const Method* m = FindMethod(method);
  if (m == nullptr) return kNone;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find(method);
  if (it == cache.end()) {
    it = cache
             .emplace(method, JoinKeys({m->AcceptanceKeys(),
                                        {limit_keys::kMaxFleetZ, limit_keys::kMaxFleetFalseAlarm}}))
             .first;
  }
  return it->second;  // map nodes do not move
}

const std::vector<AcceptanceKey>& ImuTriadKeys() {
  using namespace limit_keys;
  static const std::vector<AcceptanceKey>& keys =
      *new std::vector<AcceptanceKey>{kMaxScaleStd,  kMaxAxisStd,  kScaleRange, kImplausible,
                                      kAccelBiasStd, kGyroBiasStd, kAccelBias,  kGyroBias};
  return keys;
}

std::vector<AcceptanceKey> JoinKeys(std::initializer_list<std::vector<AcceptanceKey>> parts) {
  std::vector<AcceptanceKey> out;
  for (const std::vector<AcceptanceKey>& part : parts)
    out.insert(out.end(), part.begin(), part.end());
  return out;
}

std::optional<double> AcceptanceLimits::Get(const std::string& key) const {
  auto it = values.find(key);
  return it == values.end() ? std::nullopt : it->second;
}

json AcceptanceLimits::ToJson() const {
  json out = json::object();
  for (const auto& [key, value] : values) out[key] = value ? json(*value) : json(nullptr);
  return out;
}

Status ValidateAcceptance(const json& value, const std::string& method, const std::string& where,
                          const std::string& field_prefix) {
  const std::vector<AcceptanceKey>& keys = AcceptanceKeys(method);
  if (!value.is_object()) {
    return Status::InvalidInput(where + " must be an object of limits for " + method + " (" +
                                KeyList(keys) + ")")
        .WithField(field_prefix);
  }
  for (const auto& [key, limit] : value.items()) {
    const AcceptanceKey* known = nullptr;
    for (const AcceptanceKey& k : keys) {
      if (key == k.name) known = &k;
    }
    const std::string field = field_prefix + "." + key;
    if (known == nullptr) {
      return Status::InvalidInput(where + ": '" + key + "' is not an acceptance limit of " +
                                  method + " (known: " + KeyList(keys) + ")")
          .WithField(field);
    }
    if (!limit.is_null() &&
        (!limit.is_number() || !std::isfinite(limit.get<double>()) || limit.get<double>() < 0)) {
      return Status::InvalidInput(where + ": '" + key + "' must be a number >= 0 (" +
                                  known->meaning + "), or null for no limit")
          .WithField(field);
    }
    if (!limit.is_null() && limit.get<double>() > known->max_value) {
      return Status::InvalidInput(where + ": '" + key + "' must be at most " +
                                  Fmt(known->max_value) + " (" + known->meaning + ")")
          .WithField(field);
    }
  }
  return Status::Ok();
}

Status ValidateServerAcceptance(const json& value, const std::string& file) {
  if (!value.is_object()) {
    return Status::InvalidInput(file +
                                ": acceptance defaults must be a JSON object with one object of "
                                "limits per method, e.g. {\"pca\": {\"max_scale_std\": 0.005}}");
  }
  for (const auto& [method, limits] : value.items()) {
    if (AcceptanceKeys(method).empty()) {
      return Status::InvalidInput(file + ": '" + method + "' is not a method (" + MethodNameList() +
                                  ")")
          .WithField(method);
    }
    Status s = ValidateAcceptance(limits, method, file + ": " + method, method);
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Status LoadAcceptanceFile(const std::string& path, json* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::InvalidInput("cannot read --acceptance " + path);
  std::ostringstream text;
  text << in.rdbuf();
  json value;
  Status s = results::ParseJsonText(text.str(), path, &value);
  if (!s.ok()) return s;
  s = ValidateServerAcceptance(value, path);
  if (!s.ok()) return s;
  *out = std::move(value);
  return Status::Ok();
}

AcceptanceLimits EffectiveAcceptance(const std::string& method, const json& server_defaults,
                                     const json& config) {
  AcceptanceLimits limits;
  for (const AcceptanceKey& k : AcceptanceKeys(method)) limits.values[k.name] = k.default_value;
  auto apply = [&](const json& overrides) {
    if (!overrides.is_object()) return;
    for (const auto& [key, value] : overrides.items()) {
      if (limits.values.count(key) == 0) continue;
      limits.values[key] =
          value.is_number() ? std::optional<double>(value.get<double>()) : std::optional<double>();
    }
  };
  if (server_defaults.is_object()) {
    if (auto it = server_defaults.find(method); it != server_defaults.end()) apply(*it);
  }
  if (config.is_object()) {
    if (auto it = config.find("acceptance"); it != config.end()) apply(*it);
  }
  return limits;
}

json Verdict::ToJson(const AcceptanceLimits& limits) const {
  return {{"status", accepted() ? "accepted" : "rejected"},
          {"reasons", reasons_},
          {"limits", limits.ToJson()}};
}

std::string Fmt(double x) {
  if (!std::isfinite(x)) return "undefined";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

std::optional<double> Number(const json& j) {
  if (!j.is_number()) return std::nullopt;
  const double x = j.get<double>();
  if (!std::isfinite(x)) return std::nullopt;
  return x;
}

void Offenders::RejectInto(Verdict* verdict, const std::string& rule) const {
  if (items_.empty()) return;
  std::string text = rule + ": ";
  const size_t shown = std::min<size_t>(items_.size(), 6);
  for (size_t i = 0; i < shown; ++i) text += (i ? ", " : "") + items_[i];
  if (items_.size() > shown) text += " and " + std::to_string(items_.size() - shown) + " more";
  verdict->Reject(text);
}

std::string UnitMixupHint(double ratio, const std::string& quantity) {
  constexpr double kG = 9.80665, kDeg = 180.0 / M_PI;
  auto near = [](double x, double target) { return std::abs(x / target - 1) < 0.15; };
  if (quantity == "accelerometer") {
    if (near(ratio, kG)) return "the readings look like g but are taken as m/s^2: units?";
    if (near(ratio, 1 / kG)) return "the readings look like m/s^2 but are taken as g: units?";
  } else {
    if (near(ratio, kDeg)) return "the readings look like rad/s but are taken as deg/s: units?";
    if (near(ratio, 1 / kDeg)) return "the readings look like deg/s but are taken as rad/s: units?";
  }
  return "";
}

namespace {}  // namespace

void JudgeImuTriads(const std::vector<results::ImuTriads>& imus,
                    const std::vector<results::ImuTriadsStd>& imus_std, const TriadNominal& nominal,
                    const AcceptanceLimits& limits, const std::string& label, Verdict* verdict) {
  const auto scale_std_max = limits.Get("max_scale_std");
  const auto axis_std_max = limits.Get("max_axis_std");
  const auto range = limits.Get("scale_range");
  const auto implausible = limits.Get("implausible_factor");
  Offenders undefined, scale_std, axis_std, out_of_range, bias_std, bias, not_finite;
  static const char* const kAxes[] = {"x", "y", "z"};
  for (size_t i = 0; i < imus.size(); ++i) {
    const results::ImuTriads& imu = imus[i];
    const std::string name = label + " " + (imu.name.empty() ? std::to_string(i) : imu.name);
    const results::ImuTriadsStd* stds = i < imus_std.size() ? &imus_std[i] : nullptr;
    for (const bool accel : {true, false}) {
      const char* quantity = accel ? "accelerometer" : "gyroscope";
      const std::string who = name + " " + quantity;
      const results::SensorTriad& t = accel ? imu.accelerometer : imu.gyroscope;
      const double unit = accel ? nominal.accel_unit : nominal.gyro_unit;
      if (!t.bias.allFinite() || !t.scale.allFinite() || !t.misalignment.allFinite() ||
          !t.matrix.allFinite()) {
        not_finite.Add(who);
      }
      const std::string si_scale = accel ? "m/s^2 per reading unit" : "rad/s per reading unit";
      // Scale factors against the nominal unit conversion.
      for (int k = 0; k < 3; ++k) {
        const double ratio = t.scale(k) / unit;
        const std::string axis = who + " " + kAxes[k];
        if (!std::isfinite(ratio)) {
          undefined.Add(axis + " scale");
          continue;
        }
        if (implausible && (ratio > *implausible || ratio < 1 / *implausible)) {
          std::string hint = UnitMixupHint(ratio, quantity);
          if (hint.empty())
            hint = "units, or a wrong " + std::string(accel ? "accel_unit" : "gyro_unit") + "?";
          verdict->Reject(
              axis + ": scale " + Fmt(t.scale(k)) + " " + si_scale + " is " + Fmt(ratio) +
              " times the nominal (" +
              (accel ? "accel_unit " + nominal.accel_text : "gyro_unit " + nominal.gyro_text) +
              " = " + Fmt(unit) + " " + si_scale + "), physically implausible: " + hint);
        } else if (range && std::abs(ratio - 1) > *range) {
          out_of_range.Add(axis + " " + Fmt((ratio - 1) * 100) + " %");
        }
      }
      if (stds == nullptr) {
        undefined.Add(who + " uncertainty");
        continue;
      }
      const results::SensorTriadStd& s = accel ? stds->accelerometer : stds->gyroscope;
      for (int k = 0; k < 3; ++k) {
        const double rel = s.scale_std(k) / std::abs(t.scale(k));
        if (!std::isfinite(rel)) {
          undefined.Add(who + " " + kAxes[k] + " scale");
        } else if (scale_std_max && rel > *scale_std_max) {
          scale_std.Add(who + " " + kAxes[k] + " " + Fmt(rel * 100) + " %");
        }
      }
      double worst = 0;
      bool misalignment_undefined = false;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          if (r == c) continue;  // the unit diagonal is fixed, its std 0
          const double m = s.misalignment_std(r, c);
          if (!std::isfinite(m)) {
            // T_a's lower triangle is fixed (the frame's gauge): written as 0, not null.
            misalignment_undefined = true;
          } else {
            worst = std::max(worst, m);
          }
        }
      }
      if (misalignment_undefined) undefined.Add(who + " misalignment");
      if (axis_std_max && worst > *axis_std_max) {
        axis_std.Add(who + " " + Fmt(worst * 1e3) + " mrad");
      }
      const auto bias_std_max = limits.Get(accel ? "max_accel_bias_std" : "max_gyro_bias_std");
      const auto bias_max = limits.Get(accel ? "max_accel_bias" : "max_gyro_bias");
      const double nominal_bias = accel ? nominal.accel_bias : nominal.gyro_bias;
      const char* si = accel ? "m/s^2" : "rad/s";
      for (int k = 0; k < 3; ++k) {
        const double sigma = s.bias_std(k) * unit;
        if (!std::isfinite(sigma)) {
          undefined.Add(who + " " + kAxes[k] + " bias");
        } else if (bias_std_max && sigma > *bias_std_max) {
          bias_std.Add(who + " " + kAxes[k] + " " + Fmt(sigma) + " " + si);
        }
      }
      for (int k = 0; k < 3; ++k) {
        const double value = (t.bias(k) - nominal_bias) * unit;
        if (std::isfinite(value) && bias_max && std::abs(value) > *bias_max) {
          bias.Add(who + " " + kAxes[k] + " " + Fmt(value) + " " + si);
        }
      }
    }
  }
  not_finite.RejectInto(verdict, kNotFiniteRule);
  undefined.RejectInto(verdict,
                       "the uncertainty could not be computed, so the precision cannot be judged");
  if (range) {
    out_of_range.RejectInto(verdict, "scale factor more than " + Fmt(*range * 100) +
                                         " % from the nominal unit conversion");
  }
  if (scale_std_max) {
    scale_std.RejectInto(verdict, "scale factor too uncertain (1 sigma above " +
                                      Fmt(*scale_std_max * 100) +
                                      " %): record more or longer statics");
  }
  if (axis_std_max) {
    axis_std.RejectInto(verdict,
                        "misalignment too uncertain (1 sigma above " + Fmt(*axis_std_max * 1e3) +
                            " mrad): record more orientations and rotations about every axis");
  }
  bias_std.RejectInto(verdict,
                      "bias too uncertain (1 sigma above the limit): record longer statics");
  bias.RejectInto(verdict,
                  "bias beyond the limit (max_accel_bias / max_gyro_bias): a damaged "
                  "sensor, or a wrong nominal bias?");
}

}  // namespace calibd::server
