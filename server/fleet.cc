#include "server/fleet.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <utility>
#include <vector>

#include "core/fleet_stats.h"
#include "methods/acceptance.h"
#include "methods/method.h"
#include "methods/registry.h"
#include "results/json_text.h"
#include "server/device_lookup.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using results::ParseJsonText;

struct Member {
  std::string device;
  int64_t job_id = 0;
  std::string calibrated_at;  // ISO 8601, UTC
  std::map<std::string, double> values;
};

// Every finite number under `j`, named by its path (see server/fleet.h).
void Flatten(const json& j, const std::string& path, std::map<std::string, double>* out) {
  if (j.is_number()) {
    const double v = j.get<double>();
    if (std::isfinite(v)) (*out)[path] = v;
  } else if (j.is_object()) {
    for (const auto& [key, value] : j.items())
      Flatten(value, path.empty() ? key : path + "/" + key, out);
  } else if (j.is_array()) {
    for (size_t i = 0; i < j.size(); ++i) {
      const json& e = j[i];
      std::string key = std::to_string(i);
      if (e.is_object() && e.contains("name") && e["name"].is_string()) {
        key = e["name"].get<std::string>();
      }
      Flatten(e, path.empty() ? key : path + "/" + key, out);
    }
  }
}

// Whether `path` matches one of `patterns` ('*' one segment); every path when there are none.
bool Selected(const std::string& path, const std::vector<std::string>& patterns) {
  if (patterns.empty()) return true;
  auto split = [](const std::string& text) {
    std::vector<std::string> parts;
    size_t start = 0;
    for (size_t slash; (slash = text.find('/', start)) != std::string::npos; start = slash + 1) {
      parts.push_back(text.substr(start, slash - start));
    }
    parts.push_back(text.substr(start));
    return parts;
  };
  const std::vector<std::string> segments = split(path);
  for (const std::string& pattern : patterns) {
    const std::vector<std::string> want = split(pattern);
    if (want.size() != segments.size()) continue;
    bool match = true;
    for (size_t i = 0; match && i < want.size(); ++i)
      match = want[i] == "*" || want[i] == segments[i];
    if (match) return true;
  }
  return false;
}

std::map<std::string, double> FleetValues(const json& result, const std::string& method);

Status CollectMembers(storage::Store* store, const std::string& product, const std::string& method,
                      const FleetOptions& options, std::vector<Member>* members, int64_t* scanned,
                      bool* complete) {
  storage::DeviceFilter filter;
  filter.limit = 1000;
  *scanned = 0;
  *complete = true;
  while (true) {
    std::vector<storage::DeviceInfo> page;
    if (Status s = store->ListDevices(filter, &page); !s.ok()) return s;
    for (const storage::DeviceInfo& d : page) {
      if (*scanned >= options.max_devices) {
        *complete = false;
        return Status::Ok();
      }
      ++*scanned;
      const bool has =
          std::any_of(d.latest.begin(), d.latest.end(),
                      [&](const storage::DeviceCalibration& c) { return c.method == method; });
      if (!has) continue;
      storage::JobInfo job;
      Status s = store->LatestResult(d.serial, method, &job);
      if (s.code() == StatusCode::kNotFound) continue;  // none served (rejected or revoked)
      if (!s.ok()) return s;
      json config, result;
      if (!ParseJsonText(job.config_json, "config", &config).ok() || !config.is_object()) continue;
      const auto p = config.find("product");
      if (p == config.end() || !p->is_string() || p->get_ref<const std::string&>() != product) {
        continue;
      }
      if (!ParseJsonText(job.result_json, "result", &result).ok()) continue;
      members->push_back({d.serial, job.id, job.finished_at, FleetValues(result, method)});
    }
    if (static_cast<int>(page.size()) < filter.limit) return Status::Ok();
    filter.after = page.back().serial;
  }
}

json ZValue(double z) { return std::isfinite(z) ? json(z) : json(z > 0 ? "inf" : "-inf"); }

// core::RobustZCritical(n, p), computed once per (n, p) per process (about 20 ms each).
double CalibratedFleetZ(int64_t n, double p) {
  static std::mutex& mu = *new std::mutex;
  static auto& cache = *new std::map<std::pair<int64_t, double>, double>;
  std::lock_guard<std::mutex> lock(mu);
  auto it = cache.find({n, p});
  if (it == cache.end())
    it = cache.emplace(std::make_pair(n, p), core::RobustZCritical(n, p)).first;
  return it->second;
}

