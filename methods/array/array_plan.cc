// The plan of an array calibration, positions model (SPEC §10, Method::Plan; methods/array/
// array_method.h): the σ CalibrateArray would report for a free-motion protocol (|ω|, |ω̇|, axes
// random or one fixed axis, duration, rate), what the protocol cannot determine, and the shortest
// duration meeting max_position_std.
//
// Predicted σ: the protocol's motion is simulated (fixed seed: per sample ω = angular_rate·u,
// ω̇ = angular_acceleration·v, s = 9.81·w, u, v, w uniform on the sphere; with a rotation_axis
// u = v = ±axis, signs random) and read without noise at the nominal positions by the method's
// simulator (core::SimulateArrayReadings, one gyroscope triad per accelerometer triad); the
// method's own fit (core::CalibrateArray, the config's options) then stops at the truth and its
// CRB at the true motion is the σ a job reports on white-noise residuals (basis "crb"). Cost
// bound (an HTTP request): the replay has at most kReplayRate Hz and kReplaySamples samples; the
// information of the protocol's N samples is kept by scaling both noises by √(N_replay / N)
// (the Fisher information is a sum over i.i.d. samples, ∝ N / σ²).
//
// Undetermined: the directions d with Σ_n A_nᵀ A_n d = 0 (A_n = [ω_n]×² + [ω̇_n]×, the paper's
// Lemma 1): every non-reference triad's position along d. A rotation about one axis leaves the
// components along that axis (the method refuses such a recording: kNotDeterminable). An
// excitation below the method's noise floor is named the same way, with the method's reason.
//
// Suggested: the protocol's motion and rate for the shortest duration whose largest position σ
// meets max_position_std (bisection on log duration in [kShortest, PlanProtocol::kMaxDuration],
// bracketed from the 1/√duration law); a one-axis protocol is first replaced by random axes.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/array_simulation.h"
#include "methods/array/array_method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

constexpr double kReplayRate = 100;       // Hz: the replay's highest sample rate
constexpr int64_t kReplaySamples = 4000;  // the replay's most samples
constexpr double kShortest = 0.1;         // s: the shortest duration a suggestion considers
constexpr uint64_t kSeed = 1;

