// Planning a calibration before recording it (SPEC §10, issue #27 item 1): the protocol a person
// proposes (orientations, static duration, rate; for imu the rotations between the statics), read
// from JSON with errors naming the field and index, the candidate orientations a suggested
// protocol is chosen from, and the words for what a protocol misses. The numbers (σ, information)
// are each method's own: Method::Plan (methods/method.h) in methods/<name>/.
#ifndef CALIBD_METHODS_PLAN_H_
#define CALIBD_METHODS_PLAN_H_

#include <Eigen/Core>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/status.h"
#include "methods/acceptance.h"

namespace calibd::server {

// A protocol: static positions in order. Plain data; thread-compatible.
struct PlanProtocol {
  // Per static, the unit direction of the field (gravity's reaction, "up") in the body frame of
  // the sensors: "+z" is the z axis pointing up. At least 1, at most kMaxPositions.
  std::vector<Eigen::Vector3d> orientations;
  std::vector<std::string> labels;  // per orientation: its name ("+x+y") or "[x, y, z]"
  double static_duration = 3;       // s per static, in (0, kMaxStaticDuration]
  double rate = 100;                // samples per second, in (0, kMaxRate]
  // s per rotation between consecutive statics (imu), in (0, kMaxStaticDuration]. Each rotation
  // is the shortest one taking one orientation to the next (about the axis perpendicular to
  // both, by the angle between them).
  double rotation_duration = 2;
  // thermal: a warm-up at rest from t_min to t_max °C at temperature_rate °C/min (a linear ramp,
  // t_max > t_min), `imus` IMUs logged together (in [1, kMaxImus]); orientations optional there
  // (each held for an equal part of the ramp). Unset when the protocol names none of them.
  std::optional<double> t_min, t_max;
  double temperature_rate = 1;  // °C/min, in (0, kMaxTemperatureRate]
  int imus = 1;
  // array: free motion for `duration` s, every sample turning at |ω| = angular_rate rad/s with
  // |ω̇| = angular_acceleration rad/s² (default: angular_rate's number, per second), about axes
  // uniform on the sphere, or about rotation_axis only (body frame, unit) when set. Unset when
  // the protocol names no angular_rate.
  std::optional<double> angular_rate;
  double angular_acceleration = 0;  // 0: angular_rate's number
  std::optional<Eigen::Vector3d> rotation_axis;
  std::string rotation_axis_label;  // its name ("+z") or "[x, y, z]"
  double duration = 60;             // s, in (0, kMaxDuration]

