// `/devices` and `/devices/{serial}` (web/pages.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <exception>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "methods/registry.h"
#include "web/html.h"
#include "web/method_report.h"
#include "web/pages.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

std::string DeviceBody(const DeviceView& v) {
  std::vector<JobSummary> jobs = v.jobs;
  std::sort(jobs.begin(), jobs.end(), OlderFirst);
  std::string out = "<h1>Device " + E(v.serial) + "</h1>";
  std::vector<std::string> methods;
  for (const auto& j : jobs) {
    if (j.status == JobStatus::kSucceeded &&
        std::find(methods.begin(), methods.end(), j.method) == methods.end()) {
      methods.push_back(j.method);
    }
  }
  if (!methods.empty()) {
    out += "<ul class=\"downloads\">";
    for (const auto& m : methods) {
      const std::string base = "/api/v1/devices/" + UrlEncode(v.serial) +
                               "/calibration?method=" + UrlEncode(m) + "&format=";
      out += "<li>Latest " + E(m) + " calibration: " + ExportLinks(base, m) + "</li>";
    }
    out += "</ul>";
  }
  std::string table;
  if (jobs.empty()) {
    table = "<p class=\"empty\">No calibrations for this device.</p>";
  } else {
    table =
        "<div class=\"table-wrap\"><table class=\"table-calibrations\"><thead><tr>"
        "<th class=\"num\">#</th><th>job</th><th>method</th><th>status</th><th>created</th>"
        "<th>key figures</th><th class=\"num\">warnings</th></tr></thead><tbody>";
    for (size_t i = jobs.size(); i-- > 0;) {  // newest first
      const auto& j = jobs[i];
      std::string figures;
      if (j.status == JobStatus::kFailed) {
        std::string e = j.error;
        if (e.size() > 90) e = e.substr(0, 90) + "\xE2\x80\xA6";
        figures = "<span class=\"muted\">" + E(e.empty() ? std::string("failed") : e) + "</span>";
      } else {
        figures = E(Guard("figures", [&] { return KeyFigures(j.method, j.result); }));
      }
      // data-label: see the history page.
      table += "<tr><td class=\"num\" data-label=\"#\">" + std::to_string(i + 1) +
               "</td><td data-label=\"job\">" + JobLink(j.id) + "</td><td data-label=\"method\">" +
               E(j.method) + "</td><td data-label=\"status\">" + StatusBadge(j.status) +
               VerdictBadge(j) + "</td><td class=\"time\" data-label=\"created\">" +
               TimeHtml(j.created_at) + "</td><td data-label=\"key figures\">" + figures + "</td>" +
               WarningsCell(j) + "</tr>";
    }
    table += "</tbody></table></div>";
  }
  out += Section("calibrations", "Calibrations", table);
  std::string drift;
  for (const server::MethodDescriptor& d : server::AllMethodDescriptors()) {
    const MethodReport* report = d.report;
    const std::string m = report->method();
    std::vector<const JobSummary*> ok;
    for (const auto& j : jobs) {
      // Only what production tooling could have fetched: accepted, not revoked.
      if (GateState(j) == ServeState::kAccepted && j.method == m && j.result.is_object())
        ok.push_back(&j);
    }
    if (ok.size() < 2) continue;
    const std::string tables = Guard("Drift", [&] { return report->Drift(ok); });
    if (tables.empty()) continue;  // the method has no drift tables
    drift += "<h3>" + m + " (" + std::to_string(ok.size()) +
             " accepted calibrations; rejected and revoked ones are not compared)</h3>";
    drift += tables;
  }
  if (drift.empty()) {
    drift =
        "<p class=\"muted\">Drift needs at least two accepted (not revoked) calibrations of the "
        "same method.</p>";
  }
  out += Section("drift", "Drift between successive calibrations", drift);
  return out;
}

}  // namespace calibd::web::internal

namespace calibd::web {

using namespace internal;  // NOLINT: this file is part of internal's pages

std::string RenderDevicePage(const DeviceView& view) {
  return SafePage("Device " + view.serial, "page-device", [&] { return DeviceBody(view); });
}

std::string RenderDevicesPage(const DevicesView& view) {
  return SafePage("Devices", "page-devices", [&] {
    std::string out = "<h1>Devices</h1>";
    if (view.devices.empty()) {
      return out +
             "<p>No device has a calibration yet. Upload a recording with "
             "<code>?device=SERIAL</code> (see the README's walkthrough).</p>";
    }
    out += "<p class=\"muted small\">" + std::to_string(view.devices.size()) +
           (view.devices.size() == 1 ? " device" : " devices") +
           ". Each method's column shows its latest calibration: the time links to its report, "
           "JSON to the parameters that production tooling fetches.</p>";
    out +=
        "<div class=\"table-wrap\"><table class=\"table-devices\"><thead><tr>"
        "<th>device (serial)</th><th>first seen (UTC)</th>";
    for (const auto& m : view.methods) out += "<th>latest " + E(m) + " (UTC)</th>";
    out += "</tr></thead><tbody>";
    for (const auto& d : view.devices) {
      out += "<tr><td class=\"name\" data-label=\"device\">" + DeviceLink(d.serial) +
             "</td><td class=\"time\" data-label=\"first seen (UTC)\">" + TimeHtml(d.first_seen) +
             "</td>";
      for (const auto& m : view.methods) {
        const DevicesView::Latest* latest = nullptr;
        for (const auto& l : d.latest) {
          if (l.method == m) latest = &l;
        }
        const std::string label = " data-label=\"" + A("latest " + m) + "\"";
        if (latest == nullptr) {
          out += "<td class=\"muted\"" + label + ">" + std::string(kDash) + "</td>";
          continue;
        }
        out += "<td" + label + "><a class=\"time\" href=\"/jobs/" + std::to_string(latest->job_id) +
               "\">" + TimeHtml(latest->calibrated_at) + "</a><br><span class=\"small\">#" +
               std::to_string(latest->job_id) + " \xC2\xB7 <a href=\"" +
               A("/api/v1/devices/" + UrlEncode(d.serial) + "/calibration?method=" + UrlEncode(m)) +
               "\">JSON</a></span></td>";
      }
      out += "</tr>";
    }
    out += "</tbody></table></div>";
    if (!view.next_after.empty()) {
      out += "<nav class=\"pager\"><a class=\"older\" rel=\"next\" href=\"" +
             A("/devices?after=" + UrlEncode(view.next_after)) +
             "\">More devices \xE2\x86\x92</a></nav>";
    }
    return out;
  });
}

}  // namespace calibd::web
