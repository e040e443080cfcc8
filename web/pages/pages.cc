// `/jobs/{id}`, the report of one job, and the error page (web/pages.h).
#include "web/pages.h"

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
#include "web/report_common.h"
#include "web/svg_plot.h"

namespace calibd::web::internal {

// The export formats of a method's calibration (GET .../calibration?format=), from the method's
// registry entry (Method::ExportFormats).
std::string ExportLinks(const std::string& base, const std::string& method) {
  std::string out = "<a href=\"" + A(base + "json") + "\">JSON</a>";
  if (const server::Method* m = server::FindMethod(method)) {
    for (const server::ExportFormat& f : m->ExportFormats()) {
      out += " \xC2\xB7 <a href=\"" + A(base + f.format) + "\">" + E(f.label) + "</a>";
    }
  }
  return out;
}

std::string TimingsHtml(const JobSummary& job) {
  const double c = Seconds(job.created_at), s = Seconds(job.started_at),
               f = Seconds(job.finished_at);
  std::string out = "<dt>created</dt><dd>" + TimeHtml(job.created_at, true) + "</dd>";
  out += "<dt>started</dt><dd>" + TimeHtml(job.started_at, true);
  if (std::isfinite(c) && std::isfinite(s)) out += " (waited " + FormatDuration(s - c) + ")";
  out += "</dd><dt>finished</dt><dd>" + TimeHtml(job.finished_at, true);
  if (std::isfinite(s) && std::isfinite(f)) out += " (ran " + FormatDuration(f - s) + ")";
  out += "</dd><dt>attempts</dt><dd>" + std::to_string(job.attempts) + "</dd>";
  return out;
}

std::string DownloadsHtml(const JobView& view) {
  const JobSummary& job = view.job;
  std::string out = "<ul class=\"downloads\">";
  out += "<li><a href=\"/api/v1/jobs/" + std::to_string(job.id) +
         "\">This job and its result (JSON)</a></li>";
  if (view.recording_id > 0) {
    out += "<li><a href=\"/api/v1/recordings/" + std::to_string(view.recording_id) +
           "/data\">Recording (original CSV)</a></li>";
  }
  if (!job.device.empty() && !job.method.empty()) {
    const std::string base = "/api/v1/devices/" + UrlEncode(job.device) +
                             "/calibration?method=" + UrlEncode(job.method) + "&format=";
    out += "<li>Latest " + E(job.method) + " calibration of " + E(job.device) +
           " (may be newer than this report): " + ExportLinks(base, job.method) + "</li>";
  }
  return out + "</ul>";
}

std::string StatusCallout(const JobView& view) {
  const JobSummary& job = view.job;
  if (job.status == JobStatus::kFailed) {
    // The reason's title (looked up by code), the method's own message (what it needed and
    // found), and the catalog's advice for the reason: each said once.
    std::string out =
        "<div class=\"callout callout-error\"><p><strong>The calibration failed" +
        (job.error_title.empty() ? std::string(".") : ": " + E(job.error_title)) + "</strong>" +
        (job.error_reason.empty()
             ? std::string()
             : " <span class=\"mono small failure-code\">" + E(job.error_reason) + "</span>") +
        "</p><p class=\"failure-reason\">" +
        (job.error.empty() ? std::string("No reason was recorded.") : E(job.error)) + "</p>";
    if (!job.error_advice.empty()) {
      out += "<p class=\"failure-advice\"><strong>What to do:</strong> " + E(job.error_advice) +
             "</p>";
    }
    if (job.error_detail.is_object()) {
      out +=
          "<p class=\"muted small\">What the method found before failing is shown under <a "
          "href=\"#partial\">Before the failure</a>.</p>";
    }
    return out + "</div>";
  }
  if (job.status == JobStatus::kQueued || job.status == JobStatus::kRunning) {
    return "<div class=\"callout\"><p>This job is " + E(Name(job.status)) +
           ". Reload the page to see the result when it has finished.</p></div>";
  }
  if (job.status == JobStatus::kSucceeded) {
    const size_t w = WarningCount(job.result);
    if (w > 0) {
      return "<div class=\"callout callout-warn\"><p><strong>Succeeded with " + std::to_string(w) +
             (w == 1 ? " warning" : " warnings") +
             "</strong>: read them under <a href=\"#diagnostics\">Diagnostics</a> before using "
             "these parameters.</p></div>";
    }
    return "<div class=\"callout callout-ok\"><p><strong>Succeeded</strong> without warnings."
           "</p></div>";
  }
  return "";
}

std::string VerdictSection(const JobSummary& job) {
  const ServeState state = GateState(job);
  if (state == ServeState::kNone) return "";
  const json* verdict = Get(job.result, "verdict");
  std::string out;
  const json* reasons = Array(Get(verdict, "reasons"));
  const std::string gate = Str(Get(verdict, "status"));
  if (state == ServeState::kAccepted) {
    out += "<div class=\"callout callout-ok verdict\"><p><strong>Accepted</strong>" +
           std::string(gate == "rejected" ? " by a person, overriding the acceptance gate"
                                          : " by the acceptance gate") +
           ": this result is served as the device's calibration when it is the latest "
           "accepted one.</p>";
  } else if (state == ServeState::kRejected) {
    out +=
        "<div class=\"callout callout-error verdict\"><p><strong>Rejected by the acceptance "
        "gate</strong>: this result is never served to production tooling. Record again "
        "as advised, or accept it with a reason (POST /api/v1/jobs/" +
        std::to_string(job.id) + "/accept).</p>";
  } else {
    out +=
        "<div class=\"callout callout-warn verdict\"><p><strong>Revoked</strong>: withdrawn "
        "by a person; the device's calibration fell back to its previous accepted one.</p>";
  }
  if (reasons != nullptr && !reasons->empty()) {
    out += "<p>The gate's reasons:</p><ul class=\"verdict-reasons\">";
    for (const auto& r : *reasons)
      out += "<li>" + E(r.is_string() ? r.get<std::string>() : r.dump()) + "</li>";
    out += "</ul>";
  }
  out += "</div>";
  if (!job.events.empty()) {
    out +=
        "<div class=\"table-wrap\"><table class=\"table-events\"><thead><tr><th>when</th>"
        "<th>decision</th><th>by</th><th>reason</th></tr></thead><tbody>";
    for (const auto& e : job.events) {
      out += "<tr><td class=\"time\">" + TimeHtml(e.at) + "</td><td>" + E(e.action) + "</td><td>" +
             E(e.actor) + "</td><td>" + E(e.reason) + "</td></tr>";
    }
    out += "</tbody></table></div>";
  }
  return out;
}

// A queued or running job: its elapsed time (running) and a form that cancels it (a plain POST,
// no JavaScript; the server answers 303 back to this page).
std::string CancelHtml(const JobView& view) {
  const JobSummary& job = view.job;
  if (job.status != JobStatus::kQueued && job.status != JobStatus::kRunning) return "";
  std::string out = "<div class=\"callout job-stop\">";
  if (job.status == JobStatus::kRunning) {
    char text[64];
    if (view.elapsed_ms >= 0) {
      std::snprintf(text, sizeof text, "%.1f s", static_cast<double>(view.elapsed_ms) / 1e3);
    } else {
      std::snprintf(text, sizeof text, "?");
    }
    out += "<p>Running for <span class=\"elapsed\">" + std::string(text) +
           "</span> (reload the page to update).</p>";
  } else {
    out += "<p>Waiting for a worker.</p>";
  }
  const std::string id = std::to_string(job.id);
  out += "<form class=\"cancel-job\" method=\"post\" action=\"/api/v1/jobs/" + id +
         "/cancel\"><label>Reason <input type=\"text\" name=\"reason\" required maxlength=\"500\" "
         "placeholder=\"why stop this job\"></label> ";
  if (view.token_required) {
    out +=
        "<label>Token <input type=\"password\" name=\"token\" required "
        "autocomplete=\"current-password\"></label> ";
  }
  out += "<button type=\"submit\">Cancel job #" + id + "</button></form></div>";
  return out;
}

std::string JobBody(const JobView& view) {
  const JobSummary& job = view.job;
  std::string out;
  out += "<h1>Calibration #" + std::to_string(job.id) + " \xC2\xB7 " +
         E(job.method.empty() ? std::string("?") : job.method) +
         (job.device.empty() ? "" : " \xC2\xB7 " + E(job.device)) + " " + StatusBadge(job.status) +
         (GateState(job) == ServeState::kRejected || GateState(job) == ServeState::kRevoked
              ? " <span class=\"badge badge-" + std::string(Name(GateState(job))) + "\">" +
                    Name(GateState(job)) + "</span>"
              : std::string()) +
         "</h1>";
  out += VerdictSection(job);
  out += StatusCallout(view);
  out += CancelHtml(view);
  // Header facts.
  std::string kv = "<dl class=\"kv job-header\"><dt>device</dt><dd>" + DeviceLink(job.device) +
                   "</dd><dt>method</dt><dd>" + E(job.method) + "</dd><dt>status</dt><dd>" +
                   StatusBadge(job.status) + "</dd><dt>recording</dt><dd>";
  if (view.recording_id > 0) {
    kv += "<a href=\"/api/v1/recordings/" + std::to_string(view.recording_id) + "/data\">#" +
          std::to_string(view.recording_id) + " (download CSV)</a>";
    if (view.recording_bytes >= 0)
      kv += ", " + FormatSI(static_cast<double>(view.recording_bytes), "B");
    if (view.recording_rows >= 0) kv += ", " + std::to_string(view.recording_rows) + " rows";
    if (!view.recording_sha256.empty()) {
      kv += ", <span class=\"mono small\">sha256 " + E(view.recording_sha256.substr(0, 16)) +
            "\xE2\x80\xA6</span>";
    }
    kv += " \xC2\xB7 <a href=\"/recordings/" + std::to_string(view.recording_id) +
          "\">recording page</a>";
  } else {
    kv += kDash;
  }
  kv += "</dd>";
  // An array job that used a pca calibration of its accelerometers links to it (issue #8).
  const json* accel_cal = Get(Get(job.result, "diagnostics"), "accelerometer_calibration");
  if (accel_cal != nullptr && accel_cal->is_object()) {
    kv += "<dt>accelerometers</dt><dd class=\"accelerometer-calibration\">";
    const json* cal_job = Get(accel_cal, "job");
    if (cal_job != nullptr && cal_job->is_number_integer()) {
      const std::string id = std::to_string(cal_job->get<int64_t>());
      kv +=
          "corrected with the pca calibration of <a href=\"/jobs/" + id + "\">job #" + id + "</a>";
    } else {
      kv += "corrected with a pca calibration given inline";
    }
    const json* sensors = Get(accel_cal, "sensors");
    if (sensors != nullptr && sensors->is_number_integer()) {
      kv += " (" + std::to_string(sensors->get<int64_t>()) + " sensors)";
    }
    kv += "</dd>";
  }
  // Noise levels taken from noise jobs ({"job": ID} in the config) link to them (SPEC §7).
  const json* noise_jobs = Get(Get(job.result, "diagnostics"), "noise_jobs");
  if (noise_jobs != nullptr && noise_jobs->is_object()) {
    std::string links;
    for (const char* sensor : {"accelerometer", "gyroscope"}) {
      const json* id = Get(noise_jobs, sensor);
      if (id == nullptr || !id->is_number_integer()) continue;
      const std::string n = std::to_string(id->get<int64_t>());
      links += std::string(links.empty() ? "" : "; ") + sensor + " from <a href=\"/jobs/" + n +
               "\">noise job #" + n + "</a>";
    }
    if (!links.empty()) kv += "<dt>noise levels</dt><dd class=\"noise-jobs\">" + links + "</dd>";
  }
  kv += TimingsHtml(job) + "</dl>";
  out += kv;
  if (!view.config.is_null()) {
    const std::string pretty = PrettyJson(view.config);
    const bool short_config = std::count(pretty.begin(), pretty.end(), '\n') <= 24;
    out += std::string("<details") + (short_config ? " open" : "") +
           "><summary>Configuration</summary><pre class=\"config\">" + E(pretty) +
           "</pre></details>";
  }
  out += Section("downloads", "Downloads", DownloadsHtml(view));
  const bool has_result = job.result.is_object() && !job.result.empty();
  if (has_result) {
    std::string method = Str(Get(job.result, "method"));
    if (method.empty()) method = job.method;
    // The equation that applies the parameters to a raw reading (result key `model`).
    const std::string model = Str(Get(job.result, "model"));
    out += Section("model", "Model",
                   model.empty() ? NotAvailable("The model statement")
                                 : "<p class=\"model\">" + E(model) + "</p>");
    if (const MethodReport* report = FindMethodReport(method)) {
      out += report->Section(view);
    } else {
      out += NotAvailable("A report for method \"" + method + "\"");
    }
    out += Guard("Diagnostics", [&] { return DiagnosticsSection(job.result); });
  } else if (job.status == JobStatus::kSucceeded) {
    out += NotAvailable("The result");
  }
  if (job.status == JobStatus::kFailed && job.error_detail.is_object() &&
      !job.error_detail.empty()) {
    // The partial diagnostics (diagnostics.usable == false): the method's report draws what it
    // can, then the table of every key.
    std::string method = Str(Get(job.error_detail, "method"));
    if (method.empty()) method = job.method;
    std::string body;
    if (const MethodReport* report = FindMethodReport(method)) {
      body = Guard("The partial report", [&] { return report->Partial(view); });
    }
    const json* trimmed = Get(job.error_detail, "trimmed");
    if (trimmed != nullptr) {
      body += "<p class=\"muted small\">" + E(Str(Get(trimmed, "note"))) + "</p>";
    }
    out += Section("partial", "Before the failure",
                   "<p>What the method found before it stopped.</p>" + body);
    out += Guard("Diagnostics", [&] { return DiagnosticsSection(job.error_detail); });
  }
  return out;
}

}  // namespace calibd::web::internal

