// The plan of a mag calibration (SPEC §10, Method::Plan; methods/mag/mag_method.h): the σ the mag
// method would report for a protocol, what the protocol cannot determine, and the fewest
// orientations meeting the gate's σ limits.
//
// Protocol: the orientations are the body's attitudes relative to a local level frame (x north,
// z up) in which the Earth's field has the magnitude `field` (µT, config) and the dip `dip`
// (degrees, positive down, config; 60 when not given): each orientation's up direction as for
// imu, the attitudes chained by the shortest rotation between consecutive up directions
// (methods/plan.h ProtocolRotations), so the first one has no yaw from north. What the
// magnetometer sees is the field's direction in the body frame, Qᵀ B. Each orientation is held
// still static_duration s (accelerometer statics for the alignment and dip), each turn to the
// next takes rotation_duration s (a smooth 1 − cos slerp, logged: the turns' samples also fit
// the ellipsoid), sampled at `rate`.
//
// Predicted σ: the method itself (its Run: static detection, ellipsoid fit, alignment) on the log
// of that protocol simulated (core/mag_simulation.h, given orientations) with a nominal
// magnetometer (no hard iron, P = identity in µT, aligned with the accelerometer), white noise
// `mag_noise` per sample and axis (config, reading units) and an accelerometer with 0.02 m/s²
// per sample, mean over kPlanSeeds (16) seeds: the alignment's and dip's σ (and the soft iron's
// off-diagonal entries of S = R P, which carry it) come from the statics' scatter and vary by a
// factor 4 between logs of one protocol (12 statics: 0.00027 to 0.00113 rad over 64 seeds), the
// hard iron's and soft iron's from the residuals of thousands of samples (about 1.5 %). So the
// plan's σ is the job's on the same protocol by construction, within Monte-Carlo resolution
// (tests/server/mag_plan_test.cc).
//
// Undetermined: the information of the ellipsoid at nominal values, per sample
// f(u) = [u; u_x², 2u_x u_y, 2u_x u_z, u_y², 2u_y u_z, u_z²] (the radial residual's sensitivity to
// the hard iron and the 6 entries of A, core/mag.h), summed over the protocol's field directions
// (statics and turns). When it is singular (relative eigenvalue under 1e-9: the field directions
// lie on one circle, i.e. the turns are about one axis), the soft iron along that circle's axis
// (and the hard iron along it) is not determined: the axis is the direction in which the field
// directions do not vary. Fewer than min_alignment_statics (7) statics, or statics whose down
// directions are all about one axis: the alignment and dip are not determined (the method's
// alignment_note).
//
// Suggested (SuggestMag): a sequence of the 26 candidate up directions (methods/plan.h) chosen
// greedily by D-optimality, starting flat (+z): append the candidate (other than the current one)
// that most increases log det(I_ellipsoid + εI) + log det(I_alignment + εI), I_ellipsoid the
// information above, I_alignment = Σ_j g_j g_jᵀ over the statics, g_j = [n_j × d_j; −1] (the
// sensitivity of d_jᵀ R n_j − sin δ to R's small angles and sin δ, n_j the field's and d_j the
// down direction in the body frame). Each block is scaled by the (equal) samples per static and
// turn and the noise, which do not change the choice. Where it stops: the fewest positions k of
// that sequence (at least min_alignment_statics, at most MagSuggestOptions::max_positions) whose
// predicted result passes the method's gate with the σ limits tightened by `margin`, found by
// bisection.
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "core/mag_simulation.h"
#include "methods/mag/mag_method.h"
#include "methods/plan.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using Vector9d = Eigen::Matrix<double, 9, 1>;
using Matrix9d = Eigen::Matrix<double, 9, 9>;

constexpr double kRadPerDeg = 3.14159265358979323846 / 180;
constexpr double kPlanAccelNoise = 0.02;  // m/s² per sample, the simulated statics' accelerometer
constexpr int kTurnPoints = 8;            // field directions per turn in the design
constexpr int kPlanSeeds = 16;            // simulated logs a prediction averages

// The σ keys of the mag gate the suggestion's margin tightens.
constexpr const char* kSigmaKeys[] = {"max_hard_iron_std", "max_soft_iron_std",
                                      "max_alignment_std"};

