// Protocols of a calibration plan (methods/plan.h).
#include "methods/plan.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>

namespace calibd::server {
namespace {

using nlohmann::json;

Status FieldError(const std::string& field, const std::string& message) {
  return Status::InvalidInput("protocol." + field + " " + message).WithField("protocol." + field);
}

// A number key of the protocol in (0, max], or its default when absent.
Status ReadPositive(const json& protocol, const char* key, double max, double* out) {
  const auto it = protocol.find(key);
  if (it == protocol.end()) return Status::Ok();
  if (!it->is_number() || !(it->get<double>() > 0) || !(it->get<double>() <= max)) {
    char range[64];
    std::snprintf(range, sizeof(range), "must be a number in (0, %g]", max);
    return FieldError(key, range);
  }
  *out = it->get<double>();
  return Status::Ok();
}

std::string Num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", std::abs(x) < 5e-4 ? 0.0 : x);
  return buf;
}

// The thermal keys (methods/plan.h): t_min and t_max together, t_max > t_min, both within
// [-100, 200] °C; temperature_rate; imus.
Status ParseThermalProtocol(const json& protocol, PlanProtocol* out) {
  const bool has_min = protocol.contains("t_min"), has_max = protocol.contains("t_max");
  if (has_min != has_max) {
    return FieldError(has_min ? "t_max" : "t_min",
                      "is missing: a thermal protocol gives both t_min and t_max (°C)");
  }
  if (has_min) {
    for (const char* key : {"t_min", "t_max"}) {
      const json& v = protocol[key];
      if (!v.is_number() || !(v.get<double>() >= -100) || !(v.get<double>() <= 200)) {
        return FieldError(key, "must be a temperature in [-100, 200] °C");
      }
    }
    out->t_min = protocol["t_min"].get<double>();
    out->t_max = protocol["t_max"].get<double>();
    if (!(*out->t_max > *out->t_min)) {
      return FieldError("t_max", "must be above t_min (" + Num(*out->t_min) + " °C)");
    }
  }
  if (Status s = ReadPositive(protocol, "temperature_rate", PlanProtocol::kMaxTemperatureRate,
                              &out->temperature_rate);
      !s.ok()) {
    return s;
  }
  if (const auto it = protocol.find("imus"); it != protocol.end()) {
    // A whole number (3 or 3.0: the page's fields are typed as numbers).
    if (!it->is_number() || !(it->get<double>() >= 1) ||
        !(it->get<double>() <= PlanProtocol::kMaxImus) ||
        it->get<double>() != std::floor(it->get<double>())) {
      return FieldError(
          "imus", "must be an integer in [1, " + std::to_string(PlanProtocol::kMaxImus) + "]");
    }
    out->imus = static_cast<int>(it->get<double>());
  }
  return Status::Ok();
}

// A direction given as a name ("+z") or a vector [x, y, z]: unit *v and its label.
Status ReadDirection(const json& o, const std::string& field, Eigen::Vector3d* v,
                     std::string* label);

// The array keys (methods/plan.h): angular_rate, angular_acceleration, rotation_axis, duration.
Status ParseMotionProtocol(const json& protocol, PlanProtocol* out) {
  if (protocol.contains("angular_rate")) {
    double rate = 0;
    if (Status s = ReadPositive(protocol, "angular_rate", PlanProtocol::kMaxAngularRate, &rate);
        !s.ok()) {
      return s;
    }
    out->angular_rate = rate;
  }
  for (const char* key : {"angular_acceleration", "rotation_axis", "duration"}) {
    if (protocol.contains(key) && !out->angular_rate) {
      return FieldError("angular_rate", std::string("is missing: ") + key +
                                            " belongs to a motion protocol (array), which gives "
                                            "angular_rate (rad/s)");
    }
  }
  if (Status s = ReadPositive(protocol, "angular_acceleration",
                              PlanProtocol::kMaxAngularAcceleration, &out->angular_acceleration);
      !s.ok()) {
    return s;
  }
  if (Status s = ReadPositive(protocol, "duration", PlanProtocol::kMaxDuration, &out->duration);
      !s.ok()) {
    return s;
  }
  if (const auto it = protocol.find("rotation_axis"); it != protocol.end()) {
    Eigen::Vector3d v;
    if (Status s = ReadDirection(*it, "rotation_axis", &v, &out->rotation_axis_label); !s.ok()) {
      return s;
    }
    out->rotation_axis = v;
  }
  return Status::Ok();
}

Status ReadDirection(const json& o, const std::string& field, Eigen::Vector3d* v,
                     std::string* label) {
  if (o.is_string()) {
    if (Status s = OrientationFromName(o.get<std::string>(), v); !s.ok()) {
      return FieldError(field, s.message());
    }
    *label = o.get<std::string>();
  } else if (o.is_array() && o.size() == 3 && o[0].is_number() && o[1].is_number() &&
             o[2].is_number()) {
    *v = Eigen::Vector3d(o[0].get<double>(), o[1].get<double>(), o[2].get<double>());
    if (!v->allFinite() || !(v->norm() > 1e-9)) {
      return FieldError(field, "must be a non-zero finite vector");
    }
    v->normalize();
    *label = "[" + Num((*v)(0)) + ", " + Num((*v)(1)) + ", " + Num((*v)(2)) + "]";
  } else {
    return FieldError(field, "must be a name such as \"+x\" or a vector [x, y, z]");
  }
  return Status::Ok();
}

// protocol.orientations into out (names or vectors, normalised).
Status ParseOrientations(const json& protocol, PlanProtocol* out) {
  const auto it = protocol.find("orientations");
  if (it == protocol.end() || !it->is_array() || it->empty() ||
      it->size() > static_cast<size_t>(PlanProtocol::kMaxPositions)) {
    return FieldError("orientations", "must be an array of 1 to " +
                                          std::to_string(PlanProtocol::kMaxPositions) +
                                          " orientations (names such as \"+x\" or [x, y, z])");
  }
  for (size_t i = 0; i < it->size(); ++i) {
    const json& o = (*it)[i];
    Eigen::Vector3d v;
    std::string label;
    if (Status s = ReadDirection(o, "orientations[" + std::to_string(i) + "]", &v, &label);
        !s.ok()) {
      return s;
    }
    out->labels.push_back(label);
    out->orientations.push_back(v);
  }
  return Status::Ok();
}

}  // namespace

