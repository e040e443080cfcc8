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
// Cost bound (an HTTP request; the fit is O(N_d K²) per pass for N_d dynamic samples and K
// triads): the statics are replayed at the rate cut to at most kReplayRate Hz and
// kReplayStaticSamples samples (factor f_s; they keep their durations in seconds, so the static
// detection trims them as in a real log; below kMinReplayRate the protocol is refused, naming
// protocol.static_duration), the dynamic phase as at most kReplayWork / K² i.i.d. samples
// (factor f_d). The information, a sum over samples ∝ N / σ², is kept by scaling the statics'
// noise by √f_s and the dynamic samples' by √f_d (core::ArrayFullOptions::dynamic_noise_scale).
// The fit's rotation-excitation check compares the mean squared rate with the gyroscope noise at
// the statics' scaling: above 100 Hz it is more lenient than a job's by 1/f_s.
//
// Undetermined: the method's own refusal on the replay (too few statics found, statics that do
// not span the sphere, too little rotation about an axis, null directions of the information),
// with the parameters it names, and the directions the orientations miss (methods/plan.h).
//
// Suggested: the same orientations and motion (about random axes when the protocol turns about
// one) with every duration (each static's and the dynamic phase's) scaled by one factor c, the
// smallest whose prediction passes the gate with its σ limits tightened by kMargin. Every σ
// follows 1/√c but for the statics' trimming: c starts at the law's value from the protocol's own
// prediction (the gate alone, judged at scaled limits: no fit) and is bracketed and bisected on
// log c to 1 % with the method's fits (typically 3-4 of them). One protocol length instead of
// two: the statics fix the accelerometers and the gyroscope biases, the motion the gyroscope
// gains and the positions, and both shrink together.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/array_full_simulation.h"
#include "methods/array/array_internal.h"
#include "methods/array/array_method.h"

namespace calibd::server {
namespace {

using nlohmann::json;

constexpr double kReplayRate = 100;              // Hz: the replay's highest sample rate
constexpr int64_t kReplayStaticSamples = 20000;  // the replay's most static samples
constexpr double kMinReplayRate = 10;  // Hz: below it the statics' detection has too few samples
// The replay's dynamic samples: at most kReplayWork / K² (the fit's cost per sample grows as K²),
// within [kMinReplayDynamic, kMaxReplayDynamic]: 4000 for 8 IMUs, 250 for 32.
constexpr double kReplayWork = 256000;
constexpr int64_t kMinReplayDynamic = 200, kMaxReplayDynamic = 4000;
constexpr double kMargin = 0.1;          // the suggestion's σ limits are met by 10 %
constexpr double kSpecificForce = 9.81;  // |s| of the dynamic samples, m/s²
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

