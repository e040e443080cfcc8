#include "methods/thermal/thermal_method.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <memory>
#include <set>
#include <tuple>
#include <vector>

#include "formats/inertial_log.h"
#include "methods/config_keys.h"
#include "methods/noise/noise_reference.h"
#include "results/json_reader.h"

namespace calibd::server {

using nlohmann::json;

namespace {

Status ParseThermalConfig(const json& config, core::ThermalOptions* options, InertialUnits* units) {
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  static const std::set<std::string>& kKnown = *new std::set<std::string>{
      "method",    "device",      "accel_unit",       "gyro_unit",   "t_ref",
      "max_order", "min_order",   "min_range",        "lag",         "device_id",
      "window",    "grid_points", "hysteresis_alpha", "accel_noise", "gyro_noise"};
  for (const auto& [key, value] : config.items()) {
    if (kKnown.count(key) == 0) {
      return ConfigKeyError(key,
                            "is not a thermal config key (known: accel_unit, gyro_unit, t_ref, "
                            "max_order, min_order, min_range, lag, device_id, window, grid_points, "
                            "hysteresis_alpha, accel_noise, gyro_noise, method, device)");
    }
  }
  *options = core::ThermalOptions();
  double max_order = options->max_order, min_order = options->min_order;
  double grid = options->grid_points, t_ref = NAN;
  Status s = ConfigNumber(config, "max_order", 1, 8, &max_order);
  if (s.ok() && max_order != std::floor(max_order))
    s = ConfigKeyError("max_order", "must be an integer");
  if (s.ok()) s = ConfigNumber(config, "min_order", 0, 8, &min_order);
  if (s.ok() && min_order != std::floor(min_order))
    s = ConfigKeyError("min_order", "must be an integer");
  if (s.ok()) s = ConfigNumber(config, "grid_points", 2, 1000, &grid);
  if (s.ok() && grid != std::floor(grid)) s = ConfigKeyError("grid_points", "must be an integer");
  if (s.ok()) s = ConfigNumber(config, "t_ref", -100, 200, &t_ref);
  if (s.ok()) s = ConfigNumber(config, "min_range", 0, 300, &options->min_range);
  if (s.ok()) s = ConfigNumber(config, "window", 0.01, 3600, &options->window);
  if (s.ok()) s = ConfigNumber(config, "hysteresis_alpha", 1e-9, 0.5, &options->hysteresis_alpha);
  if (!s.ok()) return s;
  options->max_order = static_cast<int>(max_order);
  options->min_order = static_cast<int>(min_order);
  options->grid_points = static_cast<int>(grid);
  if (std::isfinite(t_ref)) options->t_ref = t_ref;
  if (auto it = config.find("lag"); it != config.end()) {
    if (it->is_number()) {
      options->lag = core::ThermalLagMode::kFixed;
      options->lag_seconds = it->get<double>();
      if (!(options->lag_seconds > 0 && options->lag_seconds <= 86400)) {
        return ConfigKeyError("lag", "in seconds must be in (0, 86400]");
      }
    } else if (*it == "estimate") {
      options->lag = core::ThermalLagMode::kEstimate;
    } else if (*it != "none") {
      return ConfigKeyError("lag", "must be \"none\", \"estimate\" or the known τ in seconds");
    }
  }
  if (auto it = config.find("device_id"); it != config.end()) {
    if (!it->is_number_integer() || it->get<int64_t>() < 0 || it->get<int64_t>() > 0xffffffffLL) {
      return ConfigKeyError("device_id", "must be an integer 0..4294967295 (PX4's TC_*_ID)");
    }
  }
  s = ParseInertialUnits(config, units);
  // σ per sample: a number in the reading units, or {"job": ID} of a noise job resolved at
  // enqueue (methods/noise/noise_reference.h, SI).
  for (auto [key, out, unit] : {std::tuple<const char*, std::optional<double>*, double>{
                                    "accel_noise", &options->accel_noise, units->accel},
                                {"gyro_noise", &options->gyro_noise, units->gyro}}) {
    std::optional<NoiseLevel> level;
    if (s.ok()) s = ReadNoiseLevel(config, key, &level);
    if (s.ok() && level) *out = level->value * (level->si ? 1.0 : unit);
  }
  if (!s.ok()) return s;
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput(error);
  return Status::Ok();
}

// The temperature column of IMU k: `temp<k>`, else `temp`; -1 when neither.
int TemperatureColumn(const std::vector<std::string>& names, int k) {
  const std::string own = "temp" + std::to_string(k);
  for (size_t j = 0; j < names.size(); ++j) {
    if (names[j] == own) return static_cast<int>(j);
  }
  for (size_t j = 0; j < names.size(); ++j) {
    if (names[j] == "temp") return static_cast<int>(j);
  }
  return -1;
}

// Each IMU's triads in SI and its temperature column (tempK, else temp), as Run and Check read
// them. kInvalidInput naming the column a log lacks.
struct ThermalInputs {
  std::vector<Eigen::MatrixX3d> accel, gyro;
  std::vector<Eigen::VectorXd> temp;
  std::vector<core::ThermalImuInput> inputs;

