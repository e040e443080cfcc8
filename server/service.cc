#include "server/service.h"

#include <arpa/inet.h>
#include <sys/socket.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
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
#include "server/config.h"
#include "server/device_lookup.h"
#include "server/gzip_stream.h"
#include "server/http_server.h"
#include "server/http_util.h"
#include "server/instance.h"
#include "server/job_budget.h"
#include "server/metrics.h"
#include "server/plan.h"
#include "server/recording_routes.h"
#include "server/service_impl.h"
#include "server/worker_pool.h"
#include "storage/store.h"

namespace calibd::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

thread_local std::chrono::steady_clock::time_point t_request_start;

bool IsLoopback(const std::string& host) {
  if (host == "localhost") return true;
  in_addr a4;
  if (inet_pton(AF_INET, host.c_str(), &a4) == 1) return (ntohl(a4.s_addr) >> 24) == 127;
  in6_addr a6;
  if (inet_pton(AF_INET6, host.c_str(), &a6) == 1) return IN6_IS_ADDR_LOOPBACK(&a6);
  return false;
}

bool ConstantTimeEquals(const std::string& a, const std::string& b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  const size_t n = std::max(a.size(), b.size());
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? a[i] : 0;
    const unsigned char y = i < b.size() ? b[i] : 0;
    diff |= x ^ y;
  }
  return diff == 0;
}

// "revoke", "accept" or "cancel" for a path /api/v1/jobs/{id}/<that>, else "".
std::string DecisionOfPath(const std::string& path) {
  const std::string prefix = "/api/v1/jobs/";
  if (path.rfind(prefix, 0) != 0) return "";
  const size_t slash = path.find('/', prefix.size());
  if (slash == std::string::npos || slash == prefix.size() ||
      path.find_first_not_of("0123456789", prefix.size()) != slash) {
    return "";
  }
  const std::string action = path.substr(slash + 1);
  return action == "revoke" || action == "accept" || action == "cancel" ? action : "";
}

// Why an SQLite --db path cannot be opened for writing, in words ("" when nothing is seen
// wrong): SQLite itself says only "unable to open database file".
std::string DbPathProblem(const std::string& db) {
  std::error_code ec;
  const fs::path path(db);
  if (fs::is_directory(path, ec)) {
    return "--db " + db + " is a directory; give the database file's path (e.g. " +
           (path / "calibd.db").string() + ")";
  }
  const bool exists = fs::exists(path, ec);
  const fs::path folder = fs::absolute(path, ec).parent_path();
  // The folder is created when missing (and that failing is said by the store).
  const fs::path checked = exists ? path : folder;
  if (!exists && !fs::exists(folder, ec)) return "";
  struct statvfs vfs;
  if (::statvfs(checked.c_str(), &vfs) == 0 && (vfs.f_flag & ST_RDONLY) != 0) {
    return "--db " + db + ": " + (exists ? "the file" : "its folder " + folder.string()) +
           " is on a read-only file system; calibd writes its database (give a writable path)";
  }
  if (exists && ::access(path.c_str(), W_OK) != 0) {
    return "--db " + db + " is read-only (" + std::strerror(errno) +
           "); calibd writes its database: give it write permission or another path";
  }
  // SQLite also writes its -wal and -shm files beside the database.
  if (::access(folder.c_str(), W_OK) != 0) {
    return "--db " + db + ": its folder " + folder.string() + " is not writable (" +
           std::strerror(errno) + "); SQLite writes the journal files " + path.filename().string() +
           "-wal and -shm there";
  }
  return "";
}

}  // namespace

