#include "methods/array/array_method.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <tuple>

#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "core/array_simulation.h"
#include "methods/array/array_result.h"
#include "methods/pca/pca_result.h"
#include "formats/inertial_log.h"
#include "methods/noise/noise_reference.h"
#include "methods/saturation_report.h"

namespace calibd::server {
namespace {

using nlohmann::json;

Status KeyError(const std::string& key, const std::string& message) {
  return Status::InvalidInput("config key '" + key + "': " + message).WithField(key);
}

// A finite JSON number.
Status ReadNumber(const json& v, const std::string& key, double* out) {
  if (!v.is_number()) return KeyError(key, "must be a number, not " + std::string(v.type_name()));
  *out = v.get<double>();
  if (!std::isfinite(*out)) return KeyError(key, "must be finite");
  return Status::Ok();
}

Status ReadPositive(const json& v, const std::string& key, double* out) {
  Status s = ReadNumber(v, key, out);
  if (!s.ok()) return s;
  if (!(*out > 0)) return KeyError(key, "must be > 0");
  return Status::Ok();
}

// An integral JSON number (1000 or 1000.0) within [lo, hi].
Status ReadInteger(const json& v, const std::string& key, int64_t lo, int64_t hi, int64_t* out) {
  double d = 0;
  Status s = ReadNumber(v, key, &d);
  if (!s.ok()) return s;
  if (d != std::floor(d) || d < static_cast<double>(lo) || d > static_cast<double>(hi))
    return KeyError(
        key, "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  *out = static_cast<int64_t>(d);
  return Status::Ok();
}

Status ReadString(const json& v, const std::string& key, std::string* out) {
  if (!v.is_string()) return KeyError(key, "must be a string, not " + std::string(v.type_name()));
  *out = v.get<std::string>();
  return Status::Ok();
}

Status ParseGeometry(const json& g, core::ArrayProblem* problem) {
  if (!g.is_object())
    return KeyError("geometry",
                    "must be an object {\"positions\": [[x,y,z], ...], "
                    "\"reference\": k}, not " +
                        std::string(g.type_name()));
  for (auto it = g.begin(); it != g.end(); ++it)
    if (it.key() != "positions" && it.key() != "reference")
      return KeyError("geometry." + it.key(),
                      "unknown key (geometry has \"positions\" and \"reference\")");
  auto p = g.find("positions");
  if (p == g.end())
    return KeyError("geometry.positions", "missing: nominal positions [[x,y,z], ...] in metres");
  if (!p->is_array() || p->empty())
    return KeyError("geometry.positions", "must be a non-empty array of [x,y,z] arrays (metres)");
  const int K = static_cast<int>(p->size());
  problem->nominal_positions.resize(3, K);
  for (int k = 0; k < K; ++k) {
    const json& row = (*p)[k];
    const std::string key = "geometry.positions[" + std::to_string(k) + "]";
    if (!row.is_array() || row.size() != 3)
      return KeyError(key, "must be an array of 3 numbers [x,y,z] (metres)");
    for (int i = 0; i < 3; ++i) {
      Status s = ReadNumber(row[i], key, &problem->nominal_positions(i, k));
      if (!s.ok()) return s;
    }
  }
  problem->reference = 0;
  auto r = g.find("reference");
  if (r != g.end()) {
    int64_t ref = 0;
    Status s = ReadInteger(*r, "geometry.reference", 0, K - 1, &ref);
    if (!s.ok()) return s;
    problem->reference = static_cast<int>(ref);
  }
  return Status::Ok();
}

// The result documents' writing conventions (NaN as null): results/json_reader.h.
using results::Num;
using results::Nums;

std::string FormatG17(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

constexpr const char* kCalibrationKey = "accelerometer_calibration";

Status CalibrationError(const std::string& message) { return KeyError(kCalibrationKey, message); }

std::string FormatG(double v, int digits = 4) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

}  // namespace

json ArrayAccelerometerCalibration::ToJson() const {
  if (!present) return nullptr;
  return {{"job", job},
          {"sensors", sensors},
          {"frame", frame},
          {"bias", bias.empty() ? json(nullptr) : json(bias)},
          {"magnitude", Num(magnitude)},
          {"max_condition_number", Num(max_condition_number)}};
}

Status ParseAccelerometerCalibration(const json& value, int triads,
                                     ArrayAccelerometerCalibration* out) {
  *out = ArrayAccelerometerCalibration();
  if (value.is_string())
    return CalibrationError(
        "a path to a pca result file is only read by `calibd calibrate` (offline); give the pca "
        "result object inline, or over HTTP {\"job\": ID} of a succeeded pca job");
  if (!value.is_object())
    return CalibrationError(
        "must be a pca result object (the result JSON of a pca calibration in the nominal "
        "frame), not " +
        std::string(value.type_name()));
  const json* result = &value;
  if (value.contains("job")) {
    const json& id = value["job"];
    if (!id.is_number_integer() || id.get<int64_t>() <= 0)
      return CalibrationError("\"job\" must be the integer id of a succeeded pca job");
    auto r = value.find("result");
    if (r == value.end())
      return CalibrationError(
          "{\"job\": " + id.dump() +
          "} is only resolvable over HTTP (the server inserts that job's result); offline, give "
          "the pca result object inline or a path to its JSON file");
    for (auto it = value.begin(); it != value.end(); ++it)
      if (it.key() != "job" && it.key() != "result")
        return CalibrationError("unknown key '" + it.key() +
                                "' next to \"job\" (expected {\"job\": ID, \"result\": {...}})");
    out->job = id;
    result = &*r;
  } else {
    out->job = nullptr;
  }
  if (!result->is_object())
    return CalibrationError("the calibration result must be a JSON object, not " +
                            std::string(result->type_name()));
  // The pca result, read once through its typed schema (methods/pca/pca_result.h); a problem is
  // named by its path in the result ("parameters.sensors[7].bias: expected a number, ...").
  results::PcaResult pca;
  if (const Status read = results::FromJson(*result, &pca); !read.ok())
    return CalibrationError(
        "is not a pca result calibd can read (" + read.message() +
        "); give the result of a pca calibration of the accelerometers, as calibd wrote it");
  if (!pca.envelope.usable || !pca.diagnostics.usable || !pca.parameters)
    return CalibrationError("the pca result is marked not usable (diagnostics.usable false)");
  const results::PcaParameters& params = *pca.parameters;
  if (params.dimension != 3)
    return CalibrationError("the pca result has dimension " + std::to_string(params.dimension) +
                            " (parameters.dimension); accelerometer triads need dimension 3");
  out->frame = results::Name(params.frame);
  if (params.frame != results::PcaFrame::kNominal)
    return CalibrationError(
        "the pca result is in the \"" + out->frame +
        "\" frame: its axes would not line up with the gyroscopes. Calibrate with \"nominal\" "
        "(one row per accelerometer axis, e.g. [1,0,0],[0,1,0],[0,0,1] per triad) so the result "
        "is in the array's body frame");
  if (!params.magnitude_known)
    return CalibrationError(
        "the pca result was computed without a known magnitude: its scale factors are only "
        "relative. Calibrate with \"magnitude\": 9.80665 (local gravity, m/s^2)");
  if (!std::isfinite(params.magnitude) || !(params.magnitude > 0))
    return CalibrationError("the pca result has no parameters.magnitude > 0");
  out->magnitude = params.magnitude;
  if (std::abs(out->magnitude - 9.80665) > 0.1)
    out->warnings.push_back(
        "accelerometer_calibration: the pca field magnitude is " + FormatG(out->magnitude) +
        ", not gravity in m/s^2 (~9.81): the corrected accelerations are in the magnitude's "
        "units while the array expects m/s^2");
  out->bias = results::Name(params.bias);
  const std::vector<results::PcaSensor>& sensors = params.sensors;
  std::map<std::string, int> index;
  for (size_t i = 0; i < sensors.size(); ++i) {
    if (!index.emplace(sensors[i].name, static_cast<int>(i)).second)
      return CalibrationError("the pca result names sensor '" + sensors[i].name +
                              "' twice (parameters.sensors[" + std::to_string(i) + "].name)");
  }
  std::vector<std::string> missing;
  int used = 0;
  out->triads.assign(triads, core::AccelerometerTriadModel());
  static const char* const kAxes[] = {"_x", "_y", "_z"};
  for (int k = 0; k < triads; ++k)
    for (int i = 0; i < 3; ++i) {
      const std::string name = "a" + std::to_string(k) + kAxes[i];
      auto it = index.find(name);
      if (it == index.end()) {
        missing.push_back(name);
        continue;
      }
      ++used;
      const results::PcaSensor& sensor = sensors[it->second];
      const std::string where = "parameters.sensors[" + std::to_string(it->second) + "]";
      // FromJson checked: 3 components (dimension 3), null read as NaN.
      for (int j = 0; j < 3; ++j) {
        if (!std::isfinite(sensor.sensitivity[j]))
          return CalibrationError("sensor '" + name + "' has a sensitivity that is not 3 finite " +
                                  "numbers (" + where + ".sensitivity)");
        out->triads[k].sensitivity(j, i) = sensor.sensitivity[j];  // column i = a_i
      }
      if (!std::isfinite(sensor.bias))
        return CalibrationError("sensor '" + name + "' has a bias that is not a finite number (" +
                                where + ".bias)");
      out->triads[k].bias(i) = sensor.bias;
    }
  // Biases are applied whatever the model says (a raw log's removed biases are corrections too):
  // warn only when there is none to apply.
  bool any_bias = false;
  for (const core::AccelerometerTriadModel& t : out->triads)
    any_bias |= (t.bias.array() != 0).any();
  if (params.bias == results::PcaBias::kNone && !any_bias && missing.empty())
    out->warnings.push_back(
        "accelerometer_calibration: the pca result assumed bias-free readings (bias: none): "
        "accelerometer biases are not corrected; calibrate with \"bias\": \"estimate\"");
  if (!missing.empty()) {
    std::string list;
    const size_t shown = std::min<size_t>(missing.size(), 12);
    for (size_t i = 0; i < shown; ++i) list += (i ? ", " : "") + missing[i];
    if (missing.size() > shown) list += " and " + std::to_string(missing.size() - shown) + " more";
    return CalibrationError(
        "the pca result has no sensor for " + std::to_string(missing.size()) + " of the " +
        std::to_string(3 * triads) + " accelerometer columns: missing " + list +
        " (its sensors must be named like the array's columns, aK_x, aK_y, aK_z)");
  }
  for (int k = 0; k < triads; ++k) {
    const double cond = core::AccelerometerConditionNumber(out->triads[k]);
    const std::string name = "a" + std::to_string(k);
    if (!(cond <= core::kMaxAccelerometerConditionNumber))
      return CalibrationError("triad " + name + ": the 3x3 block of sensitivity vectors of " +
                              name + "_x, " + name + "_y, " + name + "_z is " +
                              (std::isfinite(cond)
                                   ? "ill-conditioned (condition number " + FormatG(cond) + " > " +
                                         FormatG(core::kMaxAccelerometerConditionNumber) +
                                         "): the three axes are nearly coplanar"
                                   : std::string("singular: the three axes do not span space")) +
                              "; the readings cannot be corrected");
    out->max_condition_number = std::max(out->max_condition_number, cond);
  }
  const int ignored = static_cast<int>(sensors.size()) - used;
  if (ignored > 0)
    out->warnings.push_back("accelerometer_calibration: " + std::to_string(ignored) +
                            " sensor(s) of the pca result are not accelerometer columns of this "
                            "array and were ignored");
  out->sensors = used;
  out->present = true;
  return Status::Ok();
}

namespace {

// `gyro_unit` of an array config: "rad/s" (default) or "deg/s" (*gyro_in_degrees).
Status ParseGyroUnit(const json& config, bool* gyro_in_degrees) {
  auto u = config.find("gyro_unit");
  if (u == config.end()) return Status::Ok();
  std::string unit;
  Status s = ReadString(*u, "gyro_unit", &unit);
  if (!s.ok()) return s;
  if (unit == "deg/s")
    *gyro_in_degrees = true;
  else if (unit != "rad/s")
    return KeyError("gyro_unit", "must be \"rad/s\" or \"deg/s\", not \"" + unit + "\"");
  return Status::Ok();
}

}  // namespace

Status ParseArrayConfig(const json& config, core::ArrayProblem* geometry_part,
                        core::ArrayOptions* options, bool* gyro_in_degrees,
                        ArrayAccelerometerCalibration* calibration) {
  if (!config.is_object())
    return Status::InvalidInput("the config must be a JSON object, not " +
                                std::string(config.type_name()));
  *options = core::ArrayOptions();
  *gyro_in_degrees = false;
  static const char* const kKeys[] = {
      "method",     "device",         "geometry",        "accel_noise",
      "gyro_noise", "gyro_unit",      "gyro_saturation", "accel_saturation",
      "solver",     "max_iterations", "tolerance",       "accelerometer_calibration",
      "model"};
  if (auto m = config.find("model"); m != config.end()) {
    std::string model;
    Status s = ReadString(*m, "model", &model);
    if (!s.ok()) return s;
    if (model != "positions")
      return KeyError("model",
                      "must be \"positions\" (default) or \"full\", not \"" + model + "\"");
  }
  for (auto it = config.begin(); it != config.end(); ++it) {
    if (std::find_if(std::begin(kKeys), std::end(kKeys),
                     [&](const char* k) { return it.key() == k; }) == std::end(kKeys))
      return KeyError(it.key(),
                      "unknown key for method array (known: geometry, accel_noise, gyro_noise, "
                      "gyro_unit, gyro_saturation, accel_saturation, solver, max_iterations, "
                      "tolerance, accelerometer_calibration, model, method, device)");
  }
  // Units first: they apply to gyro_noise and gyro_saturation.
  if (Status u = ParseGyroUnit(config, gyro_in_degrees); !u.ok()) return u;
  const double gyro_scale = *gyro_in_degrees ? core::kDegree : 1.0;

  auto g = config.find("geometry");
  if (g == config.end())
    return KeyError("geometry", "missing: {\"positions\": [[x,y,z], ...], \"reference\": 0}");
  Status s = ParseGeometry(*g, geometry_part);
  if (!s.ok()) return s;

  // A number, or {"job": ID} of a noise job resolved at enqueue (methods/noise/noise_reference.h; SI).
  std::optional<NoiseLevel> accel_noise, gyro_noise;
  s = ReadNoiseLevel(config, "accel_noise", &accel_noise);
  if (!s.ok()) return s;
  if (!accel_noise) return KeyError("accel_noise", "missing: sigma_a in m/s^2");
  options->accel_noise = accel_noise->value;
  s = ReadNoiseLevel(config, "gyro_noise", &gyro_noise);
  if (!s.ok()) return s;
  if (!gyro_noise) return KeyError("gyro_noise", "missing: sigma_g in gyro_unit");
  options->gyro_noise = gyro_noise->si ? gyro_noise->value : gyro_noise->value * gyro_scale;

  if (auto it = config.find("gyro_saturation"); it != config.end() && !it->is_null()) {
    double v = 0;
    s = ReadPositive(*it, "gyro_saturation", &v);
    if (!s.ok()) return s;
    options->gyro_saturation = v * gyro_scale;
  }
  if (auto it = config.find("accel_saturation"); it != config.end() && !it->is_null()) {
    double v = 0;
    s = ReadPositive(*it, "accel_saturation", &v);
    if (!s.ok()) return s;
    options->accel_saturation = v;  // m/s^2
  }
  if (auto it = config.find("solver"); it != config.end()) {
    std::string solver;
    s = ReadString(*it, "solver", &solver);
    if (!s.ok()) return s;
    if (solver == "joint")
      options->solver = core::ArraySolver::kJoint;
    else if (solver == "bcd")
      options->solver = core::ArraySolver::kBcd;
    else
      return KeyError("solver", "must be \"joint\" or \"bcd\", not \"" + solver + "\"");
  }
  if (auto it = config.find("max_iterations"); it != config.end()) {
    int64_t v = 0;
    s = ReadInteger(*it, "max_iterations", 0, 1000000, &v);
    if (!s.ok()) return s;
    options->max_iterations = static_cast<int>(v);
  }
  if (auto it = config.find("tolerance"); it != config.end()) {
    s = ReadNumber(*it, "tolerance", &options->tolerance);
    if (!s.ok()) return s;
    if (!(options->tolerance >= 0 && options->tolerance < 1))
      return KeyError("tolerance", "must be >= 0 and < 1 (0: never stop early)");
  }
  ArrayAccelerometerCalibration parsed;
  if (auto it = config.find(kCalibrationKey); it != config.end() && !it->is_null()) {
    s = ParseAccelerometerCalibration(
        *it, static_cast<int>(geometry_part->nominal_positions.cols()), &parsed);
    if (!s.ok()) return s;
  }
  if (calibration != nullptr) *calibration = std::move(parsed);
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return Status::Ok();
}

// ----- model: full (SPEC §7, issue #14).

namespace {

bool IsFullModel(const json& config) {
  if (!config.is_object()) return false;
  auto m = config.find("model");
  return m != config.end() && m->is_string() && m->get<std::string>() == "full";
}

}  // namespace

Status ParseArrayFullConfig(const json& config, core::ArrayFullProblem* geometry_part,
                            core::ArrayFullOptions* options, bool* gyro_in_degrees) {
  if (!config.is_object())
    return Status::InvalidInput("the config must be a JSON object, not " +
                                std::string(config.type_name()));
  *options = core::ArrayFullOptions();
  *gyro_in_degrees = false;
  static const char* const kKeys[] = {
      "method",          "device",        "model",           "geometry",     "accel_noise",
      "gyro_noise",      "gyro_unit",     "gyro_saturation", "gravity",      "max_iterations",
      "tolerance",       "static_window", "min_static",      "robust_batch", "dynamic_weighting",
      "accel_saturation"};
  for (auto it = config.begin(); it != config.end(); ++it) {
    if (it.key() == "solver" || it.key() == "accelerometer_calibration")
      return KeyError(it.key(),
                      "not used with model \"full\" (it estimates the accelerometers itself "
                      "with its own joint solver); remove it or use model \"positions\"");
    if (std::find_if(std::begin(kKeys), std::end(kKeys),
                     [&](const char* k) { return it.key() == k; }) == std::end(kKeys))
      return KeyError(it.key(),
                      "unknown key for method array with model full (known: geometry, "
                      "accel_noise, gyro_noise, gyro_unit, gyro_saturation, accel_saturation, "
                      "gravity, "
                      "max_iterations, tolerance, static_window, min_static, robust_batch, "
                      "dynamic_weighting, model, method, device)");
  }
  if (Status u = ParseGyroUnit(config, gyro_in_degrees); !u.ok()) return u;
  const double gyro_scale = *gyro_in_degrees ? core::kDegree : 1.0;
  auto g = config.find("geometry");
  if (g == config.end())
    return KeyError("geometry", "missing: {\"positions\": [[x,y,z], ...], \"reference\": 0}");
  core::ArrayProblem geometry;
  Status s = ParseGeometry(*g, &geometry);
  if (!s.ok()) return s;
  geometry_part->nominal_positions = geometry.nominal_positions;
  geometry_part->reference = geometry.reference;
  auto optional_positive = [&](const char* key, double scale, double* out) -> Status {
    auto it = config.find(key);
    if (it == config.end() || it->is_null()) return Status::Ok();
    double v = 0;
    Status st = ReadPositive(*it, key, &v);
    if (!st.ok()) return st;
    *out = v * scale;
    return Status::Ok();
  };
  if (s = optional_positive("accel_noise", 1, &options->accel_noise); !s.ok()) return s;
  if (s = optional_positive("gyro_noise", gyro_scale, &options->gyro_noise); !s.ok()) return s;
  double saturation = 0;
  if (s = optional_positive("gyro_saturation", gyro_scale, &saturation); !s.ok()) return s;
  if (saturation > 0) options->gyro_saturation = saturation;
  saturation = 0;
  if (s = optional_positive("accel_saturation", 1, &saturation); !s.ok()) return s;
  if (saturation > 0) options->accel_saturation = saturation;
  if (s = optional_positive("gravity", 1, &options->gravity); !s.ok()) return s;
  if (s = optional_positive("static_window", 1, &options->statics.static_window); !s.ok()) return s;
  if (s = optional_positive("robust_batch", 1, &options->robust_batch); !s.ok()) return s;
  if (auto it = config.find("dynamic_weighting"); it != config.end()) {
    std::string w;
    if (s = ReadString(*it, "dynamic_weighting", &w); !s.ok()) return s;
    if (w == "residual")
      options->dynamic_weighting = core::ArrayFullDynamicWeighting::kResidual;
    else if (w != "noise")
      return KeyError("dynamic_weighting",
                      "must be \"noise\" (default) or \"residual\", not \"" + w + "\"");
  }
  if (auto it = config.find("min_static"); it != config.end()) {
    if (s = ReadNumber(*it, "min_static", &options->statics.min_static); !s.ok()) return s;
    if (!(options->statics.min_static >= 0)) return KeyError("min_static", "must be >= 0 (s)");
  }
  if (auto it = config.find("max_iterations"); it != config.end()) {
    int64_t v = 0;
    if (s = ReadInteger(*it, "max_iterations", 1, 1000000, &v); !s.ok()) return s;
    options->max_iterations = static_cast<int>(v);
  }
  if (auto it = config.find("tolerance"); it != config.end()) {
    if (s = ReadNumber(*it, "tolerance", &options->tolerance); !s.ok()) return s;
    if (!(options->tolerance >= 0 && options->tolerance < 1))
      return KeyError("tolerance", "must be >= 0 and < 1 (0: never stop early)");
  }
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return Status::Ok();
}

namespace {

// A sensor in reading units: the core saw readings times `unit` (SI per reading unit); the
// reported matrix maps a bias-free reading to SI, so it is multiplied by unit and the bias
// divided by it.
results::SensorTriad SensorTriadOf(const core::ArrayFullSensorReport& r, double unit) {
  results::SensorTriad t;
  t.bias = r.bias / unit;
  t.scale = r.scale * unit;
  t.misalignment = r.misalignment;
  t.matrix = r.matrix * unit;
  return t;
}

results::SensorTriadStd SensorTriadStdOf(const core::ArrayFullSensorStd& r, double unit) {
  results::SensorTriadStd t;
  t.bias_std = r.bias_std / unit;
  t.scale_std = r.scale_std * unit;
  t.misalignment_std = r.misalignment_std;
  return t;
}

constexpr const char* kFullModelEquation =
    "a_k = M_a,k (y_a,k - b_a,k), omega = M_g,k (y_g,k - b_g,k) for IMU k: y raw readings, b "
    "biases (reading units), M = matrix (SI per reading unit; scale = its diagonal, "
    "misalignment = M diag(scale)^-1), in the body frame of the reference accelerometer; a_k "
    "= s + (Omega(omega)^2 + Omega(omega_dot)) r_k with r_k the accelerometer's position "
    "(metres, nominal geometry frame, the reference held at its nominal position), s the "
    "specific force at the origin, Omega(x) the cross-product matrix";

constexpr const char* kPositionsModelEquation =
    "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k for accelerometer triad k at "
    "position r_k (metres, nominal geometry frame, the reference triad held at its "
    "nominal position), y_g = omega for every gyroscope triad: s the specific force at "
    "the origin, omega the angular rate, Omega(x) the cross-product matrix; the "
    "parameters are the positions r_k";

// Saturation of an array log (core/saturation.h), on the readings in SI (m/s², rad/s) before
// any correction: a configured accel_saturation / gyro_saturation (symmetric) overrides the search
// for its kind; otherwise the clip levels found in the data give one symmetric limit per kind
// (the tightest over the kind's channels, core::SymmetricLimit), which the fit drops like a
// configured one (every sample with any |component| at or beyond it; model full: never part of a
// static). Sets the limits in *accel_limit / *gyro_limit and, when anything is pinned, the
// diagnostics and a warning.
constexpr double kFullScaleMargin = 0.002;

Status ArraySaturation(const Eigen::MatrixXd& accel, const std::vector<std::string>& accel_names,
                       const Eigen::MatrixXd& gyro, const std::vector<std::string>& gyro_names,
                       bool degrees, const core::StopToken* stop,
                       std::optional<double>* accel_limit, std::optional<double>* gyro_limit,
                       std::optional<results::SaturationDiagnostics>* diagnostics,
                       std::vector<std::string>* warnings) {
  results::SaturationDiagnostics report{"dropped", 0, {}};
  std::vector<core::ChannelSaturation> accel_channels, gyro_channels;
  for (auto [columns, names, limit, channels, scale, unit] :
       {std::tuple<const Eigen::MatrixXd*, const std::vector<std::string>*, std::optional<double>*,
                   std::vector<core::ChannelSaturation>*, double, const char*>{
            &accel, &accel_names, accel_limit, &accel_channels, 1.0, "m/s^2"},
        std::tuple<const Eigen::MatrixXd*, const std::vector<std::string>*, std::optional<double>*,
                   std::vector<core::ChannelSaturation>*, double, const char*>{
            &gyro, &gyro_names, gyro_limit, &gyro_channels, degrees ? 1 / core::kDegree : 1.0,
            degrees ? "deg/s" : "rad/s"}}) {
    if (columns->cols() != 3 * static_cast<Eigen::Index>(names->size())) continue;
    core::SaturationOptions so;
    so.stop = stop;
    if (*limit) {
      so.low = -**limit;
      so.high = **limit;
    }
    Status s = FindSaturation(*columns, *names, so, channels);
    if (!s.ok()) return s;
    if (!*limit) {
      // The levels found, less kFullScaleMargin of them: the last fraction of a percent of a
      // sensor's range is where clipped excursions begin and end (and where its linearity is
      // least specified); the samples there are dropped with the pinned ones.
      if (const std::optional<double> level = core::SymmetricLimit(core::CombinedLimits(*channels)))
        *limit = *level * (1 - kFullScaleMargin);
    }
    AddSaturationChannels(*channels, scale, unit, &report);
  }
  if (report.channels.empty()) return Status::Ok();
  // The samples the fit drops: any |component| at or beyond its kind's limit.
  for (Eigen::Index n = 0; n < accel.rows(); ++n) {
    if ((*accel_limit && accel.row(n).cwiseAbs().maxCoeff() >= **accel_limit) ||
        (*gyro_limit && gyro.rows() == accel.rows() &&
         gyro.row(n).cwiseAbs().maxCoeff() >= **gyro_limit)) {
      ++report.samples;
    }
  }
  warnings->push_back(PinnedList(report) + ": " + std::to_string(report.samples) +
                      " sample(s) at or beyond the saturation limits were dropped from the fit; "
                      "gyro_saturation / accel_saturation in the config override the levels found");
  *diagnostics = std::move(report);
  return Status::Ok();
}

Status RunArrayFull(ArrayRecording recording, const json& config, json* result,
                    const core::StopToken* stop, core::TaskExecutor executor) {
  core::ArrayFullProblem problem;
  core::ArrayFullOptions options;
  bool degrees = false;
  Status s = ParseArrayFullConfig(config, &problem, &options, &degrees);
  if (!s.ok()) return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
  if (executor) options.executor = std::move(executor);
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int K_rec = static_cast<int>(recording.accel_names.size());
  const int G_rec = static_cast<int>(recording.gyro_names.size());
  if (K_rec != K || G_rec != K)
    return Status::InvalidInput(
               "model full needs one accelerometer and one gyroscope triad per "
               "position: the recording has " +
               std::to_string(K_rec) + " accelerometer and " + std::to_string(G_rec) +
               " gyroscope triads, geometry.positions " + std::to_string(K))
        .WithField("geometry.positions");
  if (recording.t.size() == 0)
    return Status::InvalidInput(
               "model full needs a `t` column (seconds): the statics are found "
               "from the log's timing")
        .WithField("t");
  problem.t = std::move(recording.t);  // moved, not copied: one copy of the samples per job
  problem.accel = std::move(recording.accel);
  problem.gyro = std::move(recording.gyro);
  if (degrees) problem.gyro *= core::kDegree;
  std::optional<results::SaturationDiagnostics> saturation;
  std::vector<std::string> saturation_warnings;
  options.statics.stop = stop;
  s = ArraySaturation(problem.accel, recording.accel_names, problem.gyro, recording.gyro_names,
                      degrees, stop, &options.accel_saturation, &options.gyro_saturation,
                      &saturation, &saturation_warnings);
  if (!s.ok()) return s;
  for (const auto& name : recording.accel_names)
    problem.names.push_back(name.size() > 1 && name[0] == 'a' ? name.substr(1) : name);
  options.stop = stop;  // a stopped run returns core::StoppedStatus ("array (full model): ...")
  core::ArrayFullResult r;
  s = core::CalibrateArrayFull(problem, options, &r);
  results::ArrayResult out;
  out.envelope.method = "array";
  out.envelope.warnings = r.warnings;
  for (auto& w : saturation_warnings) out.envelope.warnings.push_back(std::move(w));
  out.full = true;
  results::ArrayFullDiagnostics& d = out.full_diagnostics;
  d.saturation = std::move(saturation);
  d.termination = core::BlockLmTerminationName(r.termination);
  d.iterations = r.iterations;
  d.statics = r.statics;
  d.static_samples = r.static_samples;
  d.dynamic_samples = r.dynamic_samples;
  d.rotation_excitation.eigenvalues = r.rotation_eigenvalues;
  d.rotation_excitation.noise_floor = r.rotation_noise_floor;
  d.rotation_excitation.weakest_axis = r.weakest_rotation_axis;
  d.rotation_excitation.verdict = r.rotation_verdict;
  d.null_directions = r.null_directions;
  if (!s.ok()) {
    // The partial diagnostics kept with the failed job: what the run found before failing.
    out.envelope.usable = false;
    *result = results::ToJson(out);
    return s;
  }

  const double gyro_unit = degrees ? core::kDegree : 1.0;  // rad/s per reading unit
  out.envelope.model = kFullModelEquation;
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  params.reference = r.reference;
  for (int k = 0; k < K; ++k) {
    const core::ArrayFullTriadReport& p = r.report[k];
    const core::ArrayFullTriadStd& sd = r.report_std[k];
    results::ArrayImu imu;
    imu.triads.name = p.name;
    imu.triads.accelerometer = SensorTriadOf(p.accelerometer, 1);
    imu.triads.gyroscope = SensorTriadOf(p.gyroscope, gyro_unit);
    imu.position = p.position;
    params.imus.push_back(std::move(imu));
    results::ArrayImuStd u;
    u.triads.name = p.name;
    u.triads.accelerometer = SensorTriadStdOf(sd.accelerometer, 1);
    u.triads.gyroscope = SensorTriadStdOf(sd.gyroscope, gyro_unit);
    u.position_std = sd.position_std;
    if (r.robust) {
      results::ArrayImuRobustStd robust;
      robust.accelerometer = SensorTriadStdOf(r.report_std_robust[k].accelerometer, 1);
      robust.gyroscope = SensorTriadStdOf(r.report_std_robust[k].gyroscope, gyro_unit);
      robust.position_std = r.report_std_robust[k].position_std;
      u.robust = std::move(robust);
    }
    unc.imus.push_back(std::move(u));
    params.positions.push_back({p.name, p.position, p.position - problem.nominal_positions.col(k)});
    unc.positions.push_back({p.name, sd.position_std});
    const core::ArrayFullResidualStats& rs = r.residuals[k];
    d.residual_rms_imus.push_back({p.name,
                                   {rs.static_accel, rs.static_gyro / gyro_unit},
                                   {rs.dynamic_accel, rs.dynamic_gyro / gyro_unit}});
    // What the full model changed against the positions-only fit it starts from (the same
    // log's dynamic samples, accelerometers corrected by the statics' closed form, gyroscope
    // biases removed): the shift, and the shift in units of the full model's 1 sigma per axis
    // (null where sigma is 0: the reference, held by the gauge).
    results::ArrayPositionChange change;
    change.name = p.name;
    change.positions_only = r.initial[k].position;
    change.position_change = p.position - r.initial[k].position;
    change.position_change_norm = change.position_change.norm();
    for (int c = 0; c < 3; ++c) {
      const double sigma = sd.position_std(c);
      change.position_change_sigma(c) =
          sigma > 0 ? change.position_change(c) / sigma : std::numeric_limits<double>::quiet_NaN();
    }
    if (r.initial_position_std.cols() == K)
      change.positions_only_std = Eigen::Vector3d(r.initial_position_std.col(k));
    d.changed_from_positions_only.push_back(std::move(change));
  }
  out.parameters = std::move(params);
  out.uncertainty = std::move(unc);
  d.gauge = {r.gauge, r.reference, r.gauge_description};
  d.solver = "joint";
  d.converged = r.converged;
  d.cost = r.cost;
  d.samples_dropped = r.samples_dropped;
  d.dof = r.dof;
  d.chi2_per_dof = r.chi2_per_dof;
  d.gyro_unit = degrees ? "deg/s" : "rad/s";
  d.noise.accelerometer = r.accel_noise;
  d.noise.gyroscope = r.gyro_noise / gyro_unit;
  d.noise.source = r.noise_estimated ? "statics" : "configured";
  d.noise.dynamic_weighting =
      options.dynamic_weighting == core::ArrayFullDynamicWeighting::kResidual ? "residual"
                                                                              : "noise";
  d.noise.dynamic_accelerometer = r.dynamic_accel_noise;
  d.noise.dynamic_gyroscope = r.dynamic_gyro_noise / gyro_unit;
  d.static_noise = {r.static_noise_accel, r.static_noise_gyro / gyro_unit};
  d.residual_rms_dynamic = {r.dynamic_rms_accel, r.dynamic_rms_gyro / gyro_unit};
  for (int k = 0; k < K; ++k)
    d.time_offsets.offsets_ms.push_back({r.names[k], 1e3 * r.time_offsets(k)});
  d.time_offsets.explained_fraction = r.time_offset_explained;
  d.time_offsets.per_sample_rms_ms = 1e3 * r.jitter_rms;
  d.time_offsets.per_sample_explained_fraction = r.jitter_explained;
  d.time_offsets.note =
      "diagnostic, not part of the model: per IMU the constant sampling-time offset "
      "(relative to their mean) that best explains its gyroscope residual by omega_dot, "
      "and the same free per sample (jitter)";
  d.robust = {r.robust, r.robust_batches, options.robust_batch, options.robust_ratio};
  d.positions_only_start = r.initial_positions_from_array;
  *result = results::ToJson(out);
  return Status::Ok();
}

}  // namespace

Status RunArray(ArrayRecording recording, const json& config, json* result,
                const core::StopToken* stop, core::TaskExecutor executor) {
  if (IsFullModel(config))
    return RunArrayFull(std::move(recording), config, result, stop, std::move(executor));
  core::ArrayProblem problem;
  core::ArrayOptions options;
  bool degrees = false;
  ArrayAccelerometerCalibration calibration;
  Status s = ParseArrayConfig(config, &problem, &options, &degrees, &calibration);
  if (!s.ok()) return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
  if (executor) options.executor = std::move(executor);
  const int K = static_cast<int>(problem.nominal_positions.cols());
  const int K_rec = static_cast<int>(recording.accel_names.size());
  if (K_rec != K)
    return Status::InvalidInput(Reason::kInvalidRecording,
                                "the recording has " + std::to_string(K_rec) +
                                    " accelerometer triads but geometry.positions has " +
                                    std::to_string(K) + " positions")
        .WithField("geometry.positions");
  // Moved, not copied: a job holds one copy of the samples (the parser's).
  problem.accel = std::move(recording.accel);
  problem.gyro = std::move(recording.gyro);
  if (degrees) problem.gyro *= core::kDegree;
  // Saturation on the raw readings, before the accelerometer calibration corrects them.
  std::optional<results::SaturationDiagnostics> saturation;
  std::vector<std::string> saturation_warnings;
  s = ArraySaturation(problem.accel, recording.accel_names, problem.gyro, recording.gyro_names,
                      degrees, stop, &options.accel_saturation, &options.gyro_saturation,
                      &saturation, &saturation_warnings);
  if (!s.ok()) return s;
  problem.accel_names = std::move(recording.accel_names);
  if (calibration.present) {
    s = core::CorrectAccelerometerReadings(calibration.triads, problem.accel_names, &problem.accel);
    if (!s.ok()) return s.WithField(kCalibrationKey);
  }

  options.stop = stop;  // a stopped run returns core::StoppedStatus ("array: <stage>: ...")
  core::ArrayResult r;
  s = core::CalibrateArray(problem, options, &r);
  results::ArrayResult out;
  out.envelope.method = "array";
  out.envelope.warnings = r.warnings;
  for (auto& w : saturation_warnings) out.envelope.warnings.push_back(std::move(w));
  results::ArrayPositionsDiagnostics& d = out.diagnostics;
  d.saturation = std::move(saturation);
  d.solver = core::ArraySolverName(r.solver);
  d.termination = core::ArrayTerminationName(r.termination);
  d.iterations = r.iterations;
  d.samples = r.samples;
  d.samples_dropped = r.samples_dropped;
  d.gyro_triads = r.gyro_triads;
  d.gyro_unit = degrees ? "deg/s" : "rad/s";
  d.excitation = {r.excitation.min_eigenvalue, r.excitation.max_eigenvalue,
                  r.excitation.noise_floor, r.excitation.weakest_direction, r.excitation.verdict};
  if (!s.ok()) {
    // The partial diagnostics kept with the failed job: the samples used and dropped, the
    // excitation when the solver got that far (verdict "" before), the termination.
    out.envelope.usable = false;
    *result = results::ToJson(out);
    return s;
  }

  const double gyro_out = degrees ? 1 / core::kDegree : 1.0;
  out.envelope.model = kPositionsModelEquation;
  for (const auto& w : calibration.warnings) out.envelope.warnings.push_back(w);
  results::ArrayParameters params;
  results::ArrayUncertainty unc;
  params.reference = r.reference;
  for (int k = 0; k < K; ++k) {
    params.positions.push_back({r.names[k], r.positions.col(k), r.offsets.col(k)});
    unc.positions.push_back({r.names[k], r.position_std.col(k)});
  }
  unc.std_rms = K > 1 ? std::sqrt(r.position_std.squaredNorm() / (3.0 * (K - 1))) : 0.0;
  out.parameters = std::move(params);
  out.uncertainty = std::move(unc);

  d.converged = r.converged;
  d.cost = r.cost;
  const int64_t N = r.samples;
  d.motion.stride = std::max<int64_t>(1, (N + 1999) / 2000);
  for (int64_t n = 0; n < N; n += d.motion.stride) {
    d.motion.omega_norm.push_back(r.omega_norm(n));
    d.motion.omega_dot_norm.push_back(r.omega_dot_norm(n));
  }
  d.residual_rms = {r.residual_rms_accel, r.residual_rms_gyro * gyro_out};
  d.noise_estimate = {r.noise_estimate_accel, r.noise_estimate_gyro * gyro_out};
  // {"accelerometer": ID or null, "gyroscope": ...} (methods/noise/noise_reference.h).
  const json noise_jobs = NoiseJobsJson(config);
  results::JsonReader jobs(noise_jobs, "noise_jobs");
  jobs.Read("accelerometer", &d.noise_jobs.accelerometer);
  jobs.Read("gyroscope", &d.noise_jobs.gyroscope);
  if (!jobs.ok()) return Status::Internal(jobs.status().message());
  d.noise_configured = {options.accel_noise, options.gyro_noise * gyro_out};
  d.parallel_fraction = r.parallel_fraction;
  if (calibration.present) {
    results::ArrayCalibrationUsed used;
    if (calibration.job.is_number_integer()) used.job = calibration.job.get<int64_t>();
    used.sensors = calibration.sensors;
    used.frame = calibration.frame;
    if (!calibration.bias.empty()) used.bias = calibration.bias;
    used.magnitude = calibration.magnitude;
    used.max_condition_number = calibration.max_condition_number;
    d.accelerometer_calibration = std::move(used);
  }
  *result = results::ToJson(out);
  return Status::Ok();
}

namespace {

core::ArraySimulationOptions CoreSimulationOptions(const ArraySimulationFileOptions& options) {
  core::ArraySimulationOptions so;
  so.samples = options.samples;
  so.omega_norm = options.omega_norm_dps * core::kDegree;
  so.omega_dot_norm = options.omega_dot_norm_dps2 * core::kDegree;
  so.accel_noise = options.accel_noise;
  so.gyro_noise = options.gyro_noise_dps * core::kDegree;
  so.position_perturbation = options.position_perturbation;
  so.seed = options.seed;
  so.accel_bias = options.accel_bias;
  so.accel_scale_error = options.accel_scale_error;
  so.accel_misalignment = options.accel_misalignment;
  return so;
}

bool HasAccelErrors(const ArraySimulationFileOptions& o) {
  return o.accel_bias > 0 || o.accel_scale_error > 0 || o.accel_misalignment > 0;
}

}  // namespace

Status SimulateArrayFiles(const ArraySimulationFileOptions& options, std::string* csv, json* config,
                          json* truth) {
  if (options.gyro_unit != "rad/s" && options.gyro_unit != "deg/s")
    return Status::InvalidInput("gyro_unit must be \"rad/s\" or \"deg/s\", not \"" +
                                options.gyro_unit + "\"");
  const core::ArraySimulationOptions so = CoreSimulationOptions(options);
  core::ArraySimulation sim;
  Status s = core::SimulateArray(so, &sim);
  if (!s.ok()) return s;
  const bool degrees = options.gyro_unit == "deg/s";
  const double gyro_scale = degrees ? 1 / core::kDegree : 1.0;
  const int K = static_cast<int>(sim.problem.nominal_positions.cols());
  const int G = static_cast<int>(sim.gyro_names.size());

  std::string out = "t";
  for (int k = 0; k < K; ++k)
    for (const char* axis : {"_x", "_y", "_z"}) out += "," + sim.problem.accel_names[k] + axis;
  for (int j = 0; j < G; ++j)
    for (const char* axis : {"_x", "_y", "_z"}) out += "," + sim.gyro_names[j] + axis;
  out += '\n';
  const int64_t N = sim.problem.accel.rows();
  out.reserve(out.size() + N * (3 * (K + G) + 1) * 24);
  for (int64_t n = 0; n < N; ++n) {
    out += FormatG17(static_cast<double>(n) / 100);
    for (int c = 0; c < 3 * K; ++c) {
      out += ',';
      out += FormatG17(sim.problem.accel(n, c));
    }
    for (int c = 0; c < 3 * G; ++c) {
      out += ',';
      out += FormatG17(sim.problem.gyro(n, c) * gyro_scale);
    }
    out += '\n';
  }
  *csv = std::move(out);

  json nominal = json::array(), true_positions = json::array();
  for (int k = 0; k < K; ++k) {
    nominal.push_back(Nums(sim.problem.nominal_positions.col(k)));
    true_positions.push_back(
        {{"name", sim.problem.accel_names[k]}, {"position", Nums(sim.true_positions.col(k))}});
  }
  *config = {
      {"method", "array"},
      {"geometry", {{"positions", nominal}, {"reference", sim.problem.reference}}},
      {"accel_noise", options.accel_noise},
      {"gyro_noise", degrees ? options.gyro_noise_dps : options.gyro_noise_dps * core::kDegree},
      {"gyro_unit", options.gyro_unit}};
  *truth = {{"method", "array"},
            {"reference", sim.problem.reference},
            {"positions", true_positions},
            {"seed", options.seed},
            {"options",
             {{"samples", options.samples},
              {"omega_norm_dps", options.omega_norm_dps},
              {"omega_dot_norm_dps2", options.omega_dot_norm_dps2},
              {"accel_noise", options.accel_noise},
              {"gyro_noise_dps", options.gyro_noise_dps},
              {"position_perturbation", options.position_perturbation},
              {"gyro_unit", options.gyro_unit}}}};
  if (HasAccelErrors(options)) {
    json& o = (*truth)["options"];
    o["accel_bias"] = options.accel_bias;
    o["accel_scale_error"] = options.accel_scale_error;
    o["accel_misalignment"] = options.accel_misalignment;
    json sensors = json::array();
    for (int k = 0; k < K; ++k)
      for (int i = 0; i < 3; ++i)
        sensors.push_back({{"name", sim.problem.accel_names[k] + "_" + "xyz"[i]},
                           {"sensitivity", Nums(sim.accel_models[k].sensitivity.col(i))},
                           {"bias", sim.accel_models[k].bias(i)}});
    (*truth)["accelerometer_sensors"] = std::move(sensors);
  }
  return Status::Ok();
}

Status SimulateArrayStaticFiles(const ArraySimulationFileOptions& options, int positions,
                                std::string* csv, json* config) {
  if (options.static_samples < 1)
    return Status::InvalidInput("static_samples (readings averaged per position) must be >= 1");
  if (positions < 1) return Status::InvalidInput("static positions must be >= 1");
  const core::ArraySimulationOptions so = CoreSimulationOptions(options);
  core::ArrayStaticSimulation sim;
  const double noise = options.accel_noise / std::sqrt(static_cast<double>(options.static_samples));
  Status s = core::SimulateArrayStatic(so, positions, noise, core::kStandardGravity, &sim);
  if (!s.ok()) return s;
  const int m = static_cast<int>(sim.sensor_names.size());
  std::string out = "# calibd simulate array: static orientations of the same board, seed " +
                    std::to_string(options.seed) + ", each row the mean of " +
                    std::to_string(options.static_samples) + " samples\nposition";
  for (const std::string& name : sim.sensor_names) out += "," + name;
  out += '\n';
  for (int j = 0; j < positions; ++j) {
    out += "p" + std::to_string(j + 1);
    for (int i = 0; i < m; ++i) {
      out += ',';
      out += FormatG17(sim.readings(i, j));
    }
    out += '\n';
  }
  *csv = std::move(out);
  json nominal = json::array();
  for (int i = 0; i < m; ++i) {
    json row = {0, 0, 0};
    row[i % 3] = 1;
    nominal.push_back(row);
  }
  *config = {{"method", "pca"},
             {"magnitude", core::kStandardGravity},
             {"bias", "estimate"},
             {"nominal", std::move(nominal)}};
  return Status::Ok();
}

namespace {
// The nominal position of triad i in the config's geometry; NaN when it does not give it.
Eigen::Vector3d NominalPosition(const json& config, size_t i) {
  Eigen::Vector3d p = Eigen::Vector3d::Constant(NAN);
  if (!config.is_object() || !config.contains("geometry")) return p;
  const json& geometry = config["geometry"];
  if (!geometry.is_object() || !geometry.contains("positions")) return p;
  const json& positions = geometry["positions"];
  if (!positions.is_array() || i >= positions.size() || !positions[i].is_array() ||
      positions[i].size() != 3)
    return p;
  for (int k = 0; k < 3; ++k)
    if (positions[i][k].is_number()) p(k) = positions[i][k].get<double>();
  return p;
}
}  // namespace

void JudgeArray(const json& result, const json& config, const AcceptanceLimits& limits,
                Verdict* verdict) {
  results::ArrayResult r;
  if (Status s = results::FromJson(result, &r); !s.ok()) {
    verdict->Reject("the result cannot be judged: " + s.message());
    return;
  }
  if (!r.parameters || !r.uncertainty) {
    verdict->Reject("the result cannot be judged: it is a failed run's partial diagnostics");
    return;
  }
  const results::ArrayParameters& params = *r.parameters;
  const results::ArrayUncertainty& uncertainty = *r.uncertainty;
  // Positions (both models: parameters.positions, SPEC §4 and §7) against the nominal geometry.
  const auto offset_max = limits.Get("max_offset");
  const auto std_max = limits.Get("max_position_std");
  Offenders far, uncertain, undefined, not_finite;
  for (const results::ArrayPosition& q : params.positions) {
    if (!q.position.allFinite()) not_finite.Add(q.name);  // the reference's too
  }
  not_finite.RejectInto(verdict, kNotFiniteRule);
  for (size_t i = 0; i < params.positions.size(); ++i) {
    if (static_cast<int>(i) == params.reference) continue;  // held at its nominal position
    const results::ArrayPosition& q = params.positions[i];
    const Eigen::Vector3d std = i < uncertainty.positions.size() ? uncertainty.positions[i].std
                                                                 : Eigen::Vector3d::Constant(NAN);
    // The offset from the nominal position; a result that does not give it (a full-model result
    // without parameters.positions, stored by an earlier calibd) against the config's geometry.
    double offset = q.offset.norm();
    if (!std::isfinite(offset)) offset = (q.position - NominalPosition(config, i)).norm();
    if (offset_max && std::isfinite(offset) && offset > *offset_max) {
      far.Add(q.name + " " + Fmt(offset * 1e3) + " mm");
    }
    if (!std.allFinite()) {
      undefined.Add(q.name);
    } else if (std_max && std.maxCoeff() > *std_max) {
      uncertain.Add(q.name + " " + Fmt(std.maxCoeff() * 1e6) + " um");
    }
  }
  if (offset_max) {
    far.RejectInto(verdict, "triad more than " + Fmt(*offset_max * 1e3) +
                                " mm from its nominal position: is the geometry right (metres, "
                                "triad order), and gyro_unit?");
  }
  undefined.RejectInto(verdict,
                       "the position uncertainty could not be computed, so the precision "
                       "cannot be judged");
  if (std_max) {
    uncertain.RejectInto(verdict, "position too uncertain (1 sigma above " + Fmt(*std_max * 1e6) +
                                      " um): rotate faster and about every axis, for longer");
  }
  if (!(r.full ? r.full_diagnostics.converged : r.diagnostics.converged)) {
    verdict->Reject(
        "the solver did not converge: the positions are not the best fit; raise "
        "max_iterations or record a more exciting motion");
  }
  // Positions model: the residuals against the configured noise.
  const auto chi2_max = limits.Get("max_chi2");
  if (chi2_max && !r.full) {
    const results::SensorFigures& rms = r.diagnostics.residual_rms;
    const results::SensorFigures& noise = r.diagnostics.noise_configured;
    for (const bool accel : {true, false}) {
      const double res = accel ? rms.accelerometer : rms.gyroscope;
      const double n = accel ? noise.accelerometer : noise.gyroscope;
      if (!std::isfinite(res) || !std::isfinite(n) || n <= 0) continue;
      const double chi2 = (res / n) * (res / n);
      if (chi2 > *chi2_max) {
        verdict->Reject(std::string("the ") + (accel ? "accelerometer" : "gyroscope") +
                        " residuals are " + Fmt(res / n) + " times the configured noise (" +
                        (accel ? "accel_noise " : "gyro_noise ") + Fmt(n) + ", ratio squared " +
                        Fmt(chi2) + " above " + Fmt(*chi2_max) +
                        "): the noise figure is wrong, the sensors saturated, or the model does "
                        "not fit (a sensor's gain or bias: calibrate the accelerometers first)");
      }
    }
  }
  // Model full: every triad's gains, misalignments and biases, as for imu.
  if (r.full) {
    TriadNominal nominal;
    InertialUnits units;
    if (ParseInertialUnits(config, &units).ok()) {
      nominal.accel_unit = units.accel;
      nominal.gyro_unit = units.gyro;
      nominal.accel_text = units.accel_text;
      nominal.gyro_text = units.gyro_text;
    }
    std::vector<results::ImuTriads> imus;
    std::vector<results::ImuTriadsStd> stds;
    for (const auto& imu : params.imus) imus.push_back(imu.triads);
    for (const auto& s : uncertainty.imus) stds.push_back(s.triads);
    JudgeImuTriads(imus, stds, nominal, limits, "IMU", verdict);
  }
}

Status SimulateArrayFullFiles(const ArraySimulationFileOptions& options, std::string* csv,
                              json* config, json* truth) {
  if (options.gyro_unit != "rad/s" && options.gyro_unit != "deg/s")
    return Status::InvalidInput("gyro_unit must be \"rad/s\" or \"deg/s\", not \"" +
                                options.gyro_unit + "\"");
  core::ArrayFullSimulationOptions so;
  if (options.board == "mimu4444")
    so.nominal_positions = core::Mimu4444NominalPositions();
  else if (options.board == "paper32")
    so.nominal_positions = core::PaperArrayNominalPositions();
  else
    return Status::InvalidInput("board must be \"mimu4444\" or \"paper32\", not \"" +
                                options.board + "\"");
  so.seed = options.seed;
  so.dynamic_samples = options.samples;
  so.static_duration = 1.5;
  so.accel_noise = options.accel_noise;
  so.gyro_noise = options.gyro_noise_dps * core::kDegree;
  core::ArrayFullSimulation sim;
  Status s = core::SimulateArrayFull(so, &sim);
  if (!s.ok()) return s;
  const bool degrees = options.gyro_unit == "deg/s";
  const double unit = degrees ? core::kDegree : 1.0;  // rad/s per reading unit
  const int K = static_cast<int>(so.nominal_positions.cols());
  std::string out = "t";
  for (const char* kind : {"a", "g"})
    for (int k = 0; k < K; ++k)
      for (const char* axis : {"_x", "_y", "_z"}) out += "," + (kind + std::to_string(k)) + axis;
  out += '\n';
  const int64_t N = sim.problem.t.size();
  for (int64_t n = 0; n < N; ++n) {
    out += FormatG17(sim.problem.t(n));
    for (int c = 0; c < 3 * K; ++c) out += "," + FormatG17(sim.problem.accel(n, c));
    for (int c = 0; c < 3 * K; ++c) out += "," + FormatG17(sim.problem.gyro(n, c) / unit);
    out += '\n';
  }
  *csv = std::move(out);
  json nominal = json::array(), imus = json::array();
  for (int k = 0; k < K; ++k) {
    nominal.push_back(Nums(so.nominal_positions.col(k)));
    const core::ArrayFullTriadReport p = core::ReportArrayFullTriad(sim.truth[k]);
    imus.push_back({{"name", std::to_string(k)},
                    {"accelerometer", results::ToJson(SensorTriadOf(p.accelerometer, 1))},
                    {"gyroscope", results::ToJson(SensorTriadOf(p.gyroscope, unit))},
                    {"position", Nums(p.position)}});
  }
  *config = {{"method", "array"},
             {"model", "full"},
             {"geometry", {{"positions", nominal}, {"reference", so.reference}}},
             {"accel_noise", so.accel_noise},
             {"gyro_noise", options.gyro_noise_dps * (degrees ? 1 : core::kDegree)},
             {"gyro_unit", options.gyro_unit},
             {"static_window", 0.25},
             {"min_static", 0.5}};
  *truth = {{"method", "array"},
            {"model", "full"},
            {"reference", so.reference},
            {"imus", std::move(imus)},
            {"seed", options.seed},
            {"options",
             {{"board", options.board},
              {"dynamic_samples", options.samples},
              {"statics", so.statics},
              {"static_duration", so.static_duration},
              {"rate", so.rate},
              {"accel_noise", options.accel_noise},
              {"gyro_noise_dps", options.gyro_noise_dps},
              {"gyro_unit", options.gyro_unit}}}};
  return Status::Ok();
}

namespace {

class Array : public Method {
 public:
  const char* name() const override { return "array"; }
  Status ResolveReferences(storage::Store* store, nlohmann::json* config) const override {
    return ResolveArrayReferences(store, config);
  }
  const char* simulate_summary() const override {
    return "Carlsson et al. Section IV: 32 IMUs on a 4x4 grid, top and underside of a PCB";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override {
    struct State {
      ArraySimulationFileOptions options;
      std::string model = "positions";
      int static_positions = 0;
    };
    auto state = std::make_shared<State>();
    command->add_option("--seed", state->options.seed, "random seed")->capture_default_str();
    command->add_option("-N,--samples", state->options.samples, "number of samples N")
        ->check(CLI::Range(1, 100000000))
        ->capture_default_str();
    command->add_option("--omega", state->options.omega_norm_dps, "‖ω‖ in °/s")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--omega-dot", state->options.omega_dot_norm_dps2, "‖ω̇‖ in °/s²")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--accel-noise", state->options.accel_noise, "σ_a in m/s²")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-noise", state->options.gyro_noise_dps, "σ_g in °/s")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--position-perturbation", state->options.position_perturbation,
                     "σ of the true positions around the nominal grid, m")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-unit", state->options.gyro_unit, "unit of the gyroscope columns")
        ->check(CLI::IsMember({"rad/s", "deg/s"}))
        ->capture_default_str();

    command
        ->add_option("--accel-bias", state->options.accel_bias,
                     "σ of each accelerometer bias, m/s² (a per-triad error of the board)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--accel-scale-error", state->options.accel_scale_error,
                     "σ of each accelerometer's relative scale-factor error")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--accel-misalignment", state->options.accel_misalignment,
                     "σ of each accelerometer axis tilt, rad")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--model", state->model,
                     "positions: the seed's set-up (ideal triads); full: per-triad accelerometer "
                     "and gyroscope errors, 20 statics then the dynamic phase (-N samples), for "
                     "model full")
        ->check(CLI::IsMember({"positions", "full"}))
        ->capture_default_str();
    command->add_option("--board", state->options.board, "with --model full: mimu4444 or paper32")
        ->check(CLI::IsMember({"mimu4444", "paper32"}))
        ->capture_default_str();
    command
        ->add_option("--static-positions", state->static_positions,
                     "also write static.csv and static_config.json: the same board in n static "
                     "orientations, for a pca calibration with bias: estimate")
        ->check(CLI::Range(0, 1000000));
    command
        ->add_option("--static-samples", state->options.static_samples,
                     "samples averaged per static position (noise σ_a/√samples)")
        ->check(CLI::Range(int64_t{1}, int64_t{1000000000}))
        ->capture_default_str();
    return [state](SimulatedFiles* files) {
      if (state->model == "full") {
        return SimulateArrayFullFiles(state->options, &files->csv, &files->config, &files->truth);
      }
      Status s = SimulateArrayFiles(state->options, &files->csv, &files->config, &files->truth);
      if (!s.ok() || state->static_positions == 0) return s;
      std::string static_csv;
      nlohmann::json static_config;
      s = SimulateArrayStaticFiles(state->options, state->static_positions, &static_csv,
                                   &static_config);
      if (!s.ok()) return s;
      files->extra = {{"static.csv", static_csv},
                      {"static_config.json", static_config.dump(2) + "\n"}};
      return s;
    };
  }
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat()};
  }
  Status Export(const std::string& format, const nlohmann::json& result,
                const ExportContext& context, std::string* out) const override {
    if (format == "csv") return ArrayResultToCsv(result, out);
    if (format == "h") return ArrayResultToHeader(result, context, out);
    return NoSuchExport(format, name());
  }
  const char* summary() const override {
    return "positions of the accelerometer triads of an inertial sensor array from a free, "
           "hand-twisted recording (Carlsson, Skog, Jalden: maximum likelihood)";
  }
  bool Reads(Layout layout) const override { return layout == Layout::kArray; }
  // The positions model ignores t; the full model finds its statics from it.
  bool ReadsTime(const nlohmann::json& config) const override { return IsFullModel(config); }
  // Measured server peaks (bench/README.md, "Memory budget per job"): positions model, N = 100 000
  // samples of 32 IMUs, 14 bytes per value; full model, 8 IMUs and 23 000 rows, 58 bytes per
  // value (the per-sample Jacobians of every triad's T and b).
  double PeakBytesPerValue(const nlohmann::json& config) const override {
    return IsFullModel(config) ? 64 : 24;
  }
  Status ValidateConfig(const nlohmann::json& config) const override {
    bool degrees = false;
    if (IsFullModel(config)) {
      core::ArrayFullProblem geometry;
      core::ArrayFullOptions options;
      return ParseArrayFullConfig(config, &geometry, &options, &degrees);
    }
    core::ArrayProblem geometry;
    core::ArrayOptions options;
    return ParseArrayConfig(config, &geometry, &options, &degrees);
  }
  void Judge(const nlohmann::json& result, const nlohmann::json& config,
             const AcceptanceLimits& limits, Verdict* verdict) const override {
    JudgeArray(result, config, limits, verdict);
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>(JoinKeys({
        {
            {"max_position_std", "largest 1 sigma of a position coordinate, m", 1e-4},  // 0.1 mm
            {"max_offset",
             "largest distance of a triad from its nominal position in `geometry`, m (a wrong "
             "geometry or gyro_unit shows here)",
             0.005},               // 5 mm
            limit_keys::kMaxChi2,  // residual RMS against accel_noise and gyro_noise, each
        },
        ImuTriadKeys(),  // model full (parameters.imus) only
    }));
    return keys;
  }

  Status Run(RecordingParser* parser, const nlohmann::json& config, const RunContext& ctx,
             nlohmann::json* result) const override {
    ArrayRecording recording;
    Status s = parser->TakeArray(&recording);
    if (!s.ok()) return s;
    return RunArray(std::move(recording), config, result, ctx.stop, ctx.executor);
  }
};

}  // namespace

const Method& ArrayMethod() {
  static const Array& method = *new Array;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
