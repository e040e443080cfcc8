// The internals of Service (server/service.h) shared by its files: service.cc (lifecycle,
// routes table, policy: authorization, health, metrics), upload_routes.cc (uploads and new jobs),
// job_routes.cc (jobs, decisions, devices, exports, recordings) and api_json.cc (the API's JSON
// of jobs, events and recordings). Internal to server/.
#ifndef CALIBD_SERVER_SERVICE_IMPL_H_
#define CALIBD_SERVER_SERVICE_IMPL_H_

#include <arpa/inet.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "base/sha256.h"
#include "core/task_pool.h"
#include "formats/inertial_log.h"
#include "formats/recording.h"
#include "methods/acceptance.h"
#include "methods/exports.h"
#include "methods/method.h"
#include "server/column_cache.h"
#include "server/config.h"
#include "server/device_lookup.h"
#include "server/gzip_stream.h"
#include "server/http_server.h"
#include "server/http_util.h"
#include "server/instance.h"
#include "server/job_budget.h"
#include "server/metrics.h"
#include "server/recording_routes.h"
#include "server/service.h"
#include "server/storage_health.h"
#include "server/worker_pool.h"
#include "storage/store.h"

namespace calibd::server {

namespace fs = std::filesystem;

struct Service::Impl {
  ServeOptions options;
  std::string host;
  int requested_port = 0;
  int bound_port = 0;
  int listen_fd = -1;            // the listening socket, noted by the socket-options hook (Bind)
  std::string token;             // empty: no authentication
  nlohmann::json acceptance;     // server-wide acceptance limits (--acceptance), null for none
  int64_t job_memory_bytes = 0;  // the per-job memory budget in force (server/job_budget.h)
  int64_t job_seconds = 0;       // the time limit per job in force (--job-seconds or its default)
  fs::path staging_dir;
  std::unique_ptr<storage::Store> store;
  std::unique_ptr<ProcessInstance> instance;  // after store: removed before the store closes
  Metrics metrics;
  // The parsed-columns cache of stored inertial logs (server/column_cache.h): used by the
  // workers, the check and /segments, filled at upload. After store, before workers.
  std::unique_ptr<ColumnCache> column_cache;
  // The jobs' parallel numerics: cores - 1 threads shared by every worker (each worker computes
  // too), so W concurrent jobs use at most W + cores - 1 threads. Outlives the workers.
  std::unique_ptr<core::TaskPool> numerics;
  std::unique_ptr<WorkerPool> workers;
  std::unique_ptr<HttpServer> http;  // destroyed first: its request threads use the rest
  std::once_flag shutdown_once;
  bool shutdown_clean = true;
  bool abandoned = false;  // Shutdown left a job whose computation did not stop (Service)
  // What requests, jobs and the structure checks found about the storage (/healthz).
  StorageHealth health;
  // The scheduled structure check (options.check_seconds; none when 0), stopped by Shutdown.
  std::thread checker;
  std::mutex checker_mu;
  std::condition_variable checker_cv;
  bool checker_stop = false;

  // The routes of the HTTP API and pages, with the request filter, error handler and access log.
  void SetupRoutes();
  // The request filter: runs before the body is read (also before "100 Continue") and refuses
  // what authentication, the size limits and the encoding rules do not allow (Handled: answered,
  // the connection closed so the body is never read as a request).
  httplib::Server::HandlerResponse FilterRequest(const httplib::Request& req,
                                                 httplib::Response& res);
  // Notes the request in the metrics and, with options.access_log, one line on stderr.
  void LogAccess(const httplib::Request& req, const httplib::Response& res);
  // The /api/v1 routes, the recording routes and the HTML pages.
  void RegisterApiRoutes(httplib::Server* server);
  // Takes back at once the jobs of calibd processes of this host that died (kill -9, crash)
  // while holding them, instead of waiting for their leases to expire (ProcessInstance).
  void ReapDeadProcesses();
  // Runs Store::QuickCheck and notes its report in `health` (logged when not "ok").
  void CheckStorage();
  bool Authorized(const httplib::Request& req) const;
  // Whether `given` is the server's token (true when it has none); constant time.
  bool TokenMatches(const std::string& given) const;
  void HandleUpload(const httplib::Request& req, httplib::Response& res,
                    const httplib::ContentReader& reader);
  // The job an upload's config (with a method) asks for, checked against the recording read
  // (`summary`; `file_name`, the client's, names it in messages) before anything is stored:
  // references resolved, the config validated (*common), the time column and the job budget
  // checked. Sets rec->job; *config gets the stored (NFC) serial.
  Status CheckUploadJob(const RecordingSummary& summary, const std::string& file_name,
                        nlohmann::json* config, CommonConfig* common, storage::NewRecording* rec);
  void HandleCreateJob(const httplib::Request& req, httplib::Response& res);
  void HandleGetJob(const httplib::Request& req, httplib::Response& res);
  void HandleDecision(const httplib::Request& req, httplib::Response& res, bool revoke);
  // POST /api/v1/jobs/{id}/cancel: JSON {"reason"} or an HTML form (reason, token).
  void HandleCancel(const httplib::Request& req, httplib::Response& res);
  // Whether `req` is an HTML form post (application/x-www-form-urlencoded) to the cancel route,
  // which carries its token in the form (checked by HandleCancel), not in a header.
  static bool IsCancelForm(const httplib::Request& req);
  void HandleListJobs(const httplib::Request& req, httplib::Response& res);
  void HandleDevices(const httplib::Request& req, httplib::Response& res);
  void HandleLatest(const httplib::Request& req, httplib::Response& res);
  void HandleFleet(const httplib::Request& req, httplib::Response& res);  // fleet_routes.cc
  void HandlePlan(const httplib::Request& req, httplib::Response& res);   // plan.cc
  void HandleCheck(const httplib::Request& req, httplib::Response& res);  // check_routes.cc
  void HandleRecording(const httplib::Request& req, httplib::Response& res);
  void HandleRecordingData(const httplib::Request& req, httplib::Response& res);
  void HandleHealth(const httplib::Request& req, httplib::Response& res);
  void HandleMetrics(const httplib::Request& req, httplib::Response& res);
};

// --- The API's JSON (api_json.cc).
nlohmann::json NullIfEmpty(const std::string& s);  // null for ""
// A job as the API shows it (SPEC §5); the result only when `with_result`.
nlohmann::json JobJson(const storage::JobInfo& job, bool with_result);
nlohmann::json EventJson(const storage::JobEvent& e);
nlohmann::json RecordingJson(const storage::RecordingInfo& r);
// A positive decimal id of at most 18 digits.
bool ParseId(const std::string& text, int64_t* id);

// --- Uploads (upload_routes.cc).
bool IsGzipEncoding(const std::string& encoding);  // "gzip" or "x-gzip", any case
// The config's references to other jobs, resolved by its method before the job is stored
// (Method::ResolveReferences); a config without a known method is left to ValidateConfig.
Status ResolveJobReferences(storage::Store* store, nlohmann::json* config);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SERVICE_IMPL_H_