Service::Service(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Service::~Service() { Shutdown(); }

std::string ServeOptions::Validate() const {
  std::string host;
  int port;
  if (!SplitHostPort(listen, &host, &port)) {
    return "--listen must be HOST:PORT (e.g. 127.0.0.1:8080), not '" + listen + "'";
  }
  if (workers < 0) return "--workers must be >= 0";
  if (max_upload_bytes < 1) return "--max-upload-bytes must be >= 1";
  if (!(max_gzip_ratio >= 1)) return "--max-gzip-ratio must be >= 1";
  if (job_memory_bytes < 0) return "--job-memory-bytes must be >= 0 (0: automatic)";
  if (job_seconds < 0) return "--job-seconds must be >= 0 (0: from the per-job memory budget)";
  if (shutdown_grace_seconds < 0) return "--grace-seconds must be >= 0";
  if (http_threads < 4) return "--http-threads must be >= 4";
  if (head_timeout_seconds < 1) return "--head-timeout-seconds must be >= 1";
  if (max_connections_per_client < 1) return "--max-connections-per-client must be >= 1";
  if (max_requests_per_client < 1) return "--max-requests-per-client must be >= 1";
  if (db_path.empty()) return "--db must not be empty";
  if (column_cache_bytes < 0) return "--column-cache-bytes must be >= 0 (0: no cache)";
  return "";
}

Status Service::Create(const ServeOptions& options, std::unique_ptr<Service>* out) {
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  const std::string problem = options.Validate();
  if (!problem.empty()) return Status::InvalidInput(problem);
  SplitHostPort(options.listen, &impl->host, &impl->requested_port);
  if (!options.token_file.empty()) {
    std::ifstream in(options.token_file);
    if (!in) return Status::InvalidInput("cannot read --token-file " + options.token_file);
    std::getline(in, impl->token);
    // Spaces, tabs or a CR around the token are never part of it: a header cannot carry them
    // (HTTP trims a field value), so a token with them could never be sent. Trimmed, and said.
    const size_t first = impl->token.find_first_not_of(" \t\r\v\f");
    const size_t last = impl->token.find_last_not_of(" \t\r\v\f");
    const std::string trimmed =
        first == std::string::npos ? "" : impl->token.substr(first, last - first + 1);
    if (trimmed.size() != impl->token.size() && !trimmed.empty()) {
      std::cerr << "calibd: warning: --token-file " << options.token_file
                << " line 1: " << (first > 0 ? "leading" : "trailing")
                << (first > 0 && last + 1 < impl->token.size() ? " and trailing" : "")
                << " whitespace removed from the token (clients send it without)\n";
    }
    impl->token = trimmed;
    if (impl->token.size() < 16) {
      return Status::InvalidInput("the token in --token-file " + options.token_file +
                                  " (line 1) must have at least 16 characters");
    }
  }
  if (!IsLoopback(impl->host) && impl->token.empty() && !options.insecure) {
    return Status::InvalidInput("refusing to listen on non-loopback address '" + impl->host +
                                "' without --token-file (use --insecure to override)");
  }
  if (!options.acceptance_file.empty()) {
    Status s = LoadAcceptanceFile(options.acceptance_file, &impl->acceptance);
    if (!s.ok()) return s;
  }
  storage::StoreOptions store_options;
  store_options.max_page_count = options.db_max_pages;
  const bool sqlite = !storage::Store::IsPostgresTarget(options.db_path);
  if (sqlite && options.db_path != ":memory:") {
    const std::string problem = DbPathProblem(options.db_path);
    if (!problem.empty()) return Status::IoError(problem);
  }
  Status s = storage::Store::Open(options.db_path, store_options, &impl->store);
  if (!s.ok()) return s;
  // A damaged file serves nothing wrong, but is said at once (log, /healthz) and then on the
  // schedule (Run).
  impl->CheckStorage();
  int64_t recovered = 0;
  s = impl->store->RecoverExpiredLeases(&recovered);
  if (!s.ok()) return s;
  if (recovered > 0) {
    std::cerr << "calibd: took back " << recovered << " job(s) whose lease had lapsed\n";
  }
  // Staging (and the detection of this host's dead calibd processes) beside an SQLite file; for
  // a PostgreSQL database in the temporary folder, one per database, shared by its processes.
  const char* tmp = std::getenv("TMPDIR");
  const fs::path staging_root =
      storage::Store::IsPostgresTarget(options.db_path)
          ? fs::path(tmp != nullptr && *tmp != '\0' ? tmp : "/tmp") /
                ("calibd-staging-" + Sha256Hex(options.db_path).substr(0, 12))
          : fs::absolute(options.db_path).parent_path() / "staging";
  s = ProcessInstance::Create(staging_root, &impl->instance);
  if (!s.ok()) return s;
  impl->staging_dir = impl->instance->staging_dir();
  impl->ReapDeadProcesses();
  // The parsed-columns cache beside the staging folder (per host for PostgreSQL: a cache is
  // local, what it holds is re-derived from the database).
  ColumnCacheOptions columns;
  if (options.column_cache_bytes > 0 && options.db_path != ":memory:") {
    columns.dir = staging_root.parent_path() /
                  (storage::Store::IsPostgresTarget(options.db_path)
                       ? "calibd-columns-" + Sha256Hex(options.db_path).substr(0, 12)
                       : "columns");
    columns.max_bytes = options.column_cache_bytes;
  }
  WorkerPoolOptions pool;
  pool.storage_outcome = [d = impl.get()](const Status& st, const std::string& what, bool write) {
    d->health.Note(st, what, write);
  };
  pool.workers =
      options.workers > 0 ? options.workers : std::max(1u, std::thread::hardware_concurrency());
  pool.lease_ms = options.lease_ms;
  pool.id_prefix = impl->instance->id();
  pool.housekeeping = [d = impl.get()] { d->ReapDeadProcesses(); };
  impl->numerics = std::make_unique<core::TaskPool>(
      std::max(0, static_cast<int>(std::thread::hardware_concurrency()) - 1));
  pool.executor = impl->numerics->Executor();
  pool.acceptance = impl->acceptance;
  impl->job_memory_bytes =
      options.job_memory_bytes > 0 ? options.job_memory_bytes : DefaultJobMemoryBytes(pool.workers);
  pool.job_memory_bytes = impl->job_memory_bytes;
  columns.prefetch_memory_bytes = impl->job_memory_bytes;
  impl->column_cache = std::make_unique<ColumnCache>(columns);
  pool.column_cache = impl->column_cache.get();
  impl->job_seconds =
      options.job_seconds > 0 ? options.job_seconds : DefaultJobSeconds(impl->job_memory_bytes);
  pool.job_ms = impl->job_seconds * 1000;
  impl->workers = std::make_unique<WorkerPool>(impl->store.get(), &impl->metrics, pool);
  HttpLimits limits;
  limits.threads = options.http_threads;
  limits.read_timeout_ms = options.read_timeout_seconds * 1000;
  limits.write_timeout_ms = options.write_timeout_seconds * 1000;
  limits.head_timeout_ms = options.head_timeout_seconds * 1000;
  limits.max_connections_per_client = options.max_connections_per_client;
  limits.max_requests_per_client = options.max_requests_per_client;
  const std::string problem_http = limits.Validate();
  if (!problem_http.empty()) return Status::InvalidInput(problem_http);
  impl->http = std::make_unique<HttpServer>(limits);
  impl->SetupRoutes();
  out->reset(new Service(std::move(impl)));
  return Status::Ok();
}

// cpp-httplib 0.11 listens with a backlog of 5, and its default socket options set SO_REUSEPORT
// on Linux, which lets a second calibd bind the same port and silently take half the requests
// to another database. Bind sets SO_REUSEADDR only (a restart may reuse a port in TIME_WAIT),
// and then listens again with this backlog (Linux updates it in place): with 5, connections
// opened in a burst had their handshake dropped and waited a 1 s retransmission (wrk, 64
// connections: p99 0.7-0.9 s).
constexpr int kListenBacklog = 1024;

Status Service::Bind() {
  Impl& d = *impl_;
  d.http->set_socket_options([&d](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    d.listen_fd = sock;  // the last socket tried is the one that binds
  });
  if (d.requested_port == 0) {
    d.bound_port = d.http->bind_to_any_port(d.host);
    if (d.bound_port <= 0) return Status::IoError("cannot bind " + d.host + " to any port");
  } else {
    if (!d.http->bind_to_port(d.host, d.requested_port)) {
      return Status::IoError("cannot listen on " + d.options.listen +
                             " (address in use or not available)");
    }
    d.bound_port = d.requested_port;
  }
  if (d.listen_fd >= 0 && ::listen(d.listen_fd, kListenBacklog) != 0) {
    return Status::IoError(std::string("cannot set the listen backlog: ") + strerror(errno));
  }
  return Status::Ok();
}

int Service::port() const { return impl_->bound_port; }

void Service::Run() {
  Impl& d = *impl_;
  if (d.options.check_seconds > 0 && !d.checker.joinable()) {
    d.checker = std::thread([&d] {
      std::unique_lock<std::mutex> lock(d.checker_mu);
      for (;;) {
        if (d.checker_cv.wait_for(lock, std::chrono::seconds(d.options.check_seconds),
                                  [&d] { return d.checker_stop; })) {
          return;
        }
        lock.unlock();
        d.CheckStorage();
        lock.lock();
      }
    });
  }
  impl_->workers->Start();
  impl_->http->listen_after_bind();
}

bool Service::Shutdown() {
  Impl& d = *impl_;
  std::call_once(d.shutdown_once, [&d] {
    // First the HTTP side, waiting for requests in progress (their handlers use the store and
    // the worker pool), then the workers, then the store. One grace period for both: the jobs
    // (which ran on meanwhile) get what the requests left of it.
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::seconds(d.options.shutdown_grace_seconds);
    // The parsed-columns cache's background build ends and readers waiting for a build (a job,
    // a check) are woken with kStopped: none of them holds up the shutdown.
    if (d.column_cache) d.column_cache->Stop();
    d.http->Shutdown(d.options.shutdown_grace_seconds * 1000);
    {
      std::lock_guard<std::mutex> lock(d.checker_mu);
      d.checker_stop = true;
    }
    d.checker_cv.notify_all();
    if (d.checker.joinable()) d.checker.join();
    StopOutcome outcome = StopOutcome::kFinished;
    if (d.workers) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      outcome = d.workers->Stop(std::max(left, std::chrono::milliseconds(0)));
    }
    d.shutdown_clean = outcome == StopOutcome::kFinished;
    d.abandoned = outcome == StopOutcome::kAbandoned;
    // An abandoned job's thread still computes and may still touch the store: keep both (the
    // process exits without destroying them, RunServe).
    if (d.store && !d.abandoned) {
      d.store->Checkpoint();
      d.workers.reset();
      // The parsed-columns cache's background build reads the store: stopped (and joined)
      // before the store goes.
      d.column_cache.reset();
      d.store.reset();
    }
  });
  return d.shutdown_clean;
}

