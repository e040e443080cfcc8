// Model "full" of the `array` method (SPEC §7, issue #14): the config keys, the run and its
// result, and the simulated files of `calibd simulate array --model full`
// (methods/array/array_method.h).
#include <algorithm>
#include <cmath>
#include <limits>

#include "core/array_full.h"
#include "core/array_full_simulation.h"
#include "methods/array/array_internal.h"
#include "methods/array/array_method.h"
#include "methods/array/array_result.h"

namespace calibd::server {

using array_detail::FormatG17;
using array_detail::KeyError;
using array_detail::ParseGeometry;
using array_detail::ParseGyroUnit;
using array_detail::ReadInteger;
using array_detail::ReadNumber;
using array_detail::ReadPositive;
using array_detail::ReadString;
using array_detail::ReadTolerance;
using nlohmann::json;
using results::Nums;

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

// The result of a fit that succeeded: the model equation, parameters, uncertainty and the
// diagnostics beyond the partial ones RunArrayFull writes in any case; gyroscope figures in the
// configured unit (`degrees`: deg/s, else rad/s).
void WriteFullResult(const core::ArrayFullResult& r, const core::ArrayFullProblem& problem,
                     const core::ArrayFullOptions& options, bool degrees,
                     results::ArrayResult* out) {
  const int K = static_cast<int>(problem.nominal_positions.cols());
  results::ArrayFullDiagnostics& d = out->full_diagnostics;
  const double gyro_unit = degrees ? core::kDegree : 1.0;  // rad/s per reading unit
  out->envelope.model = kFullModelEquation;
  for (const core::ArrayFullStatic& st : r.static_intervals)
    d.static_intervals.push_back(
        {st.start, st.end, st.samples, st.accel_rms, st.gyro_rms / gyro_unit});

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
    const core::ArrayFullTriadStd& crb = r.report_std_crb[k];
    u.crb = results::ArrayImuCrbStd{SensorTriadStdOf(crb.accelerometer, 1),
                                    SensorTriadStdOf(crb.gyroscope, gyro_unit), crb.position_std};
    unc.imus.push_back(std::move(u));
    params.positions.push_back({p.name, p.position, p.position - problem.nominal_positions.col(k)});
    unc.positions.push_back({p.name, sd.position_std, crb.position_std});
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
  out->parameters = std::move(params);
  unc.basis = r.sigma_basis;
  unc.chi2_per_dof = r.chi2_per_dof;
  out->uncertainty = std::move(unc);
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
  d.robust = {r.sigma_basis == "sandwich", r.robust_batches, options.robust_batch,
              options.robust_ratio};
  d.positions_only_start = r.initial_positions_from_array;
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
  if (*gyro_in_degrees) options->gyro_message_unit = {"deg/s", core::kDegree};
  core::ArrayProblem geometry;
  Status s = ParseGeometry(config, &geometry);
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
  if (s = ReadTolerance(config, &options->tolerance); !s.ok()) return s;
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return Status::Ok();
}

namespace array_detail {

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
  *result = FullResultJson(r, s, problem, options, degrees, std::move(saturation),
                           std::move(saturation_warnings));
  return s;
}

json FullResultJson(const core::ArrayFullResult& r, const Status& status,
                    const core::ArrayFullProblem& problem, const core::ArrayFullOptions& options,
                    bool degrees, std::optional<results::SaturationDiagnostics> saturation,
                    std::vector<std::string> saturation_warnings) {
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
  if (!status.ok()) {
    // The partial diagnostics kept with the failed job: what the run found before failing.
    out.envelope.usable = false;
    return results::ToJson(out);
  }
  WriteFullResult(r, problem, options, degrees, &out);
  return results::ToJson(out);
}

}  // namespace array_detail

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

}  // namespace calibd::server
