// The HTML pages of SPEC §5: the server fills web/ view structs from storage and serves the
// rendered documents. No JavaScript; every user string is escaped by web/.
#include <algorithm>
#include <chrono>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "methods/method.h"
#include "methods/registry.h"
#include "server/config.h"
#include "server/device_lookup.h"
#include "server/failure_reasons.h"
#include "server/fleet.h"
#include "server/http_util.h"
#include "storage/store.h"
#include "web/pages.h"

namespace calibd::server {

void SendPage(httplib::Response& res, int status, std::string html) {
  res.status = status;
  res.set_header("Cache-Control", "no-cache");
  res.set_header(
      "Content-Security-Policy",
      "default-src 'none'; style-src 'unsafe-inline'; img-src data:; form-action 'self'");
  res.set_header("X-Content-Type-Options", "nosniff");
  res.set_content(std::move(html), "text/html; charset=utf-8");
}

using nlohmann::json;

namespace {

web::JobSummary Summarize(const storage::JobInfo& job) {
  web::JobSummary s;
  s.id = job.id;
  s.status = job.status;
  s.device = job.device;
  s.method = job.method;
  s.created_at = job.created_at;
  s.started_at = job.started_at;
  s.finished_at = job.finished_at;
  s.attempts = static_cast<int>(job.attempts);
  if (job.status != JobStatus::kSucceeded) s.error = job.error_message;
  if (job.status == JobStatus::kFailed) {
    const FailureReason& reason = StoredFailureReason(job.error_reason, job.error_code);
    s.error_reason = reason.code;
    s.error_title = reason.title;
    s.error_advice = reason.advice;
    if (!job.error_detail_json.empty()) {
      s.error_detail = json::parse(job.error_detail_json, nullptr, /*allow_exceptions=*/false);
      if (s.error_detail.is_discarded()) s.error_detail = json();
    }
  }
  if (!job.result_json.empty()) {
    json result;
    if (ParseJsonText(job.result_json, "result", &result).ok()) s.result = std::move(result);
  }
  s.state = job.state;
  return s;
}

// Summarize plus the revoke/accept decisions, read only where there are some to show (a result
// revoked or accepted by a person), so that a page of ordinary jobs costs no extra queries.
web::JobSummary SummarizeWithEvents(storage::Store* store, const storage::JobInfo& job,
                                    bool always) {
  web::JobSummary s = Summarize(job);
  if (!always && job.decision == Decision::kNone) return s;
  std::vector<storage::JobEvent> events;
  if (store->ListJobEvents(job.id, &events).ok()) {
    for (const auto& e : events) s.events.push_back({e.action, e.reason, e.actor, e.created_at});
  }
  return s;
}

void SendErrorPage(httplib::Response& res, const Status& s) {
  int status = s.code() == StatusCode::kNotFound ? 404 : 500;
  if (s.code() == StatusCode::kBusy || s.code() == StatusCode::kIoError) status = 503;
  SendPage(res, status,
           web::RenderErrorPage(status, status == 404 ? s.message()
                                                      : "the database is unavailable; "
                                                        "try again shortly"));
}

bool ParsePositive(const std::string& text, int64_t* out) {
  if (text.empty() || text.size() > 18 ||
      text.find_first_not_of("0123456789") != std::string::npos) {
    return false;
  }
  *out = std::stoll(text);
  return *out > 0;
}

}  // namespace

namespace {

// The history page's device field and filter: serials offered, devices listed for a prefix,
// serials read at most to find them.
constexpr int kOfferedDevices = 200;
constexpr size_t kListedDevices = 20;
constexpr size_t kMatchReads = 1000;

// The history's device field and filter: offers the first kOfferedDevices serials (a page view
// reads a bounded number of devices, however many there are) and reads the filter. Returns the
// devices whose jobs are listed: the exact serial when a device has it, else every device whose
// serial starts with what was typed, ignoring case (web::MatchDevices's rule, read from the
// store a bounded number at a time), listed together; {""} (any device) without a filter.
std::vector<std::string> FilterDevices(storage::Store* store, web::HistoryView* view) {
  storage::DeviceFilter offered;
  offered.limit = kOfferedDevices;
  std::vector<storage::DeviceInfo> devices;
  if (store->ListDevices(offered, &devices).ok()) {
    for (const auto& d : devices) view->devices.push_back(d.serial);
  }
  const std::string& typed = view->filter.device;
  web::DeviceMatch match;
  bool complete = true;
  if (typed.empty() ||
      !MatchStoredDevices(store, typed, kListedDevices, kMatchReads, &match, &complete).ok()) {
    return {typed};
  }
  if (!match.exact && !match.devices.empty()) {
    view->device_matches = match.devices;
    view->device_more = match.more;
    view->device_more_at_least = !complete;
    return match.devices;
  }
  if (match.devices.empty()) {
    view->device_hint = SimilarDeviceMessage(store, typed);
    if (view->device_hint.empty()) {
      view->device_hint = "No device is called \xE2\x80\x9C" + typed +
                          "\xE2\x80\x9D, and no device's serial starts with it (case "
                          "ignored): pick one from the list the device field offers.";
    }
  }
  return {typed};
}

}  // namespace

void RegisterHtmlRoutes(httplib::Server* http, storage::Store* store, bool token_required) {
  http->Get("/", [store](const httplib::Request& req, httplib::Response& res) {
    web::HistoryView view;
    storage::JobFilter filter;
    filter.limit = 50;
    filter.include_results = true;
    view.filter.device = req.get_param_value("device");
    const std::string method = req.get_param_value("method");
    const std::string status = req.get_param_value("status");
    if (FindMethod(method) != nullptr) view.filter.method = filter.method = method;
    view.methods.clear();
    for (const Method* m : AllMethods()) view.methods.push_back(m->name());
    JobStatus parsed_status;
    if (Parse(status, &parsed_status)) view.filter.status = filter.status = parsed_status;
    const std::string verdict = req.get_param_value("verdict");
    ServeState state;
    if (!verdict.empty() && Parse(verdict, &state)) view.filter.verdict = filter.state = state;
    if (req.has_param("before") && !ParsePositive(req.get_param_value("before"), &filter.before)) {
      return SendPage(res, 400, web::RenderErrorPage(400, "'before' must be a job id"));
    }
    const std::vector<std::string> listed = FilterDevices(store, &view);
    // One page, newest first, over the listed devices: each one's newest `limit` jobs before
    // the cursor, merged by id (the cursor is a job id, so it pages the merged list as well).
    std::vector<storage::JobInfo> jobs;
    bool more = false;
    view.total = 0;
    for (const std::string& device : listed) {
      filter.device = device;
      std::vector<storage::JobInfo> part;
      Status s = store->ListJobs(filter, &part);
      if (!s.ok()) return SendErrorPage(res, s);
      more = more || static_cast<int>(part.size()) == filter.limit;
      jobs.insert(jobs.end(), std::make_move_iterator(part.begin()),
                  std::make_move_iterator(part.end()));
      int64_t count = 0;
      if (view.total >= 0 && store->CountJobs(filter, &count).ok()) {
        view.total += count;
      } else {
        view.total = -1;
      }
    }
    std::sort(jobs.begin(), jobs.end(),
              [](const storage::JobInfo& a, const storage::JobInfo& b) { return a.id > b.id; });
    if (jobs.size() > static_cast<size_t>(filter.limit)) {
      jobs.resize(static_cast<size_t>(filter.limit));
      more = true;
    }
    for (const auto& job : jobs) view.jobs.push_back(SummarizeWithEvents(store, job, false));
    if (more && !jobs.empty()) view.next_before = std::to_string(jobs.back().id);
    SendPage(res, 200, web::RenderHistoryPage(view));
  });

  http->Get(R"(/jobs/([^/]+))",
            [store, token_required](const httplib::Request& req, httplib::Response& res) {
              int64_t id = 0;
              if (!ParsePositive(req.matches[1], &id)) {
                return SendPage(res, 404, web::RenderErrorPage(404, "no such job"));
              }
              storage::JobInfo job;
              Status s = store->GetJob(id, &job);
              if (!s.ok()) return SendErrorPage(res, s);
              web::JobView view;
              view.job = SummarizeWithEvents(store, job, true);
              view.recording_id = job.recording_id;
              view.token_required = token_required;
              if (job.status == JobStatus::kRunning && job.started_at_ms > 0) {
                const int64_t now = std::chrono::duration_cast<std::chrono::milliseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count();
                view.elapsed_ms = std::max<int64_t>(0, now - job.started_at_ms);
              }
              storage::RecordingInfo rec;
              if (store->GetRecording(job.recording_id, &rec).ok()) {
                view.recording_sha256 = rec.sha256;
                view.recording_bytes = rec.bytes;
                view.recording_rows = rec.rows;
              }
              json config;
              if (ParseJsonText(job.config_json, "config", &config).ok())
                view.config = std::move(config);
              SendPage(res, 200, web::RenderJobPage(view));
            });

  http->Get("/devices", [store](const httplib::Request& req, httplib::Response& res) {
    // A page of devices (the default limit, 100), after= the last serial of the previous one.
    storage::DeviceFilter filter;
    filter.after = ToNfc(req.get_param_value("after"));
    std::vector<storage::DeviceInfo> devices;
    Status s = store->ListDevices(filter, &devices);
    if (!s.ok()) return SendErrorPage(res, s);
    web::DevicesView view;
    view.methods.clear();
    for (const Method* m : AllMethods()) view.methods.push_back(m->name());
    for (const auto& d : devices) {
      web::DevicesView::Device row{d.serial, d.first_seen, {}};
      for (const auto& c : d.latest) row.latest.push_back({c.method, c.job_id, c.calibrated_at});
      view.devices.push_back(std::move(row));
    }
    if (static_cast<int>(devices.size()) == filter.limit) view.next_after = devices.back().serial;
    SendPage(res, 200, web::RenderDevicesPage(view));
  });

  http->Get(R"(/devices/([^/]+))", [store](const httplib::Request& req, httplib::Response& res) {
    web::DeviceView view;
    view.serial = ToNfc(std::string(req.matches[1]));  // serials are stored in NFC
    storage::JobFilter filter;
    filter.device = view.serial;
    filter.limit = 500;
    filter.include_results = true;
    std::vector<storage::JobInfo> jobs;
    Status s = store->ListJobs(filter, &jobs);
    if (!s.ok()) return SendErrorPage(res, s);
    if (jobs.empty()) {
      const std::string hint = SimilarDeviceMessage(store, view.serial);
      return SendPage(
          res, 404,
          web::RenderErrorPage(
              404, hint.empty() ? "no calibrations for device '" + view.serial + "'" : hint));
    }
    for (const auto& job : jobs) view.jobs.push_back(SummarizeWithEvents(store, job, false));
    SendPage(res, 200, web::RenderDevicePage(view));
  });

  http->Get(R"(/products/([^/]+))", [store](const httplib::Request& req, httplib::Response& res) {
    web::FleetView view;
    if (Status s = NormalizeProduct(std::string(req.matches[1]), &view.product); !s.ok()) {
      return SendErrorPage(res, s);
    }
    for (const Method* m : AllMethods()) view.methods.push_back(m->name());
    const std::string method = req.get_param_value("method");
    if (FindMethod(method) != nullptr) {
      view.method = method;
      if (Status s = FleetJson(store, view.product, method, FleetOptions(), &view.fleet); !s.ok()) {
        return SendErrorPage(res, s);
      }
    }
    SendPage(res, 200, web::RenderFleetPage(view));
  });
}

}  // namespace calibd::server