bool Service::abandoned_jobs() const { return impl_->abandoned; }

void Service::Impl::ReapDeadProcesses() {
  instance->ReapDead([this](const std::string& id) {
    int64_t n = 0;
    Status s = store->ExpireLeasesOf(id + "-", &n);  // worker ids are "<id>-<n>"
    if (!s.ok()) {
      std::cerr << "calibd: cannot take back the jobs of dead process " << id << ": "
                << s.ToString() << "\n";
    } else if (n > 0) {
      std::cerr << "calibd: took back " << n << " job(s) of dead process " << id << "\n";
    }
    return s;
  });
}

void Service::Impl::CheckStorage() {
  std::string report;
  Status s = store->QuickCheck(&report);
  if (!s.ok()) {
    // Unreachable or busy: /healthz sees that itself; the structure is checked next time.
    std::cerr << "calibd: cannot check the database: " << s.ToString() << "\n";
    return;
  }
  if (report != "ok") {
    std::cerr << "calibd: the database " << store->path() << " is damaged (quick_check): " << report
              << "\ncalibd: /healthz answers 503 until it is repaired; restore it from a backup\n";
  }
  health.NoteCheck(report);
}

bool Service::Impl::TokenMatches(const std::string& given) const {
  return token.empty() || ConstantTimeEquals(given, token);
}

