// POST /api/v1/plan (SPEC §10, server/plan.h).
#include "server/plan.h"

#include <cstdlib>
#include <string>

#include "methods/plan.h"
#include "methods/registry.h"
#include "server/config.h"
#include "server/service_impl.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// kInvalidInput of the config with its field under "config.".
Status InConfig(const Status& s) {
  if (s.ok() || s.field().empty() || s.field() == "method" || s.field().rfind("config.", 0) == 0 ||
      s.field().rfind("protocol.", 0) == 0) {
    return s;
  }
  return Status::InvalidInput(s.message()).WithField("config." + s.field());
}

// The orientations typed on the page: names and [x, y, z] vectors separated by spaces or commas.
json TypedOrientations(const std::string& text) {
  json out = json::array();
  size_t i = 0;
  while (i < text.size()) {
    const char c = text[i];
    if (c == ' ' || c == ',' || c == '\t' || c == '\n' || c == '\r') {
      ++i;
    } else if (c == '[') {
      const size_t end = text.find(']', i);
      const std::string item = text.substr(i, end == std::string::npos ? end : end - i + 1);
      json v = json::parse(item, nullptr, /*allow_exceptions=*/false);
      out.push_back(v.is_discarded() ? json(item) : v);
      i = end == std::string::npos ? text.size() : end + 1;
    } else {
      const size_t end = text.find_first_of(" ,\t\r\n[", i);
      out.push_back(text.substr(i, end == std::string::npos ? end : end - i));
      i = end == std::string::npos ? text.size() : end;
    }
  }
  return out;
}

// A typed number, or the text itself (the protocol's check then names the field).
json TypedNumber(const std::string& text) {
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  if (!text.empty() && end == text.c_str() + text.size()) return x;
  return text;
}

}  // namespace

Status PlanJson(const json& request, const json& acceptance_defaults, json* out) {
  if (!request.is_object()) {
    return Status::InvalidInput(
        "the plan request must be a JSON object {\"method\", \"config\", \"protocol\"}");
  }
  for (const auto& [key, value] : request.items()) {
    (void)value;
    if (key != "method" && key != "config" && key != "protocol") {
      return Status::InvalidInput("unknown key '" + key.substr(0, 64) +
                                  "' (expected method, config, protocol)")
          .WithField(key.substr(0, 64));
    }
  }
  const auto m = request.find("method");
  const Method* method =
      m != request.end() && m->is_string() ? FindMethod(m->get<std::string>()) : nullptr;
  if (method == nullptr) {
    return Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method");
  }
  json config = request.value("config", json::object());
  if (!config.is_object()) {
    return Status::InvalidInput("config must be a JSON object").WithField("config");
  }
  if (!config.contains("method")) config["method"] = method->name();
  if (config["method"] != method->name()) {
    return Status::InvalidInput("config.method must be the request's method (or left out)")
        .WithField("config.method");
  }
  PlanProtocol protocol;
  if (Status s = ParsePlanProtocol(request.value("protocol", json()), &protocol); !s.ok()) {
    return s;
  }
  CommonConfig common;
  if (Status s = ValidateConfig(config, &common); !s.ok()) {
    // A method without a plan says so first, whatever its config lacks.
    json ignored;
    const Status probe = method->Plan(json::object(), protocol, AcceptanceLimits(), &ignored);
    return probe.field() == "method" ? probe : InConfig(s);
  }
  const AcceptanceLimits limits = EffectiveAcceptance(method->name(), acceptance_defaults, config);
  if (Status s = method->Plan(WithoutAcceptance(config), protocol, limits, out); !s.ok()) {
    return InConfig(s);
  }
  (*out)["limits"] = limits.ToJson();
  return Status::Ok();
}

web::PlanView PlanPageView(const std::multimap<std::string, std::string>& params,
                           storage::Store* store, const json& acceptance_defaults) {
  web::PlanView view;
  for (const Method* m : AllMethods()) view.methods.push_back(m->name());
  for (const PlanCandidate& c : PlanCandidates()) view.candidates.push_back(c.name);
  view.method = view.methods.front();
  view.config = R"({"nominal": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "noise_std": 0.01})";
  view.orientations = "+x -x +y -y +z -z";
  view.static_duration = "3";
  view.rate = "100";
  view.rotation_duration = "2";
  if (params.count("method") == 0) return view;
  view.orientations.clear();
  for (const auto& [key, value] : params) {
    if (key == "method") view.method = value;
    if (key == "config") view.config = value;
    if (key == "orientations") view.orientations = value;
    if (key == "o") view.checked.push_back(value);
    if (key == "static_duration") view.static_duration = value;
    if (key == "rate") view.rate = value;
    if (key == "rotation_duration") view.rotation_duration = value;
    if (key == "t_min") view.t_min = value;
    if (key == "t_max") view.t_max = value;
    if (key == "temperature_rate") view.temperature_rate = value;
    if (key == "imus") view.imus = value;
    if (key == "angular_rate") view.angular_rate = value;
    if (key == "angular_acceleration") view.angular_acceleration = value;
    if (key == "rotation_axis") view.rotation_axis = value;
    if (key == "duration") view.duration = value;
  }
  json request = {{"method", view.method}};
  json protocol = {{"orientations", json::array()}};
  for (const std::string& c : view.checked) protocol["orientations"].push_back(c);
  for (const json& o : TypedOrientations(view.orientations)) protocol["orientations"].push_back(o);
  // A thermal warm-up or an array's motion may have no orientations (methods/plan.h).
  if (protocol["orientations"].empty() && (!view.t_min.empty() || !view.angular_rate.empty())) {
    protocol.erase("orientations");
  }
  if (const json axis = TypedOrientations(view.rotation_axis); !axis.empty()) {
    protocol["rotation_axis"] = axis[0];
  }
  for (const auto& [key, text] :
       {std::pair<const char*, const std::string*>{"static_duration", &view.static_duration},
        {"rate", &view.rate},
        {"rotation_duration", &view.rotation_duration},
        {"t_min", &view.t_min},
        {"t_max", &view.t_max},
        {"temperature_rate", &view.temperature_rate},
        {"imus", &view.imus},
        {"angular_rate", &view.angular_rate},
        {"angular_acceleration", &view.angular_acceleration},
        {"duration", &view.duration}}) {
    if (!text->empty()) protocol[key] = TypedNumber(*text);
  }
  request["protocol"] = protocol;
  json config;
  Status s = ParseJsonText(view.config.empty() ? "{}" : view.config, "config", &config);
  if (s.ok() && config.is_object()) {
    if (!config.contains("method")) config["method"] = view.method;
    s = InConfig(ResolveJobReferences(store, &config));
  }
  if (s.ok()) {
    request["config"] = config;
    s = PlanJson(request, acceptance_defaults, &view.plan);
  }
  if (!s.ok()) {
    view.error = s.message();
    view.plan = json();
  }
  return view;
}

void Service::Impl::HandlePlan(const httplib::Request& req, httplib::Response& res) {
  json body;
  Status s = ParseJsonText(req.body, "request body", &body);
  if (!s.ok()) return (void)SendStatus(res, s);
  if (body.is_object() && body.contains("config") && body["config"].is_object()) {
    json& config = body["config"];
    if (!config.contains("method") && body.contains("method")) config["method"] = body["method"];
    s = ResolveJobReferences(store.get(), &config);
    if (!s.ok()) return (void)SendStatus(res, InConfig(s));
  }
  json out;
  s = PlanJson(body, acceptance, &out);
  if (!s.ok()) return (void)SendStatus(res, s);
  res.set_content(JsonBody(out), "application/json");
}

}  // namespace calibd::server
