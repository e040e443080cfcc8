// The plan of an array calibration, full model (SPEC §10, Method::Plan; methods/array/
// array_method.h PlanArrayFull): the σ of every triad's gains, misalignments, biases and position
// that a job of the full model would report for a protocol, what the protocol cannot determine,
// and the shortest protocol of the same shape that meets the gate's σ limits.
//
// Protocol: the statics first (`orientations`, the "up" direction in the sensors' axes, each
// held `static_duration` s, in order), then the dynamic phase: `duration` s of free motion at
// |ω| = angular_rate, |ω̇| = angular_acceleration, about random axes or `rotation_axis` only, all
// logged at `rate` (the positions model's motion keys, methods/array/array_plan.cc).
//
// Predicted σ: the protocol is replayed without noise by core::SimulateArrayFull with a nominal
// array (every gain 1, no misalignment, biases 0, the triads at their nominal positions; the
// statics back to back in the given order, each dynamic sample's ω, ω̇ and specific force (|s| =
// 9.81 m/s²) drawn with those norms, fixed seed). The method's own fit (core::CalibrateArrayFull,
// the config's options at its configured noise, weighting by the noise) then stops at the truth,
// and its Cramér–Rao bound there is the σ a job reports on white-noise residuals (basis crb). The
// result is written as a job writes it (FullResultJson) and judged by the method's gate.
//
// Cost bound (an HTTP request; the fit is O(N K²) per iteration for N samples and K triads): the
// replay runs at the rate cut to at most kReplayRate Hz and kReplaySamples samples in all. Every
// part of the protocol (each static's samples, the dynamic samples) shrinks by the same factor f,
// so scaling both noises by √f keeps the protocol's information (a sum over samples, ∝ N / σ²).
// The statics keep their durations in seconds, so the static detection trims them as in a real
// log; a protocol whose replay would run below kMinReplayRate is refused, naming its length.
//
// Undetermined: the method's own refusal on the replay (too few statics found, statics that do
// not span the sphere, too little rotation about an axis, null directions of the information),
// with the parameters it names, and the directions the orientations miss (methods/plan.h).
//
// Suggested: the same orientations and motion (about random axes when the protocol turns about
// one) with every duration (each static's and the
// dynamic phase's) scaled by one factor c, the smallest whose prediction passes the gate with its
// σ limits tightened by kMargin (bisection on log c to 1 %, bracketed from c = 1 by factors of
// 4; every σ follows 1/√c but for the statics' trimming). One protocol length instead of two: the
// statics fix the accelerometers and the gyroscope biases, the motion the gyroscope gains and the
// positions, and both shrink together.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/array_full_simulation.h"
#include "methods/array/array_internal.h"
#include "methods/array/array_method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

constexpr double kReplayRate = 100;       // Hz: the replay's highest sample rate
constexpr int64_t kReplaySamples = 4000;  // the replay's most samples (statics and motion)
constexpr double kMinReplayRate = 10;     // Hz: below it the statics' detection has too few samples
constexpr double kMargin = 0.1;           // the suggestion's σ limits are met by 10 %
constexpr double kSpecificForce = 9.81;   // |s| of the dynamic samples, m/s²
constexpr uint64_t kSeed = 1;
// The σ keys of the array gate (AcceptanceKeys): the ones the suggestion's margin tightens.
constexpr const char* kSigmaKeys[] = {"max_position_std", "max_scale_std", "max_axis_std",
                                      "max_accel_bias_std", "max_gyro_bias_std"};