bool Service::Impl::Authorized(const httplib::Request& req) const {
  if (token.empty()) return true;
  const std::string header = req.get_header_value("Authorization");
  const std::string prefix = "Bearer ";
  if (header.size() <= prefix.size() || header.compare(0, prefix.size(), prefix) != 0) {
    return false;
  }
  return ConstantTimeEquals(header.substr(prefix.size()), token);
}

namespace {

// The error handler: a JSON error for an answer httplib made without a body (404, 413, 414, 400).
httplib::Server::HandlerResponse AnswerHttpError(const httplib::Request& req,
                                                 httplib::Response& res) {
  if (!res.body.empty()) return httplib::Server::HandlerResponse::Handled;
  switch (res.status) {
    case 404:
      SendError(res, 404, "not_found", "no such resource: " + req.path.substr(0, 200));
      break;
    case 413:
      SendError(res, 413, "too_large", "request body too large");
      break;
    case 414:
      SendError(res, 414, "uri_too_long", "request URI too long");
      break;
    case 400:
      SendError(res, 400, "invalid_input", "malformed request");
      break;
    default:
      SendError(res, res.status, "error", "request failed");
      break;
  }
  return httplib::Server::HandlerResponse::Handled;
}

// Known paths with another method: 405 with Allow; everything else: 404.
void AnswerNotAllowed(const httplib::Request& req, httplib::Response& res) {
  const std::string allow = AllowedMethods(req.path);
  if (allow.empty()) {
    SendError(res, 404, "not_found", "no such resource: " + req.path.substr(0, 200));
    return;
  }
  res.set_header("Allow", allow);
  SendError(res, 405, "method_not_allowed",
            req.method + " is not allowed on " + req.path.substr(0, 200) + "; allowed: " + allow);
}

}  // namespace

