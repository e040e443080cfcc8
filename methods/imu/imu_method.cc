#include "methods/imu/imu_method.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <memory>
#include <set>
#include <tuple>

#include "core/imu_simulation.h"
#include "formats/inertial_log.h"
#include "methods/imu/imu_result.h"
#include "methods/imu/openvins_yaml.h"
#include "methods/noise/noise_reference.h"
#include "methods/saturation_report.h"

namespace calibd::server {

using nlohmann::json;

namespace {

Status KeyError(const std::string& key, const std::string& message) {
  return Status::InvalidInput("config key '" + key + "': " + message).WithField(key);
}

Status ReadNumber(const json& config, const char* key, bool positive, std::optional<double>* out) {
  auto it = config.find(key);
  if (it == config.end() || it->is_null()) return Status::Ok();
  if (!it->is_number() || !std::isfinite(it->get<double>()) ||
      (positive && !(it->get<double>() > 0))) {
    return KeyError(key, positive ? "must be a number > 0" : "must be a finite number");
  }
  *out = it->get<double>();
  return Status::Ok();
}

Status ParseImuConfig(const json& config, core::ImuOptions* options) {
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  static const std::set<std::string>& kKnown = *new std::set<std::string>{"method",
                                                                          "device",
                                                                          "accel_unit",
                                                                          "gyro_unit",
                                                                          "gravity",
                                                                          "latitude",
                                                                          "height",
                                                                          "gyro_bias",
                                                                          "static_window",
                                                                          "min_static",
                                                                          "static_threshold",
                                                                          "accel_noise",
                                                                          "gyro_noise",
                                                                          "nominal_accel_bias",
                                                                          "nominal_gyro_bias",
                                                                          "accel_saturation",
                                                                          "gyro_saturation",
                                                                          "max_scale_deviation"};
  for (const auto& [key, value] : config.items()) {
    if (kKnown.count(key) == 0) {
      return KeyError(key,
                      "is not an imu config key (known: accel_unit, gyro_unit, gravity, latitude, "
                      "height, gyro_bias, static_window, min_static, static_threshold, "
                      "accel_noise, gyro_noise, nominal_accel_bias, nominal_gyro_bias, "
                      "accel_saturation, gyro_saturation, max_scale_deviation, method, device)");
    }
  }
  *options = core::ImuOptions();
  InertialUnits units;
  Status s = ParseInertialUnits(config, &units);
  if (!s.ok()) return s;
  options->accel_unit = units.accel;
  options->gyro_unit = units.gyro;
  std::optional<double> gravity, latitude, height, window, min_static, an, gn, ab, gb, deviation;
  for (auto [key, positive, out] :
       std::vector<std::tuple<const char*, bool, std::optional<double>*>>{
           {"gravity", true, &gravity},
           {"latitude", false, &latitude},
           {"height", false, &height},
           {"static_window", true, &window},
           {"min_static", false, &min_static},
           {"nominal_accel_bias", false, &ab},
           {"nominal_gyro_bias", false, &gb},
           {"max_scale_deviation", true, &deviation}}) {
    s = ReadNumber(config, key, positive, out);
    if (!s.ok()) return s;
  }
  if (gravity && (latitude || height)) {
    return KeyError("gravity", "give either gravity or latitude and height, not both");
  }
  if (height && !latitude) return KeyError("latitude", "is needed with height");
  if (latitude) {
    if (std::abs(*latitude) > 90) return KeyError("latitude", "must be in -90..90 degrees");
    options->gravity = core::Wgs84NormalGravity(*latitude, height.value_or(0));
  } else if (gravity) {
    options->gravity = *gravity;
  }
  // How far a scale factor may be from the nominal unit before the fit refuses it as a unit
  // mix-up (core default 0.25): widen it for a sensor whose gain is only roughly known.
  if (deviation) options->max_scale_deviation = *deviation;
  if (window) options->detection.static_window = *window;
  if (min_static) {
    if (*min_static < 0) return KeyError("min_static", "must be >= 0 seconds");
    options->detection.min_static = *min_static;
  }
  // σ per sample, SI: a number, or {"job": ID} of a noise job resolved at enqueue
  // (methods/noise/noise_reference.h).
  for (auto [key, out] :
       {std::pair<const char*, std::optional<double>*>{"accel_noise", &an}, {"gyro_noise", &gn}}) {
    std::optional<NoiseLevel> level;
    s = ReadNoiseLevel(config, key, &level);
    if (!s.ok()) return s;
    if (level) *out = level->value;
  }
  options->accel_noise = an;
  options->gyro_noise = gn;
  if (ab) options->nominal_accel_bias = *ab;
  if (gb) options->nominal_gyro_bias = *gb;
  if (auto it = config.find("gyro_bias"); it != config.end()) {
    if (*it == "statics") {
      options->gyro_bias = core::GyroBiasModel::kStatics;
    } else if (*it == "estimate") {
      options->gyro_bias = core::GyroBiasModel::kEstimate;
    } else {
      return KeyError("gyro_bias", "must be \"statics\" or \"estimate\"");
    }
  }
  if (auto it = config.find("static_threshold"); it != config.end() && !it->is_null()) {
    if (!it->is_object()) {
      return KeyError("static_threshold",
                      "must be {\"accelerometer\": x, \"gyroscope\": y} (window spread in "
                      "reading units; either may be left out)");
    }
    for (const auto& [key, value] : it->items()) {
      if ((key != "accelerometer" && key != "gyroscope") || !value.is_number() ||
          !(value.get<double>() > 0) || !std::isfinite(value.get<double>())) {
        return KeyError("static_threshold",
                        "must be {\"accelerometer\": x, \"gyroscope\": y} with numbers > 0");
      }
      (key == "accelerometer" ? options->detection.accel_threshold
                              : options->detection.gyro_threshold) = value.get<double>();
    }
  }
  // Saturation: a number s (readings at or beyond ±s) or [low, high] (e.g. [0, 65535] for
  // offset-binary counts), reading units. Saturated samples are dropped from the statics and
  // counted in the diagnostics.
  for (auto [key, low, high] :
       {std::tuple<const char*, double*, double*>{
            "accel_saturation", &options->accel_saturation_low, &options->accel_saturation_high},
        std::tuple<const char*, double*, double*>{"gyro_saturation", &options->gyro_saturation_low,
                                                  &options->gyro_saturation_high}}) {
    auto it = config.find(key);
    if (it == config.end() || it->is_null()) continue;
    const char* help =
        "must be a number s > 0 (readings at or beyond +-s are saturated) or [low, high] in "
        "reading units";
    if (it->is_number() && std::isfinite(it->get<double>()) && it->get<double>() > 0) {
      *low = -it->get<double>();
      *high = it->get<double>();
    } else if (it->is_array() && it->size() == 2 && (*it)[0].is_number() && (*it)[1].is_number() &&
               std::isfinite((*it)[0].get<double>()) && std::isfinite((*it)[1].get<double>()) &&
               (*it)[0].get<double>() < (*it)[1].get<double>()) {
      *low = (*it)[0].get<double>();
      *high = (*it)[1].get<double>();
    } else {
      return KeyError(key, help);
    }
  }
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return Status::Ok();
}

// "12.5-13.1 s, 40-41.2 s" for at most `max` gaps.
std::string GapList(const std::vector<core::TimeGap>& gaps, size_t max = 10) {
  std::string out;
  char buf[64];
  for (size_t i = 0; i < gaps.size() && i < max; ++i) {
    std::snprintf(buf, sizeof buf, "%s%.6g-%.6g s", i ? ", " : "", gaps[i].start, gaps[i].end);
    out += buf;
  }
  if (gaps.size() > max) out += ", ...";
  return out;
}

results::SensorTriad Triad(const core::TriadCalibration& c) {
  return {c.bias, c.scale, c.misalignment, c.matrix};
}

results::SensorTriadStd TriadStd(const core::TriadCalibration& c) {
  return {c.bias_std, c.scale_std, c.misalignment_std};
}

results::ImuFitDiagnostics FitDiagnostics(const core::ImuResult& r) {
  results::ImuFitDiagnostics f;
  for (const auto& s : r.statics) {
    f.statics.push_back({s.start, s.end, s.samples, s.accel_mean, s.accel_std, s.gyro_mean,
                         s.gyro_std, s.gravity_direction, s.norm_residual_before,
                         s.norm_residual_after});
  }
  for (const auto& q : r.rotations) {
    f.rotations.push_back({q.from, q.to, q.start, q.end, q.angle, q.direction_error_before,
                           q.direction_error_after, q.used, q.excluded});
  }
  for (const auto& t : r.threshold_trials) {
    f.threshold_trials.push_back({t.multiplier, t.statics, t.accel_chi2_per_dof, t.chosen});
  }
  const core::ImuCoverage& c = r.coverage;
  f.coverage = {c.gravity_eigenvalues,
                c.min_eigenvalue,
                c.least_covered_direction,
                c.missing_up,
                c.rotation_per_axis,
                c.weak_axes,
                c.sufficient,
                c.verdict};
  f.name = r.name;
  f.usable = r.usable;
  f.termination = core::ImuTerminationName(r.termination);
  f.reason = r.reason;
  f.chi2_per_dof = r.chi2_per_dof;
  f.degrees_of_freedom = r.degrees_of_freedom;
  f.accel_iterations = r.accel_iterations;
  f.gyro_iterations = r.gyro_iterations;
  f.joint_iterations = r.joint_iterations;
  f.accel_noise = r.accel_noise;
  f.gyro_noise = r.gyro_noise;
  f.accel_norm_rms_before = r.accel_norm_rms_before;
  f.accel_norm_rms_after = r.accel_norm_rms_after;
  f.gyro_direction_rms_before = r.gyro_direction_rms_before;
  f.gyro_direction_rms_after = r.gyro_direction_rms_after;
  f.threshold_choice = r.threshold_choice;
  f.cost = r.cost;
  return f;
}

// diagnostics.noise_jobs and noise_model of a config's resolved noise references
// (methods/noise/noise_reference.h).
void NoiseReferences(const json& config, results::ImuDiagnostics* d) {
  results::ImuDiagnostics::NoiseJobs jobs;
  results::ImuDiagnostics::NoiseModels models;
  for (auto [key, job, model] :
       {std::tuple<const char*, std::optional<int64_t>*, std::optional<results::ImuNoiseModel>*>{
            "accel_noise", &jobs.accelerometer, &models.accelerometer},
        std::tuple<const char*, std::optional<int64_t>*, std::optional<results::ImuNoiseModel>*>{
            "gyro_noise", &jobs.gyroscope, &models.gyroscope}}) {
    std::optional<NoiseLevel> level;
    if (ReadNoiseLevel(config, key, &level).ok() && level && level->job) *job = level->job;
    if (std::optional<NoiseFigures> figures = ReadNoiseFigures(config, key)) {
      *model = results::ImuNoiseModel{figures->job, figures->white_noise, figures->random_walk};
    }
  }
  d->noise_jobs = jobs;
  d->noise_model = models;
}

// The IMUs of a log: triad K of the accelerometers and of the gyroscopes, copied out (N×3 each)
// for core::CalibrateImus / FindImuStatics, which borrow them through `readings`.
struct ImuTriadCopies {
  std::vector<Eigen::MatrixX3d> accel, gyro;
  std::vector<core::ImuReadings> readings;

