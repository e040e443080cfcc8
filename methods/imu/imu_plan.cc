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
#include "methods/imu/imu_method.h"
#include "methods/plan.h"

namespace calibd::server {
namespace {

using nlohmann::json;

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
  sim.gravity = options.gravity;
  sim.accel_noise = *options.accel_noise;
  sim.gyro_noise = *options.gyro_noise;
  sim.accel_unit = options.accel_unit;
  sim.gyro_unit = options.gyro_unit;
  sim.accel_offset = options.nominal_accel_bias;
  sim.gyro_offset = options.nominal_gyro_bias;
  sim.scale_error = sim.misalignment = sim.accel_bias = sim.gyro_bias = 0;
  std::string csv;
  json sim_config, truth;
  if (Status s = SimulateImuFiles(sim, &csv, &sim_config, &truth); !s.ok()) return s;
  RecordingParser parser("plan.csv", /*collect=*/true);
  ImuMethod().PrepareParser(config, &parser);
  if (Status s = parser.Feed(csv); !s.ok()) return s;
  if (Status s = parser.Finish(); !s.ok()) return s;
  return ImuMethod().Run(&parser, config, RunContext(), result);
}

Status PlanImu(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
               json* out) {
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
         "a suggested protocol is not available for imu yet"}}};
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
