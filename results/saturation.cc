#include "results/saturation.h"

#include <cmath>

namespace calibd::results {

using nlohmann::json;

nlohmann::json ToJson(const SaturationDiagnostics& s) {
  json channels = json::array();
  for (const SaturationChannel& c : s.channels) {
    channels.push_back({{"name", c.name},
                        {"source", c.source},
                        {"unit", c.unit},
                        {"low", std::isfinite(c.low) ? json(c.low) : json()},
                        {"high", std::isfinite(c.high) ? json(c.high) : json()},
                        {"pinned_low", c.pinned_low},
                        {"pinned_high", c.pinned_high}});
  }
  return {{"policy", s.policy}, {"samples", s.samples}, {"channels", std::move(channels)}};
}

void ReadSaturation(const JsonReader& diagnostics, std::optional<SaturationDiagnostics>* out) {
  std::optional<JsonReader> r = diagnostics.OptionalObject("saturation");
  if (!r) {
    out->reset();
    return;
  }
  SaturationDiagnostics s;
  r->Read("policy", &s.policy);
  r->Read("samples", &s.samples);
  r->ReadArray("channels", &s.channels, [](const JsonReader& e, SaturationChannel* c) {
    e.Read("name", &c->name);
    e.Read("source", &c->source);
    e.Read("unit", &c->unit);
    std::optional<double> low, high;
    e.Read("low", &low);
    e.Read("high", &high);
    c->low = low.value_or(-std::numeric_limits<double>::infinity());
    c->high = high.value_or(std::numeric_limits<double>::infinity());
    e.Read("pinned_low", &c->pinned_low);
    e.Read("pinned_high", &c->pinned_high);
  });
  *out = std::move(s);
}

}  // namespace calibd::results