// Body → NED attitudes of up directions: ProtocolRotations' level frame has x north and z up
// (y west); NED = diag(1, −1, −1) of it.
std::vector<Eigen::Matrix3d> Attitudes(const std::vector<Eigen::Vector3d>& up) {
  std::vector<Eigen::Matrix3d> out = ProtocolRotations(up);
  const Eigen::Matrix3d ned = Eigen::Vector3d(1, -1, -1).asDiagonal();
  for (Eigen::Matrix3d& q : out) q = ned * q;
  return out;
}

Eigen::Vector3d FieldNed(double dip) {
  return Eigen::Vector3d(std::cos(dip * kRadPerDeg), 0, std::sin(dip * kRadPerDeg));
}

// The field directions (body frame) the protocol's log visits, each with its weight in samples.
struct Directions {
  std::vector<Eigen::Vector3d> u;
  std::vector<double> weight;
  std::vector<Eigen::Vector3d> static_field, static_down;  // per static
};

Directions FieldDirections(const std::vector<Eigen::Vector3d>& up, const PlanProtocol& protocol,
                           double dip) {
  Directions d;
  const std::vector<Eigen::Matrix3d> q = Attitudes(up);
  const Eigen::Vector3d b = FieldNed(dip);
  const double per_static = protocol.static_duration * protocol.rate;
  const double per_turn = protocol.rotation_duration * protocol.rate;
  for (size_t j = 0; j < q.size(); ++j) {
    if (j > 0) {
      const Eigen::Quaterniond from(q[j - 1]), to(q[j]);
      for (int k = 0; k < kTurnPoints; ++k) {
        const double x = 0.5 * (1 - std::cos(3.14159265358979323846 * (k + 0.5) / kTurnPoints));
        d.u.push_back(from.slerp(x, to).toRotationMatrix().transpose() * b);
        d.weight.push_back(per_turn / kTurnPoints);
      }
    }
    d.u.push_back(q[j].transpose() * b);
    d.weight.push_back(per_static);
    d.static_field.push_back(d.u.back());
    d.static_down.push_back(-up[j]);
  }
  return d;
}

// The ellipsoid's per-sample information row at nominal values (file comment).
Vector9d EllipsoidRow(const Eigen::Vector3d& u) {
  Vector9d f;
  f << u, u(0) * u(0), 2 * u(0) * u(1), 2 * u(0) * u(2), u(1) * u(1), 2 * u(1) * u(2), u(2) * u(2);
  return f;
}

Matrix9d EllipsoidInformation(const Directions& d) {
  Matrix9d info = Matrix9d::Zero();
  for (size_t i = 0; i < d.u.size(); ++i) {
    const Vector9d f = EllipsoidRow(d.u[i]);
    info += d.weight[i] * f * f.transpose();
  }
  return info;
}

Eigen::Matrix4d AlignmentInformation(const Directions& d) {
  Eigen::Matrix4d info = Eigen::Matrix4d::Zero();
  for (size_t j = 0; j < d.static_field.size(); ++j) {
    Eigen::Vector4d g;
    g << d.static_field[j].cross(d.static_down[j]), -1;
    info += g * g.transpose();
  }
  return info;
}

template <int N>
double LogDet(Eigen::Matrix<double, N, N> m) {
  m.diagonal().array() += 1e-6;
  const Eigen::LLT<Eigen::Matrix<double, N, N>> llt(m);
  if (llt.info() != Eigen::Success) return -INFINITY;
  return 2 * llt.matrixLLT().diagonal().array().log().sum();
}

// The design criterion of the suggestion (file comment), per-sample weights normalised.
double Criterion(const std::vector<Eigen::Vector3d>& up, const PlanProtocol& protocol, double dip) {
  const Directions d = FieldDirections(up, protocol, dip);
  const double scale = protocol.static_duration * protocol.rate;
  const Matrix9d info = EllipsoidInformation(d) / scale;
  return LogDet<9>(info) + LogDet<4>(AlignmentInformation(d));
}

// The field's axis the protocol leaves undetermined (the information singular), else nullopt.
std::optional<Eigen::Vector3d> MissingAxis(const Directions& d) {
  const Matrix9d info = EllipsoidInformation(d);
  const Eigen::SelfAdjointEigenSolver<Matrix9d> eig(info);
  if (eig.eigenvalues()(0) > 1e-9 * std::max(eig.eigenvalues()(8), 1e-300)) return std::nullopt;
  // The direction in which the field directions do not vary: the smallest eigenvector of their
  // (weighted) covariance.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double total = 0;
  for (size_t i = 0; i < d.u.size(); ++i) {
    mean += d.weight[i] * d.u[i];
    total += d.weight[i];
  }
  mean /= total;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < d.u.size(); ++i) {
    cov += d.weight[i] * (d.u[i] - mean) * (d.u[i] - mean).transpose();
  }
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvectors().col(0);
}