  // kInvalidInput when the log's accelerometer and gyroscope triads do not pair up.
  Status From(const ArrayRecording& log) {
    const size_t imus = log.accel_names.size();
    if (log.gyro_names.size() != imus) {
      return Status::InvalidInput(
          "the imu method pairs accelerometer triad K with gyroscope "
          "triad K, but the log has " +
          std::to_string(imus) + " accelerometer and " + std::to_string(log.gyro_names.size()) +
          " gyroscope triads");
    }
    accel.resize(imus);
    gyro.resize(imus);
    readings.resize(imus);
    for (size_t k = 0; k < imus; ++k) {
      accel[k] = log.accel.middleCols(3 * static_cast<Eigen::Index>(k), 3);
      gyro[k] = log.gyro.middleCols(3 * static_cast<Eigen::Index>(k), 3);
      readings[k].name = std::to_string(k);
      readings[k].accel = &accel[k];
      readings[k].gyro = &gyro[k];
    }
    return Status::Ok();
  }
};

// Saturation (core/saturation.h) as Run and Check find it: per kind, the configured limit or the
// clip levels found in the data, combined into the one [low, high] the fit takes (the tightest
// over the kind's channels; written into *options); pinned samples never join a static (nor any
// window holding one) and rotations through one are not used. The channels with pinned samples
// are appended to *saturation.
Status FindImuSaturation(const ArrayRecording& log, const core::StopToken* stop,
                         core::ImuOptions* options, results::SaturationDiagnostics* saturation) {
  std::vector<core::ChannelSaturation> accel_channels, gyro_channels;
  for (auto [columns, names, low, high, channels] :
       {std::tuple<const Eigen::MatrixXd*, const std::vector<std::string>*, double*, double*,
                   std::vector<core::ChannelSaturation>*>{
            &log.accel, &log.accel_names, &options->accel_saturation_low,
            &options->accel_saturation_high, &accel_channels},
        std::tuple<const Eigen::MatrixXd*, const std::vector<std::string>*, double*, double*,
                   std::vector<core::ChannelSaturation>*>{
            &log.gyro, &log.gyro_names, &options->gyro_saturation_low,
            &options->gyro_saturation_high, &gyro_channels}}) {
    core::SaturationOptions so;
    so.stop = stop;
    if (std::isfinite(*low) || std::isfinite(*high)) {  // configured: overrides the search
      so.low = *low;
      so.high = *high;
    }
    Status s = FindSaturation(*columns, *names, so, channels);
    if (!s.ok()) return s;
    if (!so.low && !so.high) {
      const core::SaturationLimits limits = core::CombinedLimits(*channels);
      *low = limits.low;
      *high = limits.high;
    }
    AddSaturationChannels(*channels, 1, "reading units", saturation);
  }
  return Status::Ok();
}

// The check's "predicted" (SPEC §10, issue #27 item 2): per IMU, the σ its job would report,
// computed as the plan computes it (the imu fit on a simulated log of a nominal IMU, here with the
// statics' orientations, durations and the times between them replayed from the log:
// core::ReplayImuProtocol) with the noise the job would use (the config's, else the statics'
// pooled σ). The simulation runs at most kPredictRate Hz (and fewer when the log is long, down
// to kPredictMinRate) with the noise density kept (σ per sample × √(rate'/rate)): the statics'
// means and the integrated rotations then carry the log's information at a fraction of its
// samples. {"uncertainty": null, "reason"} when no prediction is possible.
constexpr double kPredictRate = 100, kPredictMinRate = 20, kPredictMaxSamples = 2e5;

json PredictFromLog(const Eigen::VectorXd& t, const std::vector<core::ImuReadings>& readings,
                    const std::vector<core::ImuResult>& found, core::ImuOptions options) {
  json out = {{"uncertainty", nullptr},
              {"basis", "crb"},
              {"how",
               "the imu method's σ (its Cramér–Rao bound: what the job reports when its "
               "residuals match the noise; χ²-scaled when they exceed it) on a simulation of a "
               "nominal IMU held in the statics found, for their durations, turned between them "
               "by the shortest rotation that the nominal gyroscope integrates to, with the "
               "noise below (SI per sample; from the config, or the statics' pooled σ as the "
               "job takes it)"},
              {"noise", json::array()}};
  auto fail = [&out](const std::string& why) {
    out["noise"] = json::array();
    out["reason"] = why;
    return out;
  };
  results::ImuUncertainty stds;
  for (size_t k = 0; k < found.size() && k < readings.size(); ++k) {
    const core::StaticDetection& d = found[k].detection;
    core::ImuSimulationOptions sim;
    Status s = core::ReplayImuProtocol(t, readings[k], d, static_cast<int>(k), options, &sim);
    if (!s.ok()) return fail(s.message());
    const double rate = d.sample_period > 0 ? 1 / d.sample_period : 0;
    double duration = 0;
    for (double x : sim.static_durations) duration += x;
    for (double x : sim.rotation_durations) duration += x;
    sim.rate = std::min({rate, kPredictRate, kPredictMaxSamples / duration});
    if (!(sim.rate >= kPredictMinRate)) {
      return fail("the statics and rotations last " + Fmt(duration) +
                  " s: more than a replay within the check's time");
    }
    // The job's noise: the config's σ for every axis, else the statics' pooled σ per axis.
    const Eigen::Vector3d pooled_a =
        core::PooledStd(d, static_cast<int>(2 * k)) * options.accel_unit;
    const Eigen::Vector3d pooled_g =
        core::PooledStd(d, static_cast<int>(2 * k + 1)) * options.gyro_unit;
    const Eigen::Vector3d accel_axes =
        options.accel_noise ? Eigen::Vector3d::Constant(*options.accel_noise) : pooled_a;
    const Eigen::Vector3d gyro_axes =
        options.gyro_noise ? Eigen::Vector3d::Constant(*options.gyro_noise) : pooled_g;
    const double accel_noise = accel_axes.maxCoeff(), gyro_noise = gyro_axes.maxCoeff();
    if (!(accel_axes.minCoeff() > 0) || !(gyro_axes.minCoeff() > 0)) {
      return fail("the statics show no noise on an axis (constant readings?)");
    }
    sim.accel_axis_ratio = accel_axes / accel_noise;
    sim.gyro_axis_ratio = gyro_axes / gyro_noise;
    out["noise"].push_back({{"name", found[k].name},
                            {"accel", {accel_axes.x(), accel_axes.y(), accel_axes.z()}},
                            {"gyro", {gyro_axes.x(), gyro_axes.y(), gyro_axes.z()}},
                            {"accel_source", options.accel_noise ? "config" : "statics"},
                            {"gyro_source", options.gyro_noise ? "config" : "statics"}});
    const double keep_density = std::sqrt(sim.rate / rate);
    sim.accel_noise = accel_noise * keep_density;
    sim.gyro_noise = gyro_noise * keep_density;
    SetNominalImu(options, &sim);
    core::ImuSimulation log;
    if (s = core::SimulateImu(sim, &log); !s.ok()) return fail(s.message());
    core::ImuOptions fit = options;
    // As the job: the config's σ (at the replay's rate), else the replay's pooled σ per axis.
    if (options.accel_noise) fit.accel_noise = sim.accel_noise;
    if (options.gyro_noise) fit.gyro_noise = sim.gyro_noise;
    core::ImuResult r;
    s = core::CalibrateImu(log.t, log.accel, log.gyro, fit, &r);
    if (!s.ok()) {
      return fail("IMU " + found[k].name +
                  ": the fit of the replayed protocol failed: " + s.message());
    }
    // The CRB: the σ of a log whose residuals match the noise (a replay whose χ² is above it
    // only says that a static of the replay caught the ends of a slow rotation).
    stds.imus.push_back({found[k].name, TriadStd(r.accelerometer_crb), TriadStd(r.gyroscope_crb)});
    out["rate"] = sim.rate;
    out["statics"] = r.detection.intervals.size();
  }
  results::ImuResult typed;
  typed.envelope.method = "imu";
  stds.basis = "crb";
  typed.uncertainty = std::move(stds);
  out["uncertainty"] = results::ToJson(typed).at("uncertainty");
  return out;
}

class Imu : public Method {
 public:
  const char* name() const override { return "imu"; }
  // accel_noise / gyro_noise as {"job": ID} of a noise job (methods/noise/noise_reference.h).
  Status ResolveReferences(storage::Store* store, nlohmann::json* config) const override {
    return ResolveNoiseReferences(store, config);
  }
  bool NeedsIncreasingTime() const override { return true; }
  const char* simulate_summary() const override {
    return "one IMU placed by hand in n static orientations joined by rotations (imu_tk set-up), "
           "with biases, scale errors and misalignments";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override {
    auto options = std::make_shared<core::ImuSimulationOptions>();
    command->add_option("--seed", options->seed, "random seed")->capture_default_str();
    command->add_option("--statics", options->statics, "static orientations")
        ->check(CLI::Range(1, 10000))
        ->capture_default_str();
    command->add_option("--static-seconds", options->static_duration, "seconds per static")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    command->add_option("--rotation-seconds", options->rotation_duration, "seconds per rotation")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    command->add_option("--rate", options->rate, "samples per second")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    command->add_option("--accel-noise", options->accel_noise, "σ per sample, m/s²")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-noise", options->gyro_noise, "σ per sample, rad/s")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--scale-error", options->scale_error, "σ of the relative scale errors")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--misalignment", options->misalignment, "σ of the misalignments, rad")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--accel-bias", options->accel_bias, "σ of the accelerometer biases, m/s²")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-bias", options->gyro_bias, "σ of the gyroscope biases, rad/s")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--gyro-bias-drift", options->gyro_bias_drift,
                     "linear gyroscope bias drift, rad/s per s")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--initial-motion", options->initial_motion,
                     "seconds of rotation before the first static")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    return [options](SimulatedFiles* files) {
      return SimulateImuFiles(*options, &files->csv, &files->config, &files->truth);
    };
  }
  std::vector<std::string> FleetParameters() const override {
    return {"imus/*/accelerometer/bias/*",
            "imus/*/accelerometer/scale/*",
            "imus/*/accelerometer/misalignment/*/*",
            "imus/*/gyroscope/bias/*",
            "imus/*/gyroscope/scale/*",
            "imus/*/gyroscope/misalignment/*/*"};
  }
  std::vector<FailureReason> FailureReasons() const override {
    return {
        CatalogEntry(
            core::imu_reason::kTooFewRotations, "Too few rotations",
            "Join the static orientations by rotations: turn the device between every two statics, "
            "about every axis, and hold it still again."),
    };
  }
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat(),
            ExportFormat{"yaml", "OpenVINS kalibr_imu_chain.yaml", "application/yaml",
                         "kalibr_imu_chain.yaml"}};
  }
  Status Export(const std::string& format, const nlohmann::json& result,
                const ExportContext& context, std::string* out) const override {
    if (format == "csv") return ImuResultToCsv(result, out);
    if (format == "h") return ImuResultToHeader(result, context, out);
    if (format == "yaml") return ImuResultToOpenVinsYaml(result, context, out);
    return NoSuchExport(format, name());
  }
  const char* summary() const override {
    return "accelerometer and gyroscope gains, misalignments and biases of each IMU from a "
           "hand-held log of static orientations joined by rotations (imu_tk model, ML)";
  }
  bool Reads(Layout layout) const override { return layout == Layout::kArray; }
  Status ValidateConfig(const json& config) const override {
    core::ImuOptions options;
    return ParseImuConfig(config, &options);
  }
  Status Plan(const nlohmann::json& config, const PlanProtocol& protocol,
              const AcceptanceLimits& limits, nlohmann::json* out) const override {
    return PlanImu(config, protocol, limits, out);
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    const AcceptanceKey& chi2 = limit_keys::kMaxChi2;
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>(JoinKeys({
        ImuTriadKeys(),
        {
            // No default: a static's mean is so precise (thousands of samples) that on real
            // hardware unmodelled effects, not the noise, set the residual (imu_tk's own Xsens
            // log: chi2/dof 30 with |a| - g at 1.1 mm/s^2 RMS). The physical residuals below
            // judge the fit instead.
            {chi2.name, chi2.meaning, std::nullopt},
            {"max_accel_residual",
             "largest RMS of |a| - g over the statics after calibration, m/s^2 "
             "(diagnostics.imus[].residuals.accel_norm_rms_after)",
             0.02},  // 0.2 % of g; imu_tk's Xsens log: 0.0011
            {"max_gyro_residual",
             "largest RMS gravity-direction error per rotation after calibration, rad "
             "(diagnostics.imus[].residuals.gyro_direction_rms_after)",
             0.02},  // 1.1 degrees; imu_tk's Xsens log: 0.0079
        },
    }));
    return keys;
  }
  void Judge(const json& result, const json& config, const AcceptanceLimits& limits,
             Verdict* verdict) const override {
    TriadNominal nominal;
    InertialUnits units;
    if (ParseInertialUnits(config, &units).ok()) {
      nominal.accel_unit = units.accel;
      nominal.gyro_unit = units.gyro;
      nominal.accel_text = units.accel_text;
      nominal.gyro_text = units.gyro_text;
    }
    nominal.accel_bias = Number(config.value("nominal_accel_bias", json())).value_or(0);
    nominal.gyro_bias = Number(config.value("nominal_gyro_bias", json())).value_or(0);
    results::ImuResult r;
    if (Status s = results::FromJson(result, &r); !s.ok() || !r.parameters) {
      verdict->Reject("the result cannot be judged: " +
                      (s.ok() ? std::string("it has no parameters (a failed run)") : s.message()));
      return;
    }
    JudgeImuTriads(r.parameters->imus, r.uncertainty->imus, nominal, limits, "IMU", verdict);
    const auto chi2_max = limits.Get("max_chi2");
    const auto accel_max = limits.Get("max_accel_residual");
    const auto gyro_max = limits.Get("max_gyro_residual");
    for (const results::ImuFitDiagnostics& d : r.diagnostics.imus) {
      const std::string name = "IMU " + d.name;
      if (!d.coverage.sufficient) {
        verdict->Reject(
            name + ": the orientations do not determine every parameter: " + d.coverage.verdict);
      }
      const double chi2 = d.chi2_per_dof;
      if (chi2_max && std::isfinite(chi2) && chi2 > *chi2_max) {
        verdict->Reject(name + ": the residuals are " + Fmt(std::sqrt(chi2)) +
                        " times the noise (chi2/dof " + Fmt(chi2) + " above " + Fmt(*chi2_max) +
                        "): the device moved during a static, or the statics are too short");
      }
      const double accel = d.accel_norm_rms_after;
      if (accel_max && std::isfinite(accel) && accel > *accel_max) {
        verdict->Reject(
            name + ": after calibration |a| still differs from gravity by " + Fmt(accel) +
            " m/s^2 RMS over the statics (above " + Fmt(*accel_max) +
            " m/s^2): the board moved during a static, or gravity is wrong for this place");
      }
      const double gyro = d.gyro_direction_rms_after;
      if (gyro_max && std::isfinite(gyro) && gyro > *gyro_max) {
        verdict->Reject(name +
                        ": after calibration the integrated rotations still miss the "
                        "measured gravity direction by " +
                        Fmt(gyro) + " rad RMS (above " + Fmt(*gyro_max) +
                        " rad): rotate more slowly (the gyroscope saturated?) or "
                        "hold each static longer");
      }
    }
  }
  Status Run(RecordingParser* parser, const json& config, const RunContext& context,
             json* result) const override {
    core::ImuOptions options;
    Status s = ParseImuConfig(config, &options);
    if (!s.ok())
      return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
    options.stop = context.stop;  // a stopped run returns core::StoppedStatus ("imu: <stage>: ...")
    ArrayRecording log;
    s = parser->TakeArray(&log);
    if (!s.ok()) return s;
    s = CheckLogTimes(log, "imu", &parser->summary());
    if (!s.ok()) return s;
    // Mean sample rate (Hz) over the log.
    const double rate = log.t.size() > 1 ? static_cast<double>(log.t.size() - 1) /
                                               (log.t[log.t.size() - 1] - log.t[0])
                                         : 0.0;
    ImuTriadCopies triads;
    s = triads.From(log);
    if (!s.ok()) return s;
    std::vector<core::ImuReadings>& readings = triads.readings;
    options.detection.stop = context.stop;
    results::SaturationDiagnostics saturation{"dropped", 0, {}};
    s = FindImuSaturation(log, context.stop, &options, &saturation);
    if (!s.ok()) return s;
    log.accel.resize(0, 0);
    log.gyro.resize(0, 0);
    std::vector<core::ImuResult> results;
    s = core::CalibrateImus(log.t, readings, options, &results);
    if (results.empty()) return s.ok() ? Status::Internal("imu: no result") : s;
    results::ImuResult typed;
    typed.envelope.method = "imu";
    results::ImuParameters params;
    results::ImuUncertainty stds;
    results::ImuDiagnostics& diag = typed.diagnostics;
    std::vector<std::string>& warnings = typed.envelope.warnings;
    for (const core::ImuResult& r : results) {
      params.imus.push_back({r.name, Triad(r.accelerometer), Triad(r.gyroscope)});
      stds.imus.push_back({r.name, TriadStd(r.accelerometer), TriadStd(r.gyroscope)});
      stds.crb.push_back({r.name, TriadStd(r.accelerometer_crb), TriadStd(r.gyroscope_crb)});
      if (stds.basis != "chi2_scaled") stds.basis = r.uncertainty_basis;
      if (!(r.chi2_per_dof <= stds.chi2_per_dof)) stds.chi2_per_dof = r.chi2_per_dof;
      diag.imus.push_back(FitDiagnostics(r));
      for (const std::string& w : r.warnings) warnings.push_back("IMU " + r.name + ": " + w);
    }
    const core::StaticDetection& d = results.front().detection;
    diag.gaps.emplace();
    for (const auto& g : d.gaps) diag.gaps->push_back({g.index, g.start, g.end});
    if (!d.gaps.empty()) {
      warnings.push_back(std::to_string(d.gaps.size()) + " gap(s) in t (" + GapList(d.gaps) +
                         "): no static interval spans one, and rotations across one are not "
                         "used");
    }
    if (!saturation.channels.empty()) {
      saturation.samples = d.saturated_samples;
      warnings.push_back(PinnedList(saturation) + ": " + std::to_string(d.saturated_samples) +
                         " saturated sample(s) dropped (never in a static nor in any window "
                         "holding one; rotations through one are not used); accel_saturation / "
                         "gyro_saturation in the config override the levels found");
      diag.saturation = saturation;
    } else if (d.saturated_samples > 0) {
      warnings.push_back(std::to_string(d.saturated_samples) +
                         " saturated sample(s) dropped from the static intervals");
    }
    for (const auto& iv : d.intervals) diag.statics.push_back({iv.start, iv.end, iv.samples});
    diag.rate = rate;
    NoiseReferences(config, &diag);
    diag.saturated_samples = d.saturated_samples;
    diag.static_window = options.detection.static_window;
    diag.min_static = options.detection.min_static;
    diag.threshold_choice = results.front().threshold_choice;
    if (!s.ok()) {
      // What was found before failing: the statics on the timeline, per IMU its coverage,
      // rotations and termination (the partial diagnostics kept with the failed job; no model,
      // parameters or uncertainty).
      typed.envelope.usable = false;
      *result = results::ToJson(typed);
      return s;
    }
    typed.envelope.model =
        "a = T_a K_a (y_a - b_a), omega = T_g K_g (y_g - b_g): y raw readings, b biases "
        "(reading units), K diagonal scales (SI per reading unit), T_a upper triangular with "
        "unit diagonal (the body frame is the accelerometer's: x along its x axis, y in its x-y "
        "plane), T_g the gyroscope's misalignment to that frame (unit diagonal); matrix = T K";
    params.gravity = options.gravity;
    params.gyro_bias = core::GyroBiasModelName(options.gyro_bias);
    // The nominal SI per reading unit the log was read with (exports to SI readings).
    params.accel_unit = options.accel_unit;
    params.gyro_unit = options.gyro_unit;
    typed.parameters = std::move(params);
    typed.uncertainty = std::move(stds);
    *result = results::ToJson(typed);
    return Status::Ok();
  }
  // Steps 1-2 of Run (the same FindImuSaturation and core::FindImuStatics), no fit.
  Status Check(const ArrayRecording& log, const json& config, const RunContext& context,
               json* check) const override {
    core::ImuOptions options;
    Status s = ParseImuConfig(config, &options);
    if (!s.ok()) return s;
    options.stop = context.stop;
    options.detection.stop = context.stop;
    s = CheckLogTimes(log, "imu");
    if (!s.ok()) return s;
    ImuTriadCopies triads;
    s = triads.From(log);
    if (!s.ok()) return s;
    results::SaturationDiagnostics saturation{"dropped", 0, {}};
    s = FindImuSaturation(log, context.stop, &options, &saturation);
    if (!s.ok()) return s;
    std::vector<core::ImuResult> found;
    s = core::FindImuStatics(log.t, triads.readings, options, &found);
    if (s.code() == StatusCode::kStopped || s.code() == StatusCode::kInvalidInput) return s;
    if (found.empty()) return Status::Internal("imu: no result");
    const core::StaticDetection& d = found.front().detection;
    saturation.samples = d.saturated_samples;
    (*check)["saturation"] = results::ToJson(saturation);
    json statics = json::array();
    for (const core::StaticInterval& iv : d.intervals) {
      // IMU 0's gravity direction (the detection's triad 0), nominal units.
      const Eigen::Vector3d v = iv.mean[0] - Eigen::Vector3d::Constant(options.nominal_accel_bias);
      const Eigen::Vector3d up = v.norm() > 0 ? Eigen::Vector3d(v.normalized()) : v;
      statics.push_back({{"start", iv.start},
                         {"end", iv.end},
                         {"samples", iv.samples},
                         {"up", {up.x(), up.y(), up.z()}},
                         {"accel_norm", v.norm() * options.accel_unit}});
    }
    (*check)["statics"] = std::move(statics);
    json coverage = json::array();
    for (const core::ImuResult& r : found) {
      coverage.push_back({{"name", r.name},
                          {"sufficient", r.coverage.sufficient},
                          {"verdict", r.coverage.verdict},
                          {"missing_up", r.coverage.missing_up},
                          {"min_eigenvalue", r.coverage.min_eigenvalue}});
      for (const std::string& w : r.warnings)
        (*check)["warnings"].push_back("IMU " + r.name + ": " + w);
    }
    (*check)["coverage"] = std::move(coverage);
    (*check)["threshold_choice"] = found.front().threshold_choice;
    if (!s.ok()) {
      (*check)["job_would_fail"] = s.message();
    } else {
      options.stop = context.stop;
      (*check)["predicted"] = PredictFromLog(log.t, triads.readings, found, options);
    }
    return Status::Ok();
  }
};

}  // namespace

