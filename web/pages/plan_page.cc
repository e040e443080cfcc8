// The plan page (web/pages.h RenderPlanPage).
#include <cmath>
#include <cstdio>
#include <string>
#include <tuple>
#include <vector>

#include "web/html.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web {
namespace {

using internal::A;
using internal::E;
using internal::SafePage;
using nlohmann::json;

std::string Option(const std::string& value, const std::string& selected) {
  return "<option value=\"" + A(value) + "\"" + (value == selected ? " selected" : "") + ">" +
         E(value) + "</option>";
}

std::string Form(const PlanView& v) {
  std::string out = "<form class=\"plan-form\" method=\"get\" action=\"/plan\">";
  out += "<label>method<select name=\"method\">";
  for (const std::string& m : v.methods) out += Option(m, v.method);
  out += "</select></label>";
  out +=
      "<label>static duration (s)<input type=\"text\" name=\"static_duration\" size=\"6\" "
      "value=\"" +
      A(v.static_duration) + "\"></label>";
  out += "<label>rate (Hz)<input type=\"text\" name=\"rate\" size=\"6\" value=\"" + A(v.rate) +
         "\"></label>";
  out += "<label>rotation (s)<input type=\"text\" name=\"rotation_duration\" size=\"6\" value=\"" +
         A(v.rotation_duration) + "\"></label>";
  out +=
      "<p class=\"small\">thermal: a warm-up at rest from t_min to t_max at a steady rate. "
      "mag: config field (µT), mag_noise, dip; the orientations are attitudes in a level "
      "frame (x north), held still, with the turns between them logged.</p>";
  for (const auto& [name, label, value] :
       {std::tuple<const char*, const char*, const std::string*>{"t_min", "t_min (°C)", &v.t_min},
        {"t_max", "t_max (°C)", &v.t_max},
        {"temperature_rate", "rate (°C/min)", &v.temperature_rate},
        {"imus", "IMUs", &v.imus}}) {
    out += "<label>" + E(label) + "<input type=\"text\" name=\"" + A(name) +
           "\" size=\"6\" value=\"" + A(*value) + "\"></label>";
  }
  out +=
      "<p class=\"small\">array: free motion at |ω| (rad/s) and |ω̇| (rad/s²), about random "
      "axes or one rotation axis (a name such as +z), for a duration (s).</p>";
  for (const auto& [name, label, value] :
       {std::tuple<const char*, const char*, const std::string*>{"angular_rate", "|ω| (rad/s)",
                                                                 &v.angular_rate},
        {"angular_acceleration", "|ω̇| (rad/s²)", &v.angular_acceleration},
        {"rotation_axis", "rotation axis", &v.rotation_axis},
        {"duration", "duration (s)", &v.duration}}) {
    out += "<label>" + E(label) + "<input type=\"text\" name=\"" + A(name) +
           "\" size=\"6\" value=\"" + A(*value) + "\"></label>";
  }
  out +=
      "<p class=\"small\">Orientations: the direction pointing up (along the field), in the "
      "sensors' axes. Tick directions and/or type names or vectors, in order.</p><p>";
  for (const std::string& c : v.candidates) {
    bool on = false;
    for (const std::string& k : v.checked) on = on || k == c;
    out += "<label class=\"small\"><input type=\"checkbox\" name=\"o\" value=\"" + A(c) + "\"" +
           (on ? " checked" : "") + ">" + E(c) + "</label> ";
  }
  out +=
      "</p><label>orientations<input type=\"text\" name=\"orientations\" size=\"60\" "
      "value=\"" +
      A(v.orientations) + "\" placeholder=\"+x -x +y [0.5, 0.5, 0.7]\"></label>";
  out += "<label>config (JSON)<textarea name=\"config\" rows=\"4\" cols=\"70\">" + E(v.config) +
         "</textarea></label><button type=\"submit\">Plan</button></form>";
  return out;
}

std::string Number(const json& x) {
  return x.is_number() ? FormatSig(x.get<double>(), 3) : "<span class=\"muted\">—</span>";
}

// One row per number of the uncertainty object: its path (named array entries by name).
void SigmaRows(const json& x, const std::string& path, std::string* rows) {
  if (x.is_object()) {
    for (const auto& [key, value] : x.items()) {
      if (key == "name") continue;
      SigmaRows(value, path.empty() ? key : path + "." + key, rows);
    }
  } else if (x.is_array() && !x.empty() && x[0].is_object() && x[0].contains("name")) {
    for (const json& item : x) {
      SigmaRows(item, path + "[" + item["name"].get<std::string>() + "]", rows);
    }
  } else if (x.is_array() && !x.empty() && x[0].is_array()) {
    for (size_t i = 0; i < x.size(); ++i)
      SigmaRows(x[i], path + "[" + std::to_string(i) + "]", rows);
  } else if (x.is_array()) {
    std::string cells;
    for (const json& v : x) cells += (cells.empty() ? "" : ", ") + Number(v);
    *rows += "<tr><td>" + E(path) + "</td><td class=\"num\">" + cells + "</td></tr>";
  } else if (x.is_number() || x.is_null()) {
    *rows += "<tr><td>" + E(path) + "</td><td class=\"num\">" + Number(x) + "</td></tr>";
  }
}

std::string SigmaTable(const json& uncertainty, const std::string& cls) {
  if (!uncertainty.is_object()) return "<p class=\"muted\">No σ: see what is undetermined.</p>";
  std::string rows;
  SigmaRows(uncertainty, "", &rows);
  return "<table class=\"" + cls +
         "\"><thead><tr><th>quantity</th><th>predicted 1σ</th></tr>"
         "</thead><tbody>" +
         rows + "</tbody></table>";
}

// Dots of the orientations on two disks: the upper (z >= 0) hemisphere seen from +z, the lower
// seen from −z (x mirrored so both are seen from outside).
std::string Sphere(const json& protocol, const json& suggested) {
  const double r = 80, cy = 100, cx[2] = {100, 300};
  std::string out =
      "<svg class=\"sphere\" width=\"400\" height=\"210\" viewBox=\"0 0 400 210\" role=\"img\">"
      "<title>orientations on the sphere: left seen from +z, right from -z</title>";
  char buf[320];
  for (int h = 0; h < 2; ++h) {
    std::snprintf(buf, sizeof buf,
                  "<circle cx=\"%.0f\" cy=\"%.0f\" r=\"%.0f\" fill=\"none\" stroke=\"#888\"/>"
                  "<text x=\"%.0f\" y=\"205\" text-anchor=\"middle\" font-size=\"11\">%s</text>",
                  cx[h], cy, r, cx[h], h == 0 ? "seen from +z" : "seen from \xE2\x88\x92z");
    out += buf;
  }
  auto dots = [&](const json& list, const char* color, bool filled) {
    if (!list.is_array()) return;
    for (const json& o : list) {
      const json& d = o["direction"];
      const double x = d[0].get<double>(), y = d[1].get<double>(), z = d[2].get<double>();
      const int h = z >= -1e-9 ? 0 : 1;
      const double px = cx[h] + r * (h == 0 ? x : -x), py = cy - r * y;
      std::snprintf(buf, sizeof buf,
                    "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%d\" fill=\"%s\" stroke=\"%s\"/>", px, py,
                    filled ? 4 : 7, filled ? color : "none", color);
      out += buf;
      if (filled) {
        std::snprintf(buf, sizeof buf, "<text x=\"%.1f\" y=\"%.1f\" font-size=\"9\">", px + 5,
                      py - 5);
        out += buf + E(o["name"].get<std::string>()) + "</text>";
      }
    }
  };
  dots(protocol, "#1f77b4", false);
  dots(suggested, "#d62728", true);
  return out +
         "</svg><p class=\"small\">Open blue circles: your protocol; red dots: the "
         "suggestion.</p>";
}

std::string Result(const PlanView& v) {
  if (!v.error.empty()) {
    return "<div class=\"callout-error\"><p>" + E(v.error) + "</p></div>";
  }
  if (v.plan.is_null()) return "";
  const json& p = v.plan;
  std::string out = "<h2>Predicted σ of your protocol</h2>" +
                    SigmaTable(p.value("uncertainty", json()), "table-plan");
  const json undetermined = p.value("undetermined", json::array());
  if (!undetermined.empty()) {
    out += "<h2>Not determined</h2><ul class=\"undetermined\">";
    for (const json& u : undetermined) {
      std::string params;
      for (const json& n : u["parameters"])
        params += (params.empty() ? "" : ", ") + n.get<std::string>();
      for (const json& m : u["missing"]) out += "<li>" + E(m.get<std::string>()) + "</li>";
      if (!params.empty()) out += "<li>undetermined: " + E(params) + "</li>";
    }
    out += "</ul>";
  }
  const json suggested = p.value("suggested", json());
  json suggested_orientations;
  if (suggested.is_object()) {
    suggested_orientations = suggested["orientations"];
    out += "<h2>Suggested protocol</h2><p class=\"small\">" +
           E(suggested.value("design", std::string())) + "</p><p class=\"suggested\">";
    if (suggested_orientations.is_array()) {
      for (const json& o : suggested_orientations) out += E(o["name"].get<std::string>()) + " ";
    }
    out += "</p>";
    // thermal: the warm-up (methods/thermal/thermal_plan.cc Suggest).
    if (suggested.contains("temperature_rate")) {
      out += "<p class=\"suggested-ramp\">" + Number(suggested["t_min"]) + " → " +
             Number(suggested["t_max"]) + " °C at " + Number(suggested["temperature_rate"]) +
             " °C/min (" + Number(suggested["duration"]) + " s)</p>";
    }
    // array: the motion (methods/array/array_plan.cc Suggest), after the statics for the full
    // model (array_full_plan.cc).
    if (suggested.contains("angular_rate")) {
      out += "<p class=\"suggested-motion\">" +
             (suggested.contains("static_duration")
                  ? "each static held " + Number(suggested["static_duration"]) + " s, then "
                  : std::string()) +
             Number(suggested["duration"]) + " s at |ω| " + Number(suggested["angular_rate"]) +
             " rad/s, |ω̇| " + Number(suggested["angular_acceleration"]) +
             " rad/s², about random axes, " + Number(suggested["rate"]) + " Hz</p>";
    }
    out += suggested.value("meets_limits", false)
               ? "<p>Meets the gate's limits.</p>"
               : "<p class=\"callout-error\">Does not meet every limit:</p>";
    for (const json& u : suggested.value("unmet", json::array())) {
      out += "<p class=\"small\">" + E(u.get<std::string>()) + "</p>";
    }
    // imu: one position less, and why it fails (methods/imu/imu_plan.h SuggestImu).
    if (const json fewer = suggested.value("fewer", json()); fewer.is_object()) {
      out += "<p class=\"fewer small\">With " + std::to_string(fewer.value("positions", 0)) +
             " positions the limits are not met:";
      for (const json& u : fewer.value("unmet", json::array())) {
        out += " " + E(u.get<std::string>());
      }
      out += "</p>";
    }
    out += SigmaTable(suggested.value("uncertainty", json()), "table-plan-suggested");
  }
  out += Sphere(p["protocol"]["orientations"], suggested_orientations);
  for (const json& n : p.value("notes", json::array())) {
    out += "<p class=\"small muted\">" + E(n.get<std::string>()) + "</p>";
  }
  return out;
}

}  // namespace

std::string RenderPlanPage(const PlanView& view) {
  return SafePage("Plan a calibration", "page-plan", [&] {
    return "<h1>Plan a calibration</h1><p class=\"small\">The σ a calibration would report for "
           "a protocol, before recording it (POST /api/v1/plan).</p>" +
           Form(view) + Result(view);
  });
}

}  // namespace calibd::web