Status NeedsKey(const char* key, const std::string& what) {
  return Status::InvalidInput(std::string("config.") + key + ": the plan needs " + what)
      .WithField(std::string("config.") + key);
}

// One simulated log of the protocol, calibrated by the method.
Status PredictOnce(const json& config, const MagPlanConfig& c, const PlanProtocol& protocol,
                   uint64_t seed, json* result) {
  core::MagSimulationOptions sim;
  sim.seed = seed;
  sim.rate = protocol.rate;
  sim.orientations = Attitudes(protocol.orientations);
  sim.static_seconds = protocol.static_duration;
  sim.turn_seconds = protocol.rotation_duration;
  sim.field = c.field;
  sim.dip = c.dip;
  sim.hard_iron.setZero();
  sim.soft_iron = c.microtesla_per_unit * Eigen::Matrix3d::Identity();  // readings in mag_unit
  sim.alignment.setZero();
  sim.noise = *c.noise;
  sim.accel_noise = kPlanAccelNoise;
  std::string csv;
  json sim_config, truth;
  if (Status s = SimulateMagFiles(sim, &csv, &sim_config, &truth); !s.ok()) return s;
  RecordingParser parser("plan.csv", /*collect=*/true);
  MagMethod().PrepareParser(config, &parser);
  if (Status s = parser.Feed(csv); !s.ok()) return s;
  if (Status s = parser.Finish(); !s.ok()) return s;
  return MagMethod().Run(&parser, config, RunContext(), result);
}

// Replaces every number of `sum` (same shape as `add`) by sum + add; nulls stay null.
void AddNumbers(const json& add, json* sum) {
  if (sum->is_number() && add.is_number()) {
    *sum = sum->get<double>() + add.get<double>();
  } else if (sum->is_structured() && add.is_structured() && sum->size() == add.size()) {
    if (sum->is_array()) {
      for (size_t i = 0; i < sum->size(); ++i) AddNumbers(add[i], &(*sum)[i]);
    } else {
      for (auto& [key, value] : sum->items()) {
        if (add.contains(key)) AddNumbers(add[key], &value);
      }
    }
  }
}

void ScaleNumbers(double factor, json* j) {
  if (j->is_number_float()) {
    *j = j->get<double>() * factor;
  } else if (j->is_structured()) {
    for (json& v : *j) ScaleNumbers(factor, &v);
  }
}

}  // namespace

// What the method reports on the protocol's simulated logs: the first seed's result with its
// uncertainty replaced by the mean over kPlanSeeds seeds (file comment). kInvalidInput naming
// the config key the plan needs; the method's failure on the first seed as it is.
Status PredictMag(const json& config, const PlanProtocol& protocol, json* result) {
  MagPlanConfig c;
  if (Status s = ReadMagPlanConfig(config, &c); !s.ok()) return s;
  if (!(c.field > 0)) return NeedsKey("field", "the local field's magnitude in µT");
  if (!c.noise) {
    return NeedsKey("mag_noise",
                    "the magnetometer's white-noise σ per sample and axis, in mag_unit");
  }
  if (Status s = PredictOnce(config, c, protocol, 1, result); !s.ok()) return s;
  json mean = (*result)["uncertainty"];
  int runs = 1;
  for (uint64_t seed = 2; seed <= kPlanSeeds; ++seed) {
    json other;
    if (!PredictOnce(config, c, protocol, seed, &other).ok()) continue;
    AddNumbers(other["uncertainty"], &mean);
    ++runs;
  }
  ScaleNumbers(1.0 / runs, &mean);
  (*result)["uncertainty"] = mean;
  return Status::Ok();
}

// The first `positions` up directions of the greedy D-optimal sequence (file comment).
std::vector<const PlanCandidate*> MagGreedySequence(int positions, const PlanProtocol& protocol,
                                                    double dip) {
  std::vector<const PlanCandidate*> chosen;
  std::vector<Eigen::Vector3d> up;
  for (const PlanCandidate& c : PlanCandidates()) {
    if (c.name == "+z") chosen.push_back(&c);
  }
  up.push_back(chosen.back()->direction);
  while (static_cast<int>(chosen.size()) < positions) {
    double best = -INFINITY;
    const PlanCandidate* pick = nullptr;
    for (const PlanCandidate& c : PlanCandidates()) {
      if (&c == chosen.back()) continue;  // the same orientation again is one longer static
      up.push_back(c.direction);
      const double value = Criterion(up, protocol, dip);
      up.pop_back();
      if (pick == nullptr || value > best + 1e-9) {
        best = value;
        pick = &c;
      }
    }
    chosen.push_back(pick);
    up.push_back(pick->direction);
  }
  return chosen;
}