Status OrientationFromName(const std::string& name, Eigen::Vector3d* out) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  bool seen[3] = {false, false, false};
  if (name.empty() || name.size() % 2 != 0 || name.size() > 6) {
    return Status::InvalidInput("'" + name.substr(0, 32) +
                                "' is not an orientation name (one to three signed axes such as "
                                "+x, -z, +x+y, -x+y-z)");
  }
  for (size_t i = 0; i < name.size(); i += 2) {
    const char sign = name[i], axis = name[i + 1];
    const int k = axis == 'x' ? 0 : axis == 'y' ? 1 : axis == 'z' ? 2 : -1;
    if ((sign != '+' && sign != '-') || k < 0 || seen[k]) {
      return Status::InvalidInput("'" + name.substr(0, 32) +
                                  "' is not an orientation name (one to three signed axes, each "
                                  "once, such as +x, -z, +x+y, -x+y-z)");
    }
    seen[k] = true;
    v(k) = sign == '+' ? 1 : -1;
  }
  *out = v.normalized();
  return Status::Ok();
}

Status ParsePlanProtocol(const json& protocol, PlanProtocol* out) {
  *out = PlanProtocol();
  if (!protocol.is_object()) {
    return Status::InvalidInput("protocol must be a JSON object {\"orientations\": [...], ...}")
        .WithField("protocol");
  }
  for (const auto& [key, value] : protocol.items()) {
    (void)value;
    if (key != "orientations" && key != "static_duration" && key != "rate" &&
        key != "rotation_duration" && key != "t_min" && key != "t_max" &&
        key != "temperature_rate" && key != "imus" && key != "angular_rate" &&
        key != "angular_acceleration" && key != "rotation_axis" && key != "duration") {
      return FieldError(key.substr(0, 64),
                        "is not a protocol key (known: orientations, static_duration, rate, "
                        "rotation_duration, t_min, t_max, temperature_rate, imus, angular_rate, "
                        "angular_acceleration, rotation_axis, duration)");
    }
  }
  if (Status s = ParseThermalProtocol(protocol, out); !s.ok()) return s;
  if (Status s = ParseMotionProtocol(protocol, out); !s.ok()) return s;
  // A thermal or motion protocol may leave the orientations out (methods/plan.h).
  if ((!out->t_min && !out->angular_rate) || protocol.contains("orientations")) {
    if (Status s = ParseOrientations(protocol, out); !s.ok()) return s;
  }
  if (Status s = ReadPositive(protocol, "static_duration", PlanProtocol::kMaxStaticDuration,
                              &out->static_duration);
      !s.ok()) {
    return s;
  }
  if (Status s = ReadPositive(protocol, "rate", PlanProtocol::kMaxRate, &out->rate); !s.ok()) {
    return s;
  }
  if (Status s = ReadPositive(protocol, "rotation_duration", PlanProtocol::kMaxStaticDuration,
                              &out->rotation_duration);
      !s.ok()) {
    return s;
  }
  const double n = static_cast<double>(out->orientations.size());
  const double samples =
      out->t_min ? out->rate * (*out->t_max - *out->t_min) / out->temperature_rate * 60
      : out->angular_rate
          ? out->rate * out->duration
          : out->rate * (n * out->static_duration + (n - 1) * out->rotation_duration);
  if (samples > PlanProtocol::kMaxSamples) {
    return FieldError("rate", "× the protocol's duration is " + Num(samples) +
                                  " samples; at most " + Num(PlanProtocol::kMaxSamples) +
                                  " are planned");
  }
  return Status::Ok();
}