httplib::Server::HandlerResponse Service::Impl::FilterRequest(const httplib::Request& req,
                                                              httplib::Response& res) {
  t_request_start = std::chrono::steady_clock::now();
  const bool write = req.method != "GET" && req.method != "HEAD" && req.method != "OPTIONS";
  const bool is_upload = req.path == "/api/v1/recordings" && req.method == "POST";
  // Only uploads may be compressed, and only with gzip (decoded by HandleUpload under the
  // upload and ratio limits); httplib never decodes bodies (server/http_server.h).
  if (req.has_header(kBodyEncodingHeader)) {
    const std::string enc = req.get_header_value(kBodyEncodingHeader);
    if (ToLower(enc) != "identity" && !(is_upload && IsGzipEncoding(enc))) {
      res.set_header("Connection", "close");
      SendError(res, 415, "unsupported_media_type",
                "compressed request bodies (Content-Encoding: " + enc.substr(0, 32) +
                    ") are not accepted; " +
                    (is_upload ? "send the recording uncompressed or with Content-Encoding: gzip"
                               : "send the body uncompressed"));
      return httplib::Server::HandlerResponse::Handled;
    }
  }
  if (write && req.has_header("Content-Length")) {
    const std::string text = req.get_header_value("Content-Length");
    const int64_t limit = is_upload ? options.max_upload_bytes : options.max_json_body_bytes;
    int64_t length = -1;
    if (!text.empty() && text.find_first_not_of("0123456789") == std::string::npos) {
      // Over 18 digits: beyond any limit (and std::stoll's range from 19 on).
      length = text.size() <= 18 ? std::stoll(text) : INT64_MAX;
    }
    if (length < 0) {
      res.set_header("Connection", "close");
      SendError(res, 400, "invalid_input", "invalid Content-Length");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (length > limit) {
      res.set_header("Connection", "close");
      SendError(res, 413, "too_large",
                "the body has " + text + " bytes; the limit is " + std::to_string(limit));
      return httplib::Server::HandlerResponse::Handled;
    }
  }
  // Only uploads may stream a chunked body (cut off at the upload limit by our reader);
  // cpp-httplib would buffer any other chunked body whole, so those need a Content-Length.
  const bool chunked = ToLower(req.get_header_value("Transfer-Encoding")) == "chunked";
  if (write && !req.has_header("Content-Length") && (!chunked || !is_upload) &&
      req.method != "DELETE") {
    res.set_header("Connection", "close");
    // A decision (revoke, accept, cancel) sent without a body: what it lacks is its reason.
    if (const std::string decision = DecisionOfPath(req.path); !decision.empty()) {
      SendError(res, 411, "length_required",
                "a " + decision +
                    " needs a reason: send {\"reason\": \"...\"} as "
                    "application/json (with its Content-Length)");
      return httplib::Server::HandlerResponse::Handled;
    }
    SendError(res, 411, "length_required",
              "a request body needs Content-Length or chunked "
              "Transfer-Encoding");
    return httplib::Server::HandlerResponse::Handled;
  }
  // The job page's cancel form carries its token in the form (HandleCancel checks it).
  if (write && !Authorized(req) && !IsCancelForm(req)) {
    res.set_header("WWW-Authenticate", "Bearer");
    res.set_header("Connection", "close");
    SendError(res, 401, "unauthorized", "writes need the header 'Authorization: Bearer TOKEN'");
    return httplib::Server::HandlerResponse::Handled;
  }
  return httplib::Server::HandlerResponse::Unhandled;
}

void Service::Impl::LogAccess(const httplib::Request& req, const httplib::Response& res) {
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_request_start).count();
  metrics.ObserveRequest(req.method, RouteLabel(req.path), res.status, seconds);
  if (options.access_log) {
    char tail[96];
    std::snprintf(tail, sizeof tail, " %d %zu %.3fms\n", res.status, res.body.size(),
                  seconds * 1e3);
    // One write per line, so lines from concurrent requests never interleave.
    const std::string line = SanitizeForLog(req.remote_addr.empty() ? "-" : req.remote_addr) + " " +
                             SanitizeForLog(req.method.empty() ? "-" : req.method) + " " +
                             SanitizeForLog(req.path.empty() ? "-" : req.path) + tail;
    [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, line.data(), line.size());
  }
}

