// Model "positions" (the default) of the `array` method: the config keys, the
// accelerometer_calibration a fit may use, the run and its result (SPEC §3, §4), and the
// simulated files of `calibd simulate array` (methods/array/array_method.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "core/array_simulation.h"
#include "methods/array/array_internal.h"
#include "methods/array/array_method.h"
#include "methods/array/array_result.h"
#include "methods/noise/noise_reference.h"
#include "methods/pca/pca_result.h"

namespace calibd::server {

using array_detail::FormatG17;
using array_detail::KeyError;
using array_detail::ParseGeometry;
using array_detail::ParseGyroUnit;
using array_detail::ReadInteger;
using array_detail::ReadPositive;
using array_detail::ReadString;
using array_detail::ReadTolerance;
using nlohmann::json;

namespace {

// The result documents' writing conventions (NaN as null): results/json_reader.h.
using results::Num;
using results::Nums;

constexpr const char* kCalibrationKey = "accelerometer_calibration";

Status CalibrationError(const std::string& message) { return KeyError(kCalibrationKey, message); }

std::string FormatG(double v, int digits = 4) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

constexpr const char* kPositionsModelEquation =
    "y_a,k = s + (Omega(omega)^2 + Omega(omega_dot)) r_k for accelerometer triad k at "
    "position r_k (metres, nominal geometry frame, the reference triad held at its "
    "nominal position), y_g = omega for every gyroscope triad: s the specific force at "
    "the origin, omega the angular rate, Omega(x) the cross-product matrix; the "
    "parameters are the positions r_k";
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

namespace {

// The K accelerometer triad models (core::AccelerometerTriadModel) from the sensors aK_x, aK_y,
// aK_z of a pca result: column i of triad k's sensitivity block is the sensitivity of its axis i.
// Names not found are appended to *missing (their entries stay 0); *used counts those found.
// A name given twice, or a sensitivity or bias that is not finite, is a CalibrationError.
Status ReadTriadModels(const std::vector<results::PcaSensor>& sensors, int triads,
                       std::vector<core::AccelerometerTriadModel>* models,
                       std::vector<std::string>* missing, int* used) {
  std::map<std::string, int> index;
  for (size_t i = 0; i < sensors.size(); ++i) {
    if (!index.emplace(sensors[i].name, static_cast<int>(i)).second)
      return CalibrationError("the pca result names sensor '" + sensors[i].name +
                              "' twice (parameters.sensors[" + std::to_string(i) + "].name)");
  }
  *used = 0;
  models->assign(triads, core::AccelerometerTriadModel());
  static const char* const kAxes[] = {"_x", "_y", "_z"};
  for (int k = 0; k < triads; ++k)
    for (int i = 0; i < 3; ++i) {
      const std::string name = "a" + std::to_string(k) + kAxes[i];
      auto it = index.find(name);
      if (it == index.end()) {
        missing->push_back(name);
        continue;
      }
      ++*used;
      const results::PcaSensor& sensor = sensors[it->second];
      const std::string where = "parameters.sensors[" + std::to_string(it->second) + "]";
      // FromJson checked: 3 components (dimension 3), null read as NaN.
      for (int j = 0; j < 3; ++j) {
        if (!std::isfinite(sensor.sensitivity[j]))
          return CalibrationError("sensor '" + name + "' has a sensitivity that is not 3 finite " +
                                  "numbers (" + where + ".sensitivity)");
        (*models)[k].sensitivity(j, i) = sensor.sensitivity[j];  // column i = a_i
      }
      if (!std::isfinite(sensor.bias))
        return CalibrationError("sensor '" + name + "' has a bias that is not a finite number (" +
                                where + ".bias)");
      (*models)[k].bias(i) = sensor.bias;
    }
  return Status::Ok();
}

// Every triad's 3x3 sensitivity block invertible and well conditioned (condition number at most
// core::kMaxAccelerometerConditionNumber), else a CalibrationError naming the triad; the largest
// condition number is kept in *max_condition_number.
Status CheckTriadConditioning(const std::vector<core::AccelerometerTriadModel>& models,
                              double* max_condition_number) {
  const int triads = static_cast<int>(models.size());
  for (int k = 0; k < triads; ++k) {
    const double cond = core::AccelerometerConditionNumber(models[k]);
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
    *max_condition_number = std::max(*max_condition_number, cond);
  }
  return Status::Ok();
}

}  // namespace

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
  std::vector<std::string> missing;
  int used = 0;
  if (Status s = ReadTriadModels(sensors, triads, &out->triads, &missing, &used); !s.ok()) return s;
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
  if (Status s = CheckTriadConditioning(out->triads, &out->max_condition_number); !s.ok()) return s;
  const int ignored = static_cast<int>(sensors.size()) - used;
  if (ignored > 0)
    out->warnings.push_back("accelerometer_calibration: " + std::to_string(ignored) +
                            " sensor(s) of the pca result are not accelerometer columns of this "
                            "array and were ignored");
  out->sensors = used;
  out->present = true;
  return Status::Ok();
}

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
  if (*gyro_in_degrees) options->gyro_message_unit = {"deg/s", core::kDegree};

  Status s = ParseGeometry(config, geometry_part);
  if (!s.ok()) return s;

  // A number, or {"job": ID} of a noise job resolved at enqueue (methods/noise/noise_reference.h;
  // SI).
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
  if (s = ReadTolerance(config, &options->tolerance); !s.ok()) return s;
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

namespace array_detail {

Status RunArrayPositions(ArrayRecording recording, const json& config, json* result,
                         const core::StopToken* stop, core::TaskExecutor executor) {
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
    unc.positions.push_back({r.names[k], r.position_std.col(k), r.position_std_crb.col(k)});
  }
  unc.basis = r.sigma_basis;
  unc.chi2_per_dof = r.chi2_per_dof;
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

}  // namespace array_detail

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

}  // namespace calibd::server