Status RequireOrientations(const PlanProtocol& protocol) {
  if (!protocol.orientations.empty()) return Status::Ok();
  return FieldError("orientations",
                    "is missing: this method plans static orientations (names "
                    "such as \"+x\" or [x, y, z])");
}

std::vector<Eigen::Matrix3d> ProtocolRotations(const std::vector<Eigen::Vector3d>& up) {
  std::vector<Eigen::Matrix3d> r;
  for (size_t j = 0; j < up.size(); ++j) {
    if (j == 0) {
      r.push_back(Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), up[0])
                      .toRotationMatrix()
                      .transpose());
    } else {
      r.push_back(r.back() *
                  Eigen::Quaterniond::FromTwoVectors(up[j], up[j - 1]).toRotationMatrix());
    }
  }
  return r;
}

const std::vector<PlanCandidate>& PlanCandidates() {
  static const std::vector<PlanCandidate>& candidates = *[] {
    auto* out = new std::vector<PlanCandidate>;
    const char* axes = "xyz";
    for (int count = 1; count <= 3; ++count) {
      for (int mask = 1; mask < 8; ++mask) {
        if (__builtin_popcount(mask) != count) continue;
        for (int signs = 0; signs < 8; ++signs) {
          if ((signs & ~mask) != 0) continue;  // sign bits only on the chosen axes
          std::string name;
          for (int k = 0; k < 3; ++k) {
            if ((mask >> k & 1) == 0) continue;
            name += (signs >> k & 1) != 0 ? '-' : '+';
            name += axes[k];
          }
          Eigen::Vector3d v;
          (void)OrientationFromName(name, &v);
          out->push_back({name, v});
        }
      }
    }
    return out;
  }();
  return candidates;
}

std::string DirectionWords(const Eigen::Vector3d& direction) {
  for (int k = 0; k < 3; ++k) {
    if (std::abs(std::abs(direction(k)) - 1) < 1e-6) return std::string(1, "xyz"[k]);
  }
  return "[" + Num(direction(0)) + ", " + Num(direction(1)) + ", " + Num(direction(2)) + "]";
}

json OrientationsJson(const std::vector<Eigen::Vector3d>& directions,
                      const std::vector<std::string>& labels) {
  json out = json::array();
  for (size_t j = 0; j < directions.size(); ++j) {
    out.push_back({{"name", j < labels.size() ? labels[j] : DirectionWords(directions[j])},
                   {"direction", {directions[j](0), directions[j](1), directions[j](2)}}});
  }
  return out;
}

