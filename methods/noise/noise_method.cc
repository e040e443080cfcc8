#include "methods/noise/noise_method.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <set>
#include <vector>

#include "formats/inertial_log.h"
#include "methods/noise/noise_result.h"
#include "methods/saturation_report.h"

namespace calibd::server {

using nlohmann::json;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Status ParseNoiseConfig(const json& config, core::NoiseOptions* options, InertialUnits* units) {
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  static const std::set<std::string>& kKnown =
      *new std::set<std::string>{"method", "device", "accel_unit", "gyro_unit", "taus_per_decade"};
  for (const auto& [key, value] : config.items()) {
    if (kKnown.count(key) == 0) {
      return Status::InvalidInput("config key '" + key +
                                  "' is not a noise config key (known: accel_unit, gyro_unit, "
                                  "taus_per_decade, method, device)")
          .WithField(key);
    }
  }
  *options = core::NoiseOptions();
  if (auto it = config.find("taus_per_decade"); it != config.end()) {
    const bool integral = it->is_number() && std::isfinite(it->get<double>()) &&
                          it->get<double>() == std::floor(it->get<double>());
    if (!integral || it->get<double>() < 0 || it->get<double>() > 100) {
      return Status::InvalidInput(
                 "config key 'taus_per_decade' must be an integer 0..100 (0: octave spacing)")
          .WithField("taus_per_decade");
    }
    options->taus_per_decade = static_cast<int>(it->get<double>());
  }
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return ParseInertialUnits(config, units);
}

// Saturation as Run finds it (core/saturation.h): the default search on every channel of the
// float log (SI). The channels with pinned samples are appended to *report and, when there are
// any, report->samples counts the rows holding one.
Status FindNoiseSaturation(const ArrayRecordingFloat& log, const core::StopToken* stop,
                           results::SaturationDiagnostics* report) {
  core::SaturationOptions so;
  so.stop = stop;
  std::vector<core::ChannelSaturation> channels;
  Status s = FindSaturation(log.accel, log.accel_names, so, &channels);
  if (s.ok()) s = FindSaturation(log.gyro, log.gyro_names, so, &channels);
  if (!s.ok() || !AnyPinned(channels)) return s;
  const std::vector<core::ChannelSaturation> accel_part(channels.begin(),
                                                        channels.begin() + log.accel.cols());
  const std::vector<core::ChannelSaturation> gyro_part(channels.begin() + log.accel.cols(),
                                                       channels.end());
  AddSaturationChannels(accel_part, 1, "m/s^2", report);
  AddSaturationChannels(gyro_part, 1, "rad/s", report);
  for (Eigen::Index i = 0; i < log.t.size(); ++i) {  // rows with any channel pinned
    bool pinned = false;
    for (size_t c = 0; c < channels.size() && !pinned; ++c) {
      const auto col = static_cast<Eigen::Index>(c);
      const double v =
          col < log.accel.cols() ? log.accel(i, col) : log.gyro(i, col - log.accel.cols());
      pinned = v <= channels[c].low || v >= channels[c].high;
    }
    if (pinned) ++report->samples;
  }
  return Status::Ok();
}

// Why Run refuses a log with pinned samples (kNotStationary).
std::string ClippedLogMessage(const results::SaturationDiagnostics& report) {
  return PinnedList(report) +
         ": a noise log recorded at rest never reaches its sensor's full scale, so the sensor "
         "was knocked or moved (or its range is too small); the Allan deviation of a clipped log "
         "is not the sensor's noise, and dropping the samples would break the uniform sampling "
         "it needs: record again at rest, or cut the log before or after the knock";
}

class Noise : public Method {
 public:
  const char* name() const override { return "noise"; }
  bool NeedsIncreasingTime() const override { return true; }
  const char* simulate_summary() const override {
    return "one IMU at rest: a stationary log with known white noise and random walk";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override {
    auto options = std::make_shared<NoiseSimulationFileOptions>();
    command->add_option("--seed", options->seed, "random seed")->capture_default_str();
    command->add_option("--rate", options->rate, "samples per second")
        ->check(CLI::Range(1.0, 100000.0))
        ->capture_default_str();
    command->add_option("--seconds", options->seconds, "log length, s")
        ->check(CLI::Range(1.0, 1e6))
        ->capture_default_str();
    command->add_option("--accel-noise", options->accel_noise, "accelerometer N, m/s²/√Hz")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--accel-random-walk", options->accel_random_walk, "accelerometer K, m/s³/√Hz")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-noise", options->gyro_noise, "gyroscope N, rad/s/√Hz")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--gyro-random-walk", options->gyro_random_walk, "gyroscope K, rad/s²/√Hz")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--bias-instability", options->bias_instability,
                     "B of every channel, as a multiple of its N (0: none)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    return [options](SimulatedFiles* files) {
      return SimulateNoiseFiles(*options, &files->csv, &files->config, &files->truth);
    };
  }
  std::vector<std::string> FleetParameters() const override {
    return {"channels/*/white_noise", "channels/*/bias_instability", "channels/*/random_walk"};
  }
  std::vector<FailureReason> FailureReasons() const override {
    return {
        CatalogEntry(
            core::noise_reason::kIrregularSampling, "Irregular sample times",
            "Split the log at its gaps or resample it to a uniform rate before uploading."),
        CatalogEntry(core::noise_reason::kNotStationary, "The sensor moved",
                     "Record the sensor at rest and untouched (on a stable surface, away from "
                     "vibration) for "
                     "the whole log."),
    };
  }
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat(),
            ExportFormat{"yaml", "Kalibr imu.yaml", "application/yaml", "imu.yaml"}};
  }
  Status Export(const std::string& format, const nlohmann::json& result,
                const ExportContext& context, std::string* out) const override {
    if (format == "csv") return NoiseResultToCsv(result, out);
    if (format == "h") return NoiseResultToHeader(result, context, out);
    if (format == "yaml") return NoiseResultToKalibrYaml(result, context, out);
    return NoSuchExport(format, name());
  }
  const char* summary() const override {
    return "white noise density, bias instability and random walk of every channel of a long "
           "stationary log (Allan deviation, IEEE Std 952)";
  }
  bool Reads(Layout layout) const override { return layout == Layout::kArray; }
  Status ValidateConfig(const json& config) const override {
    core::NoiseOptions options;
    InertialUnits units;
    return ParseNoiseConfig(config, &options, &units);
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>{
        {"max_white_noise_std",
         "largest 1 sigma of a white-noise density, relative to it (log too short)", 0.2},
        {"max_accel_white_noise",
         "largest accelerometer white-noise density, m/s^2/sqrt(Hz) (far above any MEMS part: "
         "units or a moving device)",
         0.1},
        {"max_gyro_white_noise",
         "largest gyroscope white-noise density, rad/s/sqrt(Hz) (far above any MEMS part: units "
         "or a moving device)",
         0.01},
    };
    return keys;
  }
  void Judge(const json& result, const json&, const AcceptanceLimits& limits,
             Verdict* verdict) const override {
    results::NoiseResult r;
    if (Status s = results::FromJson(result, &r); !s.ok()) {
      verdict->Reject("the result cannot be judged: " + s.message());
      return;
    }
    if (!r.diagnostics.stationary) {
      verdict->Reject(
          "the log is not stationary (the device moved or was touched): noise figures of a moving "
          "device are not the sensor's; record again with the device at rest");
    }
    const auto rel_max = limits.Get("max_white_noise_std");
    Offenders missing, uncertain, too_high;
    for (size_t i = 0; i < r.channels.size(); ++i) {
      const results::NoiseChannelParameters& c = r.channels[i];
      const double n = c.white_noise;
      if (!std::isfinite(n)) {
        missing.Add(c.name);
        continue;
      }
      const double n_std = r.channel_stds[i].white_noise_std;
      if (rel_max && (!std::isfinite(n_std) || n_std / n > *rel_max)) {
        uncertain.Add(c.name + " " +
                      (std::isfinite(n_std) ? Fmt(n_std / n * 100) + " %" : "undefined"));
      }
      const auto max =
          limits.Get(c.unit == "m/s^2" ? "max_accel_white_noise" : "max_gyro_white_noise");
      if (max && n > *max) too_high.Add(c.name + " " + Fmt(n) + " " + c.unit + "/sqrt(Hz)");
    }
    missing.RejectInto(verdict,
                       "no white-noise density could be read (log too short or too few "
                       "samples)");
    if (rel_max) {
      uncertain.RejectInto(verdict, "white-noise density too uncertain (1 sigma above " +
                                        Fmt(*rel_max * 100) + " %): record a longer log");
    }
    too_high.RejectInto(verdict,
                        "white-noise density far above any MEMS sensor: check accel_unit "
                        "and gyro_unit, and that the device was at rest");
  }
  // Run's saturation search (FindNoiseSaturation) on the same floats; a noise log has no statics.
  Status Check(const ArrayRecording& log, const json& config, const RunContext& context,
               json* check) const override {
    core::NoiseOptions options;
    InertialUnits units;
    Status s = ParseNoiseConfig(config, &options, &units);
    if (!s.ok()) return s;
    ArrayRecordingFloat floats;
    floats.accel_names = log.accel_names;
    floats.gyro_names = log.gyro_names;
    floats.t = log.t;
    floats.accel = (log.accel * units.accel).cast<float>();
    floats.gyro = (log.gyro * units.gyro).cast<float>();
    results::SaturationDiagnostics report{"refused", 0, {}};
    s = FindNoiseSaturation(floats, context.stop, &report);
    if (!s.ok()) return s;
    (*check)["saturation"] = results::ToJson(report);
    if (!report.channels.empty()) {
      (*check)["job_would_fail"] = ClippedLogMessage(report);
    }
    return Status::Ok();
  }
  void PrepareParser(const json& config, RecordingParser* parser) const override {
    core::NoiseOptions options;
    InertialUnits units;
    if (ParseNoiseConfig(config, &options, &units).ok()) {
      parser->CollectArrayAsFloat(units.accel, units.gyro);
    }
  }
  // Measured (bench/README.md, "Memory budget per job"): the samples as float (4 B a value), t
  // as double and one channel's cumulative sum (double) at a time.
  double PeakBytesPerValue(const json& config) const override {
    (void)config;
    return 7;
  }
  Status Run(RecordingParser* parser, const json& config, const RunContext& context,
             json* result) const override {
    core::NoiseOptions options;
    InertialUnits units;
    Status s = ParseNoiseConfig(config, &options, &units);
    if (!s.ok())
      return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
    options.executor = context.executor;
    options.stop = context.stop;  // a stopped run returns core::StoppedStatus ("noise: ...")
    // The samples as floats in SI, one column per channel (the analysis reads them in place).
    // A prepared parser (PrepareParser) collected them so: held once, 4 bytes a value. Otherwise
    // the parser's doubles are converted (the same rounding: reading × unit in double, then to
    // float) and released kind by kind.
    ArrayRecordingFloat log;
    double accel_scale = 0, gyro_scale = 0;
    if (parser->collects_float(&accel_scale, &gyro_scale) && accel_scale == units.accel &&
        gyro_scale == units.gyro) {
      s = parser->TakeArrayFloat(&log);
      if (!s.ok()) return s;
    } else {
      ArrayRecording doubles;
      s = parser->TakeArray(&doubles);
      if (!s.ok()) return s;
      log.accel_names = std::move(doubles.accel_names);
      log.gyro_names = std::move(doubles.gyro_names);
      log.t = std::move(doubles.t);
      log.accel = (doubles.accel * units.accel).cast<float>();
      doubles.accel.resize(0, 0);
      log.gyro = (doubles.gyro * units.gyro).cast<float>();
    }
    s = CheckLogTimes(log.t, "noise", &parser->summary());
    if (!s.ok()) return s;
    // Saturation (core/saturation.h): a noise log is recorded at rest, far from full scale, so a
    // pinned sample means the sensor was knocked (or its range is wrong). Refused, not dropped:
    // the Allan deviation needs the uniformly sampled series (a hole would bias every cluster
    // that spans it) and a clipped stretch is not the sensor's noise either.
    {
      results::SaturationDiagnostics report{"refused", 0, {}};
      s = FindNoiseSaturation(log, context.stop, &report);
      if (!s.ok()) return s;
      if (!report.channels.empty()) {
        results::NoiseResult typed;
        typed.envelope.method = "noise";
        typed.envelope.usable = false;
        typed.diagnostics.samples = log.t.size();
        typed.diagnostics.saturation = report;
        typed.diagnostics.units = results::NoiseUnits{units.accel_text, units.gyro_text};
        *result = results::ToJson(typed);
        return Status::NotDeterminable(core::noise_reason::kNotStationary,
                                       ClippedLogMessage(report));
      }
    }
    const Eigen::Index n = log.t.size();
    const Eigen::Index na = log.accel.cols(), ng = log.gyro.cols();
    core::NoiseProblem problem;
    problem.samples = n;
    problem.times = log.t.data();
    static const char kAxes[] = {'x', 'y', 'z'};
    for (Eigen::Index c = 0; c < na + ng; ++c) {
      const bool accel = c < na;
      const Eigen::Index triad = (accel ? c : c - na) / 3;
      const std::string base = accel ? log.accel_names[triad] : log.gyro_names[triad];
      problem.channels.push_back({base + "_" + kAxes[c % 3], accel ? "m/s^2" : "rad/s",
                                  accel ? log.accel.col(c).data() : log.gyro.col(c - na).data()});
    }
    core::NoiseResult r;
    s = core::EstimateNoise(problem, options, &r);
    results::NoiseResult typed = NoiseResultOf(r, options.taus_per_decade);
    typed.diagnostics.units = results::NoiseUnits{units.accel_text, units.gyro_text};
    if (!s.ok()) {
      // The partial diagnostics kept with the failed job: rate, duration, jitter, per channel
      // its status and reason (which one moved) and the Allan curve as far as it was computed
      // (results::NoiseResult with usable false: no model, parameters or uncertainty).
      typed.envelope.usable = false;
      typed.envelope.model.clear();
      typed.channels.clear();
      typed.channel_stds.clear();
    }
    *result = results::ToJson(typed);
    return s;
  }
};

}  // namespace

