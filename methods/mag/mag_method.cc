#include "methods/mag/mag_method.h"

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <set>
#include <vector>

#include "core/static_detection.h"
#include "formats/inertial_log.h"
#include "methods/config_keys.h"
#include "methods/noise/noise_reference.h"

namespace calibd::server {

using nlohmann::json;

namespace {

core::StaticDetectionOptions HandHeldStatics() {
  core::StaticDetectionOptions o;
  o.static_window = 0.5;
  o.min_static = 0.5;
  return o;
}

// The config as the numerics' options.
struct MagConfig {
  core::MagOptions options;
  std::string unit_text = "uT";  // mag_unit as configured
  // Hand-held holds are short: windows and holds of 0.5 s (SPEC §7's detection otherwise).
  core::StaticDetectionOptions statics = HandHeldStatics();
  std::vector<int64_t> device_ids;  // config device_id (a number: m0's), empty when absent
  MagPlanConfig plan;  // mag_noise and dip: read by the plan only (methods/mag/mag_plan.cc)
};

// µT per reading unit of a named mag_unit; 0 for an unknown name.
double MicroteslaPerUnit(const std::string& name) {
  if (name == "uT" || name == "\xC2\xB5T" || name == "\xCE\xBCT") return 1;  // µ: micro or mu
  if (name == "gauss") return 100;
  if (name == "mG") return 0.1;
  if (name == "nT") return 0.001;
  return 0;
}

// The plan's keys (mag_noise, dip) and the field and unit they go with.
Status ParseMagPlanKeys(const json& config, const core::MagOptions& options, MagPlanConfig* out) {
  out->field = options.field;
  out->microtesla_per_unit = options.microtesla_per_unit;
  if (auto it = config.find("mag_noise"); it != config.end() && it->is_object()) {
    // Noise jobs (methods/noise) read accelerometer and gyroscope channels only.
    return ConfigKeyError("mag_noise",
                          "a noise job has no magnetometer channels to refer to: give the "
                          "magnetometer's white-noise σ per sample as a number in mag_unit");
  }
  std::optional<NoiseLevel> level;
  if (Status s = ReadNoiseLevel(config, "mag_noise", &level); !s.ok()) return s;
  if (level) out->noise = level->value;
  return ConfigNumber(config, "dip", -89, 89, &out->dip);
}

Status ParseMagConfig(const json& config, MagConfig* out) {
  if (!config.is_object()) return Status::InvalidInput("the config must be a JSON object");
  static const std::set<std::string>& kKnown =
      *new std::set<std::string>{"method",     "device",    "mag_unit",  "field", "static_window",
                                 "min_static", "device_id", "mag_noise", "dip"};
  for (const auto& [key, value] : config.items()) {
    if (kKnown.count(key) == 0) {
      return ConfigKeyError(key,
                            "is not a mag config key (known: mag_unit, field, static_window, "
                            "min_static, device_id, mag_noise, dip, method, device)");
    }
  }
  *out = MagConfig();
  if (auto it = config.find("mag_unit"); it != config.end()) {
    if (it->is_string()) {
      out->unit_text = it->get<std::string>();
      out->options.microtesla_per_unit = MicroteslaPerUnit(out->unit_text);
      if (out->options.microtesla_per_unit == 0) {
        return ConfigKeyError(
            "mag_unit",
            "must be \"uT\", \"gauss\", \"mG\", \"nT\" or a number (µT per reading "
            "unit), not \"" +
                out->unit_text + "\"");
      }
    } else if (it->is_number() && std::isfinite(it->get<double>()) && it->get<double>() > 0) {
      out->options.microtesla_per_unit = it->get<double>();
      out->unit_text = Fmt(it->get<double>()) + " uT";
    } else {
      return ConfigKeyError(
          "mag_unit",
          "must be \"uT\", \"gauss\", \"mG\", \"nT\" or a positive number (µT per "
          "reading unit)");
    }
  }
  if (auto it = config.find("field"); it != config.end()) {
    if (!it->is_number() || !(it->get<double>() > 0) || it->get<double>() > 1e4) {
      return ConfigKeyError("field",
                            "must be the local field magnitude in µT, a number in (0, 10000]");
    }
    out->options.field = it->get<double>();
  }
  if (auto it = config.find("device_id"); it != config.end()) {
    const json list = it->is_array() ? *it : json::array({*it});
    for (const json& id : list) {
      if (!id.is_number_integer() || id.get<int64_t>() < 0 || id.get<int64_t>() > INT32_MAX) {
        return ConfigKeyError("device_id",
                              "must be the magnetometer's firmware device id (PX4 CAL_MAGn_ID, "
                              "ArduPilot COMPASS_DEV_ID), an integer in [0, 2147483647], or an "
                              "array of them, one per magnetometer m0, m1, ...");
      }
    }
    for (const json& id : list) out->device_ids.push_back(id.get<int64_t>());
  }
  Status s = ConfigNumber(config, "static_window", 0.05, 60, &out->statics.static_window);
  if (s.ok()) s = ConfigNumber(config, "min_static", 0, 600, &out->statics.min_static);
  if (s.ok()) s = ParseMagPlanKeys(config, out->options, &out->plan);
  if (!s.ok()) return s;
  return out->options.Validate();
}

// The accelerometer triad whose statics serve magnetometer k: aK, else a0, else none (-1).
int AccelFor(const ArrayRecording& log, size_t k) {
  if (k < log.accel_names.size()) return static_cast<int>(k);
  return log.accel_names.empty() ? -1 : 0;
}

// The firmware device id of magnetometer k: config device_id's entry (it wins: the user names the
// sensor the files are for), else its log stream's (ULog device_id, DataFlash COMPASS_DEV_ID*),
// else none (-1); a config id that differs from the log's is warned about.
void SetDeviceId(const MagConfig& c, const ArrayRecording& log, size_t k, MagRun* run) {
  const int64_t from_log = k < log.mag_device_ids.size() ? log.mag_device_ids[k] : -1;
  if (k < c.device_ids.size()) {
    run->device_id = c.device_ids[k];
    run->device_id_source = "config";
    if (from_log >= 0 && from_log != run->device_id) {
      run->warnings.push_back("config device_id " + std::to_string(run->device_id) +
                              " differs from the log's " + std::to_string(from_log) +
                              " for this magnetometer: the exports carry the config's");
    }
  } else if (from_log >= 0) {
    run->device_id = from_log;
    run->device_id_source = "log";
  }
}

// The statics of the log on accelerometer triad `a` (and gyroscope triad `a` when there is one).
Status FindStatics(const ArrayRecording& log, int a, const MagConfig& config,
                   std::vector<core::MagStatic>* out) {
  out->clear();
  if (a < 0) return Status::Ok();
  std::vector<Eigen::MatrixX3d> triads{log.accel.middleCols(3 * a, 3)};
  if (a < static_cast<int>(log.gyro_names.size()))
    triads.emplace_back(log.gyro.middleCols(3 * a, 3));
  std::vector<core::TriadSeries> series;
  for (size_t i = 0; i < triads.size(); ++i) {
    core::TriadSeries ts;
    ts.name = (i == 0 ? "a" : "g") + std::to_string(a);
    ts.kind = i == 0 ? core::TriadKind::kAccelerometer : core::TriadKind::kGyroscope;
    ts.readings = &triads[i];
    series.push_back(ts);
  }
  core::StaticDetection found;
  const Status s = core::DetectStatics(log.t, series, config.statics, &found);
  if (!s.ok()) return s;
  for (const core::StaticInterval& i : found.intervals) {
    out->push_back({i.first, i.last, i.mean[0]});
  }
  return Status::Ok();
}

// The calibrated field's white noise per axis (µT), independent of the fit's residuals: from
// the second differences of consecutive samples (which remove a smooth turn; var = 6 σ² for
// white noise), robustly (1.4826 × their median absolute value over every axis and sample).
// NaN with fewer than 3 samples. `scale` converts S's output to µT.
double SampleNoise(const core::MagProblem& p, const core::MagResult& r, double scale) {
  const Eigen::Index n = p.y.cols();
  if (n < 3) return NAN;
  const Eigen::Matrix3Xd m = scale * r.soft_iron * p.y;  // the hard iron cancels in differences
  std::vector<double> d;
  d.reserve(static_cast<size_t>(3 * (n - 2)));
  for (Eigen::Index i = 1; i + 1 < n; ++i) {
    for (int a = 0; a < 3; ++a) d.push_back(std::abs(m(a, i + 1) - 2 * m(a, i) + m(a, i - 1)));
  }
  const auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  return 1.4826 * *mid / std::sqrt(6.0);
}

class Mag : public Method {
 public:
  const char* name() const override { return "mag"; }
  const char* summary() const override {
    return "each magnetometer's hard and soft iron, its rotation to the accelerometer and the "
           "field's dip, with 1 sigma and disturbed spans, from a log turned by hand";
  }
  bool Reads(Layout layout) const override { return layout == Layout::kArray; }
  bool NeedsIncreasingTime() const override { return true; }
  // A sensor log: the magnetometer's own times are the time base (formats/log_assembly.h), so
  // its samples are not repeated onto a faster IMU's times (which would understate σ).
  void PrepareParser(const json&, RecordingParser* parser) const override {
    parser->SetLogTimeBaseMag();
  }
  Status ValidateConfig(const json& config) const override {
    MagConfig c;
    return ParseMagConfig(config, &c);
  }
  Status Plan(const json& config, const PlanProtocol& protocol, const AcceptanceLimits& limits,
              json* out) const override {
    return PlanMag(config, protocol, limits, out);
  }
  Status Check(const ArrayRecording& log, const json& config, const RunContext& context,
               json* check) const override;
  const char* simulate_summary() const override {
    return "a magnetometer turned by hand with known hard and soft iron, misalignment, dip and "
           "disturbances";
  }
  std::function<Status(SimulatedFiles*)> AddSimulateOptions(CLI::App* command) const override;
  // Measured: the parser's doubles, the fit's 24 doubles a sample, the copies of the triads and
  // the plot (bench/README.md, "Memory budget per job": 68 B a value).
  double PeakBytesPerValue(const json&) const override { return 72; }
  std::vector<std::string> FleetParameters() const override {
    return {"mags/*/hard_iron/*", "mags/*/soft_iron_symmetric/*/*"};
  }
  std::vector<ExportFormat> ExportFormats() const override {
    return {CsvFormat(), CHeaderFormat(),
            ExportFormat{"ardupilot", "ArduPilot COMPASS parameters", "text/plain",
                         "mag-ardupilot.parm"},
            ExportFormat{"px4", "PX4 CAL_MAG parameters (QGroundControl)", "text/plain",
                         "mag-px4.params"}};
  }
  Status Export(const std::string& format, const json& result, const ExportContext& context,
                std::string* out) const override {
    if (format == "csv") return MagResultToCsv(result, out);
    if (format == "h") return MagResultToHeader(result, context, out);
    if (format == "ardupilot") return MagResultToArduPilot(result, context, out);
    if (format == "px4") return MagResultToPx4(result, context, out);
    return NoSuchExport(format, name());
  }
  const std::vector<AcceptanceKey>& AcceptanceKeys() const override {
    static const std::vector<AcceptanceKey>& keys = *new std::vector<AcceptanceKey>{
        {"max_hard_iron_std", "largest 1 sigma of a hard-iron component, uT", 0.5},
        {"max_soft_iron_std",
         "largest 1 sigma of a soft-iron entry, relative to the mean diagonal (0.01 = 1 %)", 0.01},
        {"max_alignment_std",
         "largest 1 sigma of the rotation to the accelerometer (when estimated), rad", 0.02},
        {"min_coverage_eigenvalue",
         "smallest eigenvalue of the field directions' scatter (3/N) sum u u^T (1 when spread "
         "evenly over the sphere); a magnetometer axis the field never came within 45 degrees "
         "of is rejected whatever this limit",
         0.2},
        {"min_field", "smallest plausible magnitude of the Earth's field (field_estimate), uT",
         20.0},
        {"max_field", "largest plausible magnitude of the Earth's field (field_estimate), uT",
         75.0},
        {"max_disturbed_fraction", "largest fraction of samples flagged as disturbed", 0.1},
        {limit_keys::kMaxChi2.name,
         "largest mean squared |m| residual (undisturbed samples) over the sample-to-sample noise "
         "squared (1 when the model explains the log down to the sensor's white noise)",
         9.0},
    };
    return keys;
  }
  void Judge(const json& result, const json& config, const AcceptanceLimits& limits,
             Verdict* verdict) const override;
  Status Run(RecordingParser* parser, const json& config, const RunContext& context,
             json* result) const override;
};

// Why a field estimate outside [lo, hi] µT may be a unit mix-up: the mag_unit that would put it
// inside ("" when none does).
std::string FieldUnitHint(double estimate, double per_unit, double lo, double hi) {
  for (const char* unit : {"uT", "gauss", "mG", "nT"}) {
    const double f = estimate / per_unit * MicroteslaPerUnit(unit);
    if (f >= lo && f <= hi && MicroteslaPerUnit(unit) != per_unit) {
      return std::string(" (with mag_unit \"") + unit + "\" it would be " + Fmt(f) + " uT)";
    }
  }
  return "";
}

void Mag::Judge(const json& result, const json&, const AcceptanceLimits& limits,
                Verdict* verdict) const {
  try {
    Offenders not_finite, hard, soft, align, coverage, field, disturbed, chi2;
    const json& p = result.at("parameters").at("mags");
    const json& u = result.at("uncertainty").at("mags");
    const json& d = result.at("diagnostics").at("mags");
    for (size_t i = 0; i < p.size(); ++i) {
      const std::string name = p[i].at("name").get<std::string>();
      const double per_unit = p[i].at("microtesla_per_unit").get<double>();
      for (const char* key : {"hard_iron", "soft_iron"}) {
        if (p[i].at(key).dump().find("null") != std::string::npos) not_finite.Add(name + " " + key);
      }
      double worst_h = 0, worst_s = 0, diag = 0;
      for (const json& v : u[i].at("hard_iron_std")) worst_h = std::max(worst_h, v.get<double>());
      for (int r = 0; r < 3; ++r) {
        diag += std::abs(p[i].at("soft_iron").at(r).at(r).get<double>()) / 3;
        for (const json& v : u[i].at("soft_iron_std").at(r)) {
          worst_s = std::max(worst_s, v.get<double>());
        }
      }
      worst_h *= per_unit;
      worst_s /= diag;
      if (auto lim = limits.Get("max_hard_iron_std"); lim && !(worst_h <= *lim)) {
        hard.Add(name + " " + Fmt(worst_h) + " uT");
      }
      if (auto lim = limits.Get("max_soft_iron_std"); lim && !(worst_s <= *lim)) {
        soft.Add(name + " " + Fmt(100 * worst_s) + " %");
      }
      if (const json& a = u[i].at("alignment_std"); a.is_array()) {
        double worst = 0;
        for (const json& v : a) worst = std::max(worst, v.get<double>());
        if (auto lim = limits.Get("max_alignment_std"); lim && !(worst <= *lim)) {
          align.Add(name + " " + Fmt(worst) + " rad");
        }
      }
      const json& c = d[i].at("coverage");
      const double smallest = c.at("eigenvalues").at(0).get<double>();
      const auto lim = limits.Get("min_coverage_eigenvalue");
      if ((lim && !(smallest >= *lim)) || !c.at("missing").empty()) {
        std::string missing;
        for (const json& m : c.at("missing"))
          missing += (missing.empty() ? "" : ", ") + m.get<std::string>();
        coverage.Add(name + " " + Fmt(smallest) +
                     (missing.empty() ? "" : " (the field never came near " + missing + ")"));
      }
      const double f = p[i].at("field_estimate").get<double>();
      const auto lo = limits.Get("min_field"), hi = limits.Get("max_field");
      if ((lo && !(f >= *lo)) || (hi && !(f <= *hi))) {
        field.Add(name + " " + Fmt(f) + " uT" +
                  FieldUnitHint(f, per_unit, lo.value_or(0), hi.value_or(INFINITY)));
      }
      const double frac = d[i].at("disturbed_fraction").get<double>();
      if (auto lim = limits.Get("max_disturbed_fraction"); lim && !(frac <= *lim)) {
        disturbed.Add(name + " " + Fmt(100 * frac) + " %");
      }
      if (const json& x = d[i].at("chi2"); x.is_number()) {
        if (auto lim = limits.Get("max_chi2"); lim && !(x.get<double>() <= *lim)) {
          chi2.Add(name + " " + Fmt(x.get<double>()));
        }
      }
    }
    not_finite.RejectInto(verdict, kNotFiniteRule);
    hard.RejectInto(verdict,
                    "hard iron too uncertain: turn the device through more orientations, slowly, "
                    "away from iron");
    soft.RejectInto(verdict,
                    "soft iron too uncertain: turn the device through every orientation (all six "
                    "faces up and the diagonals between them)");
    align.RejectInto(verdict,
                     "rotation to the accelerometer too uncertain: hold the device still in more "
                     "orientations, spread over the sphere");
    coverage.RejectInto(verdict,
                        "orientations poorly covered: turn the device so that the field comes "
                        "along the directions named");
    field.RejectInto(verdict,
                     "field magnitude implausible for the Earth's field (check mag_unit, or the "
                     "recording was made next to iron or a magnet)");
    disturbed.RejectInto(verdict,
                         "too many disturbed samples: record away from iron, motors, cables and "
                         "vehicles");
    chi2.RejectInto(verdict,
                    "the residuals exceed the sensor's sample-to-sample noise (max_chi2): the "
                    "field changed while turning, or the sensor is not linear");
  } catch (const std::exception& e) {
    verdict->Reject(std::string("the result cannot be judged: ") + e.what());
  }
}

Status Mag::Run(RecordingParser* parser, const json& config, const RunContext& context,
                json* result) const {
  MagConfig c;
  Status s = ParseMagConfig(config, &c);
  if (!s.ok()) return s.reason() == Reason::kUnspecified ? s.WithReason(Reason::kInvalidConfig) : s;
  c.options.stop = context.stop;
  c.statics.stop = context.stop;
  ArrayRecording log;
  s = parser->TakeArray(&log);
  if (!s.ok()) return s;
  if (log.mag_names.empty()) {
    return Status::InvalidInput(
               "mag needs magnetometer columns m0_x, m0_y, m0_z (one triad per magnetometer) "
               "and a time column t; the log has none")
        .WithReason(Reason::kInvalidRecording);
  }
  if (c.device_ids.size() > log.mag_names.size()) {
    return Status::InvalidInput("config device_id has " + std::to_string(c.device_ids.size()) +
                                " entries, the log " + std::to_string(log.mag_names.size()) +
                                " magnetometer(s)")
        .WithReason(Reason::kInvalidConfig);
  }
  s = CheckLogTimes(log, "mag", &parser->summary());
  if (!s.ok()) return s;
  std::vector<core::MagProblem> problems(log.mag_names.size());
  std::vector<MagRun> runs(log.mag_names.size());
  for (size_t k = 0; k < runs.size(); ++k) {
    MagRun& run = runs[k];
    core::MagProblem& p = problems[k];
    run.name = log.mag_names[k];
    SetDeviceId(c, log, k, &run);
    run.problem = &p;
    p.t = log.t;
    p.y = log.mag.middleCols(3 * static_cast<Eigen::Index>(k), 3).transpose();
    const int a = AccelFor(log, k);
    if (a >= 0) run.accelerometer = log.accel_names[static_cast<size_t>(a)];
    s = FindStatics(log, a, c, &p.statics);
    if (!s.ok()) return s;
    run.statics = static_cast<int>(p.statics.size());
    s = core::CalibrateMag(p, c.options, &run.result);
    if (!s.ok()) {
      if (s.code() != StatusCode::kStopped) {
        *result = {{"method", "mag"},
                   {"usable", false},
                   {"diagnostics", {{"mags", {MagDiagnostics(run, c.unit_text)}}}},
                   {"warnings", run.result.warnings}};
      }
      if (runs.size() == 1) return s;
      return Status(s.code(), "magnetometer " + run.name + ": " + s.message())
          .WithReason(s.reason());
    }
    const double to_ut = c.options.field > 0 ? 1 : run.result.field_estimate;
    run.sample_noise_std = SampleNoise(p, run.result, to_ut);
  }
  *result = MagResultToJson(runs, c.unit_text, c.options.microtesla_per_unit, c.options.field);
  return Status::Ok();
}

// The check before fitting (Method::Check): per magnetometer the samples, the statics Run's
// FindStatics finds for the alignment and whether there are enough, and the raw field magnitude
// against the Earth's in the declared mag_unit. The coverage and disturbed spans are the fit's
// (core/mag.h steps 2 and 5: they need the calibrated field directions and the residuals), and
// the predicted σ is not computed (the plan's, methods/mag/mag_plan.cc, needs the orientations of
// the turns, which the log gives only after the fit): both are said in "mags[].notes".
Status Mag::Check(const ArrayRecording& log, const json& config, const RunContext& context,
                  json* check) const {
  MagConfig c;
  if (Status s = ParseMagConfig(config, &c); !s.ok()) return s;
  c.statics.stop = context.stop;
  if (log.mag_names.empty()) {
    return Status::InvalidInput(
        "mag needs magnetometer columns m0_x, m0_y, m0_z (one triad per magnetometer); the log "
        "has none");
  }
  const AcceptanceKey* lo = nullptr;
  const AcceptanceKey* hi = nullptr;
  for (const AcceptanceKey& k : AcceptanceKeys()) {
    if (std::string(k.name) == "min_field") lo = &k;
    if (std::string(k.name) == "max_field") hi = &k;
  }
  const double min_field = lo->default_value.value_or(0);
  const double max_field = hi->default_value.value_or(INFINITY);
  const int needed = c.options.min_alignment_statics;
  json mags = json::array();
  for (size_t k = 0; k < log.mag_names.size(); ++k) {
    const int a = AccelFor(log, k);
    std::vector<core::MagStatic> statics;
    if (Status s = FindStatics(log, a, c, &statics); !s.ok()) return s;
    json list = json::array();
    for (const core::MagStatic& st : statics) {
      const Eigen::Vector3d up = st.specific_force.normalized();
      list.push_back({{"start", log.t(st.first)},
                      {"end", log.t(st.last)},
                      {"samples", st.last - st.first + 1},
                      {"up", {up(0), up(1), up(2)}}});
    }
    // The median raw magnitude (the hard iron shifts it by its size; a unit error by 10-1000).
    std::vector<double> norms(static_cast<size_t>(log.mag.rows()));
    for (Eigen::Index i = 0; i < log.mag.rows(); ++i) {
      norms[static_cast<size_t>(i)] =
          log.mag.block(i, 3 * static_cast<Eigen::Index>(k), 1, 3).norm();
    }
    std::nth_element(norms.begin(), norms.begin() + static_cast<std::ptrdiff_t>(norms.size() / 2),
                     norms.end());
    const double median = norms.empty() ? NAN : norms[norms.size() / 2];
    const double field = median * c.options.microtesla_per_unit;
    json units = json::array();
    if (!(field >= 0.5 * min_field && field <= 2 * max_field)) {
      units.push_back(
          {{"quantity", "magnetometer"},
           {"key", "mag_unit"},
           {"message",
            "the median |reading| is " + Fmt(field) + " uT with mag_unit \"" + c.unit_text +
                "\", far from the Earth's field (" + Fmt(min_field) + "-" + Fmt(max_field) +
                " uT)" +
                FieldUnitHint(field, c.options.microtesla_per_unit, min_field, max_field)}});
    }
    // The fit's first coverage stage (core/mag.h step 5, checked first): a planar log fails.
    const Eigen::Matrix3Xd y = log.mag.middleCols(3 * static_cast<Eigen::Index>(k), 3).transpose();
    const Status planar = core::CheckMagReadingsNotPlanar(y, c.options);
    if (!planar.ok() && !check->contains("job_would_fail")) {
      (*check)["job_would_fail"] =
          log.mag_names.size() == 1 ? planar.message()
                                    : "magnetometer " + log.mag_names[k] + ": " + planar.message();
    }
    mags.push_back(
        {{"name", log.mag_names[k]},
         {"readings_planar", !planar.ok()},
         {"samples", log.mag.rows()},
         {"accelerometer", a >= 0 ? json(log.accel_names[static_cast<size_t>(a)]) : json()},
         {"statics", list},
         {"alignment_statics_needed", needed},
         {"alignment_possible", static_cast<int>(statics.size()) >= needed},
         {"median_field", field},
         {"units", units},
         {"coverage", nullptr},
         {"disturbed_spans", nullptr},
         {"predicted", nullptr},
         {"notes",
          {"coverage: only the fit's first stage (readings close to a plane fail the job); the "
           "verdict and missing axes, and the disturbed spans, are found by the fit (they need "
           "the calibrated field directions and the residuals)",
           "predicted σ: not computed for mag (the turns' orientations are known only after the "
           "fit); see POST /plan"}}});
  }
  // The common keys (server/recording_check.h): the first magnetometer's statics, every unit.
  (*check)["statics"] = mags[0]["statics"];
  json& all_units = (*check)["units"];
  if (!all_units.is_array()) all_units = json::array();
  for (const json& m : mags) {
    for (const json& u : m["units"]) all_units.push_back(u);
  }
  (*check)["mags"] = mags;
  return Status::Ok();
}

std::function<Status(SimulatedFiles*)> Mag::AddSimulateOptions(CLI::App* command) const {
  auto o = std::make_shared<core::MagSimulationOptions>();
  auto disturbed = std::make_shared<int>(0);
  command->add_option("--seed", o->seed, "random seed")->capture_default_str();
  command->add_option("--rate", o->rate, "samples per second")
      ->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  command->add_option("--turns", o->turns, "orientations visited after the first")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  command->add_option("--statics", o->statics, "turns after which the device holds still")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  command->add_option("--field", o->field, "field magnitude, uT")
      ->check(CLI::Range(1.0, 1000.0))
      ->capture_default_str();
  command->add_option("--dip", o->dip, "dip (inclination), degrees, positive down")
      ->check(CLI::Range(-89.0, 89.0))
      ->capture_default_str();
  command->add_option("--noise", o->noise, "noise per axis, uT")->capture_default_str();
  command->add_option("--ar1", o->ar1, "AR(1) coefficient of the noise (0: white)")
      ->check(CLI::Range(0.0, 0.999))
      ->capture_default_str();
  command
      ->add_option("--max-tilt", o->max_tilt,
                   "largest tilt of the board from level, degrees (180: any orientation)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  command->add_flag("--yaw-only", o->yaw_only, "turn about the vertical only (poor coverage)");
  command
      ->add_option("--hard-iron-walk", o->hard_iron_walk,
                   "a hard iron that wanders: a random walk of this many uT/sqrt(s) per axis (the "
                   "truth is its log average)")
      ->check(CLI::Range(0.0, 10.0))
      ->capture_default_str();
  command
      ->add_option("--disturbances", *disturbed,
                   "spans of 3 s in which iron near the bench adds 15 uT")
      ->check(CLI::Range(0, 100))
      ->capture_default_str();
  return [o, disturbed](SimulatedFiles* files) {
    core::MagSimulationOptions options = *o;
    const double length = options.turns * options.turn_seconds;
    for (int j = 0; j < *disturbed; ++j) {
      const double start = length * (j + 0.5) / (*disturbed + 1);
      options.disturbances.push_back({start, start + 3, Eigen::Vector3d(15, -5, 8)});
    }
    return SimulateMagFiles(options, &files->csv, &files->config, &files->truth);
  };
}

}  // namespace

Status ReadMagPlanConfig(const json& config, MagPlanConfig* out) {
  MagConfig c;
  if (Status s = ParseMagConfig(config, &c); !s.ok()) return s;
  *out = c.plan;
  return Status::Ok();
}

Status SimulateMagFiles(const core::MagSimulationOptions& options, std::string* csv, json* config,
                        json* truth) {
  core::MagSimulation sim;
  const Status s = core::SimulateMag(options, &sim);
  if (!s.ok()) return s;
  csv->clear();
  *csv += "t,a0_x,a0_y,a0_z,m0_x,m0_y,m0_z\n";
  char line[320];
  for (Eigen::Index i = 0; i < sim.problem.t.size(); ++i) {
    const int n = std::snprintf(line, sizeof line, "%.10g,%.10g,%.10g,%.10g,%.10g,%.10g,%.10g\n",
                                sim.problem.t(i), sim.accel(0, i), sim.accel(1, i), sim.accel(2, i),
                                sim.problem.y(0, i), sim.problem.y(1, i), sim.problem.y(2, i));
    csv->append(line, static_cast<size_t>(n));
  }
  auto mat = [](const Eigen::Matrix3d& m) {
    json out = json::array();
    for (int r = 0; r < 3; ++r) out.push_back({m(r, 0), m(r, 1), m(r, 2)});
    return out;
  };
  *config = {{"method", "mag"}, {"field", sim.field}};
  *truth = {{"method", "mag"},
            {"seed", options.seed},
            {"hard_iron", {sim.hard_iron(0), sim.hard_iron(1), sim.hard_iron(2)}},
            {"soft_iron", mat(sim.soft_iron)},
            {"soft_iron_symmetric", mat(sim.soft_iron_symmetric)},
            {"alignment", mat(sim.alignment)},
            {"dip", sim.dip},
            {"field", sim.field}};
  return Status::Ok();
}

const Method& MagMethod() {
  static const Mag& method = *new Mag;  // never destroyed: worker threads may outlive exit
  return method;
}

}  // namespace calibd::server
