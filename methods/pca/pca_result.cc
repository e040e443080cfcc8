#include "methods/pca/pca_result.h"

#include <utility>

namespace calibd::results {

using nlohmann::json;

namespace {

template <class E, size_t N>
bool ParseName(std::string_view text, const E (&values)[N], E* out) {
  for (E v : values) {
    if (text == Name(v)) {
      *out = v;
      return true;
    }
  }
  return false;
}

// Member `key` of `r`, a string naming one value of E; else a problem naming the values.
template <class E, size_t N>
void ReadEnum(const JsonReader& r, const char* key, const E (&values)[N], E* out) {
  std::string text;
  r.Read(key, &text);
  if (!r.ok()) return;
  if (ParseName(text, values, out)) return;
  std::string expected;
  for (size_t i = 0; i < N; ++i) {
    expected += std::string(i == 0       ? ""
                            : i + 1 == N ? " or "
                                         : ", ") +
                "\"" + Name(values[i]) + "\"";
  }
  r.Fail("expected " + expected + ", found \"" + text + "\"", key);
}

constexpr PcaFrame kFrames[] = {PcaFrame::kCanonical, PcaFrame::kNominal};
constexpr PcaBias kBiases[] = {PcaBias::kNone, PcaBias::kEstimate};
constexpr PcaCoverageVerdict kVerdicts[] = {PcaCoverageVerdict::kUnknown, PcaCoverageVerdict::kGood,
                                            PcaCoverageVerdict::kPoor};

void ReadSensor(const JsonReader& r, int d, PcaSensor* out) {
  PcaSensor s;
  r.Read("name", &s.name);
  r.Read("sensitivity", &s.sensitivity);
  r.Read("scale", &s.scale);
  r.Read("axis", &s.axis);
  r.Read("bias", &s.bias);
  if (!r.ok()) return;
  for (const char* key : {"sensitivity", "axis"}) {
    const size_t n = (std::string_view(key) == "axis" ? s.axis : s.sensitivity).size();
    if (static_cast<int>(n) != d) {
      r.Fail("expected " + std::to_string(d) + " numbers (parameters.dimension), found " +
                 std::to_string(n),
             key);
      return;
    }
  }
  *out = std::move(s);
}

void ReadSensorStd(const JsonReader& r, PcaSensorStd* out) {
  PcaSensorStd s;
  r.Read("name", &s.name);
  r.Read("scale_std", &s.scale_std);
  r.Read("axis_std_rad", &s.axis_std_rad);
  r.Read("bias_std", &s.bias_std);
  if (r.Has("crb")) {
    const JsonReader c = r.Object("crb");
    PcaSensorStd::Bound b;
    c.Read("scale_std", &b.scale_std);
    c.Read("axis_std_rad", &b.axis_std_rad);
    c.Read("bias_std", &b.bias_std);
    s.crb = b;
  }
  if (r.ok()) *out = std::move(s);
}

void ReadParameters(const JsonReader& p, PcaParameters* out) {
  PcaParameters v;
  p.Read("dimension", &v.dimension);
  if (p.ok() && v.dimension < 1) {
    p.Fail("expected an integer >= 1, found " + std::to_string(v.dimension), "dimension");
  }
  p.Read("magnitude", &v.magnitude);
  p.Read("magnitude_known", &v.magnitude_known);
  ReadEnum(p, "frame", kFrames, &v.frame);
  // Not in SPEC §4 (added with bias estimation): absent, the struct's kNone.
  if (p.Present("bias")) ReadEnum(p, "bias", kBiases, &v.bias);
  if (!p.ok()) return;
  const int d = v.dimension;
  p.ReadArray("sensors", &v.sensors,
              [d](const JsonReader& e, PcaSensor* s) { ReadSensor(e, d, s); });
  if (p.ok()) *out = std::move(v);
}

void ReadUncertainty(const JsonReader& u, PcaUncertainty* out) {
  PcaUncertainty v;
  u.ReadArray("sensors", &v.sensors, ReadSensorStd);
  u.ReadExtension("noise_std", &v.noise_std);  // not in SPEC §4: absent, NaN
  // Absent in results stored before the σ convention: "crb_only" (the default), no χ².
  u.ReadExtension("basis", &v.basis);
  u.ReadExtension("chi2_per_dof", &v.chi2_per_dof);
  if (u.ok() && v.basis != "crb" && v.basis != "chi2_scaled" && v.basis != kPcaBasisCrbOnly)
    u.Fail("expected \"crb\", \"chi2_scaled\" or \"crb_only\", found \"" + v.basis + "\"", "basis");
  if (u.ok()) *out = std::move(v);
}

// diagnostics.coverage (an extension, added after the first results were stored): every member
// keeps its default when absent.
void ReadCoverage(const JsonReader& c, PcaCoverage* out) {
  PcaCoverage v;
  if (c.Present("verdict")) ReadEnum(c, "verdict", kVerdicts, &v.verdict);
  c.ReadExtension("scatter_eigenvalues", &v.scatter_eigenvalues);
  c.ReadExtension("scatter_min", &v.scatter_min);
  c.ReadExtension("design_min", &v.design_min);
  if (c.Present("positions_per_direction")) {
    JsonReader caps = c.Object("positions_per_direction");
    if (caps.ok()) {
      for (const auto& [key, value] : caps.node().items()) {
        int count = 0;
        caps.Read(key, &count);
        if (!caps.ok()) return;
        v.positions_per_direction[key] = count;
      }
    }
  }
  c.ReadExtension("advice", &v.advice);
  if (c.ok()) *out = std::move(v);
}

// `partial`: a failed run's document, whose diagnostics may lack any member (the worker leaves
// out the largest ones over the cap, server/failure_reasons.h) and, from before that rule, may
// hold null for one: every member is then read only when present and not null. Otherwise SPEC
// §4's "at least" keys are required and the others (our extensions) keep their defaults when
// absent. `usable` is the envelope's, the default of diagnostics.usable.
void ReadDiagnostics(const JsonReader& g, bool partial, bool usable, PcaDiagnostics* out) {
  PcaDiagnostics v;
  v.usable = usable;
  // SPEC's keys: required (partial: read when present and not null).
  auto spec = [&](const char* key, auto* value) {
    if (!partial || g.Has(key)) g.Read(key, value);
  };
  // Extensions: JsonReader::ReadExtension (partial: read when present and not null).
  auto extension = [&](const char* key, auto* value) {
    if (partial ? g.Has(key) : g.Present(key)) g.Read(key, value);
  };
  extension("usable", &v.usable);
  g.Read("reason", &v.reason);
  spec("singular_values", &v.singular_values);
  spec("rank_gap", &v.rank_gap);
  spec("positions", &v.positions);
  spec("min_positions", &v.min_positions);
  spec("g_eigenvalues", &v.g_eigenvalues);
  spec("residual_rms", &v.residual_rms);
  spec("magnitude_error", &v.magnitude_error);
  extension("degrees_of_freedom", &v.degrees_of_freedom);
  if (partial ? g.Has("coverage") : g.Present("coverage")) {
    PcaCoverage coverage;
    ReadCoverage(g.Object("coverage"), &coverage);
    if (g.ok()) v.coverage = std::move(coverage);
  }
  extension("noise_std", &v.noise_std);
  extension("noise_std_given", &v.noise_std_given);
  extension("noise_std_estimated", &v.noise_std_estimated);
  extension("cost_closed_form", &v.cost_closed_form);
  extension("cost", &v.cost);
  extension("refined", &v.refined);
  extension("refine_iterations", &v.refine_iterations);
  extension("reflection", &v.reflection);
  g.Read("position_labels", &v.position_labels);
  g.Read("removed_bias", &v.removed_bias);
  if (g.ok()) *out = std::move(v);
}

// diagnostics.units: the unit of every number in the diagnostics, by key (an extension; the
// members not listed are counts, flags or texts).
json DiagnosticsUnits() {
  return {{"singular_values, residual_rms, noise_std, noise_std_estimated, removed_bias",
           "reading units"},
          {"magnitude_error",
           "field units (of parameters.magnitude; relative to 1 when magnitude_known is false)"},
          {"cost, cost_closed_form", "reading units^2 (½ the sum of squared residuals)"},
          {"rank_gap", "dimensionless: singular value d over singular value d+1"},
          {"g_eigenvalues",
           "eigenvalues of g (bias none) or of the unit-norm ellipsoid shape (bias estimate): only "
           "their signs are read, all > 0 for a usable result"},
          {"coverage.scatter_eigenvalues",
           "dimensionless: eigenvalues of Σ u uᵀ / n of the unit field directions (sum 1)"},
          {"coverage.scatter_min, design_min",
           "dimensionless: 1 for orientations spread evenly over the sphere, 0 degenerate"}};
}

}  // namespace

const char* Name(PcaFrame frame) { return frame == PcaFrame::kNominal ? "nominal" : "canonical"; }

const char* Name(PcaBias bias) { return bias == PcaBias::kEstimate ? "estimate" : "none"; }

const char* Name(PcaCoverageVerdict verdict) {
  switch (verdict) {
    case PcaCoverageVerdict::kGood:
      return "good";
    case PcaCoverageVerdict::kPoor:
      return "poor";
    case PcaCoverageVerdict::kUnknown:
      break;
  }
  return "unknown";
}

bool Parse(std::string_view text, PcaFrame* out) { return ParseName(text, kFrames, out); }
bool Parse(std::string_view text, PcaBias* out) { return ParseName(text, kBiases, out); }
bool Parse(std::string_view text, PcaCoverageVerdict* out) {
  return ParseName(text, kVerdicts, out);
}

json ToJson(const PcaResult& r) {
  json out = json::object();
  WriteEnvelope(r.envelope, kPcaSchemaVersion, &out);
  if (r.parameters) {
    const PcaParameters& p = *r.parameters;
    json sensors = json::array();
    for (const PcaSensor& s : p.sensors) {
      sensors.push_back({{"name", s.name},
                         {"sensitivity", Nums(s.sensitivity)},
                         {"scale", Num(s.scale)},
                         {"axis", Nums(s.axis)},
                         {"bias", Num(s.bias)}});
    }
    out["parameters"] = {{"dimension", p.dimension},
                         {"magnitude", Num(p.magnitude)},
                         {"magnitude_known", p.magnitude_known},
                         {"frame", Name(p.frame)},
                         {"bias", Name(p.bias)},
                         {"sensors", std::move(sensors)}};
  }
  if (r.uncertainty) {
    json sensors = json::array();
    for (const PcaSensorStd& s : r.uncertainty->sensors) {
      json e = {{"name", s.name},
                {"scale_std", Num(s.scale_std)},
                {"axis_std_rad", Num(s.axis_std_rad)},
                {"bias_std", Num(s.bias_std)}};
      if (s.crb) {
        e["crb"] = {{"scale_std", Num(s.crb->scale_std)},
                    {"axis_std_rad", Num(s.crb->axis_std_rad)},
                    {"bias_std", Num(s.crb->bias_std)}};
      }
      sensors.push_back(std::move(e));
    }
    out["uncertainty"] = {{"sensors", std::move(sensors)},
                          {"noise_std", Num(r.uncertainty->noise_std)}};
    if (r.uncertainty->basis != kPcaBasisCrbOnly) {
      out["uncertainty"]["basis"] = r.uncertainty->basis;
      out["uncertainty"]["chi2_per_dof"] = Num(r.uncertainty->chi2_per_dof);
    }
  }
  const PcaDiagnostics& g = r.diagnostics;
  json diag;
  diag["usable"] = g.usable;
  if (g.reason) diag["reason"] = *g.reason;
  diag["singular_values"] = Nums(g.singular_values);
  diag["rank_gap"] = Num(g.rank_gap);
  diag["positions"] = g.positions;
  diag["min_positions"] = g.min_positions;
  diag["g_eigenvalues"] = Nums(g.g_eigenvalues);
  diag["residual_rms"] = Nums(g.residual_rms);
  diag["magnitude_error"] = Nums(g.magnitude_error);
  diag["degrees_of_freedom"] = g.degrees_of_freedom;
  if (g.coverage) {
    const PcaCoverage& c = *g.coverage;
    json caps = json::object();
    for (const auto& [name, count] : c.positions_per_direction) caps[name] = count;
    diag["coverage"] = {{"verdict", Name(c.verdict)},
                        {"scatter_eigenvalues", Nums(c.scatter_eigenvalues)},
                        {"scatter_min", Num(c.scatter_min)},
                        {"design_min", Num(c.design_min)},
                        {"positions_per_direction", std::move(caps)},
                        {"advice", c.advice}};
  }
  diag["noise_std"] = Num(g.noise_std);
  diag["noise_std_given"] = g.noise_std_given;
  diag["noise_std_estimated"] = Num(g.noise_std_estimated);
  diag["cost_closed_form"] = Num(g.cost_closed_form);
  diag["cost"] = Num(g.cost);
  diag["refined"] = g.refined;
  diag["refine_iterations"] = g.refine_iterations;
  diag["reflection"] = g.reflection;
  if (g.position_labels) diag["position_labels"] = *g.position_labels;
  if (g.removed_bias) diag["removed_bias"] = Nums(*g.removed_bias);
  diag["units"] = DiagnosticsUnits();
  out["diagnostics"] = std::move(diag);
  return out;
}

Status FromJson(const json& doc, PcaResult* out) {
  JsonReader r(doc, "pca result");
  if (!doc.is_object()) {
    r.Fail("expected an object, found " + JsonReader::TypeName(doc));
    return r.status();
  }
  PcaResult v;
  ReadEnvelope(r, "pca", kPcaSchemaVersion, &v.envelope);
  if (!r.ok()) return r.status();
  // A usable result must have parameters and uncertainty; a partial document's are not estimates
  // and are not read (as for every method: consumers test parameters, never serve a partial).
  if (v.envelope.usable) {
    PcaParameters p;
    ReadParameters(r.Object("parameters"), &p);
    if (r.ok()) v.parameters = std::move(p);
  }
  if (v.envelope.usable) {
    PcaUncertainty u;
    ReadUncertainty(r.Object("uncertainty"), &u);
    if (r.ok()) v.uncertainty = std::move(u);
  }
  if (v.envelope.usable) {
    ReadDiagnostics(r.Object("diagnostics"), false, true, &v.diagnostics);
  } else if (r.Has("diagnostics")) {
    ReadDiagnostics(r.Object("diagnostics"), true, false, &v.diagnostics);
  } else {
    v.diagnostics.usable = false;  // a partial document without diagnostics: all defaults
  }
  if (!r.ok()) return r.status();
  if (v.parameters && v.uncertainty) {
    const auto& sensors = v.parameters->sensors;
    const auto& stds = v.uncertainty->sensors;
    if (stds.size() != sensors.size()) {
      r.Fail("expected " + std::to_string(sensors.size()) +
                 " entries (one per parameters.sensors), found " + std::to_string(stds.size()),
             "uncertainty.sensors");
    }
    for (size_t i = 0; r.ok() && i < stds.size(); ++i) {
      if (stds[i].name != sensors[i].name) {
        r.Fail("\"" + stds[i].name + "\" but parameters.sensors[" + std::to_string(i) + "] is \"" +
                   sensors[i].name + "\" (the sensors must be in the same order)",
               "uncertainty.sensors[" + std::to_string(i) + "].name");
      }
    }
    if (!r.ok()) return r.status();
  }
  *out = std::move(v);
  return Status::Ok();
}

}  // namespace calibd::results