std::string Sig3(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

// What the plan reads of the config: the full model's geometry and options, the gyro unit.
struct Setup {
  json config;
  core::ArrayFullProblem geometry;
  core::ArrayFullOptions options;
  bool degrees = false;
};

// A statics-then-motion protocol, `scale` times as long in every part.
struct Protocol {
  std::vector<Eigen::Vector3d> up;
  std::vector<std::string> labels;
  double static_duration = 0, duration = 0, rate = 0;
  double angular_rate = 0, angular_acceleration = 0;
  std::optional<Eigen::Vector3d> axis;
  std::string axis_label;

  int64_t Samples() const {
    return static_cast<int64_t>(up.size()) *
               std::max<int64_t>(1, std::llround(static_duration * rate)) +
           std::llround(duration * rate);
  }
  Protocol Scaled(double c) const {
    Protocol p = *this;
    p.static_duration *= c;
    p.duration *= c;
    return p;
  }
};

struct Prediction {
  Status status;  // the fit's (kNotDeterminable: undetermined; kInvalidInput: the replay's sizes)
  core::ArrayFullResult fit;
  json result;  // as a job writes it
  Verdict verdict;
  int64_t samples = 0, replay_samples = 0;
  double replay_rate = 0, noise_scale = 1;
};

Prediction Predict(const Setup& setup, const Protocol& m, const AcceptanceLimits& limits) {
  Prediction p;
  p.samples = m.Samples();
  const double f = std::min({1.0, kReplayRate / m.rate,
                             static_cast<double>(kReplaySamples) / static_cast<double>(p.samples)});
  p.replay_rate = m.rate * f;
  p.noise_scale = std::sqrt(f);
  if (p.replay_rate < kMinReplayRate) {
    p.status = Status::InvalidInput(
                   "protocol: " + std::to_string(p.samples) +
                   " samples are too long to replay for a plan (its replay would run at " +
                   Sig3(p.replay_rate) + " Hz, below " + Sig3(kMinReplayRate) + " Hz: at most " +
                   std::to_string(kReplaySamples) +
                   " samples in all); plan a shorter protocol, its σ scales as 1/√duration")
                   .WithField("protocol.duration");
    p.verdict.Reject(p.status.message());
    return p;
  }
  core::ArrayFullSimulationOptions so;
  so.nominal_positions = setup.geometry.nominal_positions;
  so.reference = setup.geometry.reference;
  so.rate = p.replay_rate;
  so.static_directions = m.up;
  so.static_duration = m.static_duration;
  so.dynamic_samples = std::llround(m.duration * p.replay_rate);
  so.omega_norm = m.angular_rate;
  so.omega_dot_norm = m.angular_acceleration;
  so.specific_force_norm = kSpecificForce;
  so.rotation_axis = m.axis;
  so.accel_noise = so.gyro_noise = 0;
  so.gain_error = so.misalignment = so.accel_bias = so.gyro_bias = 0;
  so.position_perturbation = 0;
  so.gravity = setup.options.gravity;
  so.seed = kSeed;
  core::ArrayFullSimulation sim;
  if (p.status = core::SimulateArrayFull(so, &sim); !p.status.ok()) {
    p.verdict.Reject(p.status.message());
    return p;
  }
  p.replay_samples = sim.problem.t.size();
  core::ArrayFullOptions options = setup.options;
  options.accel_noise *= p.noise_scale;
  options.gyro_noise *= p.noise_scale;
  options.dynamic_weighting = core::ArrayFullDynamicWeighting::kNoise;
  options.threads = 1;
  options.gyro_saturation.reset();
  options.accel_saturation.reset();
  core::ArrayFullProblem problem = std::move(sim.problem);
  problem.names = setup.geometry.names;
  p.status = core::CalibrateArrayFull(problem, options, &p.fit);
  p.result = array_detail::FullResultJson(p.fit, p.status, problem, options, setup.degrees,
                                          std::nullopt, {});
  if (p.status.ok()) {
    JudgeArray(p.result, setup.config, limits, &p.verdict);
  } else {
    p.verdict.Reject(p.status.message());
  }
  return p;
}

json ProtocolJson(const Protocol& m) {
  json orientations = json::array();
  for (size_t j = 0; j < m.up.size(); ++j) {
    orientations.push_back(
        {{"name", m.labels[j]}, {"direction", {m.up[j](0), m.up[j](1), m.up[j](2)}}});
  }
  return {{"orientations", orientations},
          {"static_duration", m.static_duration},
          {"angular_rate", m.angular_rate},
          {"angular_acceleration", m.angular_acceleration},
          {"rotation_axis", m.axis ? json(m.axis_label) : json(nullptr)},
          {"duration", m.duration},
          {"rate", m.rate}};
}

// The limits with the σ keys tightened by the margin.
AcceptanceLimits Margined(const AcceptanceLimits& limits) {
  AcceptanceLimits margined = limits;
  for (const char* key : kSigmaKeys) {
    const auto it = margined.values.find(key);
    if (it != margined.values.end() && it->second) *it->second *= 1 - kMargin;
  }
  return margined;
}

// What the protocol leaves undetermined: the method's refusal with the parameters it names, and
// the directions the statics miss.
json Undetermined(const Prediction& p, const Protocol& m) {
  json out = json::array();
  if (p.status.ok()) return out;
  std::vector<std::string> parameters = p.fit.null_directions;
  std::vector<std::string> missing = MissingDirections(m.up, /*with_bias=*/true);
  for (const std::string& words : missing) {
    parameters.push_back("accelerometer gains, misalignments and biases: " + words);
  }
  if (p.fit.rotation_verdict == "insufficient" && p.fit.dynamic_samples > 0) {
    parameters.push_back("gyroscope gains and misalignments along the body axis " +
                         DirectionWords(p.fit.weakest_rotation_axis) +
                         ", and the positions' lever arms it turns");
  }
  missing.push_back(p.status.message());
  out.push_back({{"parameters", parameters}, {"missing", missing}});
  return out;
}

json Suggest(const Setup& setup, Protocol m, const AcceptanceLimits& limits) {
  m.axis.reset();  // a one-axis motion leaves the gyroscope along the other axes undetermined
  m.axis_label.clear();
  const AcceptanceLimits margined = Margined(limits);
  bool any_sigma_limit = false;
  for (const char* key : kSigmaKeys) any_sigma_limit = any_sigma_limit || limits.Get(key);
  const double longest =
      std::min(PlanProtocol::kMaxDuration / std::max(m.duration, 1e-9),
               PlanProtocol::kMaxStaticDuration / std::max(m.static_duration, 1e-9));
  int predictions = 0;
  const auto predict = [&](double c) {
    ++predictions;
    return Predict(setup, m.Scaled(c), margined);
  };
  double c = 1;
  std::string design;
  if (!any_sigma_limit) {
    design = "no σ limit in force: the protocol as it is (about random axes)";
  } else {
    // σ ∝ 1/√c: bracket from c = 1 by factors of 4, then bisect on log c. Invariant once
    // bracketed: hi passes, lo fails (or is the shortest).
    constexpr double kShortest = 1e-3;
    double hi = std::min(longest, 1.5), lo = std::max(kShortest, 1 / 1.5);
    bool hi_passes = predict(hi).verdict.accepted();
    while (!hi_passes && hi < longest) {
      lo = hi;
      hi = std::min(longest, hi * 4);
      hi_passes = predict(hi).verdict.accepted();
    }
    while (hi_passes && lo > kShortest && predict(lo).verdict.accepted()) {
      hi = lo;
      lo = std::max(kShortest, lo / 4);
    }
    for (int i = 0; i < 30 && hi_passes && hi / lo > 1.01; ++i) {
      const double mid = std::sqrt(lo * hi);
      (predict(mid).verdict.accepted() ? hi : lo) = mid;
    }
    c = hi;
    design =
        "the protocol's orientations and motion (about random axes) with every duration (each "
        "static's and the dynamic phase's) scaled by one factor, the smallest whose prediction "
        "passes the gate with "
        "its σ limits tightened by " +
        Sig3(100 * kMargin) + " % (bisection on the log of the factor, to 1 %)";
  }
  const Protocol chosen = m.Scaled(c);
  const Prediction p = Predict(setup, chosen, margined);
  ++predictions;
  json out = ProtocolJson(chosen);
  out["scale"] = c;
  out["design"] = design;
  out["margin"] = kMargin;
  out["unmet"] = p.verdict.reasons();
  out["meets_limits"] = p.verdict.accepted();
  out["uncertainty"] = p.status.ok() ? p.result["uncertainty"] : json();
  out["predictions"] = predictions;
  return out;
}

}  // namespace

