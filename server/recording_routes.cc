#include "server/recording_routes.h"

#include <nlohmann/json.hpp>

#include "methods/registry.h"
#include "server/config.h"
#include "server/http_util.h"
#include "server/recording_check.h"
#include "server/recording_segments.h"
#include "web/html.h"
#include "web/recording_page.h"

namespace calibd::server {

using nlohmann::json;

namespace {

bool ParseRecordingId(const std::string& text, int64_t* id) {
  if (text.empty() || text.size() > 18 ||
      text.find_first_not_of("0123456789") != std::string::npos) {
    return false;
  }
  *id = std::stoll(text);
  return *id > 0;
}

// A recording that is not an inertial log cannot be segmented: 422 (valid input, nothing to find).
Status AsNotSegmentable(Status s) {
  if (s.code() == StatusCode::kInvalidInput) {
    return Status(StatusCode::kNotDeterminable, s.message());
  }
  return s;
}

// The query string as given (for the page's links), keys of the segments options only.
std::string EchoQuery(const httplib::Request& req) {
  std::string q;
  for (const auto& [key, value] : req.params) {
    q += (q.empty() ? "" : "&") + UrlEncode(key) + "=" + UrlEncode(value);
  }
  return q;
}

// The page's check section: the methods it offers and, with ?check=METHOD, that check with the
// other query keys as its config (then taken out of *params, the detection options).
void CheckOnPage(storage::Store* store, ColumnCache* cache, int64_t id, int64_t job_memory_bytes,
                 std::multimap<std::string, std::string>* params, web::RecordingPageView* view) {
  for (const Method* m : AllMethods()) {
    if (m->Reads(Layout::kArray) && m->NeedsIncreasingTime())
      view->check_methods.push_back(m->name());
  }
  auto it = params->find("check");
  if (it == params->end()) return;
  view->check_method = it->second;
  std::multimap<std::string, std::string> query = *params;
  query.erase("check");
  query.emplace("method", view->check_method);
  params->clear();
  CheckRequest request;
  request.recording_id = id;
  request.job_memory_bytes = job_memory_bytes;
  request.cache = cache;
  Status s = ParseCheckQuery(query, store, &request);
  if (s.ok()) s = ComputeCheck(store, request, &view->check);
  if (!s.ok()) {
    view->check = nullptr;
    view->check_note = "No check: " + s.message();
  }
}

constexpr size_t kTimelinePoints = 3000;  // per triad: min/max of 1500 buckets
constexpr int kJobPages = 10;             // the page lists jobs among the newest 10 × 500

}  // namespace

void RegisterRecordingRoutes(httplib::Server* http, storage::Store* store, int64_t job_memory_bytes,
                             ColumnCache* cache) {
  http->Get(R"(/api/v1/recordings/([^/]+)/segments)",
            [store, cache](const httplib::Request& req, httplib::Response& res) {
              int64_t id = 0;
              if (!ParseRecordingId(req.matches[1], &id)) {
                SendError(res, 404, "not_found", "no such recording");
                return;
              }
              SegmentsOptions options;
              Status s = ParseSegmentsQuery(req.params, &options);
              if (!s.ok()) return (void)SendStatus(res, s);
              RecordingSegments segments;
              s = ComputeSegments(store, id, options, &segments, cache);
              if (!s.ok()) return (void)SendStatus(res, AsNotSegmentable(s));
              res.set_content(JsonBody(SegmentsJson(segments, options)), "application/json");
            });

  http->Get(R"(/recordings/([^/]+))", [store, job_memory_bytes, cache](const httplib::Request& req,
                                                                       httplib::Response& res) {
    int64_t id = 0;
    if (!ParseRecordingId(req.matches[1], &id)) {
      return SendPage(res, 404, web::RenderErrorPage(404, "no such recording"));
    }
    storage::RecordingInfo info;
    Status s = store->GetRecording(id, &info);
    if (s.code() == StatusCode::kNotFound) {
      return SendPage(res, 404, web::RenderErrorPage(404, "no such recording"));
    }
    if (!s.ok()) {
      return SendPage(res, 503,
                      web::RenderErrorPage(503, "the database is unavailable; try again shortly"));
    }
    web::RecordingPageView view;
    view.id = info.id;
    view.sha256 = info.sha256;
    view.layout = info.layout;
    view.device = info.device;
    view.file_name = info.file_name;
    view.created_at = info.created_at;
    view.bytes = info.bytes;
    view.rows = info.rows;
    json columns;
    if (ParseJsonText(info.columns_json, "columns", &columns).ok() && columns.is_array()) {
      for (const json& c : columns) {
        if (c.is_string()) view.columns.push_back(c.get<std::string>());
      }
    }
    if (!info.log_json.empty()) {
      view.log = json::parse(info.log_json, nullptr, /*allow_exceptions=*/false);
      // A CSV's reading options (config columns) are no log: the API shows them (`csv`).
      if (!view.log.is_object() || view.log.value("format", "") == "csv") view.log = nullptr;
    }
    // ?check=METHOD&<its config keys>: the check before fitting instead of detection options.
    std::multimap<std::string, std::string> segment_params = req.params;
    if (info.layout == LayoutName(Layout::kArray)) {
      CheckOnPage(store, cache, id, job_memory_bytes, &segment_params, &view);
    }
    SegmentsOptions options;
    options.timeline_points = kTimelinePoints;
    s = ParseSegmentsQuery(segment_params, &options);
    view.query = s.ok() && view.check_method.empty() ? EchoQuery(req) : "";
    view.accel_unit_given = s.ok() && req.has_param("accel_unit");
    view.gyro_unit_given = s.ok() && req.has_param("gyro_unit");
    if (s.ok()) {
      RecordingSegments segments;
      s = ComputeSegments(store, id, options, &segments, cache);
      if (s.ok()) {
        view.segments = SegmentsJson(segments, options);
        for (auto& tr : segments.accel_traces) {
          view.accel.push_back({tr.name, std::move(tr.t), std::move(tr.norm)});
        }
        for (auto& tr : segments.gyro_traces) {
          view.gyro.push_back({tr.name, std::move(tr.t), std::move(tr.norm)});
        }
      }
    }
    if (!s.ok()) {
      view.segments_note = s.code() == StatusCode::kInvalidInput
                               ? "No timeline: " + s.message()
                               : "No timeline: the recording could not be read.";
    }
    // Its jobs: the job list has no recording filter, so the newest jobs are scanned.
    storage::JobFilter filter;
    filter.limit = 500;
    for (int page = 0; page < kJobPages; ++page) {
      std::vector<storage::JobInfo> jobs;
      if (!store->ListJobs(filter, &jobs).ok() || jobs.empty()) break;
      for (const auto& job : jobs) {
        if (job.recording_id != id) continue;
        web::JobSummary j;
        j.id = job.id;
        j.status = job.status;
        j.device = job.device;
        j.method = job.method;
        j.created_at = job.created_at;
        view.jobs.push_back(std::move(j));
      }
      if (static_cast<int>(jobs.size()) < filter.limit) break;
      filter.before = jobs.back().id;
    }
    SendPage(res, 200, web::RenderRecordingPage(view));
  });
}

}  // namespace calibd::server
