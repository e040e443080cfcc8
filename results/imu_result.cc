#include "results/imu_result.h"

#include <algorithm>
#include <utility>

namespace calibd::results {

using nlohmann::json;

namespace {

// The "trimmed" note of a trimmed partial document and the members it dropped.
void ReadTrimmed(const JsonReader& r, std::optional<json>* trimmed,
                 std::vector<std::string>* dropped) {
  std::optional<JsonReader> t = r.OptionalObject("trimmed");
  if (!t) return;
  json raw;
  r.ReadRaw("trimmed", &raw);
  *trimmed = std::move(raw);
  std::optional<std::vector<std::string>> keys;
  t->Read("dropped", &keys);
  *dropped = keys.value_or(std::vector<std::string>());
}

bool Contains(const std::vector<std::string>& v, const char* key) {
  return std::find(v.begin(), v.end(), key) != v.end();
}

// Whether diagnostics member `key` of `d` is one the trimming dropped (listed, and absent; null
// in documents trimmed before the members were left out).
bool DroppedMember(const JsonReader& d, const std::vector<std::string>& dropped, const char* key) {
  if (!Contains(dropped, key) || !d.node().is_object()) return false;
  auto it = d.node().find(key);
  return it == d.node().end() || it->is_null();
}

json Ids(const std::optional<int64_t>& id) { return id ? json(*id) : json(nullptr); }

json NoiseModelJson(const std::optional<ImuNoiseModel>& m) {
  if (!m) return nullptr;
  return {{"job", Ids(m->job)},
          {"white_noise", Num(m->white_noise)},
          {"random_walk", Num(m->random_walk)}};
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

void ReadFit(const JsonReader& e, ImuFitDiagnostics* f) {
  e.Read("name", &f->name);
  e.Read("usable", &f->usable);
  e.Read("termination", &f->termination);
  e.Read("reason", &f->reason);
  e.Read("chi2_per_dof", &f->chi2_per_dof);
  e.Read("degrees_of_freedom", &f->degrees_of_freedom);
  const JsonReader it = e.Object("iterations");
  it.Read("accelerometer", &f->accel_iterations);
  it.Read("gyroscope", &f->gyro_iterations);
  it.Read("joint", &f->joint_iterations);
  const JsonReader noise = e.Object("noise");
  noise.Read("accelerometer", &f->accel_noise);
  noise.Read("gyroscope", &f->gyro_noise);
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
    s.Read("gravity_direction", &x->gravity_direction);
    s.Read("norm_residual_before", &x->norm_residual_before);
    s.Read("norm_residual_after", &x->norm_residual_after);
  });
  e.ReadArray("rotations", &f->rotations, [](const JsonReader& q, ImuRotation* x) {
    q.Read("from", &x->from);
    q.Read("to", &x->to);
    q.Read("start", &x->start);
    q.Read("end", &x->end);
    q.Read("angle", &x->angle);
    q.Read("direction_error_before", &x->direction_error_before);
    q.Read("direction_error_after", &x->direction_error_after);
    q.Read("used", &x->used);
    q.Read("excluded", &x->excluded);
  });
  const JsonReader c = e.Object("coverage");
  c.Read("gravity_eigenvalues", &f->coverage.gravity_eigenvalues);
  c.Read("min_eigenvalue", &f->coverage.min_eigenvalue);
  c.Read("least_covered_direction", &f->coverage.least_covered_direction);
  c.Read("missing_up", &f->coverage.missing_up);
  c.Read("rotation_per_axis", &f->coverage.rotation_per_axis);
  c.Read("weak_axes", &f->coverage.weak_axes);
  c.Read("sufficient", &f->coverage.sufficient);
  c.Read("verdict", &f->coverage.verdict);
  e.ReadArray("threshold_trials", &f->threshold_trials,
              [](const JsonReader& t, ImuThresholdTrial* x) {
                t.Read("multiplier", &x->multiplier);
                t.Read("statics", &x->statics);
                t.Read("accel_chi2_per_dof", &x->accel_chi2_per_dof);
                t.Read("chosen", &x->chosen);
              });
  e.Read("threshold_choice", &f->threshold_choice);
  e.Read("cost", &f->cost);
}

// An optional noise-model entry: null or absent is nullopt.
void ReadNoiseModel(const JsonReader& r, const char* key, std::optional<ImuNoiseModel>* out) {
  out->reset();
  if (std::optional<JsonReader> m = r.OptionalObject(key)) {
    ImuNoiseModel v;
    m->Read("job", &v.job);
    m->Read("white_noise", &v.white_noise);
    m->Read("random_walk", &v.random_walk);
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
    json imus = json::array();
    for (const ImuTriadsStd& t : r.uncertainty->imus) {
      json e = json::object();
      WriteImuTriads(t, &e);
      imus.push_back(std::move(e));
    }
    out["uncertainty"] = {{"imus", std::move(imus)}};
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
  for (const std::string& key : r.dropped) diag.erase(key);  // left out by the trimming
  if (!Contains(r.dropped, "diagnostics")) out["diagnostics"] = std::move(diag);
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
    p.Read("gravity", &params.gravity);
    p.Read("gyro_bias", &params.gyro_bias);
    ReadPresent(p, "accel_unit", &params.accel_unit);
    ReadPresent(p, "gyro_unit", &params.gyro_unit);
    p.ReadArray("imus", &params.imus,
                [](const JsonReader& e, ImuTriads* t) { ReadImuTriads(e, t); });
    v.parameters = std::move(params);
    const JsonReader u = r.Object("uncertainty");
    ImuUncertainty unc;
    u.ReadArray("imus", &unc.imus,
                [](const JsonReader& e, ImuTriadsStd* t) { ReadImuTriads(e, t); });
    if (r.ok() && unc.imus.size() != v.parameters->imus.size()) {
      u.Fail(std::to_string(v.parameters->imus.size()) + " IMUs in parameters but " +
                 std::to_string(unc.imus.size()) + " here",
             "imus");
    }
    v.uncertainty = std::move(unc);
  }
  if (r.ok() && !v.envelope.usable) ReadTrimmed(r, &v.trimmed, &v.dropped);
  if (Contains(v.dropped, "diagnostics") && !r.Has("diagnostics")) {
    // Trimmed to the bare envelope: no diagnostics to read.
  } else {
    const JsonReader d = r.Object("diagnostics");
    ImuDiagnostics& g = v.diagnostics;
    auto keep = [&](const char* key) { return !DroppedMember(d, v.dropped, key); };
    if (keep("statics")) {
      d.ReadArray("statics", &g.statics, [](const JsonReader& s, ImuInterval* x) {
        s.Read("start", &x->start);
        s.Read("end", &x->end);
        s.Read("samples", &x->samples);
      });
    }
    if (keep("rate")) ReadPresent(d, "rate", &g.rate);
    if (keep("gaps") && d.Has("gaps")) {
      std::vector<ImuGap> gaps;
      d.ReadArray("gaps", &gaps, [](const JsonReader& e, ImuGap* x) {
        e.Read("index", &x->index);
        e.Read("start", &x->start);
        e.Read("end", &x->end);
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
    if (keep("static_window")) d.Read("static_window", &g.static_window);
    if (keep("min_static")) d.Read("min_static", &g.min_static);
    if (keep("threshold_choice")) d.Read("threshold_choice", &g.threshold_choice);
    if (keep("imus")) d.ReadArray("imus", &g.imus, ReadFit);
  }
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
