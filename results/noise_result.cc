#include "results/noise_result.h"

#include <utility>

namespace calibd::results {

using nlohmann::json;

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
      stds.push_back({{"name", c.name},
                      {"white_noise_std", Num(c.white_noise_std)},
                      {"bias_instability_std", Num(c.bias_instability_std)},
                      {"random_walk_std", Num(c.random_walk_std)}});
    }
    out["parameters"] = {{"channels", std::move(params)}};
    out["uncertainty"] = {{"channels", std::move(stds)}};
  }
  const NoiseDiagnostics& d = r.diagnostics;
  json channels = json::array(), allan = json::array();
  for (const NoiseChannelDiagnostics& c : d.channels) {
    channels.push_back({{"name", c.name},
                        {"status", c.status},
                        {"reason", c.reason},
                        {"fit_points", c.fit_points},
                        {"fit_chi2", Num(c.fit_chi2)},
                        {"mean", Num(c.mean)}});
  }
  for (const NoiseAllanCurve& c : d.allan) {
    allan.push_back({{"name", c.name},
                     {"tau", Nums(c.tau)},
                     {"adev", Nums(c.adev)},
                     {"adev_lower", Nums(c.adev_lower)},
                     {"adev_upper", Nums(c.adev_upper)},
                     {"fitted_adev", Nums(c.fitted_adev)}});
  }
  json diag = {{"rate", Num(d.rate)},
               {"samples", d.samples},
               {"duration", Num(d.duration)},
               {"jitter", Num(d.jitter)},
               {"stationary", d.stationary},
               {"taus_per_decade", d.taus_per_decade},
               {"confidence", Num(d.confidence)},
               {"channels", std::move(channels)},
               {"allan", std::move(allan)}};
  if (d.units) {
    diag["units"] = {{"accel_unit", d.units->accel_unit}, {"gyro_unit", d.units->gyro_unit}};
  }
  out["diagnostics"] = std::move(diag);
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
    });
    if (r.ok() && v.channel_stds.size() != v.channels.size()) {
      unc.Fail(std::to_string(v.channels.size()) + " channels in parameters but " +
                   std::to_string(v.channel_stds.size()) + " here",
               "channels");
    }
  }
  JsonReader d = r.Object("diagnostics");
  NoiseDiagnostics& g = v.diagnostics;
  d.Read("rate", &g.rate);
  d.Read("samples", &g.samples);
  d.Read("duration", &g.duration);
  d.Read("jitter", &g.jitter);
  d.Read("stationary", &g.stationary);
  d.Read("taus_per_decade", &g.taus_per_decade);
  d.Read("confidence", &g.confidence);
  d.ReadArray("channels", &g.channels, [](const JsonReader& e, NoiseChannelDiagnostics* c) {
    e.Read("name", &c->name);
    e.Read("status", &c->status);
    e.Read("reason", &c->reason);
    e.Read("fit_points", &c->fit_points);
    e.Read("fit_chi2", &c->fit_chi2);
    e.Read("mean", &c->mean);
  });
  d.ReadArray("allan", &g.allan, [](const JsonReader& e, NoiseAllanCurve* c) {
    e.Read("name", &c->name);
    e.Read("tau", &c->tau);
    e.Read("adev", &c->adev);
    e.Read("adev_lower", &c->adev_lower);
    e.Read("adev_upper", &c->adev_upper);
    e.Read("fitted_adev", &c->fitted_adev);
  });
  if (std::optional<JsonReader> u = d.OptionalObject("units")) {
    NoiseUnits units;
    u->Read("accel_unit", &units.accel_unit);
    u->Read("gyro_unit", &units.gyro_unit);
    g.units = std::move(units);
  }
  if (!r.ok()) return r.status();
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
