#include "methods/pca/pca_method.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <set>
#include <utility>

namespace calibd::server {
namespace {

using nlohmann::json;

std::vector<double> StdVector(const Eigen::VectorXd& x) {
  return std::vector<double>(x.data(), x.data() + x.size());
}

Status KeyError(const std::string& key, const std::string& message) {
  return Status::InvalidInput("config key '" + key + "' " + message).WithField(key);
}

bool IsNumber(const json& x) { return x.is_number() && std::isfinite(x.get<double>()); }

void AppendNumber(std::string* out, double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.17g", x);
  *out += buf;
}

}  // namespace

Status ParsePcaConfig(const json& config, core::PcaOptions* options) {
  *options = core::PcaOptions();
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  static const std::set<std::string>& kKnown = *new std::set<std::string>{
      "method", "device", "dimension", "magnitude", "nominal", "refine", "bias", "noise_std"};
  for (const auto& [key, value] : config.items()) {
    if (kKnown.count(key) == 0) {
      return KeyError(key,
                      "is not a pca config key (known: dimension, magnitude, nominal, refine, "
                      "bias, noise_std, method, device)");
    }
  }
  if (auto it = config.find("dimension"); it != config.end()) {
    const json& x = *it;
    if (!x.is_number() || !std::isfinite(x.get<double>()) ||
        x.get<double>() != std::floor(x.get<double>())) {
      return KeyError("dimension", "must be an integer (the field's dimension d, usually 3)");
    }
    const double dim = x.get<double>();
    if (dim < 1 || dim > core::PcaOptions::kMaxDimension) {
      return KeyError("dimension",
                      "must be between 1 and " + std::to_string(core::PcaOptions::kMaxDimension));
    }
    options->dimension = static_cast<int>(dim);
  }
  // magnitude, noise_std: a number > 0, or null / absent for "unknown".
  for (const char* key : {"magnitude", "noise_std"}) {
    auto it = config.find(key);
    if (it == config.end() || it->is_null()) continue;
    if (!IsNumber(*it) || !(it->get<double>() > 0)) {
      return KeyError(key, "must be a number > 0 (or absent when unknown)");
    }
    (std::string(key) == "magnitude" ? options->magnitude : options->noise_std) = it->get<double>();
  }
  if (auto it = config.find("refine"); it != config.end()) {
    if (!it->is_boolean()) return KeyError("refine", "must be true or false");
    options->refine = it->get<bool>();
  }
  if (auto it = config.find("bias"); it != config.end()) {
    if (!it->is_string() || (*it != "none" && *it != "estimate")) {
      return KeyError("bias", "must be \"none\" or \"estimate\"");
    }
    options->bias = *it == "estimate" ? core::BiasModel::kEstimate : core::BiasModel::kNone;
  }
  if (auto it = config.find("nominal"); it != config.end() && !it->is_null()) {
    const int d = options->dimension;
    const std::string shape =
        "must be an array with one row of " + std::to_string(d) + " numbers (dimension) per sensor";
    if (!it->is_array() || it->empty()) return KeyError("nominal", shape);
    const int m = static_cast<int>(it->size());
    Eigen::MatrixXd nominal(d, m);
    for (int i = 0; i < m; ++i) {
      const json& row = (*it)[i];
      if (!row.is_array() || static_cast<int>(row.size()) != d) {
        return KeyError("nominal", shape + "; row " + std::to_string(i + 1) + " is not");
      }
      for (int k = 0; k < d; ++k) {
        if (!IsNumber(row[k])) {
          return KeyError("nominal",
                          shape + "; row " + std::to_string(i + 1) + " has a non-number");
        }
        nominal(k, i) = row[k].get<double>();
      }
    }
    if (nominal.colwise().norm().minCoeff() == 0) {
      return KeyError("nominal", "has a sensor with a zero sensitivity vector");
    }
    options->nominal = std::move(nominal);
  }
  std::string error;
  if (!options->IsValid(&error)) return Status::InvalidInput("pca config: " + error);
  return Status::Ok();
}

results::PcaResult MakePcaResult(const core::PcaResult& r) {
  results::PcaResult out;
  out.envelope.method = "pca";
  out.envelope.model =
      "r_i = a_i^T v + b_i: r_i the raw reading of sensor i, v the field (d components, |v| = "
      "magnitude), a_i = scale_i axis_i its sensitivity vector, b_i its bias (reading units; 0 "
      "unless estimated or removed); the calibrated field from one reading r of all m sensors is "
      "the least-squares inverse v = (A^T A)^-1 A^T (r - b), A the m x d matrix of rows a_i^T";
  out.envelope.warnings = r.warnings;

  results::PcaParameters& params = out.parameters.emplace();
  params.dimension = r.dimension;
  params.magnitude = r.magnitude;
  params.magnitude_known = r.magnitude_known;
  // kNone only before the fit, when the result is not usable and its parameters are not written.
  params.frame = r.frame == core::PcaFrame::kNominal ? results::PcaFrame::kNominal
                                                     : results::PcaFrame::kCanonical;
  params.bias = r.bias_model == core::BiasModel::kEstimate ? results::PcaBias::kEstimate
                                                           : results::PcaBias::kNone;
  results::PcaUncertainty& uncertainty = out.uncertainty.emplace();
  for (const core::PcaSensorEstimate& s : r.sensors) {
    params.sensors.push_back(
        {s.name, StdVector(s.sensitivity), s.scale, StdVector(s.axis), s.bias});
    results::PcaSensorStd& u = uncertainty.sensors.emplace_back(
        results::PcaSensorStd{s.name, s.scale_std, s.axis_std_rad, s.bias_std, std::nullopt});
    if (s.crb)
      u.crb = results::PcaSensorStd::Bound{s.crb->scale_std, s.crb->axis_std_rad, s.crb->bias_std};
  }
  uncertainty.noise_std = r.noise_std;
  uncertainty.basis = r.uncertainty_basis;
  uncertainty.chi2_per_dof = r.chi2_per_dof;

  results::PcaDiagnostics& diag = out.diagnostics;
  diag.usable = r.usable;
  if (!r.usable) diag.reason = r.reason;
  diag.singular_values = StdVector(r.singular_values);
  diag.rank_gap = r.rank_gap;  // +inf when there is no σ_{d+1} (e.g. m = d): written as null
  diag.positions = r.positions;
  diag.min_positions = r.min_positions;
  diag.g_eigenvalues = StdVector(r.g_eigenvalues);
  diag.residual_rms = StdVector(r.residual_rms);
  diag.magnitude_error = StdVector(r.magnitude_error);
  diag.degrees_of_freedom = r.degrees_of_freedom;
  {
    // How well the positions span the sphere (frame-free numbers; directions in the result's
    // frame), so a poor calibration names its real cause.
    const core::PcaCoverage& c = r.coverage;
    results::PcaCoverage& coverage = diag.coverage.emplace();
    switch (c.verdict) {
      case core::PcaCoverageVerdict::kGood:
        coverage.verdict = results::PcaCoverageVerdict::kGood;
        break;
      case core::PcaCoverageVerdict::kPoor:
        coverage.verdict = results::PcaCoverageVerdict::kPoor;
        break;
      case core::PcaCoverageVerdict::kUnknown:
        coverage.verdict = results::PcaCoverageVerdict::kUnknown;
        break;
    }
    coverage.scatter_eigenvalues = StdVector(c.scatter_eigenvalues);
    coverage.scatter_min = c.scatter_min;
    coverage.design_min = c.design_min;
    for (size_t i = 0; i < c.cap_names.size() && i < c.cap_positions.size(); ++i) {
      coverage.positions_per_direction[c.cap_names[i]] = c.cap_positions[i];
    }
    coverage.advice = c.advice;
  }
  diag.noise_std = r.noise_std;
  diag.noise_std_given = r.noise_std_given;
  diag.noise_std_estimated = r.noise_std_estimated;
  diag.cost_closed_form = r.cost_closed_form;
  diag.cost = r.cost;
  diag.refined = r.refined;
  diag.refine_iterations = r.refine_iterations;
  diag.reflection = r.reflection;
  return out;
}

Status RunPca(const PcaRecording& recording, const core::PcaOptions& options, json* result) {
  results::PcaResult typed;
  const Status s = RunPca(recording, options, &typed);
  *result = results::ToJson(typed);
  return s;
}

Status RunPca(const PcaRecording& recording, const core::PcaOptions& options,
              results::PcaResult* result) {
  core::PcaProblem problem;
  problem.m = recording.readings;
  problem.sensor_names = recording.sensor_names;
  problem.position_labels = recording.position_labels;
  const Eigen::Index m = recording.readings.rows();
  const Eigen::Index n = recording.readings.cols();
  if (recording.raw && recording.static_means.rows() == m && recording.static_means.cols() == n &&
      n > 0) {
    // The paper's Section IV: b' per position was subtracted; report its mean and standard error.
    problem.removed_bias = recording.static_means.rowwise().mean();
    problem.removed_bias_std = Eigen::VectorXd::Zero(m);
    if (n >= 2) {
      const Eigen::MatrixXd dev = recording.static_means.colwise() - problem.removed_bias;
      problem.removed_bias_std =
          (dev.rowwise().squaredNorm() / static_cast<double>((n - 1) * n)).cwiseSqrt();
    }
  }
  core::PcaResult r;
  const Status s = core::CalibratePca(problem, options, &r);
  *result = MakePcaResult(r);
  result->diagnostics.position_labels = recording.position_labels;
  if (recording.raw) result->diagnostics.removed_bias = StdVector(problem.removed_bias);
  if (!s.ok()) {
    // The partial diagnostics kept with the failed job (diagnostics.usable = false, the
    // positions, singular values and rank gap, coverage when the fit got that far); the
    // parameters are not estimates, so they are not written, nor is the model.
    result->envelope.usable = false;
    result->envelope.model.clear();
    result->parameters.reset();
    result->uncertainty.reset();
    result->diagnostics.usable = false;
    result->diagnostics.reason.reset();  // the failure's message, stored beside it
  }
  return s;
}

Status SimulatePcaFiles(const core::PcaSimulationOptions& options, std::string* csv, json* config,
                        json* truth) {
  std::string error;
  if (!options.IsValid(&error)) return Status::InvalidInput("simulate pca: " + error);
  const core::PcaSimulation sim = core::SimulatePca(options);
  const Eigen::Index m = sim.m.rows();
  const Eigen::Index n = sim.m.cols();
  csv->clear();
  csv->reserve(static_cast<size_t>(n * m * 24 + 64));
  *csv += "# calibd simulate pca: the paper's Section IV set-up, seed " +
          std::to_string(options.seed) + "\nposition";
  for (const std::string& name : sim.sensor_names) *csv += "," + name;
  *csv += "\n";
  for (Eigen::Index j = 0; j < n; ++j) {
    *csv += "p" + std::to_string(j + 1);
    for (Eigen::Index i = 0; i < m; ++i) {
      *csv += ",";
      AppendNumber(csv, sim.m(i, j));
    }
    *csv += "\n";
  }
  json nominal = json::array();
  for (Eigen::Index i = 0; i < m; ++i)
    nominal.push_back(results::Nums(StdVector(sim.a_model.col(i))));
  *config = {{"method", "pca"}, {"magnitude", options.magnitude}, {"nominal", nominal}};
  if (options.bias_std > 0) (*config)["bias"] = "estimate";
  json sensors = json::array();
  for (Eigen::Index i = 0; i < m; ++i) {
    sensors.push_back({{"name", sim.sensor_names[i]},
                       {"sensitivity", results::Nums(StdVector(sim.a_true.col(i)))},
                       {"bias", sim.b(i)}});
  }
  json v = json::array();
  for (Eigen::Index j = 0; j < n; ++j) v.push_back(results::Nums(StdVector(sim.v.col(j))));
  *truth = {{"method", "pca"},
            {"seed", options.seed},
            {"sensors", sensors},
            {"v", v},
            {"options",
             {{"positions", options.positions},
              {"noise_std", options.noise_std},
              {"axis_perturbation", options.axis_perturbation},
              {"magnitude", options.magnitude},
              {"bias_std", options.bias_std}}}};
  return Status::Ok();
}

void JudgePca(const json& result, const json& config, const AcceptanceLimits& limits,
              Verdict* verdict) {
  results::PcaResult typed;
  const Status read = results::FromJson(result, &typed);
  if (!read.ok()) {
    verdict->Reject("the result cannot be judged: " + read.message());
    return;
  }
  core::PcaOptions options;
  const Status parsed = ParsePcaConfig(config, &options);
  if (!parsed.ok()) {
    verdict->Reject("the result cannot be judged: " + parsed.message());
    return;
  }
  JudgePca(typed, options, limits, verdict);
}

namespace {

std::optional<double> Defined(double x) {
  return std::isfinite(x) ? std::optional<double>(x) : std::nullopt;
}

bool AllFinite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

// Rule: orientation coverage. It is judged first: it is the real cause of most of the other
// failures. A result stored before calibd measured the coverage has none: this rule does not
// apply to it (the precision the spread gives is still judged by the uncertainty limits).
void JudgePcaCoverage(const results::PcaDiagnostics& diag, const AcceptanceLimits& limits,
                      Verdict* verdict) {
  if (!diag.coverage.has_value()) return;
  const results::PcaCoverage& coverage = *diag.coverage;
  const auto scatter = Defined(coverage.scatter_min);
  const auto design = Defined(coverage.design_min);
  const auto min_scatter = limits.Get("min_scatter");
  const auto min_design = limits.Get("min_design");
  if ((min_scatter && (!scatter || *scatter < *min_scatter)) ||
      (min_design && (!design || *design < *min_design))) {
    const std::string& advice = coverage.advice;
    verdict->Reject(
        "the orientations are poorly spread (scatter_min " +
        (scatter ? Fmt(*scatter) : std::string("unknown")) + ", minimum " +
        (min_scatter ? Fmt(*min_scatter) : std::string("none")) + "; design_min " +
        (design ? Fmt(*design) : std::string("unknown")) + ", minimum " +
        (min_design ? Fmt(*min_design) : std::string("none")) + "; both 1 for a uniform spread)" +
        (advice.empty() ? std::string(": add positions between the axes") : ": " + advice));
  }
}

// Nominal scale per sensor: |nominal_i| when given, else 1 when the magnitude is known (readings
// in the field's unit); NaN (nothing to compare with) when the magnitude is unknown (relative
// scales).
std::vector<double> NominalScales(const results::PcaParameters& params,
                                  const core::PcaOptions& options) {
  const std::vector<results::PcaSensor>& sensors = params.sensors;
  std::vector<double> nominal_scale(sensors.size(), params.magnitude_known ? 1.0 : NAN);
  if (options.nominal.has_value()) {
    for (size_t i = 0; i < sensors.size() && static_cast<Eigen::Index>(i) < options.nominal->cols();
         ++i) {
      nominal_scale[i] = options.nominal->col(static_cast<Eigen::Index>(i)).norm();
    }
  }
  return nominal_scale;
}

// The likely cause of physically implausible scale factors (`ratio`: one offender's scale against
// its nominal): a unit mix-up between the readings and `magnitude` is the usual one.
std::string ImplausibleScaleCause(bool has_nominal, double ratio, double magnitude) {
  constexpr double kG = 9.80665;
  auto near = [](double x, double target) { return std::abs(x / target - 1) < 0.15; };
  if (!has_nominal && near(ratio, 1 / kG) && near(magnitude, kG)) {
    return "readings look like g but magnitude is " + Fmt(magnitude) +
           " (gravity in m/s^2): units? (give magnitude 1 for readings in g, or convert them to "
           "m/s^2)";
  }
  if (!has_nominal && near(ratio, kG) && near(magnitude, 1)) {
    return "readings look like m/s^2 but magnitude is " + Fmt(magnitude) +
           " (gravity in g): units? (give magnitude 9.80665 for readings in m/s^2)";
  }
  return std::string("are the readings and magnitude (") + Fmt(magnitude) + ") in the same unit" +
         (has_nominal ? ", and is nominal right?"
                      : "? (readings in another unit need nominal sensitivities)");
}

// Rules per sensor: finite numbers, a plausible scale factor near its nominal, and the scale,
// axis and bias uncertainties within their limits.
void JudgePcaSensors(const results::PcaResult& result, const core::PcaOptions& options,
                     const AcceptanceLimits& limits, Verdict* verdict) {
  const results::PcaParameters& params = *result.parameters;
  const std::vector<results::PcaSensor>& sensors = params.sensors;
  // FromJson checked: one entry per sensor, in the same order.
  const std::vector<results::PcaSensorStd>& stds = result.uncertainty->sensors;
  const double magnitude = params.magnitude;
  const bool has_nominal = options.nominal.has_value();
  const std::vector<double> nominal_scale = NominalScales(params, options);
  const auto range = limits.Get("scale_range");
  const auto implausible = limits.Get("implausible_factor");
  const auto scale_std_max = limits.Get("max_scale_std");
  const auto axis_std_max = limits.Get("max_axis_std");
  const auto bias_std_max = limits.Get("max_bias_std");
  Offenders out_of_range, absurd, scale_std, axis_std, bias_std, undefined, not_finite;
  double absurd_ratio = NAN;
  for (size_t i = 0; i < sensors.size(); ++i) {
    const results::PcaSensor& sensor = sensors[i];
    const std::string& name = sensor.name;
    const double scale = sensor.scale;
    if (!AllFinite(sensor.sensitivity) || !AllFinite(sensor.axis) || !std::isfinite(scale) ||
        !std::isfinite(sensor.bias)) {
      not_finite.Add(name);
    }
    const double ratio = scale / nominal_scale[i];
    if (std::isfinite(ratio)) {
      if (implausible && (ratio > *implausible || ratio < 1 / *implausible)) {
        absurd.Add(name + " (" + Fmt(scale) + " reading units per field unit, " + Fmt(ratio) +
                   " x the nominal)");
        absurd_ratio = ratio;
      } else if (range && std::abs(ratio - 1) > *range) {
        out_of_range.Add(name + " (" + Fmt(scale) + " against " + Fmt(nominal_scale[i]) +
                         " reading units per field unit)");
      }
    }
    const results::PcaSensorStd& sd = stds[i];
    const double rel = sd.scale_std / std::abs(scale);
    const double axis = sd.axis_std_rad;
    if (!std::isfinite(rel) || !std::isfinite(axis)) {
      undefined.Add(name);
    } else {
      if (scale_std_max && rel > *scale_std_max) scale_std.Add(name + " " + Fmt(rel * 100) + " %");
      if (axis_std_max && axis > *axis_std_max)
        axis_std.Add(name + " " + Fmt(axis * 1e3) + " mrad");
    }
    // Biases: estimated (or removed from a raw log) ones have a std; relative to the magnitude.
    const auto b_std = Defined(sd.bias_std);
    if (params.bias == results::PcaBias::kEstimate && !b_std) {
      undefined.Add(name + " bias");
    } else if (b_std && bias_std_max && std::isfinite(magnitude) && magnitude > 0 &&
               std::isfinite(scale) && scale > 0) {
      // bias_std is in reading units; / scale gives field units, / magnitude relative.
      const double rel_bias = *b_std / scale / magnitude;
      if (rel_bias > *bias_std_max) bias_std.Add(name + " " + Fmt(*b_std) + " reading units");
    }
  }
  not_finite.RejectInto(verdict, kNotFiniteRule);
  if (!absurd.empty()) {
    absurd.RejectInto(verdict, "scale factors physically implausible, " +
                                   ImplausibleScaleCause(has_nominal, absurd_ratio, magnitude));
  }
  if (range) {
    out_of_range.RejectInto(
        verdict, "scale factor more than " + Fmt(*range * 100) + " % from the nominal" +
                     std::string(has_nominal ? "" : " (1: readings in the field's unit)"));
  }
  undefined.RejectInto(verdict,
                       "the uncertainty could not be computed, so the precision cannot be judged "
                       "(give noise_std, or record more positions)");
  if (scale_std_max) {
    scale_std.RejectInto(verdict, "scale factor too uncertain (1 sigma above " +
                                      Fmt(*scale_std_max * 100) +
                                      " %): record more, better spread positions");
  }
  if (axis_std_max) {
    axis_std.RejectInto(verdict, "axis direction too uncertain (1 sigma above " +
                                     Fmt(*axis_std_max * 1e3) +
                                     " mrad): record more, better spread positions");
  }
  if (bias_std_max) {
    bias_std.RejectInto(verdict, "bias too uncertain (1 sigma above " + Fmt(*bias_std_max * 100) +
                                     " % of the field): record more positions");
  }
}

// Rule: the residual against the noise. Only meaningful when sigma was given (an estimated sigma
// is the residual itself).
void JudgePcaResiduals(const results::PcaDiagnostics& diag, const AcceptanceLimits& limits,
                       Verdict* verdict) {
  const auto chi2_max = limits.Get("max_chi2");
  const auto cost = Defined(diag.cost);
  const int dof = diag.degrees_of_freedom;
  const auto sigma = Defined(diag.noise_std);
  if (chi2_max && diag.noise_std_given && cost && sigma && *sigma > 0 && dof > 0) {
    const double chi2 = 2 * *cost / dof / (*sigma * *sigma);
    if (chi2 > *chi2_max) {
      verdict->Reject("the residuals are " + Fmt(std::sqrt(chi2)) + " times the given noise_std " +
                      Fmt(*sigma) + " reading units (chi2/dof " + Fmt(chi2) + " above " +
                      Fmt(*chi2_max) +
                      "): the device moved during a position, the field was not constant, or "
                      "noise_std is wrong");
    }
  }
}

}  // namespace

void JudgePca(const results::PcaResult& result, const core::PcaOptions& options,
              const AcceptanceLimits& limits, Verdict* verdict) {
  if (!result.parameters || !result.uncertainty) {
    verdict->Reject(
        "the result cannot be judged: it is a failed run's partial diagnostics (no parameters)");
    return;
  }
  JudgePcaCoverage(result.diagnostics, limits, verdict);
  JudgePcaSensors(result, options, limits, verdict);
  JudgePcaResiduals(result.diagnostics, limits, verdict);
}

namespace {

class Pca : public Method {
 public:
  const char* name() const override { return "pca"; }
  const char* simulate_summary() const override {
    return "Rupniewski Section IV: 4 gyroscope triads of a_model, axes perturbed, n random "
           "orientations";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override {
    auto options = std::make_shared<core::PcaSimulationOptions>();
    command->add_option("--seed", options->seed, "random seed")->capture_default_str();
    command->add_option("-n,--positions", options->positions, "number of positions n")
        ->check(CLI::Range(1, 10000000))
        ->capture_default_str();
    command->add_option("--noise", options->noise_std, "reading noise σ")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command->add_option("--magnitude", options->magnitude, "field magnitude c")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    command
        ->add_option("--axis-perturbation", options->axis_perturbation,
                     "σ of the perturbation of each sensitivity vector")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    command
        ->add_option("--bias", options->bias_std,
                     "σ of a constant bias added to each sensor (the config then says "
                     "bias: estimate)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    return [options](SimulatedFiles* files) {
      Status s = SimulatePcaFiles(*options, &files->csv, &files->config, &files->truth);
      return s;
    };
  }
  std::vector<std::string> FleetParameters() const override {
    return {"sensors/*/scale", "sensors/*/bias"};
  }
  std::vector<FailureReason> FailureReasons() const override {
    return {
        CatalogEntry(core::pca_reason::kTooFewSensors, "Too few sensors",
                     "Record with at least as many sensors as the dimension d of the field."),
        CatalogEntry(
            core::pca_reason::kNoRankGap, "No clear rank gap",
            "Record positions whose field directions differ more (spread over the sphere), and "
            "average longer per position to lower the noise."),
        CatalogEntry(core::pca_reason::kDeadSensor, "A sensor does not respond",
                     "Check the sensor the message names (power, wiring, channel mapping), or "
                     "remove it from the recording."),
    };
  }
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat()};
  }
  Status Export(const std::string& format, const nlohmann::json& result,
                const ExportContext& context, std::string* out) const override {
    if (format == "csv") return PcaResultToCsv(result, out);
    if (format == "h") return PcaResultToHeader(result, context, out);
    return NoSuchExport(format, name());
  }
  const char* summary() const override {
    return "sensitivity vectors (axis x scale) and biases of m single-axis sensors from static "
           "positions (Rupniewski, PCA-aided calibration)";
  }
  bool Reads(Layout layout) const override {
    return layout == Layout::kPcaAveraged || layout == Layout::kPcaRaw;
  }
  Status ValidateConfig(const nlohmann::json& config) const override {
    core::PcaOptions options;
    return ParsePcaConfig(config, &options);
  }
  void Judge(const nlohmann::json& result, const nlohmann::json& config,
             const AcceptanceLimits& limits, Verdict* verdict) const override {
    JudgePca(result, config, limits, verdict);
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    using namespace limit_keys;
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>{
        kMaxScaleStd,
        kMaxAxisStd,
        {"max_bias_std", "largest 1 sigma of a bias, relative to the field magnitude", 0.01},
        kScaleRange,
        kImplausible,
        kMaxChi2,  // only judged when noise_std is given (otherwise sigma is the residual itself)
        {"min_scatter",
         "smallest spread of the orientations: d x the smallest eigenvalue of the field "
         "directions' scatter (1 uniform, 0 all in a plane); diagnostics.coverage.scatter_min",
         0.3},  // core::PcaCoverage::kMinScatter
        {"min_design",
         "smallest eigenvalue of the quadric fit's design relative to a uniform sphere (what the "
         "angles between axes are estimated from); diagnostics.coverage.design_min",
         0.05},  // core::PcaCoverage::kMinDesign
    };
    return keys;
  }
  Status Plan(const nlohmann::json& config, const PlanProtocol& protocol,
              const AcceptanceLimits& limits, nlohmann::json* out) const override {
    return PlanPca(config, protocol, limits, out);
  }
  Status Run(RecordingParser* parser, const nlohmann::json& config, const RunContext& ctx,
             nlohmann::json* result) const override {
    PcaRecording recording;
    Status s = parser->TakePca(&recording);
    if (!s.ok()) return s;
    core::PcaOptions options;
    s = ParsePcaConfig(config, &options);
    if (!s.ok())
      return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
    options.stop = ctx.stop;  // a stopped run returns core::StoppedStatus ("pca: <stage>: ...")
    return RunPca(recording, options, result);
  }
};

}  // namespace

const Method& PcaMethod() {
  static const Pca& method = *new Pca;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
