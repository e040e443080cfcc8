// The plan of an imu calibration (SPEC §10, Method::Plan): the σ the imu method would report for
// a protocol, and what the protocol cannot determine.
//
// Predicted σ: the method itself (its Run, static detection included) on the log the protocol
// gives, simulated (core/imu_simulation.h) with a nominal IMU (the config's units and nominal
// biases, no scale, misalignment or bias error), the config's noise figures (accel_noise,
// gyro_noise: numbers, or {"job": ID} of a noise job resolved like an upload's), the protocol's
// orientations in order, static duration and rate, and the shortest rotation of
// rotation_duration between consecutive statics. The log is simulated at its full length (the
// gyroscope's information comes from the rotations, which do not scale with the statics), so
// the σ is the method's Cramér–Rao bound at a near-nominal estimate: within Monte-Carlo
// resolution of what a calibration of such a recording reports (tests/server/plan_test.cc).
//
// Undetermined: when the method cannot calibrate the protocol, its message and the directions
// the orientations miss (methods/plan.h MissingDirections: the null space of Σ_j [u_j; 1][u_j; 1]ᵀ,
// which is exactly that of the accelerometer's information in its bias and its response to the
// field, ȳ_j = b_a + M u_j, for known directions u_j).
//
// Suggested (SuggestImu): a sequence of orientations from the 26 candidates (methods/plan.h),
// each joined to the previous one by the shortest rotation, chosen greedily by D-optimality of a
// linearised information at nominal values (ImuDesignInformation below): starting flat (+z up),
// append the candidate (other than the current orientation) that most increases
// log det(I_accel + εI) + log det(I_gyro + εI), keeping room for the faces ±x, ±y, ±z the method's
// coverage rule needs by its minimum of statics (then only the missing faces are candidates). The
// sum is the log det of the block-diagonal information, so the noise figures, durations and rate
// (equal for every static and rotation) scale each block by a constant and do not change the
// choice: the sequence is the same for every config; only where it stops depends on them. Where it
// stops: the fewest positions k of that sequence (at least the method's min_statics, at most
// max_positions) whose predicted result (PredictImu, the method itself) passes the method's gate
// with the σ limits tightened by `margin`, found by bisection (k and k − 1 are both predicted, so k
// − 1 is known to fail); when even max_positions fail, the unmet rules are named. Work: at most 1 +
// ⌈log2(max_positions − min_statics + 1)⌉ runs of the method on simulated logs of at most
// max_positions statics and ImuSuggestOptions::max_samples samples.
#include "methods/imu/imu_plan.h"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "methods/imu/imu_method.h"
#include "methods/plan.h"

