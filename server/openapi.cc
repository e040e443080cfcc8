// The OpenAPI 3 description of the HTTP API (GET /api/v1/openapi.json). Kept true by
// tests/server/http_api_test.cc, which checks every documented path against the running server.
#include "methods/method.h"
#include "methods/registry.h"
#include "server/failure_reasons.h"
#include "server/http_util.h"

namespace calibd::server {

using nlohmann::json;

namespace {

json Ref(const std::string& name) { return {{"$ref", "#/components/schemas/" + name}}; }

json JsonResponse(const std::string& description, const json& schema) {
  return {{"description", description}, {"content", {{"application/json", {{"schema", schema}}}}}};
}

json ErrorResponse(const std::string& description) {
  return JsonResponse(description, Ref("Error"));
}

json QueryParam(const std::string& name, const std::string& type, const std::string& description,
                bool required = false) {
  return {{"name", name},
          {"in", "query"},
          {"required", required},
          {"description", description},
          {"schema", {{"type", type}}}};
}

json PathParam(const std::string& name, const std::string& type, const std::string& description) {
  return {{"name", name},
          {"in", "path"},
          {"required", true},
          {"description", description},
          {"schema", {{"type", type}}}};
}

// The schemas of a job and of its failure (components/schemas).
void AddJobSchemas(json* out) {
  json& schemas = *out;
  // A job's last failure (SPEC §5 extended: reason, title, advice, diagnostics).
  json reasons = json::array();
  for (const FailureReason& r : AllFailureReasons()) reasons.push_back(r.code);
  schemas["JobFailure"] = {
      {"type", "object"},
      {"required", {"code", "reason", "message", "advice"}},
      {"properties",
       {{"code",
         {{"type", "string"},
          {"description",
           "the kind of failure: invalid_input, not_determinable, lease_expired, ..."}}},
        {"reason",
         {{"type", "string"},
          {"enum", reasons},
          {"description", "why, as a stable snake_case code (README, Failure reasons)"}}},
        {"title", {{"type", "string"}, {"description", "the reason in a few words"}}},
        {"message", {{"type", "string"}, {"description", "the method's own account"}}},
        {"advice",
         {{"type", "string"},
          {"description", "what to record or set instead (looked up by reason)"}}},
        {"diagnostics",
         {{"type", "object"},
          {"nullable", true},
          {"description",
           "what the method found before failing: {method, usable: false, diagnostics, "
           "warnings}, at most 1 MiB (trimmed says what was left out); null in job lists without "
           "include_results"}}}}}};
  schemas["Job"] = {
      {"type", "object"},
      {"required", {"id", "status", "method", "created_at", "attempts"}},
      {"properties",
       {{"id", {{"type", "integer"}}},
        {"status", {{"type", "string"}, {"enum", {"queued", "running", "succeeded", "failed"}}}},
        {"device", {{"type", "string"}, {"nullable", true}}},
        {"method", {{"type", "string"}}},
        {"recording_id", {{"type", "integer"}}},
        {"created_at", {{"type", "string"}, {"format", "date-time"}}},
        {"started_at", {{"type", "string"}, {"nullable", true}}},
        {"finished_at", {{"type", "string"}, {"nullable", true}}},
        {"attempts", {{"type", "integer"}}},
        {"error", {{"allOf", json::array({Ref("JobFailure")})}, {"nullable", true}}},
        {"result", {{"allOf", json::array({Ref("Result")})}, {"nullable", true}}},
        {"config", {{"type", "object"}}},
        {"verdict",
         {{"type", "string"},
          {"enum", {"accepted", "rejected"}},
          {"nullable", true},
          {"description", "the acceptance gate's verdict (succeeded jobs)"}}},
        {"revoked", {{"type", "boolean"}}},
        {"state",
         {{"type", "string"},
          {"enum", {"accepted", "rejected", "revoked"}},
          {"nullable", true},
          {"description", "after people's decisions; only accepted results are served"}}},
        {"cancel",
         {{"type", "object"},
          {"nullable", true},
          {"description",
           "a cancel request (POST /jobs/{id}/cancel): at, reason, actor; a running job with one "
           "is being stopped"}}},
        {"events",
         {{"type", "array"},
          {"description",
           "GET /jobs/{id} only: revoke/accept decisions and cancel requests, oldest first"},
          {"items",
           {{"type", "object"},
            {"properties",
             {{"action", {{"type", "string"}, {"enum", {"revoke", "accept", "cancel"}}}},
              {"reason", {{"type", "string"}}},
              {"actor", {{"type", "string"}, {"description", "token | anonymous"}}},
              {"at", {{"type", "string"}, {"format", "date-time"}}}}}}}}},
        {"url", {{"type", "string"}}},
        {"report_url", {{"type", "string"}}}}}};
}

// The schemas of an error, a result (of the methods named) and a recording.
void AddSchemas(const json& method_names, json* out) {
  json& schemas = *out;
  schemas["Error"] = {
      {"type", "object"},
      {"required", {"error"}},
      {"properties",
       {{"error",
         {{"type", "object"},
          {"required", {"code", "message"}},
          {"properties",
           {{"code", {{"type", "string"}}},
            {"message", {{"type", "string"}}},
            {"line", {{"type", "integer"}, {"description", "1-based line of the fault"}}},
            {"column", {{"type", "integer"}, {"description", "1-based field number"}}},
            {"field", {{"type", "string"}, {"description", "config key or column name"}}}}}}}}}};
  schemas["Result"] = {
      {"type", "object"},
      {"description", "SPEC §4 result"},
      {"required", {"method", "parameters", "uncertainty", "diagnostics", "warnings"}},
      {"properties",
       {{"method", {{"type", "string"}, {"enum", method_names}}},
        {"schema_version",
         {{"type", "integer"},
          {"minimum", 1},
          {"description",
           "version of the method's typed result schema (results/<method>_result.h); absent in "
           "results stored before it existed, which are version 1"}}},
        {"model",
         {{"type", "string"},
          {"description", "the equation that maps a raw reading to the calibrated quantity"}}},
        {"parameters", {{"type", "object"}}},
        {"uncertainty", {{"type", "object"}}},
        {"diagnostics", {{"type", "object"}}},
        {"warnings", {{"type", "array"}, {"items", {{"type", "string"}}}}}}}};
  schemas["Recording"] = {
      {"type", "object"},
      {"properties",
       {{"id", {{"type", "integer"}}},
        {"sha256", {{"type", "string"}}},
        {"bytes", {{"type", "integer"}}},
        {"rows", {{"type", "integer"}}},
        {"layout",
         {{"type", "string"},
          {"enum",
           {LayoutName(Layout::kPcaAveraged), LayoutName(Layout::kPcaRaw),
            LayoutName(Layout::kArray)}}}},
        {"device", {{"type", "string"}, {"nullable", true}}},
        {"created_at", {{"type", "string"}}},
        {"columns", {{"type", "array"}, {"items", {{"type", "string"}}}}},
        {"sensors", {{"type", "array"}, {"items", {{"type", "string"}}}}},
        // SPEC §9 "What was read" (sensor logs; format "csv" otherwise).
        {"format",
         {{"type", "string"},
          {"enum", {"csv", "ulog", "dataflash", "rosbag1", "rosbag2", "mcap"}}}},
        {"time_base", {{"type", "string"}}},
        {"streams",
         {{"type", "array"},
          {"items",
           {{"type", "object"},
            {"description",
             "name, instance, device_id, kind, samples, rate (Hz), start, end "
             "(s on the log's clock), gaps, unit, time_source, note"}}}}},
        {"imus", {{"type", "array"}, {"items", {{"type", "object"}}}}},
        {"warnings", {{"type", "array"}, {"items", {{"type", "string"}}}}}}}};
}

// POST /recordings (with its config parameters) and a stored recording's paths.
void AddRecordingPaths(json* out) {
  json& paths = *out;
  json config_params = json::array(
      {QueryParam("method", "string", "pca | array; without it the recording is only stored"),
       QueryParam("device", "string", "serial number"),
       QueryParam("product", "string", "the product the device is a unit of (fleets)"),
       QueryParam("dimension", "integer", "pca: d"),
       QueryParam("magnitude", "number", "pca: the field's magnitude c"),
       QueryParam("refine", "boolean", "pca: ML refinement"),
       QueryParam("bias", "string", "pca: none | estimate"),
       QueryParam("nominal", "string", "pca: m×d JSON array"),
       QueryParam("geometry", "string", "array: JSON object {positions, reference}"),
       QueryParam("accel_noise", "number", "array: σ_a"),
       QueryParam("gyro_noise", "number", "array: σ_g"),
       QueryParam("gyro_unit", "string",
                  "array: rad/s | deg/s; imu, noise: rad/s | deg/s | rad/s per reading unit"),
       QueryParam("accel_unit", "string", "imu, noise: m/s^2 | g | m/s^2 per reading unit"),
       QueryParam("time_unit", "string",
                  "imu, noise, array: unit of the time column t, s (default) | ms | us | ns"),
       QueryParam("columns", "string",
                  "CSV from another tool: JSON {calibd name: the file's column}, e.g. "
                  "{\"t\": \"time_ms\", \"a0_x\": \"accX\"}; other columns are ignored"),
       QueryParam("delimiter", "string", "CSV field separator: , (default) | ; | \\t"),
       QueryParam("decimal", "string", "CSV decimal mark: . (default) | , (not with delimiter ,)"),
       QueryParam("solver", "string", "array: joint | bcd"),
       QueryParam("streams", "string",
                  "sensor logs (ULog, DataFlash, bags): JSON {\"imus\": [{\"accel\", \"gyro\", "
                  "\"temp\"}], \"mags\": [...]}, stream names as the recording lists them")});
  paths["/recordings"]["post"] = {
      {"summary", "Upload a recording (and queue a calibration when a method is given)"},
      {"security", json::array({{{"bearer", json::array()}}})},
      {"parameters", config_params},
      {"requestBody",
       {{"required", true},
        {"content",
         {{"text/csv", {{"schema", {{"type", "string"}}}}},
          {"multipart/form-data",
           {{"schema",
             {{"type", "object"},
              {"properties",
               {{"recording", {{"type", "string"}, {"format", "binary"}}},
                {"config",
                 {{"type", "string"}, {"description", "config JSON (SPEC §3)"}}}}}}}}}}}}},
      {"responses",
       {{"201",
         JsonResponse("stored (and queued)",
                      {{"type", "object"},
                       {"properties", {{"recording", Ref("Recording")}, {"job", Ref("Job")}}}})},
        {"400", ErrorResponse("malformed recording or config (line, column, field)")},
        {"401", ErrorResponse("missing or wrong token")},
        {"411", ErrorResponse("no Content-Length and not chunked")},
        {"413", ErrorResponse("body (or the gzip'd recording decompressed) larger than "
                              "--max-upload-bytes, or expanding more than --max-gzip-ratio")},
        {"415", ErrorResponse("not text/csv or multipart/form-data, or an encoding other than "
                              "gzip")},
        {"503", ErrorResponse("database busy")},
        {"507", ErrorResponse("the disk (or quota) of the database or staging folder is full "
                              "(reason disk_full); nothing was stored")}}}};
  paths["/recordings/{id}"]["get"] = {
      {"summary", "Recording metadata"},
      {"parameters", json::array({PathParam("id", "integer", "recording id")})},
      {"responses",
       {{"200", JsonResponse("metadata", Ref("Recording"))},
        {"404", ErrorResponse("no such recording")}}}};
  paths["/recordings/{id}/data"]["get"] = {
      {"summary", "The original bytes"},
      {"parameters", json::array({PathParam("id", "integer", "recording id")})},
      {"responses",
       {{"200",
         {{"description", "the CSV as uploaded"},
          {"content", {{"text/csv", {{"schema", {{"type", "string"}}}}}}}}},
        {"404", ErrorResponse("no such recording")}}}};
  paths["/recordings/{id}/segments"]["get"] = {
      {"summary", "The static intervals of a stored inertial log (SPEC section 7)"},
      {"parameters",
       json::array({PathParam("id", "integer", "recording id"),
                    QueryParam("static_window", "number", "s, default 1"),
                    QueryParam("min_static", "number", "s, default 1"),
                    QueryParam("static_threshold", "string",
                               "{\"accelerometer\": x, \"gyroscope\": y}, reading units"),
                    QueryParam("accel_unit", "string", "m/s^2 per reading unit"),
                    QueryParam("gyro_unit", "string", "rad/s per reading unit"),
                    QueryParam("time_unit", "string", "unit of t: s (default) | ms | us | ns")})},
      {"responses",
       {{"200", JsonResponse("intervals, thresholds, gaps", {{"type", "object"}})},
        {"400", ErrorResponse("bad option (field)")},
        {"404", ErrorResponse("no such recording")},
        {"422", ErrorResponse("not an inertial log")}}}};
  paths["/recordings/{id}/check"]["get"] = {
      {"summary",
       "What a job would find before fitting (SPEC section 10): timing (rate, jitter, gaps), "
       "units that look wrong, temperature range, and the method's saturation per channel, "
       "statics with their gravity directions, coverage and what the job would fail with, "
       "computed by the job's own stages; the method's config keys come as query parameters, "
       "as for an upload (SPEC section 3)"},
      {"parameters",
       json::array({PathParam("id", "integer", "recording id"),
                    QueryParam("method", "string", "a method reading inertial logs"),
                    QueryParam("job", "integer",
                               "instead of method and config keys: the config of this job")})},
      {"responses",
       {{"200", JsonResponse("the check", {{"type", "object"}})},
        {"400", ErrorResponse("bad method or config key (field)")},
        {"404", ErrorResponse("no such recording or job")},
        {"422", ErrorResponse("not an inertial log, or over the job memory budget")}}}};
}

// The jobs: queue, list, one job, and the decisions (revoke, accept, cancel) on it.
void AddJobPaths(json* out) {
  json& paths = *out;
  paths["/jobs"]["post"] = {
      {"summary", "Queue a calibration of a stored recording with another config"},
      {"security", json::array({{{"bearer", json::array()}}})},
      {"requestBody",
       {{"required", true},
        {"content",
         {{"application/json",
           {{"schema",
             {{"type", "object"},
              {"required", {"recording_id", "config"}},
              {"properties",
               {{"recording_id", {{"type", "integer"}}}, {"config", {{"type", "object"}}}}}}}}}}}}},
      {"responses",
       {{"202",
         JsonResponse("queued", {{"type", "object"}, {"properties", {{"job", Ref("Job")}}}})},
        {"400", ErrorResponse("invalid config")},
        {"404", ErrorResponse("no such recording")},
        {"415", ErrorResponse("not application/json")}}}};
  paths["/jobs"]["get"] = {
      {"summary", "Jobs, newest first, paginated"},
      {"parameters", json::array({QueryParam("device", "string", "filter"),
                                  QueryParam("method", "string", "filter"),
                                  QueryParam("status", "string", "filter"),
                                  QueryParam("verdict", "string",
                                             "filter: accepted | rejected | revoked (the "
                                             "acceptance gate's state; succeeded jobs only)"),
                                  QueryParam("limit", "integer", "1..500, default 50"),
                                  QueryParam("before", "integer", "cursor: jobs with smaller ids"),
                                  QueryParam("include_results", "boolean", "embed results")})},
      {"responses",
       {{"200", JsonResponse("a page of jobs; 'next' is the URL of the next page or null",
                             {{"type", "object"},
                              {"properties",
                               {{"jobs", {{"type", "array"}, {"items", Ref("Job")}}},
                                {"next", {{"type", "string"}, {"nullable", true}}}}}})},
        {"400", ErrorResponse("bad filter")}}}};
  paths["/jobs/{id}"]["get"] = {
      {"summary",
       "One job with its result, its verdict (the acceptance gate's), revoked, state "
       "(accepted | rejected | revoked) and events (revoke/accept decisions: action, reason, "
       "actor, at)"},
      {"parameters", json::array({PathParam("id", "integer", "job id")})},
      {"responses",
       {{"200", JsonResponse("the job", Ref("Job"))}, {"404", ErrorResponse("no such job")}}}};
  const json decision_body = {
      {"required", true},
      {"content",
       {{"application/json",
         {{"schema",
           {{"type", "object"},
            {"required", {"reason"}},
            {"properties",
             {{"reason", {{"type", "string"}, {"minLength", 1}, {"maxLength", 500}}}}}}}}}}}};
  for (const char* action : {"revoke", "accept"}) {
    const bool revoke = std::string(action) == "revoke";
    paths[std::string("/jobs/{id}/") + action]["post"] = {
        {"summary", revoke ? "Withdraw a served result: the device's calibration falls back to "
                             "its previous accepted one"
                           : "Accept a result the acceptance gate rejected (or re-accept a "
                             "revoked one)"},
        {"security", json::array({{{"bearer", json::array()}}})},
        {"parameters", json::array({PathParam("id", "integer", "job id")})},
        {"requestBody", decision_body},
        {"responses",
         {{"200", JsonResponse("the job with the recorded event",
                               {{"type", "object"}, {"properties", {{"job", Ref("Job")}}}})},
          {"400", ErrorResponse("reason missing, empty or too long")},
          {"401", ErrorResponse("missing or wrong token")},
          {"404", ErrorResponse("no such job")},
          {"409", ErrorResponse(revoke ? "the job has no served result (not succeeded, "
                                         "rejected, or already revoked)"
                                       : "the job has no result, or it is already accepted")},
          {"415", ErrorResponse("not application/json")}}}};
  }
  paths["/jobs/{id}/cancel"]["post"] = {
      {"summary",
       "Cancel a job: a queued one fails at once (200), a running one is stopped within a "
       "second on whichever host computes it (202) and fails with reason cancelled, keeping its "
       "partial diagnostics. The job page's form may post reason (and token) as "
       "application/x-www-form-urlencoded instead: answered with 303 to the job page."},
      {"security", json::array({{{"bearer", json::array()}}})},
      {"parameters", json::array({PathParam("id", "integer", "job id")})},
      {"requestBody", decision_body},
      {"responses",
       {{"200", JsonResponse("the queued job, now failed, with the recorded event",
                             {{"type", "object"}, {"properties", {{"job", Ref("Job")}}}})},
        {"202", JsonResponse("the running job, being stopped, with the recorded event",
                             {{"type", "object"}, {"properties", {{"job", Ref("Job")}}}})},
        {"303", {{"description", "form post: see the job page (Location)"}}},
        {"400", ErrorResponse("reason missing, empty or too long; body not JSON")},
        {"401", ErrorResponse("missing or wrong token")},
        {"403", ErrorResponse("a form posted from another origin")},
        {"404", ErrorResponse("no such job")},
        {"409", ErrorResponse("the job already finished (the message names its status)")},
        {"415", ErrorResponse("neither application/json nor a form")}}}};
}

// The devices and their served calibration.
void AddDevicePaths(json* out) {
  json& paths = *out;
  paths["/devices"]["get"] = {
      {"summary",
       "Devices with their latest calibration time per method, a page at a time in byte order "
       "of the serials; `next` is the next page's URL (null on the last)"},
      {"parameters", json::array({QueryParam("limit", "integer", "1..1000, default 100"),
                                  QueryParam("after", "string",
                                             "cursor: the last serial of the previous page")})},
      {"responses",
       {{"200", JsonResponse("devices", {{"type", "object"}})},
        {"400", ErrorResponse("limit out of range or an unknown query parameter")}}}};
  paths["/devices/{serial}/calibration"]["get"] = {
      {"summary",
       "The latest accepted (not rejected by the acceptance gate, not revoked) calibration of a "
       "device, for production tooling; X-Calibd-Job and X-Calibd-State name the job and its "
       "state"},
      {"parameters",
       json::array({PathParam("serial", "string", "device serial number"),
                    QueryParam("method", "string", "pca | array (needed when the device has both)"),
                    QueryParam("format", "string", "json (default) | csv | h | yaml"),
                    QueryParam("job", "integer",
                               "that job's result whatever its state (404 when it is not this "
                               "device's or has no result)"),
                    {{"name", "If-None-Match"},
                     {"in", "header"},
                     {"required", false},
                     {"schema", {{"type", "string"}}}}})},
      {"responses",
       {{"200",
         {{"description", "the calibration; ETag and Cache-Control: no-cache"},
          {"content",
           {{"application/json", {{"schema", {{"type", "object"}}}}},
            {"text/csv", {{"schema", {{"type", "string"}}}}},
            {"text/x-c", {{"schema", {{"type", "string"}}}}}}}}},
        {"304", {{"description", "not modified (If-None-Match matched the ETag)"}}},
        {"400", ErrorResponse("bad method or format")},
        {"404", ErrorResponse("no accepted calibration, or job not this device's")},
        {"409", ErrorResponse("csv, h or yaml of a stored result this calibd cannot read (e.g. "
                              "a schema_version from a newer calibd), naming the path")}}}};
  paths["/products/{product}/fleet"]["get"] = {
      {"summary",
       "A product's fleet for one method (SPEC §10): per parameter the distribution over the "
       "devices' served calibrations uploaded with config key product (median, robust spread, "
       "histogram), the outlier units by robust z, and the monthly medians"},
      {"parameters",
       json::array({PathParam("product", "string", "the product's name"),
                    QueryParam("method", "string", "the method (required)"),
                    QueryParam("outlier_z", "number", "|robust z| that flags a unit, default 5")})},
      {"responses",
       {{"200",
         JsonResponse("the fleet (an unknown product is an empty fleet)", {{"type", "object"}})},
        {"400", ErrorResponse("product not a valid name, method missing or unknown, outlier_z "
                              "not > 0, or an unknown query parameter")}}}};
  paths["/plan"]["post"] = {
      {"summary",
       "Plan a calibration (SPEC §10): the σ a recording of a protocol would give (the result's "
       "uncertainty shape), what it cannot determine, and a suggested protocol (greedy "
       "D-optimal) meeting the gate's limits"},
      {"requestBody",
       {{"required", true},
        {"content",
         {{"application/json",
           {{"schema",
             {{"type", "object"},
              {"required", {"method", "protocol"}},
              {"properties",
               {{"method", {{"type", "string"}}},
                {"config", {{"type", "object"}}},
                {"protocol", {{"type", "object"}}}}}}}}}}}}},
      {"responses",
       {{"200", JsonResponse("the plan: uncertainty, undetermined, suggested, notes, limits",
                             {{"type", "object"}})},
        {"400", ErrorResponse("a field of the request (named), or no plan for the method yet")}}}};
}

// Liveness, metrics and this document.
void AddServicePaths(json* out) {
  json& paths = *out;
  paths["/healthz"]["get"] = {
      {"summary", "Liveness (also at /healthz)"},
      {"responses",
       {{"200", JsonResponse("alive", {{"type", "object"}})},
        {"503", JsonResponse("database unavailable (status unavailable), damaged (status damaged) "
                             "or its disk full (status disk_full); problems names them",
                             {{"type", "object"}})}}}};
  paths["/metrics"]["get"] = {
      {"summary", "Prometheus text format (also at /metrics)"},
      {"responses",
       {{"200",
         {{"description", "metrics"},
          {"content", {{"text/plain", {{"schema", {{"type", "string"}}}}}}}}}}}};
  paths["/openapi.json"]["get"] = {
      {"summary", "This document"},
      {"responses", {{"200", JsonResponse("OpenAPI 3", {{"type", "object"}})}}}};
}

json Build() {
  json method_names = json::array();
  for (const Method* m : AllMethods()) method_names.push_back(m->name());
  json doc;
  doc["openapi"] = "3.0.3";
  doc["info"] = {{"title", "calibd"},
                 {"version", "0.1.0"},
                 {"description",
                  "Calibration server for multi-sensor inertial systems (SPEC.md). Writes need "
                  "'Authorization: Bearer TOKEN' when the server runs with --token-file."}};
  doc["servers"] = json::array({{{"url", "/api/v1"}}});
  doc["components"]["securitySchemes"]["bearer"] = {{"type", "http"}, {"scheme", "bearer"}};
  AddJobSchemas(&doc["components"]["schemas"]);
  AddSchemas(method_names, &doc["components"]["schemas"]);
  json& paths = doc["paths"];
  AddRecordingPaths(&paths);
  AddJobPaths(&paths);
  AddDevicePaths(&paths);
  AddServicePaths(&paths);
  return doc;
}

}  // namespace

const json& OpenApiDocument() {
  static const json& doc = *new json(Build());  // never destroyed (threads read it)
  return doc;
}

}  // namespace calibd::server