// The parameters of `result` the method's FleetParameters select, by their fleet names.
std::map<std::string, double> FleetValues(const json& result, const std::string& method) {
  std::map<std::string, double> all, selected;
  if (result.contains("parameters")) Flatten(result["parameters"], "", &all);
  const std::vector<std::string> patterns = FindMethod(method)->FleetParameters();
  for (const auto& [name, v] : all) {
    if (Selected(name, patterns)) selected[name] = v;
  }
  return selected;
}

}  // namespace

Status NormalizeProduct(std::string_view raw, std::string* out) {
  Status s = NormalizeSerial(raw, out);
  if (s.ok()) return s;
  std::string message = s.message();
  if (message.rfind("'device'", 0) == 0) message = "'product'" + message.substr(8);
  return Status::InvalidInput(message).WithField("product");
}

Status FleetJson(storage::Store* store, const std::string& product, const std::string& method,
                 const FleetOptions& options, json* out) {
  std::vector<Member> members;
  int64_t scanned = 0;
  bool complete = true;
  if (Status s = CollectMembers(store, product, method, options, &members, &scanned, &complete);
      !s.ok()) {
    return s;
  }
  // Every parameter name any member has, in name order.
  std::map<std::string, std::vector<std::pair<const Member*, double>>> by_name;
  for (const Member& m : members) {
    for (const auto& [name, v] : m.values) by_name[name].push_back({&m, v});
  }
  json parameters = json::array();
  std::map<const Member*, std::pair<std::vector<std::string>, double>> flagged;
  for (const auto& [name, entries] : by_name) {
    std::vector<double> values;
    for (const auto& e : entries) values.push_back(e.second);
    const core::RobustSummary s = core::Summarize(values, options.bins);
    // The summary includes the device judged (its z shrinks a little: conservative).
    const double threshold =
        options.outlier_false_alarm > 0
            ? CalibratedFleetZ(
                  std::max<int64_t>(s.n - 1, 3),
                  core::SidakLevel(options.outlier_false_alarm, static_cast<int>(by_name.size())))
            : options.outlier_z;
    json outliers = json::array();
    for (const auto& [m, v] : entries) {
      const double z = core::RobustZ(v, s);
      if (s.n < options.min_devices || !(std::abs(z) > threshold)) continue;
      outliers.push_back(
          {{"device", m->device}, {"job_id", m->job_id}, {"value", v}, {"z", ZValue(z)}});
      auto& f = flagged[m];
      f.first.push_back(name);
      f.second = std::max(f.second, std::abs(z));
    }
    parameters.push_back({{"name", name},
                          {"n", s.n},
                          {"median", s.median},
                          {"spread", s.spread},
                          {"min", s.min},
                          {"max", s.max},
                          {"threshold", s.n < options.min_devices ? json() : ZValue(threshold)},
                          {"histogram", {{"edges", s.edges}, {"counts", s.counts}}},
                          {"outliers", outliers}});
  }
  json device_outliers = json::array();
  json member_list = json::array();
  std::map<std::string, std::vector<const Member*>> by_month;
  for (const Member& m : members) {
    member_list.push_back(
        {{"device", m.device}, {"job_id", m.job_id}, {"calibrated_at", m.calibrated_at}});
    by_month[m.calibrated_at.substr(0, 7)].push_back(&m);
    if (auto f = flagged.find(&m); f != flagged.end()) {
      device_outliers.push_back({{"device", m.device},
                                 {"job_id", m.job_id},
                                 {"parameters", f->second.first},
                                 {"max_abs_z", ZValue(f->second.second)}});
    }
  }
  json drift = json::array();
  for (const auto& [month, ms] : by_month) {
    json medians = json::object();
    for (const auto& [name, entries] : by_name) {
      std::vector<double> values;
      for (const Member* m : ms) {
        if (auto v = m->values.find(name); v != m->values.end()) values.push_back(v->second);
      }
      if (!values.empty()) medians[name] = core::Summarize(values, 1).median;
    }
    drift.push_back({{"month", month}, {"devices", ms.size()}, {"median", medians}});
  }
  *out = {{"product", product},
          {"method", method},
          {"devices", members.size()},
          {"scanned", scanned},
          {"complete", complete},
          {"outlier_false_alarm", options.outlier_false_alarm},
          {"outlier_z", options.outlier_false_alarm > 0 ? json() : json(options.outlier_z)},
          {"members", member_list},
          {"parameters", parameters},
          {"outliers", device_outliers},
          {"drift", drift}};
  return Status::Ok();
}