results::NoiseResult NoiseResultOf(const core::NoiseResult& r, int taus_per_decade) {
  results::NoiseResult out;
  out.envelope.method = "noise";
  out.envelope.model =
      "per channel, the Allan variance sigma^2(tau) = N^2/tau + (0.664 B)^2 + K^2 tau/3 "
      "(IEEE Std 952): N white noise density (unit/sqrt(Hz)), B bias instability (unit), K "
      "random walk (unit/s/sqrt(Hz)); Kalibr's noise_density = N, random_walk = K";
  out.envelope.warnings = r.warnings;
  const auto value = [](const std::optional<double>& x) { return x.value_or(kNaN); };
  results::NoiseDiagnostics& d = out.diagnostics;
  for (const core::NoiseChannelResult& c : r.channels) {
    out.channels.push_back({c.name, c.unit, value(c.white_noise.value),
                            value(c.bias_instability.value), value(c.bias_instability_tau),
                            value(c.random_walk.value)});
    results::NoiseChannelUncertainty u;
    u.name = c.name;
    u.white_noise_std = value(c.white_noise.std);
    u.bias_instability_std = value(c.bias_instability.std);
    u.random_walk_std = value(c.random_walk.std);
    if (c.status != core::NoiseChannelStatus::kNotRun) {  // a constant channel: NaN σ, "crb"
      u.basis = c.uncertainty_basis;
      u.chi2_per_dof = c.chi2_per_dof;
      u.crb =
          results::NoiseTermStds{value(c.white_noise.crb_std), value(c.bias_instability.crb_std),
                                 value(c.random_walk.crb_std)};
      if (out.basis != "chi2_scaled") out.basis = c.uncertainty_basis;
      if (!(out.chi2_per_dof >= c.chi2_per_dof)) out.chi2_per_dof = c.chi2_per_dof;
    }
    out.channel_stds.push_back(std::move(u));
    d.allan.push_back({c.name, c.allan.tau, c.allan.adev, c.allan.adev_lower, c.allan.adev_upper,
                       c.fitted_adev, c.unit});
    d.channels.push_back({c.name, core::NoiseChannelStatusName(c.status), c.reason, c.fit_points,
                          c.fit_chi2, c.mean, c.unit});
  }
  d.rate = r.rate;
  d.samples = r.samples;
  d.duration = r.duration;
  d.jitter = r.jitter;
  d.stationary = r.stationary;
  d.taus_per_decade = taus_per_decade;
  d.confidence = r.channels.empty() ? kNaN : r.channels[0].allan.confidence;
  return out;
}