std::string Sig3(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

// A motion protocol (methods/plan.h, the array keys).
struct Motion {
  double angular_rate = 0, angular_acceleration = 0, duration = 0, rate = 0;
  std::optional<Eigen::Vector3d> axis;
  std::string axis_label;
};

struct Prediction {
  core::ArrayResult fit;  // the fit on the replay (its CRB: the σ)
  Status status;          // the fit's status (kNotDeterminable: undetermined)
  std::vector<Eigen::Vector3d> null_directions;  // of Σ A_nᵀ A_n
  double noise_scale = 1;                        // √(N_replay / N)
  int64_t samples = 0, replay_samples = 0;
  double max_std = 0;  // largest position σ (m)
};

// The replay of `m` and the method's fit on it, σ scaled to the protocol's samples.
Prediction Predict(const core::ArrayProblem& geometry, core::ArrayOptions options,
                   const Motion& m) {
  Prediction p;
  p.samples = std::max<int64_t>(1, std::llround(m.duration * m.rate));
  p.replay_samples = std::min<int64_t>(
      {p.samples, kReplaySamples,
       std::max<int64_t>(1, std::llround(m.duration * std::min(m.rate, kReplayRate)))});
  p.noise_scale = std::sqrt(static_cast<double>(p.replay_samples) / static_cast<double>(p.samples));
  const auto n = static_cast<Eigen::Index>(p.replay_samples);
  core::GaussianRng rng(kSeed);
  Eigen::Matrix3Xd omega(3, n), omega_dot(3, n), s(3, n);
  Eigen::Matrix3d info = Eigen::Matrix3d::Zero();
  for (Eigen::Index i = 0; i < n; ++i) {
    Eigen::Vector3d u, v;
    if (m.axis) {
      u = (rng.Uniform() < 0.5 ? 1 : -1) * *m.axis;
      v = (rng.Uniform() < 0.5 ? 1 : -1) * *m.axis;
    } else {
      u = rng.UnitVector();
      v = rng.UnitVector();
    }
    omega.col(i) = m.angular_rate * u;
    omega_dot.col(i) = m.angular_acceleration * v;
    s.col(i) = 9.81 * rng.UnitVector();
    Eigen::Matrix3d w, wd;
    w << 0, -omega(2, i), omega(1, i), omega(2, i), 0, -omega(0, i), -omega(1, i), omega(0, i), 0;
    wd << 0, -omega_dot(2, i), omega_dot(1, i), omega_dot(2, i), 0, -omega_dot(0, i),
        -omega_dot(1, i), omega_dot(0, i), 0;
    const Eigen::Matrix3d a = w * w + wd;
    info += a.transpose() * a;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(info);
  for (int k = 0; k < 3; ++k) {
    if (eig.eigenvalues()(k) <= 1e-12 * eig.eigenvalues()(2)) {
      p.null_directions.push_back(eig.eigenvectors().col(k));
    }
  }
  core::ArrayProblem problem = geometry;
  const int K = static_cast<int>(geometry.nominal_positions.cols());
  core::SimulateArrayReadings(geometry.nominal_positions, omega, omega_dot, s, 0, 0, K, &rng,
                              &problem.accel, &problem.gyro);
  options.accel_noise *= p.noise_scale;
  options.gyro_noise *= p.noise_scale;
  options.threads = 1;
  options.gyro_saturation.reset();
  options.accel_saturation.reset();
  p.status = core::CalibrateArray(problem, options, &p.fit);
  if (p.status.ok()) p.max_std = p.fit.position_std_crb.cwiseAbs().maxCoeff();
  return p;
}

json Vec3(const Eigen::Vector3d& v) { return {v(0), v(1), v(2)}; }

// The result's uncertainty shape (methods/array/array_result.cc, positions model), basis crb.
json UncertaintyJson(const Prediction& p) {
  const core::ArrayResult& r = p.fit;
  json positions = json::array();
  const auto K = r.position_std_crb.cols();
  for (Eigen::Index k = 0; k < K; ++k) {
    const Eigen::Vector3d std = r.position_std_crb.col(k);
    positions.push_back({{"name", r.names[static_cast<size_t>(k)]},
                         {"std", Vec3(std)},
                         {"crb", {{"std", Vec3(std)}}}});
  }
  return {{"basis", "crb"},
          {"chi2_per_dof", nullptr},
          {"positions", positions},
          {"std_rms", K > 1 ? std::sqrt(r.position_std_crb.squaredNorm() / (3.0 * (K - 1))) : 0.0}};
}

// The limits the prediction fails (empty: it meets them, or sets none).
std::vector<std::string> Unmet(const Prediction& p, const AcceptanceLimits& limits) {
  std::vector<std::string> unmet;
  if (!p.status.ok()) {
    unmet.push_back("the positions are not determined: " + p.status.message());
    return unmet;
  }
  const auto limit = limits.Get("max_position_std");
  if (limit && p.max_std > *limit) {
    unmet.push_back("largest position σ " + Sig3(p.max_std) + " m above max_position_std " +
                    Sig3(*limit) + " m");
  }
  return unmet;
}

json MotionJson(const Motion& m) {
  json out = {{"angular_rate", m.angular_rate},
              {"angular_acceleration", m.angular_acceleration},
              {"rotation_axis", m.axis ? json(m.axis_label) : json(nullptr)},
              {"duration", m.duration},
              {"rate", m.rate}};
  return out;
}

// What the prediction leaves undetermined: per null direction the non-reference triads'
// components along it; or the method's reason when the excitation is below its noise floor.
json Undetermined(const Prediction& p, const core::ArrayProblem& geometry) {
  json out = json::array();
  if (p.status.ok()) return out;
  const int K = static_cast<int>(geometry.nominal_positions.cols());
  std::vector<Eigen::Vector3d> directions = p.null_directions;
  if (directions.empty()) directions.push_back(p.fit.excitation.weakest_direction);
  for (const Eigen::Vector3d& d : directions) {
    const std::string words = DirectionWords(d);
    json parameters = json::array();
    for (int k = 0; k < K; ++k) {
      if (k != geometry.reference) {
        parameters.push_back("positions[a" + std::to_string(k) + "] along " + words);
      }
    }
    const std::string missing =
        p.null_directions.empty()
            ? "excitation along " + words + " above the noise floor: " + p.status.message()
            : "rotation that moves a triad along " + words + ": every A_n = [ω]×² + [ω̇]× maps " +
                  words + " to 0 (rotation about that axis only); rotate about the other axes too";
    out.push_back({{"parameters", parameters}, {"missing", {missing}}});
  }
  return out;
}

// The protocol's motion (random axes when it turns about one) at the shortest duration meeting
// max_position_std.
json Suggest(const core::ArrayProblem& geometry, const core::ArrayOptions& options, Motion m,
             const Prediction& planned, const AcceptanceLimits& limits) {
  m.axis.reset();
  m.axis_label.clear();
  const auto limit = limits.Get("max_position_std");
  const auto meets = [&](double duration) {
    Motion t = m;
    t.duration = duration;
    return Unmet(Predict(geometry, options, t), limits).empty();
  };
  double duration = m.duration;
  std::string design;
  if (!limit) {
    design = "no max_position_std in force: the protocol's duration (about random axes)";
  } else {
    // σ ∝ 1/√duration: bracket around the law's estimate, then bisect on log duration.
    double guess = m.duration;
    if (planned.status.ok() && planned.max_std > 0) {
      guess = m.duration * std::pow(planned.max_std / *limit, 2);
    }
    guess = std::clamp(guess, kShortest, PlanProtocol::kMaxDuration);
    double hi = std::min(PlanProtocol::kMaxDuration, guess * 1.5);
    double lo = std::max(kShortest, guess / 1.5);
    while (!meets(hi) && hi < PlanProtocol::kMaxDuration) {
      lo = hi;
      hi = std::min(PlanProtocol::kMaxDuration, hi * 4);
    }
    while (lo > kShortest && meets(lo)) {
      hi = lo;
      lo = std::max(kShortest, lo / 4);
    }
    if (meets(lo)) hi = lo;
    for (int i = 0; i < 30 && hi / lo > 1.01 && meets(hi); ++i) {
      const double mid = std::sqrt(lo * hi);
      (meets(mid) ? hi : lo) = mid;
    }
    duration = hi;
    design =
        "the protocol's angular_rate, angular_acceleration and rate about random axes, at "
        "the shortest duration whose largest position σ meets max_position_std (bisection "
        "on log duration in [" +
        Sig3(kShortest) + ", " + Sig3(PlanProtocol::kMaxDuration) + "] s, to 1 %)";
  }
  m.duration = duration;
  const Prediction p = Predict(geometry, options, m);
  json out = MotionJson(m);
  out["design"] = design;
  out["unmet"] = Unmet(p, limits);
  out["meets_limits"] = out["unmet"].empty();
  out["uncertainty"] = p.status.ok() ? UncertaintyJson(p) : json();
  return out;
}

}  // namespace

Status PlanArray(const core::ArrayProblem& geometry, const core::ArrayOptions& options,
                 const PlanProtocol& protocol, const AcceptanceLimits& limits, json* out) {
  if (!protocol.angular_rate) {
    return Status::InvalidInput(
               "protocol.angular_rate: an array plan needs the motion: angular_rate (|ω|, rad/s), "
               "optionally angular_acceleration (|ω̇|, rad/s²), rotation_axis, duration (s), rate")
        .WithField("protocol.angular_rate");
  }
  Motion m{
      *protocol.angular_rate,
      protocol.angular_acceleration > 0 ? protocol.angular_acceleration : *protocol.angular_rate,
      protocol.duration,
      protocol.rate,
      protocol.rotation_axis,
      protocol.rotation_axis_label};
  const Prediction p = Predict(geometry, options, m);
  if (!p.status.ok() && p.status.code() != StatusCode::kNotDeterminable) return p.status;
  json& o = *out;
  o = {{"method", "array"},
       {"model", "positions"},
       {"protocol", MotionJson(m)},
       {"undetermined", Undetermined(p, geometry)},
       {"uncertainty", p.status.ok() ? UncertaintyJson(p) : json()},
       {"unmet", Unmet(p, limits)},
       {"replay", {{"samples", p.samples}, {"replay_samples", p.replay_samples}, {"seed", kSeed}}},
       {"notes",
        {"σ is the Cramér–Rao bound the method's own fit reports (basis crb, i.e. white-noise "
         "residuals) on a noise-free replay of this motion at the nominal positions, one "
         "gyroscope triad per accelerometer triad",
         "the replay has at most " + Sig3(kReplayRate) + " Hz and " +
             std::to_string(kReplaySamples) +
             " samples; the protocol's information is kept by scaling the noise by √(replay "
             "samples / protocol samples) = " +
             Sig3(p.noise_scale)}}};
  o["meets_limits"] = o["unmet"].empty();
  for (const std::string& w : p.fit.warnings) o["notes"].push_back("the fit: " + w);
  o["suggested"] = Suggest(geometry, options, m, p, limits);
  return Status::Ok();
}

}  // namespace calibd::server
