// The API's jobs, decisions, devices, exports and recordings (server/service_impl.h).
#include <iostream>

#include "methods/registry.h"
#include "server/service_impl.h"

namespace calibd::server {

using nlohmann::json;

namespace {

// The id of the path's {id} (req.matches[1]); false after answering 404 "no such <what>".
bool PathId(const httplib::Request& req, httplib::Response& res, const char* what, int64_t* id) {
  if (ParseId(req.matches[1], id)) return true;
  SendError(res, 404, "not_found", std::string("no such ") + what);
  return false;
}

// The recording of the path's {id}, and that id; false after answering 404 or the store's error.
bool PathRecording(storage::Store* store, const httplib::Request& req, httplib::Response& res,
                   int64_t* id, storage::RecordingInfo* info) {
  if (!PathId(req, res, "recording", id)) return false;
  const Status s = store->GetRecording(*id, info);
  if (!s.ok()) SendStatus(res, s);
  return s.ok();
}

// The person's reason of a decision or cancel, trimmed: kInvalidInput (field "reason") when
// empty (`missing` says what it is for), over 500 bytes, or with control characters.
Status CheckReason(const std::string& missing, std::string* text) {
  constexpr size_t kMaxReason = 500;
  while (!text->empty() && isspace(static_cast<unsigned char>(text->back()))) text->pop_back();
  size_t first = 0;
  while (first < text->size() && isspace(static_cast<unsigned char>((*text)[first]))) ++first;
  text->erase(0, first);
  if (text->empty()) return Status::InvalidInput(missing).WithField("reason");
  if (text->size() > kMaxReason) {
    return Status::InvalidInput("'reason' has " + std::to_string(text->size()) +
                                " bytes; at most " + std::to_string(kMaxReason))
        .WithField("reason");
  }
  for (unsigned char ch : *text) {
    if (ch < 0x20 && ch != '\t') {
      return Status::InvalidInput("'reason' may not contain control characters")
          .WithField("reason");
    }
  }
  return Status::Ok();
}

bool IsCancelPath(const std::string& path) {
  static const std::string kPrefix = "/api/v1/jobs/", kSuffix = "/cancel";
  if (path.size() <= kPrefix.size() + kSuffix.size()) return false;
  if (path.compare(0, kPrefix.size(), kPrefix) != 0) return false;
  if (path.compare(path.size() - kSuffix.size(), kSuffix.size(), kSuffix) != 0) return false;
  const std::string id = path.substr(kPrefix.size(), path.size() - kPrefix.size() - kSuffix.size());
  return id.find('/') == std::string::npos;
}

bool IsFormMedia(const httplib::Request& req) {
  return ToLower(req.get_header_value("Content-Type"))
             .rfind("application/x-www-form-urlencoded", 0) == 0;
}

// The reason of a JSON decision body {"reason": "..."} (revoke, accept, cancel: `action`) into
// *text, untrimmed; false after answering 415 / 400 (an empty body says that the action needs a
// reason; other keys, a non-object or a non-string reason are named). An absent reason leaves
// *text empty (CheckReason then says it is required).
bool ReadJsonReason(const httplib::Request& req, httplib::Response& res, const std::string& action,
                    std::string* text) {
  const std::string media = ToLower(req.get_header_value("Content-Type"));
  if (media.rfind("application/json", 0) != 0) {
    SendError(res, 415, "unsupported_media_type",
              "send {\"reason\": \"...\"} as application/json" +
                  std::string(action == "cancel" ? " (or the job page's form as "
                                                   "application/x-www-form-urlencoded)"
                                                 : ""));
    return false;
  }
  if (req.body.find_first_not_of(" \t\r\n") == std::string::npos) {
    SendStatus(res, Status::InvalidInput("the body is empty: a " + action +
                                         " needs a reason, sent as {\"reason\": \"...\"}")
                        .WithField("reason"));
    return false;
  }
  json body;
  Status s = ParseJsonText(req.body, "request body", &body);
  if (!s.ok()) {
    SendStatus(res, s);
    return false;
  }
  if (!body.is_object()) {
    SendError(res, 400, "invalid_input", "the body must be a JSON object {\"reason\": \"...\"}");
    return false;
  }
  for (auto& [key, value] : body.items()) {
    if (key != "reason") {
      SendStatus(res,
                 Status::InvalidInput("unknown key '" + key.substr(0, 64) + "' (expected reason)")
                     .WithField(key.substr(0, 64)));
      return false;
    }
  }
  auto reason = body.find("reason");
  if (reason != body.end() && !reason->is_string()) {
    SendStatus(res, Status::InvalidInput("'reason' must be a string: say why").WithField("reason"));
    return false;
  }
  if (reason != body.end()) *text = reason->get<std::string>();
  return true;
}

}  // namespace

bool Service::Impl::IsCancelForm(const httplib::Request& req) {
  return req.method == "POST" && IsCancelPath(req.path) && IsFormMedia(req);
}

// POST /api/v1/jobs/{id}/cancel: {"reason": "..."} as JSON (the token, if any, in the
// Authorization header: the request filter checked it), or the job page's HTML form (reason, and
// token when the server has one; answered with 303 back to the job page). A queued job fails at
// once (200); a running one is asked to stop (202): at once in this process, within the worker
// pools' cancel poll (250 ms) in another process on the same database. 409 for a finished job.
void Service::Impl::HandleCancel(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  if (!PathId(req, res, "job", &id)) return;
  const bool form = IsFormMedia(req);
  std::string text;
  if (form) {
    // A form is a "simple" cross-site request (no CORS preflight): refuse one that a page of
    // another origin made the browser send (browsers send Origin with every form POST).
    const std::string origin = req.get_header_value("Origin");
    if (!origin.empty() && origin != "http://" + req.get_header_value("Host") &&
        origin != "https://" + req.get_header_value("Host")) {
      res.set_header("Connection", "close");
      SendError(res, 403, "forbidden",
                "a cancel form must be posted from this server's own job page (Origin " +
                    SanitizeForLog(origin.substr(0, 100)) + ")");
      return;
    }
    httplib::Params params;
    httplib::detail::parse_query_text(req.body, params);
    for (const auto& [key, value] : params) {
      if (key != "reason" && key != "token") {
        return (void)SendStatus(res,
                                Status::InvalidInput("unknown form field '" + key.substr(0, 64) +
                                                     "' (expected reason, token)")
                                    .WithField(key.substr(0, 64)));
      }
    }
    // A form without the Authorization header: its token field must be the server's.
    if (!Authorized(req)) {
      auto given = params.find("token");
      if (given == params.end() || !TokenMatches(given->second)) {
        res.set_header("Connection", "close");
        SendError(res, 401, "unauthorized",
                  "the token is missing or wrong: give the server's token in the form's token "
                  "field (or the header 'Authorization: Bearer TOKEN')");
        return;
      }
    }
    auto reason = params.find("reason");
    if (reason != params.end()) text = reason->second;
  } else if (!ReadJsonReason(req, res, "cancel", &text)) {
    return;
  }
  Status s = CheckReason("'reason' is required: say why the job is cancelled", &text);
  if (!s.ok()) return (void)SendStatus(res, s);
  const std::string actor = token.empty() ? "anonymous" : "token";
  storage::JobInfo job;
  storage::JobEvent event;
  s = store->CancelJob(id, text, actor, &job, &event);
  if (!s.ok()) return (void)SendStatus(res, s);
  const bool stopping = job.status == JobStatus::kRunning;
  if (stopping) workers->Cancel(id);  // this process computes it: stop now
  std::cerr << "calibd: job " << id << " cancelled by " << actor << " ("
            << (stopping ? "running: stopping it" : "it was queued") << ")\n";
  if (form) {
    res.status = 303;
    res.set_header("Location", "/jobs/" + std::to_string(id));
    res.set_content("cancelled; see /jobs/" + std::to_string(id), "text/plain");
    return;
  }
  json out = JobJson(job, false);
  out["event"] = EventJson(event);
  res.status = stopping ? 202 : 200;
  res.set_content(JsonBody(json{{"job", out}}), "application/json");
}

void Service::Impl::HandleGetJob(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  if (!PathId(req, res, "job", &id)) return;
  storage::JobInfo job;
  Status s = store->GetJob(id, &job);
  if (!s.ok()) return (void)SendStatus(res, s);
  json body = JobJson(job, true);
  std::vector<storage::JobEvent> events;
  s = store->ListJobEvents(id, &events);
  if (!s.ok()) return (void)SendStatus(res, s);
  body["events"] = json::array();
  for (const auto& e : events) body["events"].push_back(EventJson(e));
  res.set_content(JsonBody(body), "application/json");
}

// POST /api/v1/jobs/{id}/revoke and /accept {"reason": "..."}: a person's decision on a result
// (Store::RevokeJob / AcceptJob). The token check ran in the request filter (a write).
void Service::Impl::HandleDecision(const httplib::Request& req, httplib::Response& res,
                                   bool revoke) {
  int64_t id = 0;
  if (!PathId(req, res, "job", &id)) return;
  std::string text;
  if (!ReadJsonReason(req, res, revoke ? "revoke" : "accept", &text)) return;
  Status s = CheckReason(std::string("'reason' is required: say why the result is ") +
                             (revoke ? "revoked" : "accepted"),
                         &text);
  if (!s.ok()) return (void)SendStatus(res, s);
  const std::string actor = token.empty() ? "anonymous" : "token";
  storage::JobEvent event;
  s = revoke ? store->RevokeJob(id, text, actor, &event)
             : store->AcceptJob(id, text, actor, &event);
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::JobInfo job;
  s = store->GetJob(id, &job);
  if (!s.ok()) return (void)SendStatus(res, s);
  json out = JobJson(job, false);
  out["event"] = EventJson(event);
  res.set_content(JsonBody(json{{"job", out}}), "application/json");
}

void Service::Impl::HandleListJobs(const httplib::Request& req, httplib::Response& res) {
  storage::JobFilter filter;
  for (const auto& [key, value] : req.params) {
    if (key == "device") {
      filter.device = ToNfc(value);
    } else if (key == "method") {
      if (FindMethod(value) == nullptr) {
        return (void)SendStatus(
            res,
            Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method"));
      }
      filter.method = value;
    } else if (key == "verdict") {
      ServeState state;
      if (value.empty() || !Parse(value, &state)) {
        return (void)SendStatus(
            res, Status::InvalidInput("verdict must be accepted, rejected or revoked")
                     .WithField("verdict"));
      }
      filter.state = state;
    } else if (key == "status") {
      JobStatus status;
      if (!Parse(value, &status)) {
        return (void)SendStatus(
            res, Status::InvalidInput("status must be queued, running, succeeded or failed")
                     .WithField("status"));
      }
      filter.status = status;
    } else if (key == "limit") {
      int64_t limit;
      if (!ParseId(value, &limit) || limit > 500) {
        return (void)SendStatus(res,
                                Status::InvalidInput("limit must be 1..500").WithField("limit"));
      }
      filter.limit = static_cast<int>(limit);
    } else if (key == "before") {
      if (!ParseId(value, &filter.before)) {
        return (void)SendStatus(
            res, Status::InvalidInput("before must be a job id").WithField("before"));
      }
    } else if (key == "include_results") {
      filter.include_results = value == "1" || value == "true";
    } else {
      return (void)SendStatus(
          res, Status::InvalidInput("unknown query parameter '" + key.substr(0, 64) + "'")
                   .WithField(key.substr(0, 64)));
    }
  }
  std::vector<storage::JobInfo> jobs;
  Status s = store->ListJobs(filter, &jobs);
  if (!s.ok()) return (void)SendStatus(res, s);
  json list = json::array();
  for (const auto& job : jobs) list.push_back(JobJson(job, filter.include_results));
  json body = {{"jobs", list}, {"next", json()}};
  if (static_cast<int>(jobs.size()) == filter.limit && !jobs.empty()) {
    httplib::Params next = req.params;
    next.erase("before");
    next.emplace("before", std::to_string(jobs.back().id));
    body["next"] = "/api/v1/jobs?" + httplib::detail::params_to_query_str(next);
  }
  res.set_content(JsonBody(body), "application/json");
}

void Service::Impl::HandleDevices(const httplib::Request& req, httplib::Response& res) {
  // A page of devices (limit, after = the last serial of the previous page), with the URL of the
  // next page in "next" (null on the last page): the answer's size is bounded by the limit.
  storage::DeviceFilter filter;
  for (const auto& [key, value] : req.params) {
    if (key == "limit") {
      int64_t limit;
      if (!ParseId(value, &limit) || limit > 1000) {
        return (void)SendStatus(res,
                                Status::InvalidInput("limit must be 1..1000").WithField("limit"));
      }
      filter.limit = static_cast<int>(limit);
    } else if (key == "after") {
      filter.after = ToNfc(value);
    } else {
      return (void)SendStatus(res,
                              Status::InvalidInput("unknown query parameter '" + key.substr(0, 64) +
                                                   "' (known: limit, after)")
                                  .WithField(key.substr(0, 64)));
    }
  }
  std::vector<storage::DeviceInfo> devices;
  Status s = store->ListDevices(filter, &devices);
  if (!s.ok()) return (void)SendStatus(res, s);
  json list = json::array();
  for (const auto& d : devices) {
    json latest = json::object();
    for (const auto& c : d.latest) {
      latest[c.method] = {
          {"job_id", c.job_id},
          {"calibrated_at", c.calibrated_at},
          {"url", "/api/v1/devices/" + UrlEncode(d.serial) + "/calibration?method=" + c.method}};
    }
    list.push_back({{"serial", d.serial},
                    {"first_seen", NullIfEmpty(d.first_seen)},
                    {"latest", latest},
                    {"url", "/devices/" + UrlEncode(d.serial)}});
  }
  json body = {{"devices", list}, {"next", json()}};
  if (static_cast<int>(devices.size()) == filter.limit) {
    httplib::Params next = req.params;
    next.erase("after");
    next.emplace("after", devices.back().serial);
    body["next"] = "/api/v1/devices?" + httplib::detail::params_to_query_str(next);
  }
  res.set_content(JsonBody(body), "application/json");
}

namespace {

// kCorruption (naming the job and what is wrong) unless `job` holds a result that is what was
// stored (its SHA-256), parses as a JSON object, and is served (state accepted; any state when
// `any_state`, but still a known one).
Status CheckServedResult(const storage::JobInfo& job, bool any_state) {
  std::string problem;
  if (job.result_json.empty()) {
    problem = "it is empty";
  } else if (job.result_sha256.empty() || Sha256Hex(job.result_json) != job.result_sha256) {
    problem = "its SHA-256 is not the one stored with it";
  } else if (!json::accept(job.result_json)) {
    problem = "it is not JSON";
  } else if (job.result_json.front() != '{') {
    problem = "it is not a JSON object";
  } else if (job.state == ServeState::kNone || (!any_state && !job.served())) {
    problem = "its standing (accepted, rejected or revoked) is unreadable";
  }
  if (problem.empty()) return Status::Ok();
  return Status::Corruption("the stored result of job " + std::to_string(job.id) +
                            " is damaged: " + problem + "; it is not served")
      .WithReason(Reason::kStorageDamaged);
}

// kInvalidInput (field "format") unless `format` is json or a format some method exports
// (Method::ExportFormats).
Status CheckServedFormat(const std::string& format) {
  std::vector<std::string> formats = {"json"};
  for (const Method* m : AllMethods()) {
    for (const ExportFormat& f : m->ExportFormats()) {
      if (std::find(formats.begin(), formats.end(), f.format) == formats.end()) {
        formats.push_back(f.format);
      }
    }
  }
  if (std::find(formats.begin(), formats.end(), format) != formats.end()) return Status::Ok();
  std::string list;
  for (size_t i = 0; i < formats.size(); ++i) {
    list += (i == 0 ? "" : i + 1 == formats.size() ? " or " : ", ") + formats[i];
  }
  return Status::InvalidInput("format must be " + list).WithField("format");
}

// The job of `?job=ID` (`id_text`) into *job and its method into *method: one job's result,
// whatever its verdict (the response says it in X-Calibd-State), but only for this device: a
// job id never reaches another device's calibration. false after answering 400 or 404 (or the
// store's error); `method`, when given, must be the job's.
bool FindRequestedJob(storage::Store* store, const std::string& id_text, const std::string& serial,
                      std::string* method, storage::JobInfo* job, httplib::Response& res) {
  int64_t id = 0;
  if (!ParseId(id_text, &id)) {
    SendStatus(res,
               Status::InvalidInput("job must be a job id (a positive integer)").WithField("job"));
    return false;
  }
  const Status s = store->GetJob(id, job);
  if (s.code() != StatusCode::kNotFound && !s.ok()) {
    SendStatus(res, s);
    return false;
  }
  if (s.code() == StatusCode::kNotFound || job->device != serial) {
    SendError(
        res, 404, "not_found",
        "device '" + serial + "' has no job " + std::to_string(id) +
            (s.ok() ? " (that job is " +
                          (job->device.empty() ? std::string("of no device") : "another device's") +
                          ")"
                    : std::string()));
    return false;
  }
  if (job->status != JobStatus::kSucceeded) {
    SendError(res, 404, "not_found",
              "job " + std::to_string(id) + " is " + Name(job->status) + ": it has no result");
    return false;
  }
  if (!method->empty() && *method != job->method) {
    SendError(
        res, 404, "not_found",
        "job " + std::to_string(id) + " is a " + job->method + " calibration, not " + *method);
    return false;
  }
  *method = job->method;
  return true;
}

// 404 "no accepted calibration" for `serial` (`what`: "" or "pca ", ...), or the message naming
// a similar serial when there is one.
void AnswerNoCalibration(storage::Store* store, const std::string& serial, const std::string& what,
                         httplib::Response& res) {
  const std::string hint = SimilarDeviceMessage(store, serial);
  SendError(res, 404, "not_found",
            hint.empty() ? "no accepted " + what + "calibration for device '" + serial +
                               "' (rejected and revoked results are never served; see /devices/" +
                               UrlEncode(serial) + ")"
                         : hint);
}

// The one method the device has calibrations of, when no ?method= is given; false after
// answering 400 (several) or 404 (none), or the store's error.
bool OnlyMethodOfDevice(storage::Store* store, const std::string& serial, std::string* method,
                        httplib::Response& res) {
  std::vector<storage::DeviceInfo> devices;
  storage::DeviceFilter one;
  one.serial = serial;
  Status s = store->ListDevices(one, &devices);
  if (!s.ok()) {
    SendStatus(res, s);
    return false;
  }
  std::vector<std::string> methods;
  for (const auto& d : devices) {
    if (d.serial != serial) continue;
    for (const auto& c : d.latest) methods.push_back(c.method);
  }
  if (methods.size() > 1) {
    SendStatus(res, Status::InvalidInput("device '" + serial +
                                         "' has calibrations of several "
                                         "methods: add ?method=NAME")
                        .WithField("method"));
    return false;
  }
  if (methods.empty()) {
    AnswerNoCalibration(store, serial, "", res);
    return false;
  }
  *method = methods[0];
  return true;
}

// One ETag per answer: the body holds the job, its time and standing besides the result (and
// the C header's guard the job id), so two jobs with the same result, or one result before and
// after a revoke, never share an ETag (a flashing script's If-None-Match must not keep a revoked
// calibration).
std::string CalibrationETag(const storage::JobInfo& job, const std::string& serial,
                            const std::string& format) {
  return "\"" +
         Sha256Hex(job.result_sha256 + "\n" + std::to_string(job.id) + "\n" + Name(job.state) +
                   "\n" + job.finished_at + "\n" + serial + "\n" + format)
             .substr(0, 32) +
         "-" + format + "\"";
}

// The hot path of production tooling: the stored result is valid JSON text already (the worker
// wrote it with json::dump), so it is embedded as is, without parsing it again.
void AnswerCalibrationJson(const storage::JobInfo& job, const std::string& serial,
                           const std::string& method, httplib::Response& res) {
  json head = {{"device", serial},         {"method", method},
               {"job_id", job.id},         {"calibrated_at", job.finished_at},
               {"state", Name(job.state)}, {"result", nullptr}};
  std::string body = head.dump(-1, ' ', false, json::error_handler_t::replace);
  const std::string placeholder = "\"result\":null";
  const size_t at = body.rfind(placeholder);
  body.replace(at, placeholder.size(), "\"result\":" + job.result_json);
  body += "\n";
  res.set_content(std::move(body), "application/json");
}

// The result in one of the method's own formats (Method::Export), as an attachment.
void AnswerCalibrationExport(const storage::JobInfo& job, const std::string& serial,
                             const std::string& method, const std::string& format,
                             httplib::Response& res) {
  json result;
  Status s = ParseJsonText(job.result_json, "stored result", &result);
  if (!s.ok()) {
    std::cerr << "calibd: job " << job.id << ": " << s.ToString() << "\n";  // where it broke
    return (void)SendStatus(res, Status::Internal("stored result is not JSON"));
  }
  const Method* exporter = FindMethod(method);
  if (exporter == nullptr) return (void)SendStatus(res, Status::Internal("unknown stored method"));
  const std::vector<ExportFormat> exports = exporter->ExportFormats();
  const auto f = std::find_if(exports.begin(), exports.end(),
                              [&](const ExportFormat& e) { return e.format == format; });
  if (f == exports.end()) return (void)SendStatus(res, NoSuchExport(format, exporter->name()));
  std::string text;
  // With the job's config (nominal offsets for SI exports; a stored config is validated JSON).
  const ExportContext context{
      job.id,
      serial,
      method,
      job.finished_at,
      Name(job.state),
      json::parse(job.config_json.empty() ? "{}" : job.config_json, nullptr, false)};
  s = exporter->Export(format, result, context, &text);
  if (!s.ok()) return (void)SendStatus(res, s);
  MarkNotAccepted(format, context, &text);
  const std::string file_name =
      f->file_name.empty() ? "calibration-" + std::to_string(job.id) + "." + format : f->file_name;
  res.set_header("Content-Disposition", "attachment; filename=\"" + file_name + "\"");
  res.set_content(text, f->content_type);
}

}  // namespace

void Service::Impl::HandleLatest(const httplib::Request& req, httplib::Response& res) {
  // Serials are stored in NFC: a decomposed "CAFE\u0301" in the URL finds "CAF\u00c9".
  const std::string serial = ToNfc(std::string(req.matches[1]));
  std::string method = req.get_param_value("method");
  const std::string format = req.has_param("format") ? req.get_param_value("format") : "json";
  if (Status s = CheckServedFormat(format); !s.ok()) return (void)SendStatus(res, s);
  storage::JobInfo job;
  const bool by_job = req.has_param("job");
  if (by_job) {
    if (!FindRequestedJob(store.get(), req.get_param_value("job"), serial, &method, &job, res)) {
      return;
    }
  } else {
    if (method.empty()) {
      if (!OnlyMethodOfDevice(store.get(), serial, &method, res)) return;
    } else if (FindMethod(method) == nullptr) {
      return (void)SendStatus(
          res,
          Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method"));
    }
    const Status s = store->LatestResult(serial, method, &job);
    if (s.code() == StatusCode::kNotFound) {
      return AnswerNoCalibration(store.get(), serial, method + " ", res);
    }
    if (!s.ok()) return (void)SendStatus(res, s);
  }
  // Never a 200 without a sound, served result: a damaged database can hand back a row whose
  // result is empty, cut or changed, or whose standing is unreadable (README "Storage damage").
  if (Status s = CheckServedResult(job, /*any_state=*/by_job); !s.ok()) {
    health.Note(s, "the result of job " + std::to_string(job.id), false);
    std::cerr << "calibd: " << s.message() << "\n";
    return (void)SendStatus(res, s);
  }
  const std::string etag = CalibrationETag(job, serial, format);
  res.set_header("ETag", etag);
  res.set_header("Cache-Control", "no-cache");
  res.set_header("X-Calibd-Job", std::to_string(job.id));
  res.set_header("X-Calibd-State", Name(job.state));
  if (IfNoneMatchHits(req.get_header_value("If-None-Match"), etag)) {
    res.status = 304;
    return;
  }
  if (format == "json") return AnswerCalibrationJson(job, serial, method, res);
  AnswerCalibrationExport(job, serial, method, format, res);
}

void Service::Impl::HandleRecording(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  storage::RecordingInfo info;
  if (!PathRecording(store.get(), req, res, &id, &info)) return;
  res.set_content(JsonBody(RecordingJson(info)), "application/json");
}

void Service::Impl::HandleRecordingData(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  storage::RecordingInfo info;
  if (!PathRecording(store.get(), req, res, &id, &info)) return;
  res.set_header("Content-Disposition",
                 "attachment; filename=\"recording-" + std::to_string(id) + ".csv\"");
  // The bytes are checked against their SHA-256 before the answer starts (a second read): a
  // damaged copy answers 500 storage_damaged, never a 200 with other bytes than those uploaded.
  Status verified = store->ReadRecordingData(id, [](std::string_view) { return true; });
  health.Note(verified, "recording " + std::to_string(id), false);
  if (!verified.ok()) {
    std::cerr << "calibd: " << verified.message() << "\n";
    return (void)SendStatus(res, verified);
  }
  res.set_header("ETag", "\"" + info.sha256 + "\"");
  storage::Store* st = store.get();
  res.set_content_provider(static_cast<size_t>(info.bytes), "text/csv",
                           [st, id](size_t offset, size_t, httplib::DataSink& sink) {
                             if (offset != 0)
                               return false;  // everything is written in the first call
                             Status rs = st->ReadRecordingData(id, [&sink](std::string_view chunk) {
                               return sink.write(chunk.data(), chunk.size());
                             });
                             return rs.ok();
                           });
}

}  // namespace calibd::server
