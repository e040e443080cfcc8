#include "methods/array/array_result.h"

#include <utility>

namespace calibd::results {
namespace {

using nlohmann::json;

json OptionalInt(const std::optional<int64_t>& v) { return v ? json(*v) : json(nullptr); }

// Member `key` of *out when the count is known (an absent count is left out).
template <class T>
void PutCount(json* out, const char* key, const std::optional<T>& v) {
  if (v) (*out)[key] = *v;
}

// An extension member (JsonReader::ReadExtension): absent, *out keeps its default. Null too:
// every default is what null reads as (NaN, an empty string or list, nullopt), and the worker
// used to write the partial diagnostics' members it left out as null.
template <class T>
void Ext(const JsonReader& r, std::string_view key, T* out) {
  if (r.Has(key)) r.ReadExtension(key, out);
}
template <class T, class F>
void ExtArray(const JsonReader& r, std::string_view key, std::vector<T>* out, F read_one) {
  if (r.Has(key)) r.ReadArrayExtension(key, out, read_one);
}

// A member SPEC requires when `required` (a usable result), else an extension (kept at its
// default when absent: results of an earlier calibd, partial documents).
template <class T>
void ReadMember(const JsonReader& r, bool required, std::string_view key, T* out) {
  if (required)
    r.Read(key, out);
  else
    Ext(r, key, out);
}
// The same into a std::optional: required, the member must be there (not null); else nullopt
// stays when it is absent.
template <class T>
void ReadMember(const JsonReader& r, bool required, std::string_view key, std::optional<T>* out) {
  if (!required && !r.Has(key)) return;
  T value{};
  const bool was_ok = r.ok();
  r.Read(key, &value);
  if (was_ok && r.ok()) *out = std::move(value);
}

// A reader of member `key` when it must be an object (required), else when it is present
// (nullopt when an extension object is absent or null: its members keep their defaults).
std::optional<JsonReader> MemberObject(const JsonReader& r, bool required, std::string_view key) {
  if (required || r.Has(key)) return r.Object(key);
  return std::nullopt;
}

json Figures(const SensorFigures& f) {
  return {{"accelerometer", Num(f.accelerometer)}, {"gyroscope", Num(f.gyroscope)}};
}

// {"accelerometer", "gyroscope"} at `key`: required (both members) or an extension (each member
// NaN when absent).
void ReadFigures(const JsonReader& r, const char* key, SensorFigures* out, bool required = true) {
  const std::optional<JsonReader> f = MemberObject(r, required, key);
  if (!f) return;
  ReadMember(*f, required, "accelerometer", &out->accelerometer);
  ReadMember(*f, required, "gyroscope", &out->gyroscope);
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
  for (const auto& s : stds) {
    json e = {{"name", s.name}, {"std", Nums(s.std)}};
    if (s.crb) e["crb"] = {{"std", Nums(*s.crb)}};
    out.push_back(std::move(e));
  }
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
  json out = {{"basis", u.basis},
              {"chi2_per_dof", Num(u.chi2_per_dof)},
              {"positions", PositionStdsJson(u.positions)}};
  if (!full) {
    out["std_rms"] = Num(u.std_rms);
    return out;
  }
  json imus = json::array();
  for (const auto& s : u.imus) {
    json e = json::object();
    WriteImuTriads(s.triads, &e);
    e["position_std"] = Nums(s.position_std);
    if (s.crb) {
      e["crb"] = {{"accelerometer", ToJson(s.crb->accelerometer)},
                  {"gyroscope", ToJson(s.crb->gyroscope)},
                  {"position_std", Nums(s.crb->position_std)}};
    }
    imus.push_back(std::move(e));
  }
  out["imus"] = std::move(imus);
  return out;
}

// parameters.positions (SPEC for the positions model; for the full model an extension, derived
// from parameters.imus when absent).
void ReadParameters(const JsonReader& r, bool full, ArrayParameters* out) {
  r.Read("reference", &out->reference);
  auto read_position = [](const JsonReader& e, ArrayPosition* p) {
    e.Read("name", &p->name);
    e.Read("position", &p->position);
    e.Read("offset", &p->offset);
  };
  if (!full) {
    r.ReadArray("positions", &out->positions, read_position);
    return;
  }
  std::optional<std::string> model;
  Ext(r, "model", &model);
  if (r.ok() && model && *model != "full")
    r.Fail("expected \"full\", found \"" + *model + "\"", "model");
  r.ReadArray("imus", &out->imus, [](const JsonReader& e, ArrayImu* imu) {
    ReadImuTriads(e, &imu->triads);
    e.Read("position", &imu->position);
  });
  if (r.Has("positions")) {
    r.ReadArray("positions", &out->positions, read_position);
  } else {
    for (const ArrayImu& imu : out->imus)
      out->positions.push_back({imu.triads.name, imu.position, array_internal::kNaN3});
  }
}

void ReadUncertainty(const JsonReader& r, bool full, ArrayUncertainty* out) {
  auto read_std = [](const JsonReader& e, ArrayPositionStd* s) {
    e.Read("name", &s->name);
    e.Read("std", &s->std);
    if (std::optional<JsonReader> crb = e.OptionalObject("crb")) {
      Eigen::Vector3d v = array_internal::kNaN3;
      crb->Read("std", &v);
      if (crb->ok()) s->crb = v;
    }
  };
  Ext(r, "basis", &out->basis);
  if (r.ok() && out->basis != "crb" && out->basis != "sandwich" && out->basis != kArrayBasisCrbOnly)
    r.Fail("expected \"crb\", \"sandwich\" or \"crb_only\", found \"" + out->basis + "\"", "basis");
  Ext(r, "chi2_per_dof", &out->chi2_per_dof);
  if (!full) {
    r.ReadArray("positions", &out->positions, read_std);
    Ext(r, "std_rms", &out->std_rms);
    return;
  }
  r.ReadArray("imus", &out->imus, [](const JsonReader& e, ArrayImuStd* s) {
    ReadImuTriads(e, &s->triads);
    e.Read("position_std", &s->position_std);
    if (std::optional<JsonReader> crb = e.OptionalObject("crb")) {
      ArrayImuCrbStd v;
      ReadTriad(*crb, "accelerometer", &v.accelerometer);
      ReadTriad(*crb, "gyroscope", &v.gyroscope);
      crb->Read("position_std", &v.position_std);
      if (crb->ok()) s->crb = std::move(v);
    }
  });
  if (r.Has("positions")) {
    r.ReadArray("positions", &out->positions, read_std);
  } else {
    for (const ArrayImuStd& s : out->imus)
      out->positions.push_back(
          {s.triads.name, s.position_std,
           s.crb ? std::optional<Eigen::Vector3d>(s.crb->position_std) : std::nullopt});
  }
}

// ---- diagnostics, positions model ----

// The unit of every accelerometer figure in the diagnostics of either model (the gyroscope's are
// in the config's gyro_unit, named by diagnostics.gyro_unit).
constexpr const char* kAccelDiagnosticsUnit = "m/s^2";

// diagnostics.units (an extension): what the numbers the unit keys above leave unnamed are.
json DiagnosticsUnits(bool full) {
  json units = {
      {"cost", "dimensionless: the sum of squared whitened residuals (χ², per iteration)"}};
  if (full) {
    units["rotation_excitation.weakest_axis"] = "unit vector, body frame";
    units["static_intervals[].start, end"] = "s";
  } else {
    units["excitation.weakest_direction"] = "unit vector, body frame";
    units["accelerometer_calibration.magnitude"] = "m/s^2";
    units["accelerometer_calibration.max_condition_number"] =
        "dimensionless: largest over the triads' sensitivity matrices";
    units["parallel_fraction"] = "dimensionless: fraction of the samples";
  }
  return units;
}

json ExcitationJson(const ArrayExcitation& e) {
  return {
      {"min_eigenvalue", Num(e.min_eigenvalue)},
      {"max_eigenvalue", Num(e.max_eigenvalue)},
      {"noise_floor", Num(e.noise_floor)},
      {"weakest_direction", Nums(e.weakest_direction)},
      {"verdict", e.verdict},
      {"units", "rad^2/s^4"}};  // of the eigenvalues and the noise floor (SI, whatever gyro_unit)
}

json PositionsDiagnosticsJson(const ArrayPositionsDiagnostics& d, bool usable) {
  json out = {{"solver", d.solver},
              {"termination", d.termination},
              {"gyro_unit", d.gyro_unit},
              {"accel_unit", kAccelDiagnosticsUnit},
              {"excitation", ExcitationJson(d.excitation)}};
  if (usable) {  // SPEC's: always there
    out["iterations"] = d.iterations.value_or(0);
    out["samples"] = d.samples.value_or(0);
    out["samples_dropped"] = d.samples_dropped.value_or(0);
  } else {
    PutCount(&out, "iterations", d.iterations);
    PutCount(&out, "samples", d.samples);
    PutCount(&out, "samples_dropped", d.samples_dropped);
  }
  PutCount(&out, "gyro_triads", d.gyro_triads);
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
  if (d.saturation) out["saturation"] = ToJson(*d.saturation);
  out["units"] = DiagnosticsUnits(false);
  return out;
}

// SPEC §4 requires of a usable result solver, iterations, converged, cost, samples,
// samples_dropped, residual_rms and noise_estimate (accelerometer, gyroscope) and the excitation's
// smallest eigenvalue and verdict; the rest are extensions, and every member of a partial
// document is optional.
void ReadPositionsDiagnostics(const JsonReader& r, bool usable, ArrayPositionsDiagnostics* d) {
  const bool spec = usable;
  ReadMember(r, spec, "solver", &d->solver);
  Ext(r, "termination", &d->termination);
  ReadMember(r, spec, "iterations", &d->iterations);
  ReadMember(r, spec, "samples", &d->samples);
  ReadMember(r, spec, "samples_dropped", &d->samples_dropped);
  ReadMember(r, false, "gyro_triads", &d->gyro_triads);
  Ext(r, "gyro_unit", &d->gyro_unit);
  if (const std::optional<JsonReader> e = MemberObject(r, spec, "excitation")) {
    ReadMember(*e, spec, "min_eigenvalue", &d->excitation.min_eigenvalue);
    Ext(*e, "max_eigenvalue", &d->excitation.max_eigenvalue);
    Ext(*e, "noise_floor", &d->excitation.noise_floor);
    Ext(*e, "weakest_direction", &d->excitation.weakest_direction);
    ReadMember(*e, spec, "verdict", &d->excitation.verdict);
  }
  if (!usable) return;
  r.Read("converged", &d->converged);
  r.Read("cost", &d->cost);
  ReadFigures(r, "residual_rms", &d->residual_rms);
  ReadFigures(r, "noise_estimate", &d->noise_estimate);
  if (const std::optional<JsonReader> jobs = MemberObject(r, false, "noise_jobs")) {
    Ext(*jobs, "accelerometer", &d->noise_jobs.accelerometer);
    Ext(*jobs, "gyroscope", &d->noise_jobs.gyroscope);
  }
  ReadFigures(r, "noise_configured", &d->noise_configured, false);
  Ext(r, "parallel_fraction", &d->parallel_fraction);
  if (const std::optional<JsonReader> m = MemberObject(r, false, "motion")) {
    Ext(*m, "stride", &d->motion.stride);
    Ext(*m, "omega_norm", &d->motion.omega_norm);
    Ext(*m, "omega_dot_norm", &d->motion.omega_dot_norm);
    if (const std::optional<JsonReader> units = MemberObject(*m, false, "units")) {
      Ext(*units, "omega_norm", &d->motion.omega_norm_unit);
      Ext(*units, "omega_dot_norm", &d->motion.omega_dot_norm_unit);
    }
  }
  // Null (or absent: before it existed) when the config had no accelerometer_calibration.
  if (std::optional<JsonReader> c = r.OptionalObject("accelerometer_calibration")) {
    ArrayCalibrationUsed v;
    Ext(*c, "job", &v.job);
    Ext(*c, "sensors", &v.sensors);
    Ext(*c, "frame", &v.frame);
    Ext(*c, "bias", &v.bias);
    Ext(*c, "magnitude", &v.magnitude);
    Ext(*c, "max_condition_number", &v.max_condition_number);
    if (c->ok()) d->accelerometer_calibration = std::move(v);
  }
  ReadSaturation(r, &d->saturation);
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
  json out = {
      {"model", "full"}, {"termination", d.termination}, {"null_directions", d.null_directions}};
  if (usable)
    out["iterations"] = d.iterations.value_or(0);  // SPEC's: always there
  else
    PutCount(&out, "iterations", d.iterations);
  PutCount(&out, "statics", d.statics);
  PutCount(&out, "static_samples", d.static_samples);
  PutCount(&out, "dynamic_samples", d.dynamic_samples);
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
  PutCount(&out, "dof", d.dof);
  out["chi2_per_dof"] = Num(d.chi2_per_dof);
  out["gyro_unit"] = d.gyro_unit;
  out["accel_unit"] = kAccelDiagnosticsUnit;
  out["noise"] = {{"accelerometer", Num(d.noise.accelerometer)},
                  {"gyroscope", Num(d.noise.gyroscope)},
                  {"source", d.noise.source},
                  {"dynamic_weighting", d.noise.dynamic_weighting},
                  {"dynamic_accelerometer", Num(d.noise.dynamic_accelerometer)},
                  {"dynamic_gyroscope", Num(d.noise.dynamic_gyroscope)}};
  out["static_noise"] = Figures(d.static_noise);
  json statics = json::array();
  for (const ArrayFullStaticInterval& st : d.static_intervals)
    statics.push_back({{"start", Num(st.start)},
                       {"end", Num(st.end)},
                       {"samples", st.samples},
                       {"accel_residual_rms", Num(st.accel_residual_rms)},
                       {"gyro_residual_rms", Num(st.gyro_residual_rms)}});
  out["static_intervals"] = std::move(statics);
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
  PutCount(&out, "positions_only_start", d.positions_only_start);
  if (d.saturation) out["saturation"] = ToJson(*d.saturation);
  json changed = json::array();
  for (const auto& c : d.changed_from_positions_only) {
    json e = {{"name", c.name},
              {"positions_only", Nums(c.positions_only)},
              {"position_change", Nums(c.position_change)},
              {"position_change_norm", Num(c.position_change_norm)},
              {"position_change_sigma", Nums(c.position_change_sigma)},
              {"unit", "m"}};  // of every member but position_change_sigma (shift / σ)
    if (c.positions_only_std) e["positions_only_std"] = Nums(*c.positions_only_std);
    changed.push_back(std::move(e));
  }
  out["changed_from_positions_only"] = std::move(changed);
  out["units"] = DiagnosticsUnits(true);
  return out;
}

// The rotation excitation (an extension: absent, NaN and an empty verdict).
void ReadRotation(const JsonReader& r, const char* key, bool usable, ArrayRotationExcitation* e) {
  const std::optional<JsonReader> x = MemberObject(r, false, key);
  if (!x) return;
  Ext(*x, "eigenvalues", &e->eigenvalues);
  Ext(*x, "noise_floor", &e->noise_floor);
  Ext(*x, "weakest_axis", &e->weakest_axis);
  Ext(*x, "verdict", &e->verdict);
  if (usable) Ext(*x, "units", &e->units);
}

// SPEC requires of a usable full-model result the §4 members it has (solver, iterations,
// converged, cost, samples_dropped) and §7's gauge (its scale); the rest are extensions (README
// Changelog), and every member of a partial document is optional.
void ReadFullDiagnostics(const JsonReader& r, bool usable, ArrayFullDiagnostics* d) {
  Ext(r, "termination", &d->termination);
  ReadMember(r, usable, "iterations", &d->iterations);
  ReadMember(r, false, "statics", &d->statics);
  ReadMember(r, false, "static_samples", &d->static_samples);
  ReadMember(r, false, "dynamic_samples", &d->dynamic_samples);
  Ext(r, "null_directions", &d->null_directions);
  if (!usable) {
    ReadRotation(r, "rotation", false, &d->rotation_excitation);
    return;
  }
  ReadRotation(r, "rotation_excitation", true, &d->rotation_excitation);
  JsonReader g = r.Object("gauge");
  g.Read("scale", &d->gauge.scale);
  Ext(g, "reference", &d->gauge.reference);
  Ext(g, "description", &d->gauge.description);
  r.Read("solver", &d->solver);
  r.Read("converged", &d->converged);
  r.Read("cost", &d->cost);
  r.Read("samples_dropped", &d->samples_dropped);
  ReadMember(r, false, "dof", &d->dof);
  Ext(r, "chi2_per_dof", &d->chi2_per_dof);
  Ext(r, "gyro_unit", &d->gyro_unit);
  if (const std::optional<JsonReader> n = MemberObject(r, false, "noise")) {
    Ext(*n, "accelerometer", &d->noise.accelerometer);
    Ext(*n, "gyroscope", &d->noise.gyroscope);
    Ext(*n, "source", &d->noise.source);
    Ext(*n, "dynamic_weighting", &d->noise.dynamic_weighting);
    Ext(*n, "dynamic_accelerometer", &d->noise.dynamic_accelerometer);
    Ext(*n, "dynamic_gyroscope", &d->noise.dynamic_gyroscope);
  }
  ReadFigures(r, "static_noise", &d->static_noise, false);
  ExtArray(r, "static_intervals", &d->static_intervals,
           [](const JsonReader& e, ArrayFullStaticInterval* st) {
             Ext(e, "start", &st->start);
             Ext(e, "end", &st->end);
             Ext(e, "samples", &st->samples);
             Ext(e, "accel_residual_rms", &st->accel_residual_rms);
             Ext(e, "gyro_residual_rms", &st->gyro_residual_rms);
           });
  if (const std::optional<JsonReader> rms = MemberObject(r, false, "residual_rms")) {
    ReadFigures(*rms, "dynamic", &d->residual_rms_dynamic, false);
    ExtArray(*rms, "imus", &d->residual_rms_imus, [](const JsonReader& e, ArrayImuResiduals* i) {
      Ext(e, "name", &i->name);
      ReadFigures(e, "static", &i->static_rms, false);
      ReadFigures(e, "dynamic", &i->dynamic_rms, false);
    });
  }
  if (const std::optional<JsonReader> t = MemberObject(r, false, "time_offsets")) {
    ExtArray(*t, "offsets_ms", &d->time_offsets.offsets_ms,
             [](const JsonReader& e, ArrayTimeOffset* o) {
               Ext(e, "name", &o->name);
               Ext(e, "offset", &o->offset);
             });
    Ext(*t, "explained_fraction", &d->time_offsets.explained_fraction);
    Ext(*t, "per_sample_rms_ms", &d->time_offsets.per_sample_rms_ms);
    Ext(*t, "per_sample_explained_fraction", &d->time_offsets.per_sample_explained_fraction);
    Ext(*t, "note", &d->time_offsets.note);
  }
  if (const std::optional<JsonReader> b = MemberObject(r, false, "robust")) {
    Ext(*b, "used", &d->robust.used);
    Ext(*b, "batches", &d->robust.batches);
    Ext(*b, "batch_seconds", &d->robust.batch_seconds);
    Ext(*b, "ratio", &d->robust.ratio);
  }
  ReadMember(r, false, "positions_only_start", &d->positions_only_start);
  ReadSaturation(r, &d->saturation);
  ExtArray(r, "changed_from_positions_only", &d->changed_from_positions_only,
           [](const JsonReader& e, ArrayPositionChange* c) {
             Ext(e, "name", &c->name);
             Ext(e, "positions_only", &c->positions_only);
             e.Read("positions_only_std", &c->positions_only_std);
             Ext(e, "position_change", &c->position_change);
             Ext(e, "position_change_norm", &c->position_change_norm);
             Ext(e, "position_change_sigma", &c->position_change_sigma);
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
  // A partial document may lack its diagnostics altogether (left out over the size cap).
  const std::optional<JsonReader> diag = MemberObject(r, usable, "diagnostics");
  std::optional<std::string> model;
  if (diag) diag->Read("model", &model);
  if (model && *model != "full")
    diag->Fail("expected \"full\" or no model (the positions model), found \"" + *model + "\"",
               "model");
  // Without diagnostics.model (a result stripped to SPEC's keys): the full model has
  // parameters.imus (SPEC §7).
  v.full = model.has_value() ||
           (usable && r.Has("parameters") && r.Object("parameters").Present("imus"));
  if (usable) {
    ArrayParameters p;
    ReadParameters(r.Object("parameters"), v.full, &p);
    ArrayUncertainty u;
    ReadUncertainty(r.Object("uncertainty"), v.full, &u);
    v.parameters = std::move(p);
    v.uncertainty = std::move(u);
  }
  if (diag && v.full)
    ReadFullDiagnostics(*diag, usable, &v.full_diagnostics);
  else if (diag)
    ReadPositionsDiagnostics(*diag, usable, &v.diagnostics);
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