namespace calibd::web {

using namespace internal;  // NOLINT: this file is part of internal's pages

std::string KeyFigures(const std::string& method, const json& result) {
  if (!result.is_object()) return kDash;
  std::string m = Str(Get(result, "method"));
  if (m.empty()) m = method;
  const MethodReport* report = FindMethodReport(m);
  const std::string figures = report != nullptr ? report->KeyFigures(result) : "";
  return figures.empty() ? kDash : figures;
}

std::string RenderJobPage(const JobView& view) {
  const std::string title = "Calibration #" + std::to_string(view.job.id) +
                            (view.job.device.empty() ? "" : " \xC2\xB7 " + view.job.device);
  return SafePage(title, "page-job", [&] { return JobBody(view); });
}

std::string RenderErrorPage(int status, const std::string& message) {
  std::string reason;
  switch (status) {
    case 400:
      reason = "Bad request";
      break;
    case 401:
      reason = "Unauthorized";
      break;
    case 404:
      reason = "Not found";
      break;
    case 405:
      reason = "Method not allowed";
      break;
    case 422:
      reason = "Cannot be calibrated";
      break;
    case 500:
      reason = "Internal error";
      break;
    case 503:
      reason = "Overloaded";
      break;
    default:
      reason = "Error";
  }
  try {
    const std::string body =
        "<h1>" + std::to_string(status) + " \xC2\xB7 " + reason +
        "</h1><div class=\"callout callout-error\"><p class=\"error-message\">" + E(message) +
        "</p></div><p><a href=\"/\">Back to the calibration "
        "history</a></p>";
    return RenderPage(std::to_string(status) + " " + reason, "page-error", body);
  } catch (...) {
    return "<!doctype html><title>Error</title><p>Error</p>";
  }
}

}  // namespace calibd::web
