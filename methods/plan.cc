// Protocols of a calibration plan (methods/plan.h).
#include "methods/plan.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
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
        key != "rotation_duration") {
      return FieldError(key.substr(0, 64),
                        "is not a protocol key (known: orientations, static_duration, rate, "
                        "rotation_duration)");
    }
  }
  const auto it = protocol.find("orientations");
  if (it == protocol.end() || !it->is_array() || it->empty() ||
      it->size() > static_cast<size_t>(PlanProtocol::kMaxPositions)) {
    return FieldError("orientations", "must be an array of 1 to " +
                                          std::to_string(PlanProtocol::kMaxPositions) +
                                          " orientations (names such as \"+x\" or [x, y, z])");
  }
  for (size_t i = 0; i < it->size(); ++i) {
    const json& o = (*it)[i];
    const std::string field = "orientations[" + std::to_string(i) + "]";
    Eigen::Vector3d v;
    if (o.is_string()) {
      if (Status s = OrientationFromName(o.get<std::string>(), &v); !s.ok()) {
        return FieldError(field, s.message());
      }
      out->labels.push_back(o.get<std::string>());
    } else if (o.is_array() && o.size() == 3 && o[0].is_number() && o[1].is_number() &&
               o[2].is_number()) {
      v = Eigen::Vector3d(o[0].get<double>(), o[1].get<double>(), o[2].get<double>());
      if (!v.allFinite() || !(v.norm() > 1e-9)) {
        return FieldError(field, "must be a non-zero finite vector");
      }
      v.normalize();
      out->labels.push_back("[" + Num(v(0)) + ", " + Num(v(1)) + ", " + Num(v(2)) + "]");
    } else {
      return FieldError(field, "must be a name such as \"+x\" or a vector [x, y, z]");
    }
    out->orientations.push_back(v);
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
  const double samples = out->rate * (n * out->static_duration + (n - 1) * out->rotation_duration);
  if (samples > PlanProtocol::kMaxSamples) {
    return FieldError("rate", "× the protocol's duration is " + Num(samples) +
                                  " samples; at most " + Num(PlanProtocol::kMaxSamples) +
                                  " are planned");
  }
  return Status::Ok();
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

}  // namespace calibd::server