void Service::Impl::RegisterApiRoutes(httplib::Server* server) {
  httplib::Server& http = *server;
  http.Post("/api/v1/recordings",
            [this](const httplib::Request& req, httplib::Response& res,
                   const httplib::ContentReader& reader) { HandleUpload(req, res, reader); });
  http.Post("/api/v1/jobs", [this](const httplib::Request& req, httplib::Response& res) {
    HandleCreateJob(req, res);
  });
  http.Get(R"(/api/v1/jobs/([^/]+))",
           [this](const httplib::Request& req, httplib::Response& res) { HandleGetJob(req, res); });
  http.Post(R"(/api/v1/jobs/([^/]+)/revoke)",
            [this](const httplib::Request& req, httplib::Response& res) {
              HandleDecision(req, res, /*revoke=*/true);
            });
  http.Post(R"(/api/v1/jobs/([^/]+)/accept)",
            [this](const httplib::Request& req, httplib::Response& res) {
              HandleDecision(req, res, /*revoke=*/false);
            });
  http.Post(
      R"(/api/v1/jobs/([^/]+)/cancel)",
      [this](const httplib::Request& req, httplib::Response& res) { HandleCancel(req, res); });
  http.Get("/api/v1/jobs", [this](const httplib::Request& req, httplib::Response& res) {
    HandleListJobs(req, res);
  });
  http.Get("/api/v1/devices", [this](const httplib::Request& req, httplib::Response& res) {
    HandleDevices(req, res);
  });
  http.Get(R"(/api/v1/devices/([^/]+)/calibration)",
           [this](const httplib::Request& req, httplib::Response& res) { HandleLatest(req, res); });
  http.Post("/api/v1/plan",
            [this](const httplib::Request& req, httplib::Response& res) { HandlePlan(req, res); });
  http.Get("/plan", [this](const httplib::Request& req, httplib::Response& res) {
    SendPage(res, 200, web::RenderPlanPage(PlanPageView(req.params, store.get(), acceptance)));
  });
  http.Get(R"(/api/v1/recordings/([^/]+)/check)",
           [this](const httplib::Request& req, httplib::Response& res) { HandleCheck(req, res); });
  http.Get(R"(/api/v1/products/([^/]+)/fleet)",
           [this](const httplib::Request& req, httplib::Response& res) { HandleFleet(req, res); });
  http.Get(
      R"(/api/v1/recordings/([^/]+))",
      [this](const httplib::Request& req, httplib::Response& res) { HandleRecording(req, res); });
  http.Get(R"(/api/v1/recordings/([^/]+)/data)",
           [this](const httplib::Request& req, httplib::Response& res) {
             HandleRecordingData(req, res);
           });
  http.Get("/api/v1/healthz",
           [this](const httplib::Request& req, httplib::Response& res) { HandleHealth(req, res); });
  http.Get("/healthz",
           [this](const httplib::Request& req, httplib::Response& res) { HandleHealth(req, res); });
  http.Get("/api/v1/metrics", [this](const httplib::Request& req, httplib::Response& res) {
    HandleMetrics(req, res);
  });
  http.Get("/metrics", [this](const httplib::Request& req, httplib::Response& res) {
    HandleMetrics(req, res);
  });
  http.Get("/api/v1/openapi.json", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(JsonBody(OpenApiDocument()), "application/json");
  });
  RegisterRecordingRoutes(&http, store.get(), job_memory_bytes,
                          column_cache.get());  // /segments and the recording page
  RegisterHtmlRoutes(&http, store.get(), !token.empty());
}