Status PlanArrayFull(const json& config, const PlanProtocol& protocol,
                     const AcceptanceLimits& limits, json* out) {
  Setup setup;
  setup.config = config;
  if (Status s = ParseArrayFullConfig(config, &setup.geometry, &setup.options, &setup.degrees);
      !s.ok()) {
    return s;
  }
  for (const char* key : {"accel_noise", "gyro_noise"}) {
    if (!config.contains(key)) {
      return Status::InvalidInput(
                 std::string("config.") + key +
                 ": the full model's plan needs the white-noise σ per sample (accel_noise in "
                 "m/s², gyro_noise in gyro_unit)")
          .WithField(std::string("config.") + key);
    }
  }
  if (Status s = RequireOrientations(protocol); !s.ok()) return s;
  if (!protocol.angular_rate) {
    return Status::InvalidInput(
               "protocol.angular_rate: the full model's plan needs the dynamic phase after the "
               "statics: angular_rate (|ω|, rad/s), optionally angular_acceleration (|ω̇|, "
               "rad/s²), rotation_axis, duration (s)")
        .WithField("protocol.angular_rate");
  }
  Protocol m;
  m.up = protocol.orientations;
  m.labels = protocol.labels;
  m.static_duration = protocol.static_duration;
  m.duration = protocol.duration;
  m.rate = protocol.rate;
  m.angular_rate = *protocol.angular_rate;
  m.angular_acceleration =
      protocol.angular_acceleration > 0 ? protocol.angular_acceleration : *protocol.angular_rate;
  m.axis = protocol.rotation_axis;
  m.axis_label = protocol.rotation_axis_label;
  const Prediction p = Predict(setup, m, limits);
  if (p.status.code() == StatusCode::kInvalidInput) return p.status;
  json& o = *out;
  o = {{"method", "array"},
       {"model", "full"},
       {"protocol", ProtocolJson(m)},
       {"undetermined", Undetermined(p, m)},
       {"uncertainty", p.status.ok() ? p.result["uncertainty"] : json()},
       {"unmet", p.verdict.reasons()},
       {"meets_limits", p.verdict.accepted()},
       {"replay",
        {{"samples", p.samples},
         {"replay_samples", p.replay_samples},
         {"replay_rate", p.replay_rate},
         {"seed", kSeed}}},
       {"notes",
        {"σ is the Cramér–Rao bound the full model's own fit reports (basis crb, i.e. white-noise "
         "residuals) on a noise-free replay of this protocol with a nominal array: a real "
         "recording whose residuals exceed the noise reports the larger sandwich σ",
         "the replay has at most " + Sig3(kReplayRate) + " Hz and " +
             std::to_string(kReplaySamples) +
             " samples; the protocol's information is kept by scaling the noise by √(replay "
             "samples / protocol samples) = " +
             Sig3(p.noise_scale)}}};
  if (p.status.ok()) o["verdict"] = p.verdict.ToJson(limits);
  // The fit's warnings about the protocol (e.g. little rotation about an axis); not those of its
  // residual-aware σ, which a noise-free replay makes meaningless.
  for (const std::string& w : p.fit.warnings) {
    if (w.find("residual-aware") == std::string::npos) o["notes"].push_back("the fit: " + w);
  }
  o["suggested"] = Suggest(setup, m, limits);
  return Status::Ok();
}

}  // namespace calibd::server
