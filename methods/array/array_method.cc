// The `array` method (methods/array/array_method.h): the Method for the registry (config keys,
// acceptance gate, exports, `calibd simulate array` options), RunArray's dispatch on "model" and
// what both models share (methods/array/array_internal.h). The models themselves:
// array_positions.cc ("positions", the default) and array_full_method.cc ("full", SPEC §7).
#include "methods/array/array_method.h"

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <memory>
#include <tuple>

#include "core/array_simulation.h"
#include "formats/inertial_log.h"
#include "methods/array/array_internal.h"
#include "methods/array/array_result.h"
#include "methods/saturation_report.h"

namespace calibd::server {

using array_detail::IsFullModel;
using nlohmann::json;

namespace array_detail {

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

Status ParseGeometry(const json& config, core::ArrayProblem* problem) {
  auto geometry = config.find("geometry");
  if (geometry == config.end())
    return KeyError("geometry", "missing: {\"positions\": [[x,y,z], ...], \"reference\": 0}");
  const json& g = *geometry;
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

Status ReadTolerance(const json& config, double* tolerance) {
  auto it = config.find("tolerance");
  if (it == config.end()) return Status::Ok();
  if (Status s = ReadNumber(*it, "tolerance", tolerance); !s.ok()) return s;
  if (!(*tolerance >= 0 && *tolerance < 1))
    return KeyError("tolerance", "must be >= 0 and < 1 (0: never stop early)");
  return Status::Ok();
}

std::string FormatG17(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

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

bool IsFullModel(const json& config) {
  if (!config.is_object()) return false;
  auto m = config.find("model");
  return m != config.end() && m->is_string() && m->get<std::string>() == "full";
}

// The levels found are used less this fraction of them (see ArraySaturation).
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

}  // namespace array_detail

Status RunArray(ArrayRecording recording, const json& config, json* result,
                const core::StopToken* stop, core::TaskExecutor executor) {
  if (IsFullModel(config))
    return array_detail::RunArrayFull(std::move(recording), config, result, stop,
                                      std::move(executor));
  return array_detail::RunArrayPositions(std::move(recording), config, result, stop,
                                         std::move(executor));
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
                        (accel ? "accel_noise " : "gyro_noise ") + Fmt(n) + " " +
                        (accel ? std::string("m/s^2") : r.diagnostics.gyro_unit) +
                        ", ratio squared " + Fmt(chi2) + " above " + Fmt(*chi2_max) +
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
  std::vector<std::string> FleetParameters() const override {
    return {"imus/*/position/*",
            "imus/*/accelerometer/bias/*",
            "imus/*/accelerometer/scale/*",
            "imus/*/accelerometer/misalignment/*/*",
            "imus/*/gyroscope/bias/*",
            "imus/*/gyroscope/scale/*",
            "imus/*/gyroscope/misalignment/*/*",
            "positions/*/position/*"};
  }
  std::vector<FailureReason> FailureReasons() const override {
    return {
        CatalogEntry(core::array_reason::kNoDynamicPhase, "No dynamic phase",
                     "After the statics, rotate the board for a while (about every axis) before "
                     "stopping the "
                     "log."),
        CatalogEntry(core::array_reason::kNoGyroscope, "No gyroscope",
                     "Record with at least one gyroscope triad (columns g0_x, g0_y, g0_z)."),
        CatalogEntry(core::array_reason::kTooFewTriads, "Too few accelerometer triads",
                     "Mount at least 3 accelerometer triads that are not on one line."),
        CatalogEntry(core::array_reason::kTriadsCollinear, "Triads on one line",
                     "Mount at least 3 triads that span a plane and give their nominal positions."),
        CatalogEntry(core::array_reason::kTooFewSamples, "Too few usable samples",
                     "Record longer while rotating, below the gyroscopes' range."),
        CatalogEntry(
            core::array_reason::kWeakExcitation, "Weak excitation",
            "Rotate the array about every axis, briskly and in changing directions, not about one "
            "fixed axis only."),
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
  // The saturation search Run runs (ArraySaturation, with the config's limits and gyro unit),
  // for either model: the channels pinned and the samples the fit would drop. No statics yet.
  Status Check(const ArrayRecording& log, const nlohmann::json& config, const RunContext& ctx,
               nlohmann::json* check) const override {
    std::optional<double> accel_limit, gyro_limit;
    bool degrees = false;
    Status s;
    if (IsFullModel(config)) {
      core::ArrayFullProblem geometry;
      core::ArrayFullOptions options;
      s = ParseArrayFullConfig(config, &geometry, &options, &degrees);
      accel_limit = options.accel_saturation;
      gyro_limit = options.gyro_saturation;
    } else {
      core::ArrayProblem geometry;
      core::ArrayOptions options;
      s = ParseArrayConfig(config, &geometry, &options, &degrees);
      accel_limit = options.accel_saturation;
      gyro_limit = options.gyro_saturation;
    }
    if (!s.ok()) return s;
    const Eigen::MatrixXd gyro = degrees ? Eigen::MatrixXd(log.gyro * core::kDegree) : log.gyro;
    std::optional<results::SaturationDiagnostics> saturation;
    std::vector<std::string> warnings;
    s = array_detail::ArraySaturation(log.accel, log.accel_names, gyro, log.gyro_names, degrees,
                                      ctx.stop, &accel_limit, &gyro_limit, &saturation, &warnings);
    if (!s.ok()) return s;
    (*check)["saturation"] =
        results::ToJson(saturation.value_or(results::SaturationDiagnostics{"dropped", 0, {}}));
    for (const std::string& w : warnings) (*check)["warnings"].push_back(w);
    return Status::Ok();
  }
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
  // The positions model's plan (PlanArray) or the full model's (PlanArrayFull).
  Status Plan(const nlohmann::json& config, const PlanProtocol& protocol,
              const AcceptanceLimits& limits, nlohmann::json* out) const override {
    if (IsFullModel(config)) return PlanArrayFull(config, protocol, limits, out);
    core::ArrayProblem geometry;
    core::ArrayOptions options;
    bool degrees = false;
    if (Status s = ParseArrayConfig(config, &geometry, &options, &degrees); !s.ok()) return s;
    return PlanArray(geometry, options, protocol, limits, out);
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