namespace calibd::server {
namespace {

using nlohmann::json;

// The σ keys of the imu gate (methods/acceptance.h ImuTriadKeys): the ones the suggestion's
// margin tightens.
constexpr const char* kSigmaKeys[] = {"max_scale_std", "max_axis_std", "max_accel_bias_std",
                                      "max_gyro_bias_std"};

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d s;
  s << 0, -v(2), v(1), v(2), 0, -v(0), -v(1), v(0), 0;
  return s;
}

// The right Jacobian of SO(3) at φ: Exp(φ + δ) ≈ Exp(φ) Exp(J_r(φ) δ).
Eigen::Matrix3d RightJacobian(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d k = Skew(phi);
  if (theta < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * k;
  return Eigen::Matrix3d::Identity() - (1 - std::cos(theta)) / (theta * theta) * k +
         (theta - std::sin(theta)) / (theta * theta * theta) * k * k;
}

}  // namespace

ImuDesignInformation ImuDesign(const std::vector<Eigen::Vector3d>& up) {
  ImuDesignInformation info;
  info.accel = Eigen::Matrix<double, 9, 9>::Zero();
  info.gyro = Eigen::Matrix<double, 9, 9>::Zero();
  for (const Eigen::Vector3d& u : up) {
    Eigen::Matrix<double, 9, 1> f;
    f << u, u.cwiseProduct(u), u(0) * u(1), u(0) * u(2), u(1) * u(2);
    info.accel += f * f.transpose();
  }
  const std::vector<Eigen::Matrix3d> r = ProtocolRotations(up);
  for (size_t j = 1; j < up.size(); ++j) {
    const Eigen::AngleAxisd step(r[j - 1].transpose() * r[j]);
    const Eigen::Vector3d phi = step.angle() * step.axis();
    Eigen::Matrix<double, 3, 9> dphi = Eigen::Matrix<double, 3, 9>::Zero();
    for (int row = 0; row < 3; ++row) dphi.block<1, 3>(row, 3 * row) = phi.transpose();
    const Eigen::Matrix<double, 3, 9> jac = Skew(up[j]) * RightJacobian(phi) * dphi;
    info.gyro += jac.transpose() * jac;
  }
  return info;
}

double ImuDesignCriterion(const ImuDesignInformation& info) {
  double value = 0;
  for (const Eigen::Matrix<double, 9, 9>* m : {&info.accel, &info.gyro}) {
    Eigen::Matrix<double, 9, 9> regular = *m;
    regular.diagonal().array() += 1e-6;
    const Eigen::LLT<Eigen::Matrix<double, 9, 9>> llt(regular);
    if (llt.info() != Eigen::Success) return -INFINITY;
    value += 2 * llt.matrixLLT().diagonal().array().log().sum();
  }
  return value;
}

std::vector<const PlanCandidate*> ImuGreedySequence(int positions) {
  const int min_positions = core::ImuOptions().min_statics;
  std::vector<const PlanCandidate*> chosen;
  std::vector<Eigen::Vector3d> up;
  std::vector<const PlanCandidate*> faces_missing;  // ±x, ±y, ±z not chosen yet
  for (const PlanCandidate& c : PlanCandidates()) {
    if (c.name.size() == 2) faces_missing.push_back(&c);
  }
  auto take = [&](const PlanCandidate* c) {
    chosen.push_back(c);
    up.push_back(c->direction);
    faces_missing.erase(std::remove(faces_missing.begin(), faces_missing.end(), c),
                        faces_missing.end());
  };
  for (const PlanCandidate& c : PlanCandidates()) {
    if (c.name == "+z") take(&c);
  }
  while (static_cast<int>(chosen.size()) < positions) {
    // The method's coverage rule (every body axis up and down within 45°, core/imu.h
    // ImuCoverage; an edge diagonal is on the boundary) is met by the method's minimum: once
    // the positions left before it are as many as the faces missing, only those are candidates.
    const bool faces_only =
        !faces_missing.empty() &&
        static_cast<int>(faces_missing.size()) >= min_positions - static_cast<int>(chosen.size());
    double best = -INFINITY;
    const PlanCandidate* pick = nullptr;
    for (const PlanCandidate& c : PlanCandidates()) {
      if (&c == chosen.back()) continue;  // the same orientation again is one longer static
      if (faces_only &&
          std::find(faces_missing.begin(), faces_missing.end(), &c) == faces_missing.end()) {
        continue;
      }
      up.push_back(c.direction);
      const double value = ImuDesignCriterion(ImuDesign(up));
      up.pop_back();
      if (pick == nullptr || value > best + 1e-9) {
        best = value;
        pick = &c;
      }
    }
    take(pick);
  }
  return chosen;
}

bool ImuSuggestOptions::IsValid(std::string* error) const {
  if (!(max_positions >= 9 && max_positions <= PlanProtocol::kMaxPositions)) {
    *error = "max_positions must be in [9, " + std::to_string(PlanProtocol::kMaxPositions) +
             "] (the method needs 9 statics)";
    return false;
  }
  if (!(margin >= 0 && margin < 1)) {
    *error = "margin must be in [0, 1)";
    return false;
  }
  if (!(max_samples > 0)) {
    *error = "max_samples must be > 0";
    return false;
  }
  return true;
}

namespace {

Status MissingNoise(const char* key) {
  return Status::InvalidInput(std::string("config.") + key +
                              ": the plan needs the white-noise σ per sample (SI), a number or "
                              "{\"job\": ID} of a noise job")
      .WithField(std::string("config.") + key);
}

}  // namespace

Status PredictImu(const json& config, const PlanProtocol& protocol, json* result) {
  core::ImuOptions options;
  if (Status s = ParseImuOptions(config, &options); !s.ok()) return s;
  if (!options.accel_noise) return MissingNoise("accel_noise");
  if (!options.gyro_noise) return MissingNoise("gyro_noise");
  core::ImuSimulationOptions sim;
  sim.statics = static_cast<int>(protocol.orientations.size());
  sim.orientations = ProtocolRotations(protocol.orientations);
  sim.static_duration = protocol.static_duration;
  sim.rotation_duration = protocol.rotation_duration;
  sim.rate = protocol.rate;
  sim.accel_noise = *options.accel_noise;
  sim.gyro_noise = *options.gyro_noise;
  SetNominalImu(options, &sim);
  std::string csv;
  json sim_config, truth;
  if (Status s = SimulateImuFiles(sim, &csv, &sim_config, &truth); !s.ok()) return s;
  RecordingParser parser("plan.csv", /*collect=*/true);
  ImuMethod().PrepareParser(config, &parser);
  if (Status s = parser.Feed(csv); !s.ok()) return s;
  if (Status s = parser.Finish(); !s.ok()) return s;
  return ImuMethod().Run(&parser, config, RunContext(), result);
}

json SuggestImu(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
                const ImuSuggestOptions& options) {
  SuggestSettings settings;
  settings.min_positions = core::ImuOptions().min_statics;
  settings.max_positions = options.max_positions;
  settings.margin = options.margin;
  settings.max_samples = options.max_samples;
  return SuggestGreedyProtocol(
      settings, protocol, limits, {std::begin(kSigmaKeys), std::end(kSigmaKeys)},
      "greedy D-optimal over the 26 directions ±x, ±y, ±z, the 12 edge and 8 corner diagonals, "
      "starting flat (+z up), each joined to the previous one by the shortest rotation: the "
      "candidate that most increases log det of the linearised accelerometer (|a| = g at each "
      "static) and gyroscope (the gravity direction after each rotation) information at nominal "
      "values",
      "the imu method on the simulated log", ImuGreedySequence,
      [&](const PlanProtocol& p, json* result) { return PredictImu(config, p, result); },
      [&](const json& result, const AcceptanceLimits& margined, Verdict* verdict) {
        ImuMethod().Judge(result, config, margined, verdict);
      },
      "the imu method needs " + std::to_string(settings.min_positions) + " statics");
}

Status PlanImu(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
               json* out) {
  if (Status s = RequireOrientations(protocol); !s.ok()) return s;
  json result;
  const Status s = PredictImu(config, protocol, &result);
  if (s.code() == StatusCode::kInvalidInput) return s;
  json& o = *out;
  o = {{"method", "imu"},
       {"protocol",
        {{"orientations", OrientationsJson(protocol.orientations, protocol.labels)},
         {"static_duration", protocol.static_duration},
         {"rate", protocol.rate},
         {"rotation_duration", protocol.rotation_duration},
         {"rotations", "the shortest rotation between consecutive orientations"}}},
       {"undetermined", json::array()},
       {"uncertainty", nullptr},
       {"suggested", nullptr},
       {"notes",
        {"σ is what the imu method reports for a log of this protocol simulated with a nominal "
         "IMU and the config's noise figures (its Cramér–Rao bound, uncertainty.*.crb, and the "
         "primary σ)",
         "the suggested protocol keeps this protocol's static duration, rotation duration and "
         "rate"}}};
  o["suggested"] = SuggestImu(config, protocol, limits, ImuSuggestOptions());
  if (!s.ok()) {
    std::vector<std::string> parameters;
    std::vector<std::string> missing = MissingDirections(protocol.orientations, true);
    for (const std::string& m : missing) {
      parameters.push_back("accelerometer response (scale, misalignment) and bias: " + m);
    }
    missing.push_back(s.message());
    o["undetermined"].push_back({{"parameters", parameters}, {"missing", missing}});
    return Status::Ok();
  }
  o["uncertainty"] = result["uncertainty"];
  Verdict verdict;
  ImuMethod().Judge(result, config, limits, &verdict);
  o["verdict"] = verdict.ToJson(limits);
  return Status::Ok();
}

}  // namespace calibd::server