void Service::Impl::SetupRoutes() {
  httplib::Server& http = *this->http;
  http.set_payload_max_length(static_cast<size_t>(options.max_upload_bytes));
  // Authentication, size and encoding limits, before the body is read (FilterRequest).
  this->http->SetRequestFilter([this](const httplib::Request& req, httplib::Response& res) {
    return FilterRequest(req, res);
  });
  http.set_exception_handler(AnswerException);
  http.set_error_handler(httplib::Server::HandlerWithResponse(AnswerHttpError));
  this->http->SetAccessLogger(
      [this](const httplib::Request& req, const httplib::Response& res) { LogAccess(req, res); });
  RegisterApiRoutes(&http);
  // Known paths with another method: 405 with Allow; everything else: 404.
  http.Get(".*", AnswerNotAllowed);
  http.Post(".*", AnswerNotAllowed);
  http.Put(".*", AnswerNotAllowed);
  http.Patch(".*", AnswerNotAllowed);
  http.Delete(".*", AnswerNotAllowed);
  http.Options(".*", AnswerNotAllowed);
}

void Service::Impl::HandleHealth(const httplib::Request&, httplib::Response& res) {
  storage::QueueCounts counts;
  Status s = store->QueueDepth(&counts);
  if (!s.ok()) {
    health.Note(s, "the job queue", false);
    res.status = 503;
    json body = {
        {"status", "unavailable"}, {"backend", store->backend()}, {"database", s.message()}};
    if (s.code() == StatusCode::kCorruption) body["status"] = "damaged";
    const json problems = health.Problems();
    if (!problems.empty()) body["problems"] = problems;
    res.set_content(JsonBody(body), "application/json");
    return;
  }
  // Damage found by the structure check or by a read, or a full disk: not healthy, whatever
  // still works (README "Storage damage").
  if (const json problems = health.Problems(); !problems.empty()) {
    res.status = 503;
    res.set_content(JsonBody(json{{"status", problems.contains("damage") ? "damaged" : "disk_full"},
                                  {"backend", store->backend()},
                                  {"database", "reachable"},
                                  {"problems", problems},
                                  {"queued", counts.queued},
                                  {"running", counts.running}}),
                    "application/json");
    return;
  }
  res.set_content(json{{"status", "ok"},
                       {"backend", store->backend()},
                       {"database", "reachable"},
                       {"queued", counts.queued},
                       {"running", counts.running},
                       {"workers_busy", workers->running_jobs()}}
                      .dump(),
                  "application/json");
}

void Service::Impl::HandleMetrics(const httplib::Request&, httplib::Response& res) {
  std::map<std::string, std::map<std::string, double>> gauges;
  storage::QueueCounts counts;
  const bool database_up = store->QueueDepth(&counts).ok();
  gauges["calibd_database_up"] = {
      {"backend=\"" + std::string(store->backend()) + "\"", database_up ? 1.0 : 0.0}};
  if (database_up) {
    gauges["calibd_jobs"] = {{"state=\"queued\"", static_cast<double>(counts.queued)},
                             {"state=\"running\"", static_cast<double>(counts.running)},
                             {"state=\"succeeded\"", static_cast<double>(counts.succeeded)},
                             {"state=\"failed\"", static_cast<double>(counts.failed)}};
  }
  gauges["calibd_workers_busy"] = {{"", static_cast<double>(workers->running_jobs())}};
  const HttpCounters c = http->counters();
  gauges["calibd_http_connections"] = {
      {"state=\"open\"", static_cast<double>(c.open_connections)},
      {"state=\"receiving_head\"", static_cast<double>(c.pending_heads)},
      {"state=\"in_request\"", static_cast<double>(c.requests_in_progress)}};
  // Counters since the start (Prometheus reads them as gauges here; rate() works on both).
  gauges["calibd_http_refusals"] = {
      {"reason=\"connections_per_client\"", static_cast<double>(c.refused_connections)},
      {"reason=\"requests_per_client_waited\"", static_cast<double>(c.delayed_requests)},
      {"reason=\"head_timeout\"", static_cast<double>(c.head_timeouts)},
      {"reason=\"head_too_large\"", static_cast<double>(c.heads_too_large)},
      {"reason=\"lingering_close\"", static_cast<double>(c.lingering_closes)}};
  res.set_content(
      metrics.Render(
          gauges, {{"calibd_jobs", "Jobs in the queue by state."},
                   {"calibd_workers_busy", "Workers running a job."},
                   {"calibd_database_up", "1 when the database answered this scrape, by backend."},
                   {"calibd_http_connections", "Client connections by state."},
                   {"calibd_http_refusals",
                    "Connections refused or closed by the front end since the start, by "
                    "reason."}}),
      "text/plain; version=0.0.4");
}

}  // namespace calibd::server