std::vector<std::string> MissingDirections(const std::vector<Eigen::Vector3d>& orientations,
                                           bool with_bias) {
  const int p = with_bias ? 4 : 3;
  Eigen::MatrixXd design = Eigen::MatrixXd::Zero(p, p);
  Eigen::VectorXd f(p);
  for (const Eigen::Vector3d& u : orientations) {
    f.head(3) = u;
    if (with_bias) f(3) = 1;
    design += f * f.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(design);
  const double scale = std::max(design.trace(), 1.0);
  std::vector<std::string> out;
  for (int k = 0; k < p; ++k) {
    if (eig.eigenvalues()(k) > 1e-9 * scale) continue;
    Eigen::VectorXd z = eig.eigenvectors().col(k);
    const Eigen::Vector3d dir = z.head(3).normalized();
    if (!with_bias || std::abs(z(3)) < 1e-6) {
      out.push_back("no orientation with a component along " + DirectionWords(dir));
    } else {
      out.push_back("every orientation has the same component along " + DirectionWords(dir) +
                    ": the bias and the sensitivity along " + DirectionWords(dir) +
                    " are not separated");
    }
  }
  return out;
}

PlanProtocol PlanPrefix(const std::vector<const PlanCandidate*>& sequence, int k,
                        const PlanProtocol& protocol) {
  PlanProtocol out = protocol;
  out.orientations.clear();
  out.labels.clear();
  for (int j = 0; j < k; ++j) {
    out.orientations.push_back(sequence[static_cast<size_t>(j)]->direction);
    out.labels.push_back(sequence[static_cast<size_t>(j)]->name);
  }
  return out;
}

void SuggestFewestPositions(
    const std::vector<const PlanCandidate*>& sequence, const PlanProtocol& protocol,
    int min_positions, int cap,
    const std::function<Status(const PlanProtocol&, nlohmann::json*)>& predict,
    const std::function<void(const nlohmann::json&, Verdict*)>& judge, const std::string& too_few,
    nlohmann::json* out) {
  struct Trial {
    bool predicted = false;  // the method ran and gave parameters
    nlohmann::json result;
    Verdict verdict;
  };
  int predictions = 0;
  const auto attempt = [&](int k) {
    ++predictions;
    Trial t;
    const Status s = predict(PlanPrefix(sequence, k, protocol), &t.result);
    t.predicted = s.ok();
    if (s.ok()) {
      judge(t.result, &t.verdict);
    } else {
      t.verdict.Reject(s.message());
    }
    return t;
  };
  // Invariant: hi passes (or is the cap), lo fails (lo = min − 1: the method refuses it).
  int hi = cap, lo = min_positions - 1;
  Trial best = attempt(hi), fewer;
  bool fewer_predicted = false;
  if (best.verdict.accepted()) {
    while (hi - lo > 1) {
      const int mid = lo + (hi - lo) / 2;
      Trial t = attempt(mid);
      if (t.verdict.accepted()) {
        hi = mid;
        best = std::move(t);
      } else {
        lo = mid;
        fewer = std::move(t);
        fewer_predicted = true;
      }
    }
  }
  const PlanProtocol chosen = PlanPrefix(sequence, hi, protocol);
  nlohmann::json& o = *out;
  o["orientations"] = OrientationsJson(chosen.orientations, chosen.labels);
  o["meets_limits"] = best.verdict.accepted();
  o["unmet"] = best.verdict.reasons();
  if (best.predicted) o["uncertainty"] = best.result["uncertainty"];
  if (best.verdict.accepted()) {
    o["fewer"] = {
        {"positions", lo},
        {"unmet", fewer_predicted ? fewer.verdict.reasons() : std::vector<std::string>{too_few}}};
  }
  o["predictions"] = predictions;
}

json SuggestGreedyProtocol(
    const SuggestSettings& settings, const PlanProtocol& protocol, const AcceptanceLimits& limits,
    const std::vector<std::string>& sigma_keys, const std::string& design,
    const std::string& predicted_by,
    const std::function<std::vector<const PlanCandidate*>(int cap)>& sequence,
    const std::function<Status(const PlanProtocol&, json*)>& predict,
    const std::function<void(const json&, const AcceptanceLimits&, Verdict*)>& judge,
    const std::string& too_few) {
  const double per_position =
      protocol.rate * (protocol.static_duration + protocol.rotation_duration);
  const int by_samples = static_cast<int>(std::floor(
      (settings.max_samples + protocol.rate * protocol.rotation_duration) / per_position));
  const int cap = std::min(settings.max_positions, by_samples);
  AcceptanceLimits margined = limits;
  for (const std::string& key : sigma_keys) {
    const auto it = margined.values.find(key);
    if (it != margined.values.end() && it->second) *it->second *= 1 - settings.margin;
  }
  json out = {{"design", design + "; the fewest positions of that sequence, from " +
                             std::to_string(settings.min_positions) + " to " +
                             std::to_string(settings.max_positions) + ", whose predicted result (" +
                             predicted_by + ") passes the gate with its σ limits tightened by " +
                             Fmt(settings.margin * 100) + " %, by bisection"},
              {"rotations", "the shortest rotation between consecutive orientations"},
              {"margin", settings.margin},
              {"orientations", json::array()},
              {"meets_limits", false},
              {"unmet", json::array()},
              {"uncertainty", nullptr},
              {"fewer", nullptr},
              {"predictions", 0}};
  if (cap < settings.min_positions) {
    out["unmet"].push_back("a log of " + std::to_string(settings.min_positions) +
                           " positions at this rate and duration has more than " +
                           Fmt(settings.max_samples) +
                           " samples, the most a suggestion simulates (max_samples): shorten the "
                           "statics or lower the rate");
    return out;
  }
  SuggestFewestPositions(
      sequence(cap), protocol, settings.min_positions, cap, predict,
      [&](const json& result, Verdict* verdict) { judge(result, margined, verdict); }, too_few,
      &out);
  return out;
}

}  // namespace calibd::server