Status SimulateImuFiles(const core::ImuSimulationOptions& options, std::string* csv, json* config,
                        json* truth) {
  core::ImuSimulation sim;
  Status s = core::SimulateImu(options, &sim);
  if (!s.ok()) return s;
  csv->clear();
  csv->reserve(static_cast<size_t>(sim.t.size()) * 100);
  *csv += "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (Eigen::Index i = 0; i < sim.t.size(); ++i) {
    const int n = std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n",
                                sim.t[i], sim.accel(i, 0), sim.accel(i, 1), sim.accel(i, 2),
                                sim.gyro(i, 0), sim.gyro(i, 1), sim.gyro(i, 2));
    csv->append(line, static_cast<size_t>(n));
  }
  *config = {{"method", "imu"},
             {"accel_unit", options.accel_unit},
             {"gyro_unit", options.gyro_unit},
             {"gravity", options.gravity}};
  if (options.accel_offset != 0) (*config)["nominal_accel_bias"] = options.accel_offset;
  if (options.gyro_offset != 0) (*config)["nominal_gyro_bias"] = options.gyro_offset;
  auto triad = [](const core::ImuTriadTruth& t) {
    return results::ToJson(results::SensorTriad{t.bias, t.scale, t.misalignment, t.matrix});
  };
  *truth = {{"method", "imu"},
            {"seed", options.seed},
            {"statics", options.statics},
            {"accelerometer", triad(sim.accel_truth)},
            {"gyroscope", triad(sim.gyro_truth)}};
  return Status::Ok();
}

void SetNominalImu(const core::ImuOptions& options, core::ImuSimulationOptions* sim) {
  sim->gravity = options.gravity;
  sim->accel_unit = options.accel_unit;
  sim->gyro_unit = options.gyro_unit;
  sim->accel_offset = options.nominal_accel_bias;
  sim->gyro_offset = options.nominal_gyro_bias;
  sim->scale_error = sim->misalignment = sim->accel_bias = sim->gyro_bias = 0;
}

Status ParseImuOptions(const json& config, core::ImuOptions* options) {
  return ParseImuConfig(config, options);
}

const Method& ImuMethod() {
  static const Imu& method = *new Imu;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
