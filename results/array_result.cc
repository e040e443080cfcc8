#include "results/array_result.h"

#include <utility>

namespace calibd::results {
namespace {

using nlohmann::json;

json OptionalInt(const std::optional<int64_t>& v) { return v ? json(*v) : json(nullptr); }

json Figures(const SensorFigures& f) {
  return {{"accelerometer", Num(f.accelerometer)}, {"gyroscope", Num(f.gyroscope)}};
}

void ReadFigures(const JsonReader& r, const char* key, SensorFigures* out) {
  JsonReader f = r.Object(key);
  f.Read("accelerometer", &out->accelerometer);
  f.Read("gyroscope", &out->gyroscope);
}

// ---- parameters / uncertainty ----

json PositionsJson(const std::vector<ArrayPosition>& positions) {
  json out = json::array();
  for (const auto& p : positions)
    out.push_back({{"name", p.name}, {"position", Nums(p.position)}, {"offset", Nums(p.offset)}});
  return out;
}

json PositionStdsJson(const std::vector<ArrayPositionStd>& stds) {
  json out = json::array();
  for (const auto& s : stds) out.push_back({{"name", s.name}, {"std", Nums(s.std)}});
  return out;
}

json ParametersJson(const ArrayParameters& p, bool full) {
  json out = {{"reference", p.reference}, {"positions", PositionsJson(p.positions)}};
  if (full) {
    out["model"] = "full";
    json imus = json::array();
    for (const auto& imu : p.imus) {
      json e = json::object();
      WriteImuTriads(imu.triads, &e);
      e["position"] = Nums(imu.position);
      imus.push_back(std::move(e));
    }
    out["imus"] = std::move(imus);
  }
  return out;
}

json UncertaintyJson(const ArrayUncertainty& u, bool full) {
  json out = {{"positions", PositionStdsJson(u.positions)}};
  if (!full) {
    out["std_rms"] = Num(u.std_rms);
    return out;
  }
  json imus = json::array();
  for (const auto& s : u.imus) {
    json e = json::object();
    WriteImuTriads(s.triads, &e);
    e["position_std"] = Nums(s.position_std);
    if (s.robust) {
      e["robust"] = {{"accelerometer", ToJson(s.robust->accelerometer)},
                     {"gyroscope", ToJson(s.robust->gyroscope)},
                     {"position_std", Nums(s.robust->position_std)}};
    }
    imus.push_back(std::move(e));
  }
  out["imus"] = std::move(imus);
  return out;
}

void ReadParameters(const JsonReader& r, bool full, ArrayParameters* out) {
  r.Read("reference", &out->reference);
  r.ReadArray("positions", &out->positions, [](const JsonReader& e, ArrayPosition* p) {
    e.Read("name", &p->name);
    e.Read("position", &p->position);
    e.Read("offset", &p->offset);
  });
  if (!full) return;
  std::string model;
  r.Read("model", &model);
  if (r.ok() && model != "full") r.Fail("expected \"full\", found \"" + model + "\"", "model");
  r.ReadArray("imus", &out->imus, [](const JsonReader& e, ArrayImu* imu) {
    ReadImuTriads(e, &imu->triads);
    e.Read("position", &imu->position);
  });
}

void ReadUncertainty(const JsonReader& r, bool full, ArrayUncertainty* out) {
  r.ReadArray("positions", &out->positions, [](const JsonReader& e, ArrayPositionStd* s) {
    e.Read("name", &s->name);
    e.Read("std", &s->std);
  });
  if (!full) {
    r.Read("std_rms", &out->std_rms);
    return;
  }
  r.ReadArray("imus", &out->imus, [](const JsonReader& e, ArrayImuStd* s) {
    ReadImuTriads(e, &s->triads);
    e.Read("position_std", &s->position_std);
    if (std::optional<JsonReader> robust = e.OptionalObject("robust")) {
      ArrayImuRobustStd v;
      ReadTriad(*robust, "accelerometer", &v.accelerometer);
      ReadTriad(*robust, "gyroscope", &v.gyroscope);
      robust->Read("position_std", &v.position_std);
      if (robust->ok()) s->robust = std::move(v);
    }
  });
}

// ---- diagnostics, positions model ----

json ExcitationJson(const ArrayExcitation& e) {
  return {{"min_eigenvalue", Num(e.min_eigenvalue)},
          {"max_eigenvalue", Num(e.max_eigenvalue)},
          {"noise_floor", Num(e.noise_floor)},
          {"weakest_direction", Nums(e.weakest_direction)},
          {"verdict", e.verdict}};
}

json PositionsDiagnosticsJson(const ArrayPositionsDiagnostics& d, bool usable) {
  json out = {{"solver", d.solver},
              {"termination", d.termination},
              {"iterations", d.iterations},
              {"samples", d.samples},
              {"samples_dropped", d.samples_dropped},
              {"gyro_triads", d.gyro_triads},
              {"gyro_unit", d.gyro_unit},
              {"excitation", ExcitationJson(d.excitation)}};
  if (!usable) return out;
  out["converged"] = d.converged;
  out["cost"] = Nums(d.cost);
  out["residual_rms"] = Figures(d.residual_rms);
  out["noise_estimate"] = Figures(d.noise_estimate);
  out["noise_jobs"] = {{"accelerometer", OptionalInt(d.noise_jobs.accelerometer)},
                       {"gyroscope", OptionalInt(d.noise_jobs.gyroscope)}};
  out["noise_configured"] = Figures(d.noise_configured);
  out["parallel_fraction"] = Num(d.parallel_fraction);
  out["motion"] = {{"stride", d.motion.stride},
                   {"omega_norm", Nums(d.motion.omega_norm)},
                   {"omega_dot_norm", Nums(d.motion.omega_dot_norm)},
                   {"units",
                    {{"omega_norm", d.motion.omega_norm_unit},
                     {"omega_dot_norm", d.motion.omega_dot_norm_unit}}}};
  if (d.accelerometer_calibration) {
    const ArrayCalibrationUsed& c = *d.accelerometer_calibration;
    out["accelerometer_calibration"] = {{"job", OptionalInt(c.job)},
                                        {"sensors", c.sensors},
                                        {"frame", c.frame},
                                        {"bias", c.bias ? json(*c.bias) : json(nullptr)},
                                        {"magnitude", Num(c.magnitude)},
                                        {"max_condition_number", Num(c.max_condition_number)}};
  } else {
    out["accelerometer_calibration"] = nullptr;
  }
  return out;
}

void ReadPositionsDiagnostics(const JsonReader& r, bool usable, ArrayPositionsDiagnostics* d) {
  r.Read("solver", &d->solver);
  r.Read("termination", &d->termination);
  r.Read("iterations", &d->iterations);
  r.Read("samples", &d->samples);
  r.Read("samples_dropped", &d->samples_dropped);
  r.Read("gyro_triads", &d->gyro_triads);
  r.Read("gyro_unit", &d->gyro_unit);
  JsonReader e = r.Object("excitation");
  e.Read("min_eigenvalue", &d->excitation.min_eigenvalue);
  e.Read("max_eigenvalue", &d->excitation.max_eigenvalue);
  e.Read("noise_floor", &d->excitation.noise_floor);
  e.Read("weakest_direction", &d->excitation.weakest_direction);
  e.Read("verdict", &d->excitation.verdict);
  if (!usable) return;
  r.Read("converged", &d->converged);
  r.Read("cost", &d->cost);
  ReadFigures(r, "residual_rms", &d->residual_rms);
  ReadFigures(r, "noise_estimate", &d->noise_estimate);
  JsonReader jobs = r.Object("noise_jobs");
  jobs.Read("accelerometer", &d->noise_jobs.accelerometer);
  jobs.Read("gyroscope", &d->noise_jobs.gyroscope);
  ReadFigures(r, "noise_configured", &d->noise_configured);
  r.Read("parallel_fraction", &d->parallel_fraction);
  JsonReader m = r.Object("motion");
  m.Read("stride", &d->motion.stride);
  m.Read("omega_norm", &d->motion.omega_norm);
  m.Read("omega_dot_norm", &d->motion.omega_dot_norm);
  JsonReader units = m.Object("units");
  units.Read("omega_norm", &d->motion.omega_norm_unit);
  units.Read("omega_dot_norm", &d->motion.omega_dot_norm_unit);
  // Required, null when the config had no accelerometer_calibration.
  if (r.ok() && !r.node().contains("accelerometer_calibration"))
    r.Fail("missing", "accelerometer_calibration");
  if (std::optional<JsonReader> c = r.OptionalObject("accelerometer_calibration")) {
    ArrayCalibrationUsed v;
    c->Read("job", &v.job);
    c->Read("sensors", &v.sensors);
    c->Read("frame", &v.frame);
    c->Read("bias", &v.bias);
    c->Read("magnitude", &v.magnitude);
    c->Read("max_condition_number", &v.max_condition_number);
    if (c->ok()) d->accelerometer_calibration = std::move(v);
  }
}

// ---- diagnostics, full model ----

json RotationJson(const ArrayRotationExcitation& e, bool usable) {
  json out = {{"eigenvalues", Nums(e.eigenvalues)},
              {"noise_floor", Num(e.noise_floor)},
              {"weakest_axis", Nums(e.weakest_axis)},
              {"verdict", e.verdict}};
  if (usable) out["units"] = e.units;
  return out;
}

json FullDiagnosticsJson(const ArrayFullDiagnostics& d, bool usable) {
  json out = {{"model", "full"},
              {"termination", d.termination},
              {"iterations", d.iterations},
              {"statics", d.statics},
              {"static_samples", d.static_samples},
              {"dynamic_samples", d.dynamic_samples},
              {"null_directions", d.null_directions}};
  if (!usable) {
    out["rotation"] = RotationJson(d.rotation_excitation, false);
    return out;
  }
  out["rotation_excitation"] = RotationJson(d.rotation_excitation, true);
  out["gauge"] = {{"scale", d.gauge.scale},
                  {"reference", d.gauge.reference},
                  {"description", d.gauge.description}};
  out["solver"] = d.solver;
  out["converged"] = d.converged;
  out["cost"] = Nums(d.cost);
  out["samples_dropped"] = d.samples_dropped;
  out["dof"] = d.dof;
  out["chi2_per_dof"] = Num(d.chi2_per_dof);
  out["gyro_unit"] = d.gyro_unit;
  out["noise"] = {{"accelerometer", Num(d.noise.accelerometer)},
                  {"gyroscope", Num(d.noise.gyroscope)},
                  {"source", d.noise.source},
                  {"dynamic_weighting", d.noise.dynamic_weighting},
                  {"dynamic_accelerometer", Num(d.noise.dynamic_accelerometer)},
                  {"dynamic_gyroscope", Num(d.noise.dynamic_gyroscope)}};
  out["static_noise"] = Figures(d.static_noise);
  json imus = json::array();
  for (const auto& i : d.residual_rms_imus)
    imus.push_back(
        {{"name", i.name}, {"static", Figures(i.static_rms)}, {"dynamic", Figures(i.dynamic_rms)}});
  out["residual_rms"] = {{"dynamic", Figures(d.residual_rms_dynamic)}, {"imus", std::move(imus)}};
  json offsets = json::array();
  for (const auto& o : d.time_offsets.offsets_ms)
    offsets.push_back({{"name", o.name}, {"offset", Num(o.offset)}});
  out["time_offsets"] = {
      {"offsets_ms", std::move(offsets)},
      {"explained_fraction", Num(d.time_offsets.explained_fraction)},
      {"per_sample_rms_ms", Num(d.time_offsets.per_sample_rms_ms)},
      {"per_sample_explained_fraction", Num(d.time_offsets.per_sample_explained_fraction)},
      {"note", d.time_offsets.note}};
  out["robust"] = {{"used", d.robust.used},
                   {"batches", d.robust.batches},
                   {"batch_seconds", Num(d.robust.batch_seconds)},
                   {"ratio", Num(d.robust.ratio)}};
  out["positions_only_start"] = d.positions_only_start;
  json changed = json::array();
  for (const auto& c : d.changed_from_positions_only) {
    json e = {{"name", c.name},
              {"positions_only", Nums(c.positions_only)},
              {"position_change", Nums(c.position_change)},
              {"position_change_norm", Num(c.position_change_norm)},
              {"position_change_sigma", Nums(c.position_change_sigma)}};
    if (c.positions_only_std) e["positions_only_std"] = Nums(*c.positions_only_std);
    changed.push_back(std::move(e));
  }
  out["changed_from_positions_only"] = std::move(changed);
  return out;
}

void ReadRotation(const JsonReader& r, const char* key, bool usable, ArrayRotationExcitation* e) {
  JsonReader x = r.Object(key);
  x.Read("eigenvalues", &e->eigenvalues);
  x.Read("noise_floor", &e->noise_floor);
  x.Read("weakest_axis", &e->weakest_axis);
  x.Read("verdict", &e->verdict);
  if (usable) x.Read("units", &e->units);
}

void ReadFullDiagnostics(const JsonReader& r, bool usable, ArrayFullDiagnostics* d) {
  r.Read("termination", &d->termination);
  r.Read("iterations", &d->iterations);
  r.Read("statics", &d->statics);
  r.Read("static_samples", &d->static_samples);
  r.Read("dynamic_samples", &d->dynamic_samples);
  r.Read("null_directions", &d->null_directions);
  if (!usable) {
    ReadRotation(r, "rotation", false, &d->rotation_excitation);
    return;
  }
  ReadRotation(r, "rotation_excitation", true, &d->rotation_excitation);
  JsonReader g = r.Object("gauge");
  g.Read("scale", &d->gauge.scale);
  g.Read("reference", &d->gauge.reference);
  g.Read("description", &d->gauge.description);
  r.Read("solver", &d->solver);
  r.Read("converged", &d->converged);
  r.Read("cost", &d->cost);
  r.Read("samples_dropped", &d->samples_dropped);
  r.Read("dof", &d->dof);
  r.Read("chi2_per_dof", &d->chi2_per_dof);
  r.Read("gyro_unit", &d->gyro_unit);
  JsonReader n = r.Object("noise");
  n.Read("accelerometer", &d->noise.accelerometer);
  n.Read("gyroscope", &d->noise.gyroscope);
  n.Read("source", &d->noise.source);
  n.Read("dynamic_weighting", &d->noise.dynamic_weighting);
  n.Read("dynamic_accelerometer", &d->noise.dynamic_accelerometer);
  n.Read("dynamic_gyroscope", &d->noise.dynamic_gyroscope);
  ReadFigures(r, "static_noise", &d->static_noise);
  JsonReader rms = r.Object("residual_rms");
  ReadFigures(rms, "dynamic", &d->residual_rms_dynamic);
  rms.ReadArray("imus", &d->residual_rms_imus, [](const JsonReader& e, ArrayImuResiduals* i) {
    e.Read("name", &i->name);
    ReadFigures(e, "static", &i->static_rms);
    ReadFigures(e, "dynamic", &i->dynamic_rms);
  });
  JsonReader t = r.Object("time_offsets");
  t.ReadArray("offsets_ms", &d->time_offsets.offsets_ms,
              [](const JsonReader& e, ArrayTimeOffset* o) {
                e.Read("name", &o->name);
                e.Read("offset", &o->offset);
              });
  t.Read("explained_fraction", &d->time_offsets.explained_fraction);
  t.Read("per_sample_rms_ms", &d->time_offsets.per_sample_rms_ms);
  t.Read("per_sample_explained_fraction", &d->time_offsets.per_sample_explained_fraction);
  t.Read("note", &d->time_offsets.note);
  JsonReader b = r.Object("robust");
  b.Read("used", &d->robust.used);
  b.Read("batches", &d->robust.batches);
  b.Read("batch_seconds", &d->robust.batch_seconds);
  b.Read("ratio", &d->robust.ratio);
  r.Read("positions_only_start", &d->positions_only_start);
  r.ReadArray("changed_from_positions_only", &d->changed_from_positions_only,
              [](const JsonReader& e, ArrayPositionChange* c) {
                e.Read("name", &c->name);
                e.Read("positions_only", &c->positions_only);
                e.Read("positions_only_std", &c->positions_only_std);
                e.Read("position_change", &c->position_change);
                e.Read("position_change_norm", &c->position_change_norm);
                e.Read("position_change_sigma", &c->position_change_sigma);
              });
}

}  // namespace

json ToJson(const ArrayResult& r) {
  json out = json::object();
  WriteEnvelope(r.envelope, kArraySchemaVersion, &out);
  const bool usable = r.envelope.usable;
  if (usable && r.parameters) out["parameters"] = ParametersJson(*r.parameters, r.full);
  if (usable && r.uncertainty) out["uncertainty"] = UncertaintyJson(*r.uncertainty, r.full);
  out["diagnostics"] = r.full ? FullDiagnosticsJson(r.full_diagnostics, usable)
                              : PositionsDiagnosticsJson(r.diagnostics, usable);
  return out;
}

Status FromJson(const json& doc, ArrayResult* out) {
  if (!doc.is_object())
    return Status::InvalidInput("array result: expected an object, found " +
                                JsonReader::TypeName(doc));
  JsonReader r(doc, "array result");
  ArrayResult v;
  ReadEnvelope(r, "array", kArraySchemaVersion, &v.envelope);
  const bool usable = v.envelope.usable;
  JsonReader diag = r.Object("diagnostics");
  std::optional<std::string> model;
  diag.Read("model", &model);
  if (model && *model != "full")
    diag.Fail("expected \"full\" or no model (the positions model), found \"" + *model + "\"",
              "model");
  v.full = model.has_value();
  if (usable) {
    ArrayParameters p;
    ReadParameters(r.Object("parameters"), v.full, &p);
    ArrayUncertainty u;
    ReadUncertainty(r.Object("uncertainty"), v.full, &u);
    v.parameters = std::move(p);
    v.uncertainty = std::move(u);
  }
  if (v.full)
    ReadFullDiagnostics(diag, usable, &v.full_diagnostics);
  else
    ReadPositionsDiagnostics(diag, usable, &v.diagnostics);
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
