// The fleet page (web/pages.h RenderFleetPage).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "web/html.h"
#include "web/pages.h"
#include "web/report_common.h"

namespace calibd::web {
namespace {

using internal::A;
using internal::DeviceLink;
using internal::E;
using internal::JobLink;
using internal::NumCell;
using nlohmann::json;

double Number(const json& j) {
  return j.is_number() ? j.get<double>() : std::numeric_limits<double>::quiet_NaN();
}

std::string ZText(const json& z) {
  if (z.is_string())
    return z.get<std::string>() == "inf" ? "+\xE2\x88\x9E" : "\xE2\x88\x92\xE2\x88\x9E";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%+.1f", Number(z));
  return buf;
}

// The histogram as bars, 96 × 20 px, its title the bins' edges and counts.
std::string Histogram(const json& h) {
  const json& counts = h["counts"];
  const json& edges = h["edges"];
  if (!counts.is_array() || counts.empty()) return "";
  int64_t top = 1;
  for (const json& c : counts) top = std::max<int64_t>(top, c.get<int64_t>());
  const double width = 96.0 / static_cast<double>(counts.size());
  std::string title;
  std::string bars;
  for (size_t b = 0; b < counts.size(); ++b) {
    const int64_t c = counts[b].get<int64_t>();
    const double height = 20.0 * static_cast<double>(c) / static_cast<double>(top);
    char rect[160];
    std::snprintf(rect, sizeof rect, "<rect x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\"/>",
                  width * static_cast<double>(b), 20 - height, std::max(width - 1, 0.5), height);
    bars += rect;
    if (b + 1 < edges.size()) {
      title += FormatSig(Number(edges[b]), 4) + " to " + FormatSig(Number(edges[b + 1]), 4) + ": " +
               std::to_string(c) + "\n";
    }
  }
  return "<svg class=\"hist\" width=\"96\" height=\"20\" viewBox=\"0 0 96 20\" role=\"img\">"
         "<title>" +
         E(title) + "</title><g fill=\"currentColor\">" + bars + "</g></svg>";
}

std::string OutlierList(const json& outliers) {
  std::string out;
  for (const json& o : outliers) {
    if (!out.empty()) out += "<br>";
    out += DeviceLink(o["device"].get<std::string>()) + " " + E(ZText(o["z"])) + "\xCF\x83";
  }
  return out.empty() ? "<span class=\"muted\">none</span>" : out;
}

std::string MethodLinks(const FleetView& view) {
  std::string out = "<p class=\"small\">Method: ";
  for (size_t i = 0; i < view.methods.size(); ++i) {
    const std::string& m = view.methods[i];
    if (i) out += " \xC2\xB7 ";
    out += m == view.method
               ? "<strong>" + E(m) + "</strong>"
               : "<a href=\"" +
                     A("/products/" + UrlEncode(view.product) + "?method=" + UrlEncode(m)) + "\">" +
                     E(m) + "</a>";
  }
  return out + "</p>";
}

}  // namespace

std::string RenderFleetPage(const FleetView& view) {
  return internal::SafePage("Fleet " + view.product, "page-fleet", [&] {
    const json& f = view.fleet;
    std::string out = "<h1>Fleet of product " + E(view.product) + "</h1>" + MethodLinks(view);
    if (view.method.empty() || !f.is_object()) return out + "<p>Choose a method above.</p>";
    const int64_t devices = f.value("devices", int64_t{0});
    if (devices == 0) {
      return out + "<p>No device of this product has a served " + E(view.method) +
             " calibration. Uploads name their product with <code>product=NAME</code>.</p>";
    }
    out += "<p class=\"muted small\">" + std::to_string(devices) +
           (devices == 1 ? " device" : " devices") +
           ": each one's latest served calibration. A unit is flagged when a parameter lies more "
           "than " +
           (f["outlier_z"].is_number() ? FormatSig(Number(f["outlier_z"]), 3)
                                       : std::string("the threshold (column \"flag at |z|\")")) +
           " robust standard deviations (1.4826 \xC3\x97 the median absolute deviation) from "
           "the fleet's median" +
           (f["outlier_z"].is_number()
                ? std::string()
                : ", set per parameter for the fleet's size so that a unit like the others is "
                  "flagged with probability " +
                      FormatSig(Number(f["outlier_false_alarm"]), 2) + " over all its parameters") +
           "; parameters known for fewer than " +
           std::to_string(f.value("min_devices", int64_t{0})) + " devices flag none." +
           (f.value("complete", true) ? "" : " Only part of the devices was scanned.") + "</p>";
    out += "<h2>Flagged units</h2>";
    if (f["outliers"].empty()) {
      out += "<p>None.</p>";
    } else {
      out += "<ul class=\"flagged\">";
      for (const json& o : f["outliers"]) {
        std::string names;
        for (const json& n : o["parameters"])
          names += (names.empty() ? "" : ", ") + E(n.get<std::string>());
        out += "<li>" + DeviceLink(o["device"].get<std::string>()) + " (" +
               JobLink(o["job_id"].get<int64_t>()) + "): " + names + "; largest |z| " +
               E(ZText(o["max_abs_z"])) + "</li>";
      }
      out += "</ul>";
    }
    out +=
        "<h2>Parameters</h2><div class=\"table-wrap\"><table class=\"table-fleet\"><thead><tr>"
        "<th>parameter</th><th class=\"num\">devices</th><th class=\"num\">median</th>"
        "<th class=\"num\">spread</th><th class=\"num\">flag at |z|</th>"
        "<th class=\"num\">min</th><th class=\"num\">max</th>"
        "<th>distribution</th><th>outliers (z)</th></tr></thead><tbody>";
    for (const json& p : f["parameters"]) {
      out += "<tr><td class=\"name\">" + E(p["name"].get<std::string>()) + "</td>" +
             NumCell(std::to_string(p["n"].get<int64_t>())) + NumCell(Number(p["median"]), 6) +
             NumCell(Number(p["spread"]), 3) +
             (p.contains("threshold") && p["threshold"].is_number()
                  ? NumCell(Number(p["threshold"]), 3)
                  : NumCell(std::string("\xE2\x80\x94"))) +
             NumCell(Number(p["min"]), 6) + NumCell(Number(p["max"]), 6) + "<td>" +
             Histogram(p["histogram"]) + "</td><td>" + OutlierList(p["outliers"]) + "</td></tr>";
    }
    out += "</tbody></table></div>";
    // The members, linked (the first kMaxListed; the JSON has them all).
    constexpr size_t kMaxListed = 300;
    out += "<h2>Units</h2><p class=\"members small\">";
    size_t listed = 0;
    for (const json& m : f["members"]) {
      if (listed == kMaxListed) break;
      out += std::string(listed++ ? " \xC2\xB7 " : "") +
             DeviceLink(m["device"].get<std::string>()) + " (" +
             JobLink(m["job_id"].get<int64_t>()) + ")";
    }
    if (f["members"].size() > kMaxListed) {
      out += " \xC2\xB7 and " + std::to_string(f["members"].size() - kMaxListed) + " more";
    }
    out += "</p>";
    out += "<p class=\"small\"><a href=\"" +
           A("/api/v1/products/" + UrlEncode(view.product) +
             "/fleet?method=" + UrlEncode(view.method)) +
           "\">JSON</a> (with the monthly medians and the members).</p>";
    return out;
  });
}

}  // namespace calibd::web