  int64_t StaticSamples() const {
    return static_cast<int64_t>(up.size()) *
           std::max<int64_t>(1, std::llround(static_duration * rate));
  }
  int64_t DynamicSamples() const { return std::llround(duration * rate); }
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
  int64_t samples = 0, replay_samples = 0, replay_dynamic_samples = 0;
  double replay_rate = 0;
  double static_scale = 1, dynamic_scale = 1;  // f_s, f_d: replay samples / protocol samples
};

Prediction Predict(const Setup& setup, const Protocol& m, const AcceptanceLimits& limits) {
  Prediction p;
  p.samples = m.StaticSamples() + m.DynamicSamples();
  const int K = static_cast<int>(setup.geometry.nominal_positions.cols());
  p.static_scale = std::min({1.0, kReplayRate / m.rate,
                             static_cast<double>(kReplayStaticSamples) /
                                 static_cast<double>(std::max<int64_t>(1, m.StaticSamples()))});
  p.replay_rate = m.rate * p.static_scale;
  const auto most_dynamic = std::clamp<int64_t>(std::llround(kReplayWork / (K * K)),
                                                kMinReplayDynamic, kMaxReplayDynamic);
  p.replay_dynamic_samples = std::min(m.DynamicSamples(), most_dynamic);
  p.dynamic_scale = m.DynamicSamples() > 0 ? static_cast<double>(p.replay_dynamic_samples) /
                                                 static_cast<double>(m.DynamicSamples())
                                           : 1.0;
  if (p.replay_rate < kMinReplayRate) {
    p.status = Status::InvalidInput(
                   "protocol: the statics' " + std::to_string(m.StaticSamples()) +
                   " samples are too many to replay for a plan (their replay would run at " +
                   Sig3(p.replay_rate) + " Hz, below " + Sig3(kMinReplayRate) + " Hz: at most " +
                   std::to_string(kReplayStaticSamples) +
                   " samples); plan shorter statics, their σ scales as 1/√duration")
                   .WithField("protocol.static_duration");
    p.verdict.Reject(p.status.message());
    return p;
  }
  core::ArrayFullSimulationOptions so;
  so.nominal_positions = setup.geometry.nominal_positions;
  so.reference = setup.geometry.reference;
  so.rate = p.replay_rate;
  so.static_directions = m.up;
  so.static_duration = m.static_duration;
  so.dynamic_samples = p.replay_dynamic_samples;
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
  // The information of every part kept (a sum over samples, ∝ N / σ²): the statics' σ scaled
  // by √f_s, the dynamic samples' by √f_d.
  options.accel_noise *= std::sqrt(p.static_scale);
  options.gyro_noise *= std::sqrt(p.static_scale);
  options.dynamic_noise_scale = std::sqrt(p.dynamic_scale / p.static_scale);
  options.dynamic_weighting = core::ArrayFullDynamicWeighting::kNoise;
  options.residual_aware_sigma = false;  // no residuals in a noise-free replay
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
  if (p.status.reason() == core::array_reason::kWeakExcitation) {  // not a refusal before it
    parameters.push_back("gyroscope gains and misalignments along the body axis " +
                         DirectionWords(p.fit.weakest_rotation_axis) +
                         ", and the positions' lever arms it turns");
  }
  missing.push_back(p.status.message());
  out.push_back({{"parameters", parameters}, {"missing", missing}});
  return out;
}

// The smallest λ for which `result` passes the gate with its σ limits multiplied by λ (the gate
// only, no fit: log bisection to 1e-6); nullopt when it fails for a reason other than σ.
std::optional<double> SigmaLimitFactor(const Setup& setup, const json& result,
                                       const AcceptanceLimits& limits) {
  const auto passes = [&](double lambda) {
    AcceptanceLimits scaled = limits;
    for (const char* key : kSigmaKeys) {
      const auto it = scaled.values.find(key);
      if (it != scaled.values.end() && it->second) *it->second *= lambda;
    }
    Verdict verdict;
    JudgeArray(result, setup.config, scaled, &verdict);
    return verdict.accepted();
  };
  double lo = 1e-6, hi = 1e6;
  if (!passes(hi)) return std::nullopt;
  if (passes(lo)) return lo;
  while (hi / lo > 1 + 1e-6) {
    const double mid = std::sqrt(lo * hi);
    (passes(mid) ? hi : lo) = mid;
  }
  return hi;
}

json Suggest(const Setup& setup, Protocol m, const Prediction& planned,
             const AcceptanceLimits& limits) {
  const bool one_axis = m.axis.has_value();
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
  // The protocol's own prediction (about random axes: a new one when it turned about one).
  Prediction chosen = one_axis ? predict(1) : planned;
  if (!one_axis && chosen.status.ok()) {
    chosen.verdict = Verdict();
    JudgeArray(chosen.result, setup.config, margined, &chosen.verdict);
  }
  double c = 1;
  std::string design;
  if (!any_sigma_limit) {
    design = "no σ limit in force: the protocol as it is (about random axes)";
  } else {
    // Every σ ∝ 1/√c (but for the statics' trimming): the law's factor from the protocol's own
    // prediction, c₀ = λ² for the smallest λ at which its σ meet the limits × λ; then bracketed by
    // predictions in steps of 3 % (doubling in log while on one side) and bisected on log c to
    // 1 %. Invariant: hi passes, lo fails (or is the shortest).
    constexpr double kShortest = 1e-3;
    double c0 = 1;
    if (chosen.status.ok()) {
      if (const auto lambda = SigmaLimitFactor(setup, chosen.result, margined)) {
        c0 = *lambda * *lambda;
      }
    }
    // Statics shorter than min_static are not found (the law cannot see that): start no lower.
    const double floor =
        m.static_duration > 0 ? setup.options.statics.min_static / m.static_duration : kShortest;
    c0 = std::clamp(std::max(c0, floor), kShortest, longest);
    double hi = c0, lo = c0, step = 1.03;
    Prediction at_hi = predict(hi);
    bool hi_passes = at_hi.verdict.accepted();
    if (hi_passes) {
      for (lo = std::max(kShortest, hi / step); lo < hi; lo = std::max(kShortest, hi / step)) {
        Prediction at_lo = predict(lo);
        if (!at_lo.verdict.accepted()) break;
        hi = lo;
        at_hi = std::move(at_lo);
        step *= step;
      }
    } else {
      while (!hi_passes && hi < longest) {
        lo = hi;
        hi = std::min(longest, hi * step);
        step *= step;
        at_hi = predict(hi);
        hi_passes = at_hi.verdict.accepted();
      }
    }
    for (int i = 0; i < 30 && hi_passes && hi / lo > 1.01; ++i) {
      const double mid = std::sqrt(lo * hi);
      Prediction at_mid = predict(mid);
      if (at_mid.verdict.accepted()) {
        hi = mid;
        at_hi = std::move(at_mid);
      } else {
        lo = mid;
      }
    }
    c = hi;
    chosen = std::move(at_hi);
    design =
        "the protocol's orientations and motion (about random axes) with every duration (each "
        "static's and the dynamic phase's) scaled by one factor, the smallest whose prediction "
        "passes the gate with its σ limits tightened by " +
        Sig3(100 * kMargin) +
        " % (from the factor the 1/√duration law gives, bisection on its log to 1 %)";
  }
  json out = ProtocolJson(m.Scaled(c));
  out["scale"] = c;
  out["design"] = design;
  out["margin"] = kMargin;
  out["unmet"] = chosen.verdict.reasons();
  out["meets_limits"] = chosen.verdict.accepted();
  out["uncertainty"] = chosen.status.ok() ? chosen.result["uncertainty"] : json();
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
         {"replay_dynamic_samples", p.replay_dynamic_samples},
         {"seed", kSeed}}},
       {"notes",
        {"σ is the Cramér–Rao bound the full model's own fit reports (basis crb, i.e. white-noise "
         "residuals) on a noise-free replay of this protocol with a nominal array: a real "
         "recording whose residuals exceed the noise reports the larger sandwich σ",
         "the replay runs at " + Sig3(p.replay_rate) + " Hz (at most " + Sig3(kReplayRate) +
             " Hz and " + std::to_string(kReplayStaticSamples) + " static samples) with " +
             std::to_string(p.replay_dynamic_samples) + " dynamic samples (at most " +
             Sig3(kReplayWork) +
             " / IMUs²); the protocol's information is kept by scaling the statics' noise by " +
             Sig3(std::sqrt(p.static_scale)) + " and the dynamic samples' by " +
             Sig3(std::sqrt(p.dynamic_scale))}}};
  if (p.status.ok()) o["verdict"] = p.verdict.ToJson(limits);
  // The fit's warnings about the protocol (e.g. little rotation about an axis).
  for (const std::string& w : p.fit.warnings) o["notes"].push_back("the fit: " + w);
  o["suggested"] = Suggest(setup, m, p, limits);
  return Status::Ok();
}

}  // namespace calibd::server
