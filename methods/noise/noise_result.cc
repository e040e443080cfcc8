#include "methods/noise/noise_result.h"

#include <algorithm>
#include <utility>

namespace calibd::results {

using nlohmann::json;

namespace {

void CheckBasis(const JsonReader& r, const std::string& basis) {
  if (r.ok() && basis != "crb" && basis != "chi2_scaled" && basis != kNoiseBasisCrbOnly)
    r.Fail("expected \"crb\", \"chi2_scaled\" or \"crb_only\", found \"" + basis + "\"", "basis");
}

}  // namespace

json ToJson(const NoiseResult& r) {
  json out = json::object();
  WriteEnvelope(r.envelope, kNoiseSchemaVersion, &out);
  if (r.envelope.usable) {
    json params = json::array(), stds = json::array();
    for (const NoiseChannelParameters& c : r.channels) {
      params.push_back({{"name", c.name},
                        {"unit", c.unit},
                        {"white_noise", Num(c.white_noise)},
                        {"bias_instability", Num(c.bias_instability)},
                        {"bias_instability_tau", Num(c.bias_instability_tau)},
                        {"random_walk", Num(c.random_walk)}});
    }
    for (const NoiseChannelUncertainty& c : r.channel_stds) {
      json e = {{"name", c.name},
                {"white_noise_std", Num(c.white_noise_std)},
                {"bias_instability_std", Num(c.bias_instability_std)},
                {"random_walk_std", Num(c.random_walk_std)}};
      if (c.basis != kNoiseBasisCrbOnly) {
        e["basis"] = c.basis;
        e["chi2_per_dof"] = Num(c.chi2_per_dof);
      }
      if (c.crb) {
        e["crb"] = {{"white_noise_std", Num(c.crb->white_noise_std)},
                    {"bias_instability_std", Num(c.crb->bias_instability_std)},
                    {"random_walk_std", Num(c.crb->random_walk_std)}};
      }
      stds.push_back(std::move(e));
    }
    out["parameters"] = {{"channels", std::move(params)}};
    out["uncertainty"] = {{"channels", std::move(stds)}};
    if (r.basis != kNoiseBasisCrbOnly) {
      out["uncertainty"]["basis"] = r.basis;
      out["uncertainty"]["chi2_per_dof"] = Num(r.chi2_per_dof);
    }
  }
  const NoiseDiagnostics& d = r.diagnostics;
  json channels = json::array(), allan = json::array();
  for (const NoiseChannelDiagnostics& c : d.channels) {
    json e = {{"name", c.name},
              {"status", c.status},
              {"reason", c.reason},
              {"fit_points", c.fit_points},
              {"fit_chi2", Num(c.fit_chi2)},
              {"mean", Num(c.mean)}};
    if (!c.unit.empty()) e["unit"] = c.unit;
    channels.push_back(std::move(e));
  }
  for (const NoiseAllanCurve& c : d.allan) {
    json e = {{"name", c.name},
              {"tau", Nums(c.tau)},
              {"tau_unit", "s"},
              {"adev", Nums(c.adev)},
              {"adev_lower", Nums(c.adev_lower)},
              {"adev_upper", Nums(c.adev_upper)},
              {"fitted_adev", Nums(c.fitted_adev)}};
    if (!c.unit.empty()) e["unit"] = c.unit;
    allan.push_back(std::move(e));
  }
  json diag = {{"rate", Num(d.rate)},
               {"rate_unit", "Hz"},
               {"samples", d.samples},
               {"duration", Num(d.duration)},
               {"duration_unit", "s"},
               {"jitter", Num(d.jitter)},
               {"jitter_unit", "fraction of the sample period"},
               {"stationary", d.stationary},
               {"taus_per_decade", d.taus_per_decade},
               {"confidence", Num(d.confidence)},
               {"confidence_unit", "probability that an Allan interval holds the true value"},
               {"channels", std::move(channels)},
               {"allan", std::move(allan)}};
  if (d.units) {
    diag["units"] = {{"accel_unit", d.units->accel_unit}, {"gyro_unit", d.units->gyro_unit}};
  }
  if (d.saturation) diag["saturation"] = ToJson(*d.saturation);
  for (const std::string& key : r.dropped) diag.erase(key);  // left out by the trimming
  if (!ContainsKey(r.dropped, "diagnostics")) out["diagnostics"] = std::move(diag);
  if (r.trimmed) out["trimmed"] = *r.trimmed;
  return out;
}

Status FromJson(const json& doc, NoiseResult* out) {
  JsonReader r(doc, "noise result");
  if (!doc.is_object()) {
    r.Fail("expected an object, found " + JsonReader::TypeName(doc));
    return r.status();
  }
  NoiseResult v;
  ReadEnvelope(r, "noise", kNoiseSchemaVersion, &v.envelope);
  if (r.ok() && v.envelope.usable) {
    r.Object("parameters")
        .ReadArray("channels", &v.channels, [](const JsonReader& e, NoiseChannelParameters* c) {
          e.Read("name", &c->name);
          e.Read("unit", &c->unit);
          e.Read("white_noise", &c->white_noise);
          e.Read("bias_instability", &c->bias_instability);
          e.Read("bias_instability_tau", &c->bias_instability_tau);
          e.Read("random_walk", &c->random_walk);
        });
    JsonReader unc = r.Object("uncertainty");
    unc.ReadArray("channels", &v.channel_stds, [](const JsonReader& e, NoiseChannelUncertainty* c) {
      e.Read("name", &c->name);
      e.Read("white_noise_std", &c->white_noise_std);
      e.Read("bias_instability_std", &c->bias_instability_std);
      e.Read("random_walk_std", &c->random_walk_std);
      // Absent in results stored before the σ convention: "crb_only", no χ², no crb.
      e.ReadExtension("basis", &c->basis);
      e.ReadExtension("chi2_per_dof", &c->chi2_per_dof);
      CheckBasis(e, c->basis);
      if (std::optional<JsonReader> b = e.OptionalObject("crb")) {
        NoiseTermStds crb;
        b->Read("white_noise_std", &crb.white_noise_std);
        b->Read("bias_instability_std", &crb.bias_instability_std);
        b->Read("random_walk_std", &crb.random_walk_std);
        c->crb = crb;
      }
    });
    unc.ReadExtension("basis", &v.basis);
    unc.ReadExtension("chi2_per_dof", &v.chi2_per_dof);
    CheckBasis(unc, v.basis);
    if (r.ok() && v.channel_stds.size() != v.channels.size()) {
      unc.Fail(std::to_string(v.channels.size()) + " channels in parameters but " +
                   std::to_string(v.channel_stds.size()) + " here",
               "channels");
    }
  }
  if (r.ok() && !v.envelope.usable) ReadTrimmed(r, &v.trimmed, &v.dropped);
  // A partial document (usable false) may lack the diagnostics or any member of them (the
  // worker leaves out the largest when over its cap): all optional there.
  const bool partial = !v.envelope.usable;
  if (partial && !r.Has("diagnostics")) {
    // Trimmed to the bare envelope (or written without diagnostics): none to read.
  } else {
    JsonReader d = r.Object("diagnostics");
    NoiseDiagnostics& g = v.diagnostics;
    // Members the trimming set to null (documents trimmed before they were left out) are skipped.
    auto keep = [&](const char* key) { return !DroppedMember(d, v.dropped, key); };
    // SPEC's members (rate, samples, allan): required in a result, optional in a partial one.
    auto spec = [&](const char* key) { return keep(key) && (!partial || d.Present(key)); };
    if (spec("rate")) d.Read("rate", &g.rate);
    if (spec("samples")) d.Read("samples", &g.samples);
    if (spec("allan")) {
      d.ReadArray("allan", &g.allan, [](const JsonReader& e, NoiseAllanCurve* c) {
        e.Read("name", &c->name);
        e.Read("tau", &c->tau);
        e.Read("adev", &c->adev);
        e.Read("adev_lower", &c->adev_lower);
        e.Read("adev_upper", &c->adev_upper);
        e.ReadExtension("fitted_adev", &c->fitted_adev);
        e.ReadExtension("unit", &c->unit);
      });
    }
    // Extensions: absent in a result of an earlier calibd, the defaults of noise_result.h.
    if (keep("duration")) d.ReadExtension("duration", &g.duration);
    if (keep("jitter")) d.ReadExtension("jitter", &g.jitter);
    if (keep("stationary")) d.ReadExtension("stationary", &g.stationary);
    if (keep("taus_per_decade")) d.ReadExtension("taus_per_decade", &g.taus_per_decade);
    if (keep("confidence")) d.ReadExtension("confidence", &g.confidence);
    if (keep("channels")) {
      d.ReadArrayExtension("channels", &g.channels,
                           [](const JsonReader& e, NoiseChannelDiagnostics* c) {
                             e.ReadExtension("name", &c->name);
                             e.ReadExtension("status", &c->status);
                             e.ReadExtension("reason", &c->reason);
                             e.ReadExtension("fit_points", &c->fit_points);
                             e.ReadExtension("fit_chi2", &c->fit_chi2);
                             e.ReadExtension("mean", &c->mean);
                             e.ReadExtension("unit", &c->unit);
                           });
    }
    if (std::optional<JsonReader> u = d.OptionalObject("units")) {
      NoiseUnits units;
      u->ReadExtension("accel_unit", &units.accel_unit);
      u->ReadExtension("gyro_unit", &units.gyro_unit);
      g.units = std::move(units);
    }
    ReadSaturation(d, &g.saturation);
  }
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
