#include "results/envelope.h"

#include <algorithm>
#include <string>
#include <utility>

namespace calibd::results {

using nlohmann::json;

void ReadEnvelope(const JsonReader& r, const char* method, int newest, Envelope* out) {
  Envelope e;
  r.Read("method", &e.method);
  if (r.ok() && e.method != method) {
    r.Fail("expected \"" + std::string(method) + "\", found \"" + e.method + "\"", "method");
  }
  std::optional<int> version;
  r.Read("schema_version", &version);
  e.schema_version = version.value_or(1);
  if (r.ok() && (e.schema_version < 1 || e.schema_version > newest)) {
    r.Fail(
        "version " + std::to_string(e.schema_version) +
            (e.schema_version > newest ? " is newer than this calibd reads (up to " +
                                             std::to_string(newest) + "): upgrade calibd to read it"
                                       : " does not exist (versions start at 1)"),
        "schema_version");
  }
  std::optional<bool> usable;
  r.Read("usable", &usable);
  e.usable = usable.value_or(true);
  if (e.usable) {
    r.Read("model", &e.model);
  } else {
    std::optional<std::string> model;
    r.Read("model", &model);
    e.model = model.value_or("");
  }
  if (std::optional<JsonReader> v = r.OptionalObject("verdict")) {
    StoredVerdict verdict;
    std::string status;
    v->Read("status", &status);
    if (v->ok() && !Parse(status, &verdict.status)) {
      v->Fail("expected \"accepted\" or \"rejected\", found \"" + status + "\"", "status");
    }
    if (v->ok() && verdict.status == GateVerdict::kNone) {
      v->Fail("expected \"accepted\" or \"rejected\", found \"\"", "status");
    }
    v->Read("reasons", &verdict.reasons);
    if (std::optional<JsonReader> limits = v->OptionalObject("limits")) {
      for (const auto& [key, value] : limits->node().items()) {
        std::optional<double> limit;
        limits->Read(key, &limit);
        verdict.limits[key] = limit;
      }
    }
    e.verdict = std::move(verdict);
  }
  std::optional<std::vector<std::string>> warnings;
  r.Read("warnings", &warnings);
  e.warnings = warnings.value_or(std::vector<std::string>());
  if (r.ok()) *out = std::move(e);
}

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

bool ContainsKey(const std::vector<std::string>& keys, const char* key) {
  return std::find(keys.begin(), keys.end(), key) != keys.end();
}

bool DroppedMember(const JsonReader& d, const std::vector<std::string>& dropped, const char* key) {
  if (!ContainsKey(dropped, key) || !d.node().is_object()) return false;
  auto it = d.node().find(key);
  return it == d.node().end() || it->is_null();
}

json VerdictJson(const StoredVerdict& v) {
  json limits = json::object();
  for (const auto& [key, value] : v.limits) limits[key] = Num(value);
  return {{"status", Name(v.status)}, {"reasons", v.reasons}, {"limits", std::move(limits)}};
}

void WriteEnvelope(const Envelope& e, int version, json* out) {
  (*out)["method"] = e.method;
  (*out)["schema_version"] = version;
  if (!e.usable) (*out)["usable"] = false;
  if (e.usable || !e.model.empty()) (*out)["model"] = e.model;
  if (e.verdict) (*out)["verdict"] = VerdictJson(*e.verdict);
  (*out)["warnings"] = e.warnings;
}

}  // namespace calibd::results