  static constexpr int kMaxPositions = 1000;
  static constexpr int kMaxImus = 64;
  static constexpr double kMaxTemperatureRate = 60;
  static constexpr double kMaxStaticDuration = 600;
  static constexpr double kMaxRate = 10000;
  static constexpr double kMaxSamples = 2e7;              // rate × total duration
  static constexpr double kMaxAngularRate = 100;          // rad/s
  static constexpr double kMaxAngularAcceleration = 1e4;  // rad/s²
  static constexpr double kMaxDuration = 3600;            // s
};

// Reads {"orientations": [name or [x, y, z], ...], "static_duration", "rate",
// "rotation_duration", "t_min", "t_max", "temperature_rate", "imus", "angular_rate",
// "angular_acceleration", "rotation_axis", "duration"} (all but orientations optional, defaults
// as above; orientations may be left out when t_min or t_max is given: a thermal protocol, or
// when angular_rate is given: an array's motion protocol. A method needing orientations then names
// protocol.orientations). A name is up to three signed axes, e.g. "+x", "-z", "+x+y", "-x+y-z" (the
// sum, normalised). kInvalidInput with WithField("protocol.orientations[3]") etc. naming what is
// wrong; unknown keys are errors.
Status ParsePlanProtocol(const nlohmann::json& protocol, PlanProtocol* out);

// kInvalidInput naming protocol.orientations when the protocol has none (a thermal protocol sent
// to a method that plans orientations).
Status RequireOrientations(const PlanProtocol& protocol);

// The unit vector of a name such as "+x-y"; kInvalidInput when it is not one.
Status OrientationFromName(const std::string& name, Eigen::Vector3d* out);

// The body orientations R_j (body → world, world z up) of a protocol's up directions:
// R_jᵀ z = u_j, R_0 the shortest rotation from z, each next one from the previous by the shortest
// rotation (about u_{j+1} × u_j, by the angle between them; about some perpendicular axis when
// opposite). What a simulation of the protocol turns the body through.
std::vector<Eigen::Matrix3d> ProtocolRotations(const std::vector<Eigen::Vector3d>& up);

// The candidates of a suggested protocol: the 26 directions ±x, ±y, ±z (6), the 12 edge
// diagonals (+x+y, ...) and the 8 corner diagonals (+x+y+z, ...), unit length, with their names.
struct PlanCandidate {
  std::string name;
  Eigen::Vector3d direction;
};
const std::vector<PlanCandidate>& PlanCandidates();

// The first k positions of a greedy sequence as a protocol (its durations and rate kept).
PlanProtocol PlanPrefix(const std::vector<const PlanCandidate*>& sequence, int k,
                        const PlanProtocol& protocol);

// The suggestion's cut of a greedy sequence (the imu and mag plans): the fewest of its first
// `cap` positions whose prediction passes the gate, by bisection between min_positions − 1 (the
// method refuses it) and cap (passes, or is the cap). `predict` runs the method on a protocol
// (non-OK: no result, its message the reason it fails); `judge` is the method's gate (with the
// plan's tightened limits). Sets `orientations`, `meets_limits`, `unmet`, `uncertainty`, `fewer`
// ({positions, unmet}: one position less and why it fails; `too_few` when that many were not
// predicted, the method refusing them) and `predictions` (the method's runs it took) in *out.
void SuggestFewestPositions(
    const std::vector<const PlanCandidate*>& sequence, const PlanProtocol& protocol,
    int min_positions, int cap,
    const std::function<Status(const PlanProtocol&, nlohmann::json*)>& predict,
    const std::function<void(const nlohmann::json&, Verdict*)>& judge, const std::string& too_few,
    nlohmann::json* out);

// How a suggestion is cut from a greedy sequence (the imu and mag plans). Plain data.
struct SuggestSettings {
  int min_positions = 9;     // >= 1: the fewest statics the method takes (it refuses fewer)
  int max_positions = 24;    // in [min_positions, PlanProtocol::kMaxPositions]: the longest
  double margin = 0.1;       // in [0, 1): the σ limits are met by this fraction (a plan's σ is
                             // within Monte-Carlo resolution of a recording's, not exact)
  double max_samples = 5e5;  // > 0: fewer positions when a log of max_positions has more
};

// The imu and mag plans' `suggested` object: cap = max_positions, less where a log of cap
// positions (the protocol's static and rotation durations and rate) would have more than
// max_samples samples (then none is simulated and `unmet` says so); the gate's `sigma_keys`
// tightened by the margin; the first positions of sequence(cap) cut by SuggestFewestPositions
// (`judge` gets the tightened limits). `design` says how the sequence is chosen, `predicted_by`
// what predicts a protocol's result (e.g. "the imu method on the simulated log"); the object also
// holds `rotations`, `margin`, `orientations`, `meets_limits`, `unmet`, `uncertainty`, `fewer`
// and `predictions`.
nlohmann::json SuggestGreedyProtocol(
    const SuggestSettings& settings, const PlanProtocol& protocol, const AcceptanceLimits& limits,
    const std::vector<std::string>& sigma_keys, const std::string& design,
    const std::string& predicted_by,
    const std::function<std::vector<const PlanCandidate*>(int cap)>& sequence,
    const std::function<Status(const PlanProtocol&, nlohmann::json*)>& predict,
    const std::function<void(const nlohmann::json&, const AcceptanceLimits&, Verdict*)>& judge,
    const std::string& too_few);

// "z" for a unit axis direction (either sign), "[0.71, 0.71, 0]" otherwise: for messages.
std::string DirectionWords(const Eigen::Vector3d& direction);

// The JSON of a protocol's orientations for the answer: [{"name", "direction": [x, y, z]}].
nlohmann::json OrientationsJson(const std::vector<Eigen::Vector3d>& directions,
                                const std::vector<std::string>& labels);

// What the orientations fail to span, from the null space of their design Σ_j f_j f_jᵀ with
// f_j = [u_j; 1] (with_bias) or u_j: the information every method's sensitivities (and biases)
// are estimated from. One sentence per null direction ("no orientation with a component along
// z", "every orientation has the same component along x: the bias and the sensitivity along x are
// not separated"); empty when the design is regular.
std::vector<std::string> MissingDirections(const std::vector<Eigen::Vector3d>& orientations,
                                           bool with_bias);

}  // namespace calibd::server

#endif  // CALIBD_METHODS_PLAN_H_