json SuggestMag(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
                double dip) {
  SuggestSettings settings;
  settings.min_positions = core::MagOptions().min_alignment_statics;
  settings.max_positions = 26;
  return SuggestGreedyProtocol(
      settings, protocol, limits, {std::begin(kSigmaKeys), std::end(kSigmaKeys)},
      "greedy D-optimal over the 26 up directions ±x, ±y, ±z, the 12 edge and 8 corner "
      "diagonals, starting flat (+z up), each joined to the previous one by the shortest "
      "rotation: the candidate that most increases log det of the ellipsoid's information (the "
      "field's directions in the body frame over the statics and turns) plus log det of the "
      "alignment's (the statics' field and down directions) at nominal values",
      "the mag method on the simulated logs",
      [&](int cap) { return MagGreedySequence(cap, protocol, dip); },
      [&](const PlanProtocol& p, json* result) { return PredictMag(config, p, result); },
      [&](const json& result, const AcceptanceLimits& margined, Verdict* verdict) {
        MagMethod().Judge(result, config, margined, verdict);
      },
      "the alignment needs " + std::to_string(settings.min_positions) + " statics");
}

Status PlanMag(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
               json* out) {
  if (Status s = RequireOrientations(protocol); !s.ok()) return s;
  json result;
  const Status s = PredictMag(config, protocol, &result);
  if (s.code() == StatusCode::kInvalidInput) return s;
  MagPlanConfig c;
  if (Status r = ReadMagPlanConfig(config, &c); !r.ok()) return r;
  json& o = *out;
  o = {{"method", "mag"},
       {"protocol",
        {{"orientations", OrientationsJson(protocol.orientations, protocol.labels)},
         {"static_duration", protocol.static_duration},
         {"rate", protocol.rate},
         {"rotation_duration", protocol.rotation_duration},
         {"rotations", "the shortest rotation between consecutive orientations"},
         {"field", c.field},
         {"dip", c.dip}}},
       {"undetermined", json::array()},
       {"uncertainty", nullptr},
       {"suggested", nullptr},
       {"notes",
        {"the orientations are the body's attitudes in a level frame (x north, z up) where the "
         "field has the config's magnitude and dip (default 60 degrees): each up direction "
         "reached from the previous by the shortest rotation, the first with no yaw from north",
         "σ is the mean over " + std::to_string(kPlanSeeds) +
             " logs of this protocol simulated with a nominal magnetometer (no hard iron, identity "
             "soft iron, aligned) and mag_noise, of what the mag method reports on them",
         "the suggested protocol keeps this protocol's static duration, rotation duration and "
         "rate"}}};
  o["suggested"] = SuggestMag(config, protocol, limits, c.dip);
  const Directions d = FieldDirections(protocol.orientations, protocol, c.dip);
  if (const std::optional<Eigen::Vector3d> axis = MissingAxis(d)) {
    o["undetermined"].push_back(
        {{"parameters",
          {"soft iron along " + DirectionWords(*axis), "hard iron along " + DirectionWords(*axis)}},
         {"missing",
          {"the field's direction in the body frame never varies along " + DirectionWords(*axis) +
           " (the turns are all about that axis): turn the device about another axis"}}});
  }
  if (!s.ok()) {
    if (o["undetermined"].empty()) {
      o["undetermined"].push_back({{"parameters", {"hard iron", "soft iron", "alignment", "dip"}},
                                   {"missing", {s.message()}}});
    } else {
      o["undetermined"][0]["missing"].push_back(s.message());
    }
    return Status::Ok();
  }
  const json& mag = result["parameters"]["mags"][0];
  if (mag["alignment"].is_null()) {
    o["undetermined"].push_back(
        {{"parameters", {"alignment", "dip"}},
         {"missing", {result["diagnostics"]["mags"][0].value("alignment_note", "")}}});
  }
  o["uncertainty"] = result["uncertainty"];
  Verdict verdict;
  MagMethod().Judge(result, config, limits, &verdict);
  o["verdict"] = verdict.ToJson(limits);
  return Status::Ok();
}

}  // namespace calibd::server