json NoiseResultToJson(const core::NoiseResult& r, int taus_per_decade) {
  return results::ToJson(NoiseResultOf(r, taus_per_decade));
}

Status SimulateNoiseFiles(const NoiseSimulationFileOptions& o, std::string* csv, json* config,
                          json* truth) {
  core::NoiseSimulationOptions sim;
  sim.rate = o.rate;
  sim.duration = o.seconds;
  sim.seed = o.seed;
  static const char kAxes[] = {'x', 'y', 'z'};
  json channels = json::array();
  for (int c = 0; c < 6; ++c) {
    core::NoiseSimulationChannel ch;
    const bool accel = c < 3;
    ch.name = std::string(accel ? "a0_" : "g0_") + kAxes[c % 3];
    ch.unit = accel ? "m/s^2" : "rad/s";
    ch.white_noise = accel ? o.accel_noise : o.gyro_noise;
    ch.random_walk = accel ? o.accel_random_walk : o.gyro_random_walk;
    ch.bias_instability = o.bias_instability * ch.white_noise;
    ch.offset = c == 2 ? 9.80665 : 0;  // lying flat: gravity on z
    sim.channels.push_back(ch);
    channels.push_back({{"name", ch.name},
                        {"unit", ch.unit},
                        {"white_noise", ch.white_noise},
                        {"random_walk", ch.random_walk},
                        {"bias_instability", ch.bias_instability}});
  }
  std::string error;
  if (!sim.IsValid(&error)) return Status::InvalidInput(error);
  const core::NoiseSimulation log = core::SimulateNoise(sim);
  csv->clear();
  csv->reserve(static_cast<size_t>(log.samples.rows()) * 90);
  *csv += "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  char line[256];
  for (Eigen::Index i = 0; i < log.samples.rows(); ++i) {
    const auto& x = log.samples;
    const int n = std::snprintf(line, sizeof line, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n",
                                log.times[i], x(i, 0), x(i, 1), x(i, 2), x(i, 3), x(i, 4), x(i, 5));
    csv->append(line, static_cast<size_t>(n));
  }
  *config = {{"method", "noise"}};
  *truth = {{"method", "noise"},
            {"rate", o.rate},
            {"seconds", o.seconds},
            {"seed", o.seed},
            {"channels", channels}};
  return Status::Ok();
}

const Method& NoiseMethod() {
  static const Noise& method = *new Noise;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
