#include "methods/imu/imu_result.h"

#include <algorithm>
#include <utility>

namespace calibd::results {

using nlohmann::json;

namespace {

json Ids(const std::optional<int64_t>& id) { return id ? json(*id) : json(nullptr); }

json NoiseModelJson(const std::optional<ImuNoiseModel>& m) {
  if (!m) return nullptr;
  return {{"job", Ids(m->job)},
          {"white_noise", Num(m->white_noise)},
          {"random_walk", Num(m->random_walk)}};
}

// diagnostics.units: the unit of every number in the diagnostics, by key (an extension; the
// members not listed are counts, flags, texts or named ratios such as chi2_per_dof).
json DiagnosticsUnits() {
  const char* accel_reading = "accelerometer reading units (parameters.accel_unit SI per unit)";
  const char* gyro_reading = "gyroscope reading units (parameters.gyro_unit SI per unit)";
  return {{"statics[].start, end", "s"},
          {"static_window, min_static", "s"},
          {"gaps[].start, end", "s"},
          {"imus[].statics[].start, end", "s"},
          {"imus[].rotations[].start, end", "s"},
          {"rate", "Hz"},
          {"imus[].statics[].accel_mean, accel_std", accel_reading},
          {"imus[].statics[].gyro_mean, gyro_std", gyro_reading},
          {"imus[].statics[].gravity_direction", "unit vector in the body frame, calibrated"},
          {"imus[].statics[].norm_residual_before, norm_residual_after", "m/s^2 (|a| - g)"},
          {"imus[].rotations[].angle, direction_error_before, direction_error_after", "rad"},
          {"imus[].noise.accelerometer", "m/s^2 (σ per axis per sample)"},
          {"imus[].noise.gyroscope", "rad/s (σ per axis per sample)"},
          {"imus[].residuals.accel_norm_rms_before, accel_norm_rms_after", "m/s^2"},
          {"imus[].residuals.gyro_direction_rms_before, gyro_direction_rms_after", "rad"},
          {"imus[].coverage.gravity_eigenvalues, min_eigenvalue",
           "dimensionless: eigenvalues of (3/n) Σ u uᵀ of unit gravity directions, all 1 for an "
           "even spread"},
          {"imus[].coverage.rotation_per_axis", "rad (∫|ω| dt per body axis)"},
          {"imus[].coverage.least_covered_direction", "unit vector, body frame"},
          {"imus[].cost", "dimensionless: ½χ² of the whitened residuals"},
          {"noise_model.*.white_noise", "m/s^2/√Hz (accelerometer), rad/s/√Hz (gyroscope)"},
          {"noise_model.*.random_walk", "m/s^2/s/√Hz (accelerometer), rad/s/s/√Hz (gyroscope)"}};
}

json FitJson(const ImuFitDiagnostics& f) {
  json statics = json::array(), rotations = json::array(), trials = json::array();
  for (const ImuStatic& s : f.statics) {
    statics.push_back({{"start", Num(s.start)},
                       {"end", Num(s.end)},
                       {"samples", s.samples},
                       {"accel_mean", Nums(s.accel_mean)},
                       {"accel_std", Nums(s.accel_std)},
                       {"gyro_mean", Nums(s.gyro_mean)},
                       {"gyro_std", Nums(s.gyro_std)},
                       {"gravity_direction", Nums(s.gravity_direction)},
                       {"norm_residual_before", Num(s.norm_residual_before)},
                       {"norm_residual_after", Num(s.norm_residual_after)}});
  }
  for (const ImuRotation& q : f.rotations) {
    rotations.push_back({{"from", q.from},
                         {"to", q.to},
                         {"start", Num(q.start)},
                         {"end", Num(q.end)},
                         {"angle", Num(q.angle)},
                         {"direction_error_before", Num(q.direction_error_before)},
                         {"direction_error_after", Num(q.direction_error_after)},
                         {"used", q.used},
                         {"excluded", q.excluded}});
  }
  for (const ImuThresholdTrial& t : f.threshold_trials) {
    trials.push_back({{"multiplier", Num(t.multiplier)},
                      {"statics", t.statics},
                      {"accel_chi2_per_dof", Num(t.accel_chi2_per_dof)},
                      {"chosen", t.chosen}});
  }
  const ImuCoverage& c = f.coverage;
  return {{"name", f.name},
          {"usable", f.usable},
          {"termination", f.termination},
          {"reason", f.reason},
          {"chi2_per_dof", Num(f.chi2_per_dof)},
          {"degrees_of_freedom", f.degrees_of_freedom},
          {"iterations",
           {{"accelerometer", f.accel_iterations},
            {"gyroscope", f.gyro_iterations},
            {"joint", f.joint_iterations}}},
          {"noise", {{"accelerometer", Nums(f.accel_noise)}, {"gyroscope", Nums(f.gyro_noise)}}},
          {"residuals",
           {{"accel_norm_rms_before", Num(f.accel_norm_rms_before)},
            {"accel_norm_rms_after", Num(f.accel_norm_rms_after)},
            {"gyro_direction_rms_before", Num(f.gyro_direction_rms_before)},
            {"gyro_direction_rms_after", Num(f.gyro_direction_rms_after)}}},
          {"statics", std::move(statics)},
          {"rotations", std::move(rotations)},
          {"coverage",
           {{"gravity_eigenvalues", Nums(c.gravity_eigenvalues)},
            {"min_eigenvalue", Num(c.min_eigenvalue)},
            {"least_covered_direction", Nums(c.least_covered_direction)},
            {"missing_up", c.missing_up},
            {"rotation_per_axis", Nums(c.rotation_per_axis)},
            {"weak_axes", c.weak_axes},
            {"sufficient", c.sufficient},
            {"verdict", c.verdict}}},
          {"threshold_trials", std::move(trials)},
          {"threshold_choice", f.threshold_choice},
          {"cost", Nums(f.cost)}};
}

// One IMU's fit diagnostics. SPEC §7 requires its statics (start, end, samples, per-channel mean
// and std), rotations (angle, direction error before and after), coverage (the verdict) and
// residuals; every other member is an extension (absent in a result of an earlier calibd: the
// struct's default). `usable` absent: the document's own usable.
void ReadFit(const JsonReader& e, bool document_usable, ImuFitDiagnostics* f) {
  f->usable = document_usable;
  e.ReadExtension("name", &f->name);
  e.ReadExtension("usable", &f->usable);
  e.ReadExtension("termination", &f->termination);
  e.ReadExtension("reason", &f->reason);
  e.ReadExtension("chi2_per_dof", &f->chi2_per_dof);
  e.ReadExtension("degrees_of_freedom", &f->degrees_of_freedom);
  if (e.Present("iterations")) {
    const JsonReader it = e.Object("iterations");
    it.ReadExtension("accelerometer", &f->accel_iterations);
    it.ReadExtension("gyroscope", &f->gyro_iterations);
    it.ReadExtension("joint", &f->joint_iterations);
  }
  if (e.Present("noise")) {
    const JsonReader noise = e.Object("noise");
    noise.ReadExtension("accelerometer", &f->accel_noise);
    noise.ReadExtension("gyroscope", &f->gyro_noise);
  }
  const JsonReader res = e.Object("residuals");
  res.Read("accel_norm_rms_before", &f->accel_norm_rms_before);
  res.Read("accel_norm_rms_after", &f->accel_norm_rms_after);
  res.Read("gyro_direction_rms_before", &f->gyro_direction_rms_before);
  res.Read("gyro_direction_rms_after", &f->gyro_direction_rms_after);
  e.ReadArray("statics", &f->statics, [](const JsonReader& s, ImuStatic* x) {
    s.Read("start", &x->start);
    s.Read("end", &x->end);
    s.Read("samples", &x->samples);
    s.Read("accel_mean", &x->accel_mean);
    s.Read("accel_std", &x->accel_std);
    s.Read("gyro_mean", &x->gyro_mean);
    s.Read("gyro_std", &x->gyro_std);
    s.ReadExtension("gravity_direction", &x->gravity_direction);
    s.ReadExtension("norm_residual_before", &x->norm_residual_before);
    s.ReadExtension("norm_residual_after", &x->norm_residual_after);
  });
  e.ReadArray("rotations", &f->rotations, [](const JsonReader& q, ImuRotation* x) {
    q.ReadExtension("from", &x->from);
    q.ReadExtension("to", &x->to);
    q.ReadExtension("start", &x->start);
    q.ReadExtension("end", &x->end);
    q.Read("angle", &x->angle);
    q.Read("direction_error_before", &x->direction_error_before);
    q.Read("direction_error_after", &x->direction_error_after);
    q.ReadExtension("used", &x->used);
    q.ReadExtension("excluded", &x->excluded);
  });
  const JsonReader c = e.Object("coverage");
  c.ReadExtension("gravity_eigenvalues", &f->coverage.gravity_eigenvalues);
  c.ReadExtension("min_eigenvalue", &f->coverage.min_eigenvalue);
  c.ReadExtension("least_covered_direction", &f->coverage.least_covered_direction);
  c.ReadExtension("missing_up", &f->coverage.missing_up);
  c.ReadExtension("rotation_per_axis", &f->coverage.rotation_per_axis);
  c.ReadExtension("weak_axes", &f->coverage.weak_axes);
  c.ReadExtension("sufficient", &f->coverage.sufficient);
  c.Read("verdict", &f->coverage.verdict);
  e.ReadArrayExtension("threshold_trials", &f->threshold_trials,
                       [](const JsonReader& t, ImuThresholdTrial* x) {
                         t.ReadExtension("multiplier", &x->multiplier);
                         t.ReadExtension("statics", &x->statics);
                         t.ReadExtension("accel_chi2_per_dof", &x->accel_chi2_per_dof);
                         t.ReadExtension("chosen", &x->chosen);
                       });
  e.ReadExtension("threshold_choice", &f->threshold_choice);
  e.ReadExtension("cost", &f->cost);
}

// An optional noise-model entry: null or absent is nullopt.
void ReadNoiseModel(const JsonReader& r, const char* key, std::optional<ImuNoiseModel>* out) {
  out->reset();
  if (std::optional<JsonReader> m = r.OptionalObject(key)) {
    ImuNoiseModel v;
    m->Read("job", &v.job);
    m->ReadExtension("white_noise", &v.white_noise);
    m->ReadExtension("random_walk", &v.random_walk);
    *out = v;
  }
}

// An optional number that, when present, may be null (NaN): present-and-null stays present, so
// the document writes back as it was.
void ReadPresent(const JsonReader& r, const char* key, std::optional<double>* out) {
  out->reset();
  if (!r.node().is_object() || !r.node().contains(key)) return;
  double v = 0;
  r.Read(key, &v);
  *out = v;
}

}  // namespace

json ToJson(const ImuResult& r) {
  json out = json::object();
  WriteEnvelope(r.envelope, kImuSchemaVersion, &out);
  if (r.parameters) {
    const ImuParameters& p = *r.parameters;
    json imus = json::array();
    for (const ImuTriads& t : p.imus) {
      json e = json::object();
      WriteImuTriads(t, &e);
      imus.push_back(std::move(e));
    }
    json params = {{"gravity", Num(p.gravity)}, {"gyro_bias", p.gyro_bias}, {"imus", imus}};
    if (p.accel_unit) params["accel_unit"] = Num(*p.accel_unit);
    if (p.gyro_unit) params["gyro_unit"] = Num(*p.gyro_unit);
    out["parameters"] = std::move(params);
  }
  if (r.uncertainty) {
    const ImuUncertainty& u = *r.uncertainty;
    json imus = json::array();
    for (size_t i = 0; i < u.imus.size(); ++i) {
      json e = json::object();
      WriteImuTriads(u.imus[i], &e);
      if (i < u.crb.size()) {
        e["crb"] = {{"accelerometer", ToJson(u.crb[i].accelerometer)},
                    {"gyroscope", ToJson(u.crb[i].gyroscope)}};
      }
      imus.push_back(std::move(e));
    }
    out["uncertainty"] = {{"imus", std::move(imus)}};
    if (u.basis != "crb_only") {
      out["uncertainty"]["basis"] = u.basis;
      out["uncertainty"]["chi2_per_dof"] = Num(u.chi2_per_dof);
    }
  }
  const ImuDiagnostics& d = r.diagnostics;
  json statics = json::array(), fits = json::array();
  for (const ImuInterval& s : d.statics) {
    statics.push_back({{"start", Num(s.start)}, {"end", Num(s.end)}, {"samples", s.samples}});
  }
  for (const ImuFitDiagnostics& f : d.imus) fits.push_back(FitJson(f));
  json diag = {{"statics", std::move(statics)},
               {"static_window", Num(d.static_window)},
               {"min_static", Num(d.min_static)},
               {"threshold_choice", d.threshold_choice},
               {"imus", std::move(fits)}};
  if (d.rate) diag["rate"] = Num(*d.rate);
  if (d.gaps) {
    json gaps = json::array();
    for (const ImuGap& g : *d.gaps) {
      gaps.push_back({{"index", g.index}, {"start", Num(g.start)}, {"end", Num(g.end)}});
    }
    diag["gaps"] = std::move(gaps);
  }
  if (d.noise_jobs) {
    diag["noise_jobs"] = {{"accelerometer", Ids(d.noise_jobs->accelerometer)},
                          {"gyroscope", Ids(d.noise_jobs->gyroscope)}};
  }
  if (d.noise_model) {
    diag["noise_model"] = {{"accelerometer", NoiseModelJson(d.noise_model->accelerometer)},
                           {"gyroscope", NoiseModelJson(d.noise_model->gyroscope)}};
  }
  if (d.saturated_samples) diag["saturated_samples"] = *d.saturated_samples;
  if (d.saturation) diag["saturation"] = ToJson(*d.saturation);
  diag["units"] = DiagnosticsUnits();
  for (const std::string& key : r.dropped) diag.erase(key);  // left out by the trimming
  if (!ContainsKey(r.dropped, "diagnostics")) out["diagnostics"] = std::move(diag);
  if (r.trimmed) out["trimmed"] = *r.trimmed;
  return out;
}

Status FromJson(const json& doc, ImuResult* out) {
  JsonReader r(doc, "imu result");
  if (!doc.is_object()) {
    r.Fail("expected an object, found " + JsonReader::TypeName(doc));
    return r.status();
  }
  ImuResult v;
  ReadEnvelope(r, "imu", kImuSchemaVersion, &v.envelope);
  if (r.ok() && v.envelope.usable) {
    const JsonReader p = r.Object("parameters");
    ImuParameters params;
    p.ReadExtension("gravity", &params.gravity);
    p.ReadExtension("gyro_bias", &params.gyro_bias);
    ReadPresent(p, "accel_unit", &params.accel_unit);
    ReadPresent(p, "gyro_unit", &params.gyro_unit);
    p.ReadArray("imus", &params.imus,
                [](const JsonReader& e, ImuTriads* t) { ReadImuTriads(e, t); });
    v.parameters = std::move(params);
    const JsonReader u = r.Object("uncertainty");
    ImuUncertainty unc;
    u.ReadArray("imus", &unc.imus, [&unc](const JsonReader& e, ImuTriadsStd* t) {
      ReadImuTriads(e, t);
      if (!e.Has("crb")) return;
      const JsonReader c = e.Object("crb");
      ImuTriadsStd crb{t->name, {}, {}};
      ReadTriad(c, "accelerometer", &crb.accelerometer);
      ReadTriad(c, "gyroscope", &crb.gyroscope);
      unc.crb.push_back(std::move(crb));
    });
    // Without basis: stored by an earlier calibd, its σ the CRB ("crb_only", the default).
    u.ReadExtension("basis", &unc.basis);
    u.ReadExtension("chi2_per_dof", &unc.chi2_per_dof);
    if (r.ok() && !unc.crb.empty() && unc.crb.size() != unc.imus.size()) {
      u.Fail("crb in " + std::to_string(unc.crb.size()) + " of " + std::to_string(unc.imus.size()) +
                 " IMUs",
             "imus");
    }
    if (r.ok() && unc.imus.size() != v.parameters->imus.size()) {
      u.Fail(std::to_string(v.parameters->imus.size()) + " IMUs in parameters but " +
                 std::to_string(unc.imus.size()) + " here",
             "imus");
    }
    v.uncertainty = std::move(unc);
  }
  if (r.ok() && !v.envelope.usable) ReadTrimmed(r, &v.trimmed, &v.dropped);
  // A partial document (usable false) may lack the diagnostics or any member of them (the
  // worker leaves out the largest when over its cap): all optional there.
  const bool partial = !v.envelope.usable;
  if (partial && !r.Has("diagnostics")) {
    // Trimmed to the bare envelope (or written without diagnostics): none to read.
  } else {
    const JsonReader d = r.Object("diagnostics");
    ImuDiagnostics& g = v.diagnostics;
    // SPEC's members: required in a result, optional in a partial document; members the
    // trimming set to null (documents trimmed before they were left out) are skipped.
    auto keep = [&](const char* key) {
      return !DroppedMember(d, v.dropped, key) && (!partial || d.Present(key));
    };
    auto read_statics = [](const JsonReader& s, ImuInterval* x) {
      s.Read("start", &x->start);
      s.Read("end", &x->end);
      s.Read("samples", &x->samples);
    };
    if (keep("statics")) d.ReadArray("statics", &g.statics, read_statics);
    if (keep("threshold_choice")) d.Read("threshold_choice", &g.threshold_choice);
    if (keep("imus")) {
      d.ReadArray("imus", &g.imus, [&](const JsonReader& e, ImuFitDiagnostics* f) {
        ReadFit(e, v.envelope.usable, f);
      });
    }
    // Extensions (absent in results of an earlier calibd).
    if (!DroppedMember(d, v.dropped, "rate")) ReadPresent(d, "rate", &g.rate);
    if (!DroppedMember(d, v.dropped, "gaps") && d.Has("gaps")) {
      std::vector<ImuGap> gaps;
      d.ReadArray("gaps", &gaps, [](const JsonReader& e, ImuGap* x) {
        e.ReadExtension("index", &x->index);
        e.ReadExtension("start", &x->start);
        e.ReadExtension("end", &x->end);
      });
      g.gaps = std::move(gaps);
    }
    if (std::optional<JsonReader> jobs = d.OptionalObject("noise_jobs")) {
      ImuDiagnostics::NoiseJobs n;
      jobs->Read("accelerometer", &n.accelerometer);
      jobs->Read("gyroscope", &n.gyroscope);
      g.noise_jobs = n;
    }
    if (std::optional<JsonReader> model = d.OptionalObject("noise_model")) {
      ImuDiagnostics::NoiseModels n;
      ReadNoiseModel(*model, "accelerometer", &n.accelerometer);
      ReadNoiseModel(*model, "gyroscope", &n.gyroscope);
      g.noise_model = n;
    }
    d.Read("saturated_samples", &g.saturated_samples);
    ReadSaturation(d, &g.saturation);
    if (!DroppedMember(d, v.dropped, "static_window")) {
      d.ReadExtension("static_window", &g.static_window);
    }
    if (!DroppedMember(d, v.dropped, "min_static")) d.ReadExtension("min_static", &g.min_static);
    // Diagnostics written without the IMUs' names (an earlier calibd): the parameters' names.
    for (size_t i = 0; i < g.imus.size(); ++i) {
      if (!g.imus[i].name.empty() || !d.node().contains("imus")) continue;
      if (d.node().at("imus").at(i).contains("name")) continue;
      g.imus[i].name = v.parameters && i < v.parameters->imus.size() ? v.parameters->imus[i].name
                                                                     : std::to_string(i);
    }
  }
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
