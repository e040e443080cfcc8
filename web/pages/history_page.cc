// `/`: the calibration history (web/pages.h).
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
#include "web/pages.h"
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

std::string Option(const std::string& value, const std::string& label, const std::string& current) {
  return "<option value=\"" + A(value) + "\"" + (value == current ? " selected" : "") + ">" +
         E(label) + "</option>";
}

std::string FilterQuery(const HistoryFilter& f) {
  std::string q;
  if (!f.device.empty()) q += "&device=" + UrlEncode(f.device);
  if (!f.method.empty()) q += "&method=" + UrlEncode(f.method);
  if (f.status) q += "&status=" + UrlEncode(Name(*f.status));
  if (f.verdict) q += "&verdict=" + UrlEncode(Name(*f.verdict));
  return q;
}

std::string HistoryBody(const HistoryView& v) {
  std::string out =
      "<h1>Calibration history</h1><p class=\"small\"><a href=\"/plan\">Plan a "
      "calibration</a>: the σ a protocol would give, before recording it.</p>";
  out += "<form class=\"filters\" method=\"get\" action=\"/\">";
  out += "<label>device<input type=\"text\" name=\"device\" value=\"" + A(v.filter.device) +
         "\" list=\"devices\" size=\"18\"></label>";
  if (!v.devices.empty()) {
    out += "<datalist id=\"devices\">";
    for (const auto& d : v.devices) out += "<option value=\"" + A(d) + "\">";
    out += "</datalist>";
  }
  out += "<label>method<select name=\"method\">" + Option("", "any", v.filter.method);
  for (const std::string& m : v.methods) out += Option(m, m, v.filter.method);
  if (!v.filter.method.empty() &&
      std::find(v.methods.begin(), v.methods.end(), v.filter.method) == v.methods.end()) {
    out += Option(v.filter.method, v.filter.method, v.filter.method);
  }
  const std::string status = v.filter.status ? Name(*v.filter.status) : "";
  out += "</select></label><label>status<select name=\"status\">" + Option("", "any", status);
  for (JobStatus s :
       {JobStatus::kSucceeded, JobStatus::kFailed, JobStatus::kRunning, JobStatus::kQueued}) {
    out += Option(Name(s), Name(s), status);
  }
  const std::string verdict = v.filter.verdict ? Name(*v.filter.verdict) : "";
  out += "</select></label><label>verdict<select name=\"verdict\">" + Option("", "any", verdict);
  for (ServeState s : {ServeState::kAccepted, ServeState::kRejected, ServeState::kRevoked}) {
    out += Option(Name(s), Name(s), verdict);
  }
  out += "</select></label><button type=\"submit\">Filter</button>";
  out += "<a href=\"/\">clear</a></form>";
  if (!v.filter.device.empty() && (!v.device_matches.empty() || !v.device_hint.empty())) {
    out += "<div class=\"callout device-hint\"><p>";
    if (v.device_matches.empty()) {
      out += E(v.device_hint) + "</p>";
    } else {
      out += "No device is called \xE2\x80\x9C" + E(v.filter.device) + "\xE2\x80\x9D";
      const size_t n = v.device_matches.size();
      out += ": showing " +
             (n == 1 ? std::string("the device")
                     : "the " + std::to_string(n) +
                           (v.device_more > 0 || v.device_more_at_least ? " first" : "") +
                           " devices") +
             " whose serial starts with it (case ignored): ";
      for (size_t i = 0; i < n; ++i) {
        out += (i ? ", " : "") + std::string("<a href=\"") +
               A("/?device=" + UrlEncode(v.device_matches[i])) + "\">" + E(v.device_matches[i]) +
               "</a>";
      }
      out += ".";
      if (v.device_more > 0) {
        out += std::string(v.device_more_at_least ? " At least " : " ") +
               std::to_string(v.device_more) +
               " more devices match: type more of the serial to see theirs.";
      } else if (v.device_more_at_least) {
        out += " More devices may match: type more of the serial to see theirs.";
      }
      out += "</p>";
    }
    out += "</div>";
  }
  if (v.total >= 0) {
    out += "<p class=\"muted small\">" + std::to_string(v.total) + " matching calibrations.</p>";
  }
  if (v.jobs.empty()) {
    out += "<p class=\"empty\">No calibrations match.</p>";
  } else {
    out +=
        "<div class=\"table-wrap\"><table class=\"table-history\"><thead><tr><th>job</th>"
        "<th>device</th><th>method</th><th>status</th><th>created</th><th>key figures</th>"
        "<th class=\"num\">warnings</th></tr></thead><tbody>";
    for (const auto& j : v.jobs) {
      std::string figures;
      if (j.status == JobStatus::kFailed) {
        std::string e = j.error;
        if (e.size() > 90) e = e.substr(0, 90) + "\xE2\x80\xA6";
        figures = "<span class=\"muted\">" + E(e.empty() ? std::string("failed") : e) + "</span>";
      } else {
        figures = E(Guard("figures", [&] { return KeyFigures(j.method, j.result); }));
      }
      // data-label: the column's name, shown before the value where a narrow screen stacks
      // the cells of a row (the stylesheet).
      out += "<tr><td data-label=\"job\">" + JobLink(j.id) +
             "</td><td class=\"name\" data-label=\"device\">" + DeviceLink(j.device) +
             "</td><td data-label=\"method\">" + E(j.method) + "</td><td data-label=\"status\">" +
             StatusBadge(j.status) + VerdictBadge(j) +
             "</td><td class=\"time\" data-label=\"created\">" + TimeHtml(j.created_at) +
             "</td><td data-label=\"key figures\">" + figures + "</td>" + WarningsCell(j) + "</tr>";
    }
    out += "</tbody></table></div>";
  }
  out += "<nav class=\"pager\">";
  if (!v.next_before.empty()) {
    out += "<a class=\"older\" rel=\"next\" href=\"" +
           A("/?before=" + UrlEncode(v.next_before) + FilterQuery(v.filter)) +
           "\">Older calibrations \xE2\x86\x92</a>";
  }
  out += "</nav>";
  return out;
}

}  // namespace calibd::web::internal

namespace calibd::web {

using namespace internal;  // NOLINT: this file is part of internal's pages

DeviceMatch MatchDevices(const std::string& typed, const std::vector<std::string>& known,
                         size_t limit) {
  DeviceMatch m;
  if (typed.empty()) return m;
  if (std::find(known.begin(), known.end(), typed) != known.end()) {
    m.exact = true;
    m.devices = {typed};
    return m;
  }
  const auto lower = [](char c) { return c >= 'A' && c <= 'Z' ? static_cast<char>(c + 32) : c; };
  for (const std::string& serial : known) {
    if (serial.size() < typed.size()) continue;
    bool prefix = true;
    for (size_t i = 0; i < typed.size() && prefix; ++i)
      prefix = lower(serial[i]) == lower(typed[i]);
    if (!prefix) continue;
    if (m.devices.size() < limit) {
      m.devices.push_back(serial);
    } else {
      ++m.more;
    }
  }
  return m;
}

std::string RenderHistoryPage(const HistoryView& view) {
  return SafePage("Calibration history", "page-history", [&] { return HistoryBody(view); });
}

}  // namespace calibd::web