  Status From(const ArrayRecording& log, const InertialUnits& units) {
    const int imus = static_cast<int>(log.accel_names.size());
    if (static_cast<int>(log.gyro_names.size()) != imus) {
      return Status::InvalidInput(
          "thermal needs one gyroscope triad per accelerometer triad (aK_*, "
          "gK_* of IMU K); the log has " +
          std::to_string(imus) + " and " + std::to_string(log.gyro_names.size()));
    }
    accel.resize(imus);
    gyro.resize(imus);
    temp.resize(imus);
    inputs.clear();
    for (int k = 0; k < imus; ++k) {
      const int column = TemperatureColumn(log.temp_names, k);
      if (column < 0) {
        return Status::InvalidInput("thermal: no temperature column for IMU " + std::to_string(k) +
                                    " (a 'temp" + std::to_string(k) +
                                    "' column in °C, or one 'temp' for all IMUs)")
            .WithField("temp" + std::to_string(k));
      }
      accel[k] = log.accel.middleCols(3 * k, 3) * units.accel;
      gyro[k] = log.gyro.middleCols(3 * k, 3) * units.gyro;
      temp[k] = log.temperature.col(column);
      inputs.push_back({std::to_string(k), &accel[k], &gyro[k], &temp[k]});
    }
    return Status::Ok();
  }
};

class Thermal : public Method {
 public:
  const char* name() const override { return "thermal"; }
  const char* summary() const override {
    return "each IMU's accelerometer and gyroscope bias against temperature, with its band, "
           "orders from the cubic up averaged by BIC weight and a heating/cooling hysteresis test, "
           "from a warm-up log";
  }
  bool Reads(Layout layout) const override { return layout == Layout::kArray; }
  // accel_noise / gyro_noise as {"job": ID} of a noise job (methods/noise/noise_reference.h).
  Status ResolveReferences(storage::Store* store, json* config) const override {
    return ResolveNoiseReferences(store, config);
  }
  bool NeedsIncreasingTime() const override { return true; }
  Status ValidateConfig(const json& config) const override {
    core::ThermalOptions options;
    InertialUnits units;
    return ParseThermalConfig(config, &options, &units);
  }
  Status Plan(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
              json* out) const override {
    core::ThermalOptions options;
    InertialUnits units;
    if (Status s = ParseThermalConfig(config, &options, &units); !s.ok()) return s;
    return PlanThermal(options, protocol, limits, out);
  }
  const char* simulate_summary() const override {
    return "one IMU at rest warming (and cooling) with a known polynomial bias per channel";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override;
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat(),
            ExportFormat{"ardupilot", "ArduPilot INS_TCAL parameters", "text/plain",
                         "thermal-ardupilot.parm"},
            ExportFormat{"px4", "PX4 TC_ parameters (QGroundControl)", "text/plain",
                         "thermal-px4.params"}};
  }
  Status Export(const std::string& format, const json& result, const ExportContext& context,
                std::string* out) const override {
    if (format == "csv") return ThermalResultToCsv(result, out);
    if (format == "h") return ThermalResultToHeader(result, context, out);
    if (format == "ardupilot") return ThermalResultToArduPilot(result, context, out);
    if (format == "px4") return ThermalResultToPx4(result, context, out);
    return NoSuchExport(format, name());
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>{
        {"max_accel_band_std",
         "largest 1 sigma of an accelerometer bias curve over [t_min, t_max], m/s^2", 0.01},
        {"max_gyro_band_std",
         "largest 1 sigma of a gyroscope bias curve over [t_min, t_max], rad/s", 0.001},
        {"max_hysteresis_z",
         "largest |z| of the heating - cooling difference (null: the Bonferroni bound at the "
         "config's hysteresis_alpha, diagnostics.imus[].hysteresis_critical_z)",
         std::nullopt},
        limit_keys::kMaxChi2,
    };
    return keys;
  }
  void Judge(const json& result, const json& config, const AcceptanceLimits& limits,
             Verdict* verdict) const override;
  Status Run(RecordingParser* parser, const json& config, const RunContext& context,
             json* result) const override;
  Status Check(const ArrayRecording& log, const json& config, const RunContext& context,
               json* check) const override;
};

void Thermal::Judge(const json& result, const json&, const AcceptanceLimits& limits,
                    Verdict* verdict) const {
  try {
    Offenders band, chi2, hysteresis;
    const auto max_chi2 = limits.Get("max_chi2");
    const auto max_z = limits.Get("max_hysteresis_z");
    const json& unc = result.at("uncertainty").at("imus");
    const json& diag = result.at("diagnostics").at("imus");
    for (size_t i = 0; i < unc.size(); ++i) {
      const std::string imu = unc[i].at("name").get<std::string>();
      for (const char* sensor : {"accelerometer", "gyroscope"}) {
        const auto limit =
            limits.Get(sensor[0] == 'a' ? "max_accel_band_std" : "max_gyro_band_std");
        const json& std = unc[i].at(sensor).at("bias").at("std");
        for (size_t a = 0; a < std.size(); ++a) {
          double worst = 0;
          for (const json& v : std[a]) worst = std::max(worst, v.get<double>());
          if (limit && worst > *limit) {
            band.Add("IMU " + imu + " " + sensor + " " + std::string(1, char('x' + a)) + " " +
                     Fmt(worst));
          }
        }
      }
      const json& d = diag[i];
      const double critical = d.at("hysteresis_critical_z").get<double>();
      for (const json& ch : d.at("channels")) {
        const std::string label = "IMU " + imu + " " + ch.at("name").get<std::string>();
        const json& c2 = ch.at("chi2_per_dof");
        if (max_chi2 && c2.is_number() && c2.get<double>() > *max_chi2) {
          chi2.Add(label + " " + Fmt(c2.get<double>()));
        }
        const json& h = ch.at("hysteresis");
        if (h.at("tested").get<bool>()) {
          const double z = h.at("max_abs_z").get<double>();
          if (z > max_z.value_or(critical)) hysteresis.Add(label + " |z| " + Fmt(z));
        }
      }
    }
    band.RejectInto(verdict,
                    "bias curve too uncertain over the temperature range: record longer statics, "
                    "a slower ramp or a wider range");
    chi2.RejectInto(verdict,
                    "the window means scatter beyond their noise (chi2/dof above max_chi2): the "
                    "device moved, the temperature lags the sensor, or the order is too low");
    hysteresis.RejectInto(verdict,
                          "heating and cooling disagree (hysteresis, or a temperature reading "
                          "that lags the sensor: try lag \"estimate\"): the bias is not a "
                          "function of the temperature read");
  } catch (const std::exception& e) {
    verdict->Reject(std::string("the result cannot be judged: ") + e.what());
  }
}

Status Thermal::Run(RecordingParser* parser, const json& config, const RunContext& context,
                    json* result) const {
  core::ThermalOptions options;
  InertialUnits units;
  Status s = ParseThermalConfig(config, &options, &units);
  if (!s.ok()) return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
  options.statics.stop = context.stop;
  ArrayRecording log;
  s = parser->TakeArray(&log);
  if (!s.ok()) return s;
  s = CheckLogTimes(log, "thermal", &parser->summary());
  if (!s.ok()) return s;
  ThermalInputs in;
  s = in.From(log, units);
  if (!s.ok()) return s;
  core::ThermalResult r;
  s = core::CalibrateThermal(log.t, in.inputs, options, &r);
  if (!s.ok()) return s;
  *result = ThermalResultToJson(r, options);
  (*result)["diagnostics"]["noise_jobs"] = NoiseJobsJson(config);
  return Status::Ok();
}

// Stages 1 and 5 of Run (core::FindThermalWindows), no fit: the statics (IMU 0's, with the
// temperatures of their windows), per IMU the range, windows, phases, orientations and lag the
// fit would see, the message the job would stop with (range below min_range, too few windows,
// lag not determinable), and per IMU the σ the job would report (PredictThermalWindows).
Status Thermal::Check(const ArrayRecording& log, const json& config, const RunContext& context,
                      json* check) const {
  core::ThermalOptions options;
  InertialUnits units;
  Status s = ParseThermalConfig(config, &options, &units);
  if (!s.ok()) return s;
  options.statics.stop = context.stop;
  s = CheckLogTimes(log, "thermal");
  if (!s.ok()) return s;
  ThermalInputs in;
  s = in.From(log, units);
  if (!s.ok()) return s;
  json imus = json::array(), predicted = json::array();
  for (size_t k = 0; k < in.inputs.size(); ++k) {
    core::ThermalImuResult r;
    s = core::FindThermalWindows(log.t, in.inputs[k], options, &r);
    if (s.code() == StatusCode::kStopped || s.code() == StatusCode::kInvalidInput) return s;
    if (!s.ok() && !check->contains("job_would_fail")) (*check)["job_would_fail"] = s.message();
    if (k == 0) {
      json statics = json::array();
      for (const core::StaticInterval& iv : r.statics.intervals) {
        const Eigen::Vector3d v = iv.mean[0] * units.accel;
        const Eigen::Vector3d up = v.norm() > 0 ? Eigen::Vector3d(v.normalized()) : v;
        double t_lo = NAN, t_hi = NAN;
        for (const core::ThermalWindow& w : r.windows) {
          if (w.start >= iv.start && w.end <= iv.end) {
            t_lo = std::isnan(t_lo) ? w.temperature : std::min(t_lo, w.temperature);
            t_hi = std::isnan(t_hi) ? w.temperature : std::max(t_hi, w.temperature);
          }
        }
        statics.push_back({{"start", iv.start},
                           {"end", iv.end},
                           {"samples", iv.samples},
                           {"up", {up.x(), up.y(), up.z()}},
                           {"accel_norm", v.norm()},
                           {"temperature", {results::Num(t_lo), results::Num(t_hi)}}});
      }
      (*check)["statics"] = std::move(statics);
    }
    const bool found = !r.windows.empty();
    imus.push_back({{"name", r.name},
                    {"windows", r.windows.size()},
                    {"t_min", found ? results::Num(r.t_min) : json()},
                    {"t_max", found ? results::Num(r.t_max) : json()},
                    {"range", found ? results::Num(r.t_max - r.t_min) : json()},
                    {"min_range", options.min_range},
                    {"heating_windows", r.heating_windows},
                    {"cooling_windows", r.cooling_windows},
                    {"orientations", r.orientations},
                    {"lag", r.lag ? json(*r.lag) : json()}});
    predicted.push_back(PredictThermalWindows(options, r));
  }
  (*check)["thermal"] = {{"window", options.window}, {"imus", std::move(imus)}};
  // The result's uncertainty shape over the IMUs that give a curve; each IMU's orders or why not.
  json unc = json::array(), per_imu = json::array();
  std::string reason;
  for (size_t k = 0; k < predicted.size(); ++k) {
    json& p = predicted[k];
    if (p["uncertainty"].is_object()) {
      unc.push_back(std::move(p["uncertainty"]));
      per_imu.push_back({{"name", imus[k]["name"]}, {"orders", p["orders"]}});
    } else {
      reason = p["reason"].get<std::string>();
      per_imu.push_back({{"name", imus[k]["name"]}, {"reason", p["reason"]}});
    }
  }
  const bool none = unc.empty();
  (*check)["predicted"] = {
      {"basis", "crb"},
      {"how",
       "the thermal method's white-noise σ of the bias curves on the windows found (each mean's "
       "σ the job's: the config's noise/√n, else the window's own samples), at the floor order "
       "the job offers first; the job's BIC average over higher orders widens it towards "
       "orders.band_std_at_max_order, a χ²/dof above 1 scales it, and the scale stage's "
       "parameters (opposite faces) are not counted"},
      {"uncertainty",
       none ? json() : json{{"basis", "crb"}, {"chi2_per_dof", nullptr}, {"imus", std::move(unc)}}},
      {"imus", std::move(per_imu)}};
  if (none) (*check)["predicted"]["reason"] = reason;
  return Status::Ok();
}

std::function<Status(SimulatedFiles*)> Thermal::AddSimulateOptions(CLI::App* command) const {
  auto o = std::make_shared<core::ThermalSimulationOptions>();
  auto order = std::make_shared<int>(3);
  auto hysteresis = std::make_shared<double>(0);
  auto scale_order = std::make_shared<int>(0);
  command->add_option("--seed", o->seed, "random seed")->capture_default_str();
  command->add_option("--rate", o->rate, "samples per second")
      ->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  command->add_option("--warmup", o->warmup, "warm-up duration, s")
      ->check(CLI::Range(10.0, 1e6))
      ->capture_default_str();
  command->add_option("--cooldown", o->cooldown, "cool-down duration after it, s (0: none)")
      ->check(CLI::Range(0.0, 1e6))
      ->capture_default_str();
  command->add_option("--delta", o->delta, "asymptotic temperature rise, degC")
      ->capture_default_str();
  command->add_option("--order", *order, "order of the true polynomials")
      ->check(CLI::Range(1, 5))
      ->capture_default_str();
  command->add_option("--accel-noise", o->accel_noise, "m/s^2 per sample")->capture_default_str();
  command->add_option("--gyro-noise", o->gyro_noise, "rad/s per sample")->capture_default_str();
  command->add_option("--hysteresis", *hysteresis, "gyroscope y offset while cooling, rad/s")
      ->capture_default_str();
  command->add_option("--lag", o->lag, "the sensor's lag behind the temperature reading, s")
      ->check(CLI::Range(0.0, 1e5))
      ->capture_default_str();
  command->add_option("--orientations", o->orientations, "orientations held in turn (1..6)")
      ->check(CLI::Range(1, 6))
      ->capture_default_str();
  command
      ->add_option("--cycles", o->cycles,
                   "times the orientations' sequence is held over the log (a repeated tumble)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  command
      ->add_option("--scale-order", *scale_order,
                   "order of the accelerometers' true scale drift (0: none; seen with "
                   "--orientations >= 2)")
      ->check(CLI::Range(0, 5))
      ->capture_default_str();
  return [o, order, hysteresis, scale_order](SimulatedFiles* files) {
    core::ThermalSimulationOptions options = *o;
    options.coefficients = core::DefaultThermalTruth(*order);
    if (*scale_order > 0) options.scale_coefficients = core::DefaultThermalScaleTruth(*scale_order);
    options.hysteresis(4) = *hysteresis;
    return SimulateThermalFiles(options, &files->csv, &files->config, &files->truth);
  };
}

}  // namespace

Status SimulateThermalFiles(const core::ThermalSimulationOptions& options, std::string* csv,
                            json* config, json* truth) {
  const core::ThermalSimulation sim = core::SimulateThermal(options);
  csv->clear();
  *csv += "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z,temp0\n";
  char line[320];
  for (Eigen::Index i = 0; i < sim.t.size(); ++i) {
    const int n =
        std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.6f\n",
                      sim.t(i), sim.accel(i, 0), sim.accel(i, 1), sim.accel(i, 2), sim.gyro(i, 0),
                      sim.gyro(i, 1), sim.gyro(i, 2), sim.temp(i));
    csv->append(line, static_cast<size_t>(n));
  }
  json sensors[2];
  for (int s = 0; s < 2; ++s) {
    json coefficients = json::array(), b0 = json::array();
    for (int a = 0; a < 3; ++a) {
      const Eigen::VectorXd& c = sim.truth.coefficients[static_cast<size_t>(3 * s + a)];
      coefficients.push_back(std::vector<double>(c.data(), c.data() + c.size()));
      b0.push_back(sim.truth.b0(3 * s + a));
    }
    sensors[s] = {{"coefficients", coefficients}, {"b0", b0}};
  }
  json scale = json::array();  // per accelerometer axis d_1..d_p (empty arrays: no drift)
  for (int a = 0; a < 3; ++a) {
    scale.push_back(
        sim.truth.scale_coefficients.empty()
            ? std::vector<double>()
            : std::vector<double>(sim.truth.scale_coefficients[static_cast<size_t>(a)].data(),
                                  sim.truth.scale_coefficients[static_cast<size_t>(a)].data() +
                                      sim.truth.scale_coefficients[static_cast<size_t>(a)].size()));
  }
  sensors[0]["scale_coefficients"] = scale;
  // t is in seconds by construction: said, since a slow log (10 Hz and below, as warm-ups are
  // often logged) would otherwise be refused as ambiguous (formats/inertial_log.h CheckTimeUnit).
  *config = {{"method", "thermal"}, {"time_unit", "s"}};
  *truth = {{"method", "thermal"},
            {"t_ref", sim.truth.t_ref},
            {"seed", sim.truth.seed},
            {"lag", sim.truth.lag},
            {"accelerometer", sensors[0]},
            {"gyroscope", sensors[1]},
            {"hysteresis",
             std::vector<double>(sim.truth.hysteresis.data(), sim.truth.hysteresis.data() + 6)}};
  return Status::Ok();
}

const Method& ThermalMethod() {
  static const Thermal& method = *new Thermal;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