Status ApplyFleetGate(storage::Store* store, const std::string& method, const std::string& device,
                      const json& config, const json& acceptance_defaults,
                      const FleetOptions& options, json* result) {
  if (!result->is_object() || !result->contains("verdict") || !config.is_object()) {
    return Status::Ok();
  }
  const AcceptanceLimits limits = EffectiveAcceptance(method, acceptance_defaults, config);
  const std::optional<double> max_z = limits.Get(limit_keys::kMaxFleetZ.name);
  const std::optional<double> alpha = limits.Get(limit_keys::kMaxFleetFalseAlarm.name);
  const auto product = config.find("product");
  if ((!max_z && !alpha) || product == config.end() || !product->is_string()) return Status::Ok();
  std::vector<Member> members;
  int64_t scanned = 0;
  bool complete = true;
  if (Status s = CollectMembers(store, product->get<std::string>(), method, options, &members,
                                &scanned, &complete);
      !s.ok()) {
    return s;
  }
  members.erase(std::remove_if(members.begin(), members.end(),
                               [&](const Member& m) { return m.device == device; }),
                members.end());
  json judged = json::array();
  std::vector<double> zs;
  for (const auto& [name, value] : FleetValues(*result, method)) {
    std::vector<double> values;
    for (const Member& m : members) {
      if (auto v = m.values.find(name); v != m.values.end()) values.push_back(v->second);
    }
    if (static_cast<int64_t>(values.size()) < options.min_devices) continue;
    const core::RobustSummary s = core::Summarize(values, 1);
    zs.push_back(core::RobustZ(value, s));
    judged.push_back({{"name", name},
                      {"value", value},
                      {"median", s.median},
                      {"spread", s.spread},
                      {"n", s.n},
                      {"z", ZValue(zs.back())}});
  }
  // Each parameter's threshold: max_fleet_z, or the one calibrated to max_fleet_false_alarm for
  // its fleet size and the number judged, whichever is smaller.
  Offenders offenders;
  const int m = static_cast<int>(judged.size());
  for (size_t i = 0; i < judged.size(); ++i) {
    json& j = judged[i];
    double threshold = max_z.value_or(std::numeric_limits<double>::infinity());
    if (alpha && *alpha > 0) {
      threshold =
          std::min(threshold, CalibratedFleetZ(j["n"].get<int64_t>(), core::SidakLevel(*alpha, m)));
    }
    j["threshold"] = ZValue(threshold);
    const double z = zs[i];
    if (std::abs(z) > threshold) {
      offenders.Add(j["name"].get<std::string>() + " (z " +
                    (std::isfinite(z) ? Fmt(z) : std::string(z > 0 ? "+inf" : "-inf")) + " above " +
                    Fmt(threshold) + ")");
    }
  }
  std::string rules = max_z ? "max_fleet_z " + Fmt(*max_z) : "";
  if (alpha) {
    rules += (rules.empty() ? "" : ", ") + std::string("max_fleet_false_alarm ") + Fmt(*alpha);
  }
  json& verdict = (*result)["verdict"];
  Verdict fleet;
  offenders.RejectInto(&fleet, "outside the fleet of product '" + product->get<std::string>() +
                                   "' (" + std::to_string(members.size()) + " other devices; " +
                                   rules + ")");
  if (!fleet.accepted()) {
    verdict["status"] = "rejected";
    if (!verdict.contains("reasons") || !verdict["reasons"].is_array()) {
      verdict["reasons"] = json::array();
    }
    for (const std::string& r : fleet.reasons()) verdict["reasons"].push_back(r);
  }
  if (result->contains("diagnostics") && (*result)["diagnostics"].is_object()) {
    json d = {{"product", *product},
              {"devices", members.size()},
              {"max_fleet_z", max_z ? json(*max_z) : json()},
              {"max_fleet_false_alarm", alpha ? json(*alpha) : json()},
              {"judged", !judged.empty()},
              {"parameters", judged}};
    if (judged.empty()) {
      d["note"] = "not judged: no parameter is known for " + std::to_string(options.min_devices) +
                  " or more other devices of the product";
    }
    (*result)["diagnostics"]["fleet"] = d;
  }
  return Status::Ok();
}

}  // namespace calibd::server
