// The API's JSON of jobs, events and recordings (server/service_impl.h).
#include "server/failure_reasons.h"
#include "server/service_impl.h"

namespace calibd::server {

using nlohmann::json;

json NullIfEmpty(const std::string& s) { return s.empty() ? json() : json(s); }

// A job as the API shows it (SPEC §5).
json JobJson(const storage::JobInfo& job, bool with_result) {
  json j = {{"id", job.id},
            {"status", Name(job.status)},
            {"device", NullIfEmpty(job.device)},
            {"method", job.method},
            {"recording_id", job.recording_id},
            {"created_at", NullIfEmpty(job.created_at)},
            {"started_at", NullIfEmpty(job.started_at)},
            {"finished_at", NullIfEmpty(job.finished_at)},
            {"attempts", job.attempts},
            {"error", json()},
            {"result", json()},
            {"url", "/api/v1/jobs/" + std::to_string(job.id)},
            {"report_url", "/jobs/" + std::to_string(job.id)}};
  if (!job.error_code.empty() && job.status != JobStatus::kSucceeded) {
    // SPEC §5 extended (README, "Failure reasons"): the reason code with its title and generic
    // advice from the catalog (server/failure_reasons.h), the method's own message, and the partial
    // diagnostics it found before failing (null when none, and in lists without results).
    const FailureReason& reason = StoredFailureReason(job.error_reason, job.error_code);
    json diagnostics;
    if (!job.error_detail_json.empty()) {
      diagnostics = json::parse(job.error_detail_json, nullptr, /*allow_exceptions=*/false);
      if (diagnostics.is_discarded()) diagnostics = json();
    }
    j["error"] = {{"code", job.error_code},  {"reason", reason.code},
                  {"title", reason.title},   {"message", job.error_message},
                  {"advice", reason.advice}, {"diagnostics", std::move(diagnostics)}};
  }
  json config;
  if (ParseJsonText(job.config_json, "config", &config).ok()) j["config"] = std::move(config);
  if (with_result && !job.result_json.empty()) {
    json result;
    if (ParseJsonText(job.result_json, "result", &result).ok()) j["result"] = std::move(result);
  }
  // The acceptance gate: the gate's verdict, a person's decision, and what follows (only the
  // "accepted" state is ever served as the device's calibration).
  j["verdict"] = NullIfEmpty(Name(job.verdict));
  j["revoked"] = job.decision == Decision::kRevoked;
  j["state"] = NullIfEmpty(Name(job.state));
  // A cancel request (POST /jobs/{id}/cancel): a running job with one is being stopped.
  j["cancel"] = job.cancel_requested_at_ms == 0 ? json()
                                                : json{{"at", job.cancel_requested_at},
                                                       {"reason", job.cancel_reason},
                                                       {"actor", job.cancel_actor}};
  return j;
}

json EventJson(const storage::JobEvent& e) {
  return {{"action", e.action}, {"reason", e.reason}, {"actor", e.actor}, {"at", e.created_at}};
}

json RecordingJson(const storage::RecordingInfo& r) {
  json j = {{"id", r.id},
            {"sha256", r.sha256},
            {"bytes", r.bytes},
            {"rows", r.rows},
            {"layout", r.layout},
            {"device", NullIfEmpty(r.device)},
            {"file_name", NullIfEmpty(r.file_name)},
            {"created_at", NullIfEmpty(r.created_at)},
            {"url", "/api/v1/recordings/" + std::to_string(r.id)},
            {"data_url", "/api/v1/recordings/" + std::to_string(r.id) + "/data"}};
  json columns, sensors;
  if (ParseJsonText(r.columns_json, "columns", &columns).ok()) j["columns"] = columns;
  if (ParseJsonText(r.sensors_json, "sensors", &sensors).ok()) j["sensors"] = sensors;
  // SPEC §9 "What was read": a sensor log's format, time base, streams, IMUs and warnings; a
  // CSV read with config columns/delimiter/decimal: `csv` (the mapping used) and warnings.
  j["format"] = "csv";
  json log;
  if (!r.log_json.empty() && ParseJsonText(r.log_json, "log", &log).ok() && log.is_object()) {
    for (const char* key : {"format", "time_base", "streams", "imus", "csv", "warnings"}) {
      if (log.contains(key)) j[key] = log[key];
    }
  }
  return j;
}

bool ParseId(const std::string& text, int64_t* id) {
  if (text.empty() || text.size() > 18) return false;
  int64_t v = 0;
  for (char c : text) {
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
  }
  *id = v;
  return v > 0;
}

}  // namespace calibd::server
