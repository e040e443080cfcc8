#include "server/service.h"

#include <arpa/inet.h>
#include <sys/socket.h>
#include <unistd.h>

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
#include "server/acceptance.h"
#include "server/config.h"
#include "server/device_lookup.h"
#include "server/exports.h"
#include "server/gzip_stream.h"
#include "server/http_server.h"
#include "server/http_util.h"
#include "server/inertial_log.h"
#include "server/instance.h"
#include "server/job_budget.h"
#include "server/method.h"
#include "server/metrics.h"
#include "server/noise_reference.h"
#include "server/recording.h"
#include "server/recording_routes.h"
#include "server/worker_pool.h"
#include "storage/store.h"

namespace calibd::server {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

thread_local std::chrono::steady_clock::time_point t_request_start;

// A staged upload file, removed when this goes out of scope.
class StagingFile {
 public:
  StagingFile() = default;
  ~StagingFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!path_.empty()) ::unlink(path_.c_str());
  }
  Status Create(const fs::path& dir) {
    std::string tmpl = (dir / "upload-XXXXXX").string();
    fd_ = ::mkstemp(tmpl.data());
    if (fd_ < 0) return Status::IoError("cannot create a staging file in " + dir.string());
    path_ = tmpl;
    return Status::Ok();
  }
  bool Write(const char* data, size_t len) {
    while (len > 0) {
      const ssize_t n = ::write(fd_, data, len);
      if (n < 0) {
        if (errno == EINTR) continue;
        return false;
      }
      data += n;
      len -= static_cast<size_t>(n);
    }
    return true;
  }
  Status Close() {
    if (fd_ >= 0 && ::close(fd_) != 0) {
      fd_ = -1;
      return Status::IoError("cannot write the staging file");
    }
    fd_ = -1;
    return Status::Ok();
  }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
};

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

json NullIfEmpty(const std::string& s) { return s.empty() ? json() : json(s); }

// A job as the API shows it (SPEC §5).
json JobJson(const storage::JobInfo& job, bool with_result) {
  json j = {{"id", job.id},
            {"status", job.status},
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
  if (!job.error_code.empty() && job.status != "succeeded") {
    j["error"] = {{"code", job.error_code}, {"message", job.error_message}};
  }
  json config;
  if (ParseJsonText(job.config_json, "config", &config).ok()) j["config"] = std::move(config);
  if (with_result && !job.result_json.empty()) {
    json result;
    if (ParseJsonText(job.result_json, "result", &result).ok()) j["result"] = std::move(result);
  }
  // The acceptance gate: the gate's verdict, a person's decision, and what follows (only the
  // "accepted" state is ever served as the device's calibration).
  j["verdict"] = NullIfEmpty(job.verdict);
  j["revoked"] = job.decision == "revoked";
  j["state"] = NullIfEmpty(job.state);
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
  return j;
}

bool IsGzipEncoding(const std::string& encoding) {
  const std::string e = ToLower(encoding);
  return e == "gzip" || e == "x-gzip";
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

// Over HTTP, an array config may name its accelerometer calibration by a succeeded pca job:
// {"accelerometer_calibration": {"job": ID}} becomes {"job": ID, "result": {...}} before the job
// is stored, so the job is self-contained (its result cannot change under it) and says which
// calibration it used.
Status ResolveCalibrationReference(storage::Store* store, json* config) {
  if (!config->is_object()) return Status::Ok();
  // accel_noise / gyro_noise: {"job": ID} of a noise job, resolved the same way.
  Status noise = ResolveNoiseReferences(store, config);
  if (!noise.ok()) return noise;
  auto it = config->find("accelerometer_calibration");
  if (it == config->end() || !it->is_object() || !it->contains("job") || it->contains("result")) {
    return Status::Ok();
  }
  const json& ref = (*it)["job"];
  if (!ref.is_number_integer() || it->size() != 1) {
    return Status::InvalidInput(
               "'accelerometer_calibration' must be a pca result or {\"job\": ID} of a "
               "succeeded pca job")
        .WithField("accelerometer_calibration");
  }
  const int64_t id = ref.get<int64_t>();
  storage::JobInfo job;
  Status s = store->GetJob(id, &job);
  if (s.code() == StatusCode::kNotFound) {
    return Status::InvalidInput("accelerometer_calibration: there is no job " + std::to_string(id))
        .WithField("accelerometer_calibration");
  }
  if (!s.ok()) return s;
  if (job.method != "pca" || job.status != "succeeded") {
    return Status::InvalidInput("accelerometer_calibration: job " + std::to_string(id) + " is a " +
                                job.status + " " + job.method +
                                " job; it must be a succeeded pca job")
        .WithField("accelerometer_calibration");
  }
  if (!job.served()) {
    // The gate applies to calibrations that feed other calibrations too.
    return Status::InvalidInput(
               "accelerometer_calibration: job " + std::to_string(id) + " is " + job.state +
               (job.state == "rejected" ? " by the acceptance gate" : std::string()) +
               " (see /jobs/" + std::to_string(id) +
               "); use an accepted pca calibration, or accept this one with a "
               "reason first")
        .WithField("accelerometer_calibration");
  }
  json result;
  s = ParseJsonText(job.result_json, "result of job " + std::to_string(id), &result);
  if (!s.ok()) return Status::Internal("stored result is not JSON");
  *it = json{{"job", id}, {"result", std::move(result)}};
  return Status::Ok();
}

}  // namespace

struct Service::Impl {
  ServeOptions options;
  std::string host;
  int requested_port = 0;
  int bound_port = 0;
  int listen_fd = -1;            // the listening socket, noted by the socket-options hook (Bind)
  std::string token;             // empty: no authentication
  nlohmann::json acceptance;     // server-wide acceptance limits (--acceptance), null for none
  int64_t job_memory_bytes = 0;  // the per-job memory budget in force (server/job_budget.h)
  fs::path staging_dir;
  std::unique_ptr<storage::Store> store;
  std::unique_ptr<ProcessInstance> instance;  // after store: removed before the store closes
  Metrics metrics;
  // The jobs' parallel numerics: cores - 1 threads shared by every worker (each worker computes
  // too), so W concurrent jobs use at most W + cores - 1 threads. Outlives the workers.
  std::unique_ptr<core::TaskPool> numerics;
  std::unique_ptr<WorkerPool> workers;
  std::unique_ptr<HttpServer> http;  // destroyed first: its request threads use the rest
  std::once_flag shutdown_once;
  bool shutdown_clean = true;

  void SetupRoutes();
  // Takes back at once the jobs of calibd processes of this host that died (kill -9, crash)
  // while holding them, instead of waiting for their leases to expire (ProcessInstance).
  void ReapDeadProcesses();
  bool Authorized(const httplib::Request& req) const;
  void HandleUpload(const httplib::Request& req, httplib::Response& res,
                    const httplib::ContentReader& reader);
  void HandleCreateJob(const httplib::Request& req, httplib::Response& res);
  void HandleGetJob(const httplib::Request& req, httplib::Response& res);
  void HandleDecision(const httplib::Request& req, httplib::Response& res, bool revoke);
  void HandleListJobs(const httplib::Request& req, httplib::Response& res);
  void HandleDevices(const httplib::Request& req, httplib::Response& res);
  void HandleLatest(const httplib::Request& req, httplib::Response& res);
  void HandleRecording(const httplib::Request& req, httplib::Response& res);
  void HandleRecordingData(const httplib::Request& req, httplib::Response& res);
  void HandleHealth(const httplib::Request& req, httplib::Response& res);
  void HandleMetrics(const httplib::Request& req, httplib::Response& res);
};

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
  if (http_threads < 4) return "--http-threads must be >= 4";
  if (head_timeout_seconds < 1) return "--head-timeout-seconds must be >= 1";
  if (max_connections_per_client < 1) return "--max-connections-per-client must be >= 1";
  if (max_requests_per_client < 1) return "--max-requests-per-client must be >= 1";
  if (db_path.empty()) return "--db must not be empty";
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
    while (!impl->token.empty() && isspace(static_cast<unsigned char>(impl->token.back()))) {
      impl->token.pop_back();
    }
    if (impl->token.size() < 16) {
      return Status::InvalidInput("the token in --token-file must have at least 16 characters");
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
  Status s = storage::Store::Open(options.db_path, store_options, &impl->store);
  if (!s.ok()) return s;
  int64_t recovered = 0;
  s = impl->store->RecoverExpiredLeases(&recovered);
  if (!s.ok()) return s;
  if (recovered > 0) {
    std::cerr << "calibd: took back " << recovered << " job(s) whose lease had lapsed\n";
  }
  s = ProcessInstance::Create(fs::absolute(options.db_path).parent_path() / "staging",
                              &impl->instance);
  if (!s.ok()) return s;
  impl->staging_dir = impl->instance->staging_dir();
  impl->ReapDeadProcesses();
  WorkerPoolOptions pool;
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
  impl_->workers->Start();
  impl_->http->listen_after_bind();
}

bool Service::Shutdown() {
  Impl& d = *impl_;
  std::call_once(d.shutdown_once, [&d] {
    // First the HTTP side, waiting for requests in progress (their handlers use the store and
    // the worker pool), then the workers, then the store.
    d.http->Shutdown(d.options.shutdown_grace_seconds * 1000);
    if (d.workers) {
      d.shutdown_clean = d.workers->Stop(std::chrono::seconds(d.options.shutdown_grace_seconds));
    }
    if (d.store) {
      d.store->Checkpoint();
      d.workers.reset();
      d.store.reset();
    }
  });
  return d.shutdown_clean;
}

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

bool Service::Impl::Authorized(const httplib::Request& req) const {
  if (token.empty()) return true;
  const std::string header = req.get_header_value("Authorization");
  const std::string prefix = "Bearer ";
  if (header.size() <= prefix.size() || header.compare(0, prefix.size(), prefix) != 0) {
    return false;
  }
  return ConstantTimeEquals(header.substr(prefix.size()), token);
}

void Service::Impl::SetupRoutes() {
  httplib::Server& http = *this->http;
  http.set_payload_max_length(static_cast<size_t>(options.max_upload_bytes));

  // Runs before the body is read (also before "100 Continue"): authentication, size and encoding
  // limits. A refused request's connection is closed, so its body is never read as a request.
  this->http->SetRequestFilter([this](const httplib::Request& req, httplib::Response& res) {
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
      if (!text.empty() && text.size() <= 19 &&
          text.find_first_not_of("0123456789") == std::string::npos) {
        length = std::stoll(text);
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
      SendError(res, 411, "length_required",
                "a request body needs Content-Length or chunked "
                "Transfer-Encoding");
      return httplib::Server::HandlerResponse::Handled;
    }
    if (write && !Authorized(req)) {
      res.set_header("WWW-Authenticate", "Bearer");
      res.set_header("Connection", "close");
      SendError(res, 401, "unauthorized", "writes need the header 'Authorization: Bearer TOKEN'");
      return httplib::Server::HandlerResponse::Handled;
    }
    return httplib::Server::HandlerResponse::Unhandled;
  });

  http.set_exception_handler(
      [](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
        // Never exception text: it may reveal internals.
        SendError(res, 500, "internal", "internal server error");
      });

  http.set_error_handler(
      httplib::Server::HandlerWithResponse([](const httplib::Request& req, httplib::Response& res) {
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
      }));

  this->http->SetAccessLogger([this](const httplib::Request& req, const httplib::Response& res) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_request_start).count();
    metrics.ObserveRequest(req.method, RouteLabel(req.path), res.status, seconds);
    if (options.access_log) {
      char tail[96];
      std::snprintf(tail, sizeof tail, " %d %zu %.3fms\n", res.status, res.body.size(),
                    seconds * 1e3);
      // One write per line, so lines from concurrent requests never interleave.
      const std::string line = SanitizeForLog(req.remote_addr.empty() ? "-" : req.remote_addr) +
                               " " + SanitizeForLog(req.method.empty() ? "-" : req.method) + " " +
                               SanitizeForLog(req.path.empty() ? "-" : req.path) + tail;
      [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, line.data(), line.size());
    }
  });

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
  http.Get("/api/v1/jobs", [this](const httplib::Request& req, httplib::Response& res) {
    HandleListJobs(req, res);
  });
  http.Get("/api/v1/devices", [this](const httplib::Request& req, httplib::Response& res) {
    HandleDevices(req, res);
  });
  http.Get(R"(/api/v1/devices/([^/]+)/calibration)",
           [this](const httplib::Request& req, httplib::Response& res) { HandleLatest(req, res); });
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
  RegisterRecordingRoutes(&http, store.get());  // /segments and the recording page
  RegisterHtmlRoutes(&http, store.get());

  // Known paths with another method: 405 with Allow; everything else: 404.
  auto not_allowed = [](const httplib::Request& req, httplib::Response& res) {
    const std::string allow = AllowedMethods(req.path);
    if (allow.empty()) {
      SendError(res, 404, "not_found", "no such resource: " + req.path.substr(0, 200));
      return;
    }
    res.set_header("Allow", allow);
    SendError(res, 405, "method_not_allowed",
              req.method + " is not allowed on " + req.path.substr(0, 200) + "; allowed: " + allow);
  };
  http.Get(".*", not_allowed);
  http.Post(".*", not_allowed);
  http.Put(".*", not_allowed);
  http.Patch(".*", not_allowed);
  http.Delete(".*", not_allowed);
  http.Options(".*", not_allowed);
}

void Service::Impl::HandleUpload(const httplib::Request& req, httplib::Response& res,
                                 const httplib::ContentReader& reader) {
  int64_t received = 0;
  auto finish = [&](int status) { metrics.ObserveUpload(received, status); };

  // Config from the query string (text/csv bodies) — validated before the body is read.
  json config;
  Status s = ConfigFromQuery(req.params, &config);
  if (!s.ok()) return finish(SendStatus(res, s));

  const std::string content_type = req.get_header_value("Content-Type");
  const std::string media = ToLower(content_type.substr(0, content_type.find(';')));
  const bool multipart = req.is_multipart_form_data();
  const bool body_gzip = IsGzipEncoding(req.get_header_value(kBodyEncodingHeader));
  if (multipart && body_gzip) {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "a gzip-compressed multipart body is not accepted; compress the 'recording' part "
              "instead (a .csv.gz file)");
    return finish(415);
  }
  if (!multipart && media != "text/csv" && media != "text/plain" && media != "application/csv" &&
      media != "application/octet-stream" && media != "application/gzip" &&
      media != "application/x-gzip") {
    res.set_header("Connection", "close");
    SendError(res, 415, "unsupported_media_type",
              "send the recording as text/csv, or as multipart/form-data with parts 'recording' "
              "and 'config'; not '" +
                  content_type.substr(0, 64) + "'");
    return finish(415);
  }

  StagingFile staged;
  s = staged.Create(staging_dir);
  if (!s.ok()) return finish(SendStatus(res, s));
  Sha256 sha;
  RecordingParser parser("upload", /*collect=*/false);
  Status parse_status;  // first CSV error
  Status body_status;   // first other error (size, I/O, multipart shape)
  std::string file_name;

  // The recording may be gzip-compressed (Content-Encoding: gzip, or a body or part that starts
  // with the gzip magic bytes, e.g. a .csv.gz file). It is decompressed as it arrives, and the
  // decompressed CSV is what is parsed, hashed and stored: the same log sent compressed or not
  // is one recording, and GET /recordings/{id}/data returns the CSV.
  GzipLimits gzip_limits;
  gzip_limits.max_output_bytes = options.max_upload_bytes;
  gzip_limits.max_ratio = options.max_gzip_ratio;
  std::unique_ptr<GzipInflater> inflater;  // set when the recording is compressed
  std::string head;                        // the first bytes, until the magic can be seen
  bool decided = false;                    // compressed or not is known
  int64_t csv_bytes = 0;

  auto take_csv_bytes = [&](const char* data, size_t len) {
    csv_bytes += static_cast<int64_t>(len);
    if (csv_bytes > options.max_upload_bytes) {
      body_status =
          Status(StatusCode::kTooLarge, "the recording is larger than the limit of " +
                                            std::to_string(options.max_upload_bytes) + " bytes");
      return false;
    }
    sha.Update(std::string_view(data, len));
    if (!staged.Write(data, len)) {
      body_status = Status::IoError("cannot write the upload to disk");
      return false;
    }
    parse_status = parser.Feed(std::string_view(data, len));
    return parse_status.ok();
  };
  auto feed_recording = [&](const char* data, size_t len) {
    if (!inflater) return take_csv_bytes(data, len);
    Status st = inflater->Feed(data, len, take_csv_bytes);
    if (!st.ok() && !GzipInflater::IsSinkStopped(st)) body_status = st;
    return st.ok();
  };
  auto take_recording_bytes = [&](const char* data, size_t len) {
    received += static_cast<int64_t>(len);
    if (received > options.max_upload_bytes) {
      body_status =
          Status(StatusCode::kTooLarge, "the upload is larger than the limit of " +
                                            std::to_string(options.max_upload_bytes) + " bytes");
      return false;
    }
    if (!decided) {
      const size_t take = std::min(len, 2 - head.size());
      head.append(data, take);
      data += take;
      len -= take;
      if (head.size() < 2 && !body_gzip) return true;
      decided = true;
      if (body_gzip || LooksLikeGzip(head.data(), head.size())) {
        inflater = std::make_unique<GzipInflater>(gzip_limits, "the recording");
      }
      if (!feed_recording(head.data(), head.size())) return false;
    }
    return len == 0 || feed_recording(data, len);
  };
  // After the last byte: a recording of one byte, and the end of a gzip stream.
  auto end_recording = [&] {
    if (!decided && !head.empty()) {
      decided = true;
      if (!feed_recording(head.data(), head.size())) return;
    }
    if (inflater) {
      Status st = inflater->Finish();
      if (!st.ok()) body_status = st;
    }
  };

  bool read_ok;
  if (multipart) {
    std::string part;  // name of the current part
    std::string config_text;
    bool have_recording = false, have_config = false;
    read_ok = reader(
        [&](const httplib::MultipartFormData& header) {
          part = header.name;
          if (part == "recording") {
            if (have_recording) {
              body_status =
                  Status::InvalidInput("more than one 'recording' part").WithField("recording");
              return false;
            }
            have_recording = true;
            file_name = header.filename;
          } else if (part == "config") {
            if (have_config) {
              body_status = Status::InvalidInput("more than one 'config' part").WithField("config");
              return false;
            }
            have_config = true;
          } else {
            body_status = Status::InvalidInput("unknown multipart part '" + part.substr(0, 64) +
                                               "': expected 'recording' and 'config'")
                              .WithField(part.substr(0, 64));
            return false;
          }
          return true;
        },
        [&](const char* data, size_t len) {
          if (part == "recording") return take_recording_bytes(data, len);
          received += static_cast<int64_t>(len);
          if (static_cast<int64_t>(config_text.size() + len) > options.max_json_body_bytes) {
            body_status = Status(StatusCode::kTooLarge,
                                 "the config part is larger than " +
                                     std::to_string(options.max_json_body_bytes) + " bytes");
            return false;
          }
          config_text.append(data, len);
          return true;
        });
    if (read_ok && body_status.ok() && parse_status.ok()) {
      if (!have_recording) {
        body_status = Status::InvalidInput("no 'recording' part in the multipart body")
                          .WithField("recording");
      } else if (have_config) {
        json part_config;
        Status cs = ParseJsonText(config_text, "config", &part_config);
        if (!cs.ok()) {
          body_status = cs.WithField("config");
        } else if (!part_config.is_object()) {
          body_status =
              Status::InvalidInput("the config part must be a JSON object").WithField("config");
        } else {
          for (auto& [key, value] : part_config.items()) {
            if (config.contains(key)) {
              body_status = Status::InvalidInput("key '" + key +
                                                 "' given both in the query and the config part")
                                .WithField(key);
              break;
            }
            config[key] = value;
          }
        }
      }
    }
  } else {
    read_ok = reader([&](const char* data, size_t len) { return take_recording_bytes(data, len); });
  }
  if (read_ok && body_status.ok() && parse_status.ok()) end_recording();

  if (!body_status.ok()) {
    res.set_header("Connection", "close");
    return finish(SendStatus(res, body_status));
  }
  if (!parse_status.ok()) {
    res.set_header("Connection", "close");
    return finish(SendStatus(res, parse_status));
  }
  if (!read_ok) {
    // The connection broke or the body was malformed (e.g. bad chunk sizes, truncated multipart).
    res.set_header("Connection", "close");
    SendError(res, 400, "invalid_input", "the request body could not be read completely");
    return finish(400);
  }
  s = parser.Finish();
  if (!s.ok()) return finish(SendStatus(res, s));
  const RecordingSummary& summary = parser.summary();

  storage::NewRecording rec;
  rec.path = staged.path();
  rec.sha256 = sha.HexDigest();
  rec.layout = LayoutName(summary.layout);
  rec.rows = summary.rows;
  rec.columns_json = json(summary.columns).dump();
  rec.sensors_json = json(summary.sensors).dump();
  rec.file_name = file_name;
  CommonConfig common;
  const bool has_method = config.contains("method");
  if (has_method) {
    s = ResolveCalibrationReference(store.get(), &config);
    if (!s.ok()) return finish(SendStatus(res, s));
    s = ValidateConfig(config, &common);
    if (!s.ok()) return finish(SendStatus(res, s));
    if (FindMethod(common.method)->NeedsIncreasingTime()) {  // raw-log methods
      s = CheckTimesIncrease(summary, common.method);
      if (!s.ok()) return finish(SendStatus(res, s));
    }
    if (!FindMethod(common.method)->Reads(summary.layout)) {
      return finish(SendStatus(res, Status::InvalidInput(std::string("method '") + common.method +
                                                         "' cannot read the recording's " +
                                                         LayoutName(summary.layout) + " layout")
                                        .WithField("method")));
    }
    const RecordingShape shape{summary.rows, static_cast<int64_t>(summary.columns.size())};
    s = CheckJobBudget(*FindMethod(common.method), shape, WithoutAcceptance(config),
                       job_memory_bytes);
    if (!s.ok()) return finish(SendStatus(res, s));
    rec.job = storage::NewJob{common.method, common.device,
                              config.dump(-1, ' ', false, json::error_handler_t::replace)};
  } else if (config.contains("device")) {
    if (!config["device"].is_string()) {
      return finish(
          SendStatus(res, Status::InvalidInput("'device' must be a string").WithField("device")));
    }
    common.device = config["device"].get<std::string>();
    for (auto& [key, value] : config.items()) {
      if (key != "device") {
        return finish(
            SendStatus(res, Status::InvalidInput("config key '" + key + "' given without 'method'")
                                .WithField(key)));
      }
    }
  }
  rec.device = common.device;
  s = staged.Close();
  if (!s.ok()) return finish(SendStatus(res, s));

  storage::RecordingInfo info;
  bool existed = false;
  s = store->PutRecording(rec, &info, &existed);
  if (!s.ok()) return finish(SendStatus(res, s));
  json body = {{"recording",
                {{"id", info.id},
                 {"sha256", info.sha256},
                 {"bytes", info.bytes},
                 {"rows", info.rows},
                 {"layout", info.layout},
                 {"existed", existed},
                 {"compressed_bytes", inflater ? json(inflater->compressed_bytes()) : json()},
                 {"url", "/api/v1/recordings/" + std::to_string(info.id)}}}};
  if (info.job) {
    body["job"] = {{"id", info.job->id},
                   {"status", info.job->status},
                   {"url", "/api/v1/jobs/" + std::to_string(info.job->id)},
                   {"report_url", "/jobs/" + std::to_string(info.job->id)}};
    res.set_header("Location", "/api/v1/jobs/" + std::to_string(info.job->id));
    workers->Notify();
  } else {
    res.set_header("Location", "/api/v1/recordings/" + std::to_string(info.id));
  }
  res.status = 201;
  res.set_content(JsonBody(body), "application/json");
  finish(201);
}

void Service::Impl::HandleCreateJob(const httplib::Request& req, httplib::Response& res) {
  const std::string media = ToLower(req.get_header_value("Content-Type"));
  if (media.rfind("application/json", 0) != 0) {
    SendError(res, 415, "unsupported_media_type", "send the job as application/json");
    return;
  }
  json body;
  Status s = ParseJsonText(req.body, "request body", &body);
  if (!s.ok()) return (void)SendStatus(res, s);
  if (!body.is_object()) {
    SendError(res, 400, "invalid_input", "the body must be a JSON object");
    return;
  }
  for (auto& [key, value] : body.items()) {
    if (key != "recording_id" && key != "config") {
      return (void)SendStatus(
          res, Status::InvalidInput("unknown key '" + key + "' (expected recording_id, config)")
                   .WithField(key));
    }
  }
  if (!body.contains("recording_id") || !body["recording_id"].is_number_integer()) {
    return (void)SendStatus(
        res, Status::InvalidInput("'recording_id' must be an integer").WithField("recording_id"));
  }
  if (!body.contains("config")) {
    return (void)SendStatus(res, Status::InvalidInput("missing 'config'").WithField("config"));
  }
  const int64_t recording_id = body["recording_id"].get<int64_t>();
  json& config = body["config"];
  s = ResolveCalibrationReference(store.get(), &config);
  if (!s.ok()) return (void)SendStatus(res, s);
  CommonConfig common;
  s = ValidateConfig(config, &common);
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::RecordingInfo recording;
  s = store->GetRecording(recording_id, &recording);
  if (!s.ok()) return (void)SendStatus(res, s);
  Layout layout;
  if (!LayoutFromName(recording.layout, &layout) || !FindMethod(common.method)->Reads(layout)) {
    return (void)SendStatus(
        res,
        Status::InvalidInput("method '" + common.method + "' cannot read recording " +
                             std::to_string(recording_id) + "'s " + recording.layout + " layout")
            .WithField("method"));
  }
  const json columns = json::parse(recording.columns_json, nullptr, /*allow_exceptions=*/false);
  const RecordingShape shape{recording.rows,
                             columns.is_array() ? static_cast<int64_t>(columns.size()) : 0};
  s = CheckJobBudget(*FindMethod(common.method), shape, WithoutAcceptance(config),
                     job_memory_bytes);
  if (!s.ok()) return (void)SendStatus(res, s);
  storage::JobInfo job;
  s = store->EnqueueJob(recording_id, common.method, common.device,
                        config.dump(-1, ' ', false, json::error_handler_t::replace), &job);
  if (!s.ok()) return (void)SendStatus(res, s);
  workers->Notify();
  res.status = 202;
  res.set_header("Location", "/api/v1/jobs/" + std::to_string(job.id));
  res.set_content(JsonBody(json{{"job", JobJson(job, false)}}), "application/json");
}

void Service::Impl::HandleGetJob(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  if (!ParseId(req.matches[1], &id)) {
    SendError(res, 404, "not_found", "no such job");
    return;
  }
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
  constexpr size_t kMaxReason = 500;
  int64_t id = 0;
  if (!ParseId(req.matches[1], &id)) {
    SendError(res, 404, "not_found", "no such job");
    return;
  }
  const std::string media = ToLower(req.get_header_value("Content-Type"));
  if (media.rfind("application/json", 0) != 0) {
    SendError(res, 415, "unsupported_media_type", "send {\"reason\": \"...\"} as application/json");
    return;
  }
  json body;
  Status s = ParseJsonText(req.body, "request body", &body);
  if (!s.ok()) return (void)SendStatus(res, s);
  if (!body.is_object()) {
    SendError(res, 400, "invalid_input", "the body must be a JSON object {\"reason\": \"...\"}");
    return;
  }
  for (auto& [key, value] : body.items()) {
    if (key != "reason") {
      return (void)SendStatus(
          res, Status::InvalidInput("unknown key '" + key.substr(0, 64) + "' (expected reason)")
                   .WithField(key.substr(0, 64)));
    }
  }
  auto reason = body.find("reason");
  std::string text;
  if (reason != body.end() && reason->is_string()) text = reason->get<std::string>();
  while (!text.empty() && isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
  while (!text.empty() && isspace(static_cast<unsigned char>(text.front()))) text.erase(0, 1);
  if (text.empty()) {
    return (void)SendStatus(res, Status::InvalidInput(std::string("'reason' is required: say why "
                                                                  "the result is ") +
                                                      (revoke ? "revoked" : "accepted"))
                                     .WithField("reason"));
  }
  if (text.size() > kMaxReason) {
    return (void)SendStatus(res,
                            Status::InvalidInput("'reason' has " + std::to_string(text.size()) +
                                                 " bytes; at most " + std::to_string(kMaxReason))
                                .WithField("reason"));
  }
  for (unsigned char ch : text) {
    if (ch < 0x20 && ch != '\t') {
      return (void)SendStatus(
          res,
          Status::InvalidInput("'reason' may not contain control characters").WithField("reason"));
    }
  }
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
      filter.device = value;
    } else if (key == "method") {
      if (FindMethod(value) == nullptr) {
        return (void)SendStatus(
            res,
            Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method"));
      }
      filter.method = value;
    } else if (key == "verdict") {
      if (value != "accepted" && value != "rejected" && value != "revoked") {
        return (void)SendStatus(
            res, Status::InvalidInput("verdict must be accepted, rejected or revoked")
                     .WithField("verdict"));
      }
      filter.state = value;
    } else if (key == "status") {
      if (value != "queued" && value != "running" && value != "succeeded" && value != "failed") {
        return (void)SendStatus(
            res, Status::InvalidInput("status must be queued, running, succeeded or failed")
                     .WithField("status"));
      }
      filter.status = value;
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

void Service::Impl::HandleDevices(const httplib::Request&, httplib::Response& res) {
  std::vector<storage::DeviceInfo> devices;
  Status s = store->ListDevices(&devices);
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
  res.set_content(JsonBody(json{{"devices", list}}), "application/json");
}

void Service::Impl::HandleLatest(const httplib::Request& req, httplib::Response& res) {
  const std::string serial = req.matches[1];
  std::string method = req.get_param_value("method");
  const std::string format = req.has_param("format") ? req.get_param_value("format") : "json";
  // json, or a format some method exports (Method::ExportFormats).
  std::vector<std::string> formats = {"json"};
  for (const Method* m : AllMethods()) {
    for (const ExportFormat& f : m->ExportFormats()) {
      if (std::find(formats.begin(), formats.end(), f.format) == formats.end()) {
        formats.push_back(f.format);
      }
    }
  }
  if (std::find(formats.begin(), formats.end(), format) == formats.end()) {
    std::string list;
    for (size_t i = 0; i < formats.size(); ++i) {
      list += (i == 0 ? "" : i + 1 == formats.size() ? " or " : ", ") + formats[i];
    }
    return (void)SendStatus(res,
                            Status::InvalidInput("format must be " + list).WithField("format"));
  }
  storage::JobInfo job;
  Status s;
  if (req.has_param("job")) {
    // One job's result, whatever its verdict (the response says it in X-Calibd-State), but only
    // for this device: a job id never reaches another device's calibration.
    int64_t id = 0;
    if (!ParseId(req.get_param_value("job"), &id)) {
      return (void)SendStatus(
          res, Status::InvalidInput("job must be a job id (a positive integer)").WithField("job"));
    }
    s = store->GetJob(id, &job);
    if (s.code() != StatusCode::kNotFound && !s.ok()) return (void)SendStatus(res, s);
    if (s.code() == StatusCode::kNotFound || job.device != serial) {
      SendError(res, 404, "not_found",
                "device '" + serial + "' has no job " + std::to_string(id) +
                    (s.ok() ? " (that job is " +
                                  (job.device.empty() ? std::string("of no device")
                                                      : "another device's") +
                                  ")"
                            : std::string()));
      return;
    }
    if (job.status != "succeeded") {
      SendError(res, 404, "not_found",
                "job " + std::to_string(id) + " is " + job.status + ": it has no result");
      return;
    }
    if (!method.empty() && method != job.method) {
      SendError(
          res, 404, "not_found",
          "job " + std::to_string(id) + " is a " + job.method + " calibration, not " + method);
      return;
    }
    method = job.method;
  } else if (method.empty()) {
    std::vector<storage::DeviceInfo> devices;
    Status s = store->ListDevices(&devices);
    if (!s.ok()) return (void)SendStatus(res, s);
    std::vector<std::string> methods;
    for (const auto& d : devices) {
      if (d.serial != serial) continue;
      for (const auto& c : d.latest) methods.push_back(c.method);
    }
    if (methods.size() > 1) {
      return (void)SendStatus(res, Status::InvalidInput("device '" + serial +
                                                        "' has calibrations of several "
                                                        "methods: add ?method=NAME")
                                       .WithField("method"));
    }
    if (methods.empty()) {
      const std::string hint = WrongCaseDeviceMessage(store.get(), serial);
      SendError(res, 404, "not_found",
                hint.empty()
                    ? "no accepted calibration for device '" + serial +
                          "' (rejected and revoked results are never served; see /devices/" +
                          UrlEncode(serial) + ")"
                    : hint);
      return;
    }
    method = methods[0];
  } else if (FindMethod(method) == nullptr) {
    return (void)SendStatus(
        res, Status::InvalidInput("method must be " + MethodNamesForMessage()).WithField("method"));
  }
  if (!req.has_param("job")) {
    s = store->LatestResult(serial, method, &job);
    if (s.code() == StatusCode::kNotFound) {
      const std::string hint = WrongCaseDeviceMessage(store.get(), serial);
      SendError(res, 404, "not_found",
                hint.empty()
                    ? "no accepted " + method + " calibration for device '" + serial +
                          "' (rejected and revoked results are never served; see /devices/" +
                          UrlEncode(serial) + ")"
                    : hint);
      return;
    }
    if (!s.ok()) return (void)SendStatus(res, s);
  }
  const std::string etag = "\"" + job.result_sha256.substr(0, 32) + "-" + format + "\"";
  res.set_header("ETag", etag);
  res.set_header("Cache-Control", "no-cache");
  res.set_header("X-Calibd-Job", std::to_string(job.id));
  res.set_header("X-Calibd-State", job.state);
  if (IfNoneMatchHits(req.get_header_value("If-None-Match"), etag)) {
    res.status = 304;
    return;
  }
  if (format == "json") {
    // The hot path of production tooling: the stored result is valid JSON text already (the
    // worker wrote it with json::dump), so it is embedded as is, without parsing it again.
    json head = {{"device", serial},   {"method", method},
                 {"job_id", job.id},   {"calibrated_at", job.finished_at},
                 {"state", job.state}, {"result", nullptr}};
    std::string body = head.dump(-1, ' ', false, json::error_handler_t::replace);
    const std::string placeholder = "\"result\":null";
    const size_t at = body.rfind(placeholder);
    body.replace(at, placeholder.size(), "\"result\":" + job.result_json);
    body += "\n";
    res.set_content(std::move(body), "application/json");
    return;
  }
  json result;
  s = ParseJsonText(job.result_json, "stored result", &result);
  if (!s.ok()) return (void)SendStatus(res, Status::Internal("stored result is not JSON"));
  // The method writes its own formats (Method::Export).
  const Method* exporter = FindMethod(method);
  if (exporter == nullptr) return (void)SendStatus(res, Status::Internal("unknown stored method"));
  const std::vector<ExportFormat> exports = exporter->ExportFormats();
  const auto f = std::find_if(exports.begin(), exports.end(),
                              [&](const ExportFormat& e) { return e.format == format; });
  if (f == exports.end()) return (void)SendStatus(res, NoSuchExport(format, exporter->name()));
  std::string text;
  s = exporter->Export(format, result, ExportContext{job.id, serial, method, job.finished_at},
                       &text);
  if (!s.ok()) return (void)SendStatus(res, s);
  const std::string file_name =
      f->file_name.empty() ? "calibration-" + std::to_string(job.id) + "." + format : f->file_name;
  res.set_header("Content-Disposition", "attachment; filename=\"" + file_name + "\"");
  res.set_content(text, f->content_type);
}

void Service::Impl::HandleRecording(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  if (!ParseId(req.matches[1], &id)) {
    SendError(res, 404, "not_found", "no such recording");
    return;
  }
  storage::RecordingInfo info;
  Status s = store->GetRecording(id, &info);
  if (!s.ok()) return (void)SendStatus(res, s);
  res.set_content(JsonBody(RecordingJson(info)), "application/json");
}

void Service::Impl::HandleRecordingData(const httplib::Request& req, httplib::Response& res) {
  int64_t id = 0;
  if (!ParseId(req.matches[1], &id)) {
    SendError(res, 404, "not_found", "no such recording");
    return;
  }
  storage::RecordingInfo info;
  Status s = store->GetRecording(id, &info);
  if (!s.ok()) return (void)SendStatus(res, s);
  res.set_header("Content-Disposition",
                 "attachment; filename=\"recording-" + std::to_string(id) + ".csv\"");
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

void Service::Impl::HandleHealth(const httplib::Request&, httplib::Response& res) {
  storage::QueueCounts counts;
  Status s = store->QueueDepth(&counts);
  if (!s.ok()) {
    res.status = 503;
    res.set_content(JsonBody(json{{"status", "unavailable"}, {"database", s.message()}}),
                    "application/json");
    return;
  }
  res.set_content(json{{"status", "ok"},
                       {"queued", counts.queued},
                       {"running", counts.running},
                       {"workers_busy", workers->running_jobs()}}
                      .dump(),
                  "application/json");
}

void Service::Impl::HandleMetrics(const httplib::Request&, httplib::Response& res) {
  std::map<std::string, std::map<std::string, double>> gauges;
  storage::QueueCounts counts;
  if (store->QueueDepth(&counts).ok()) {
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
      metrics.Render(gauges, {{"calibd_jobs", "Jobs in the queue by state."},
                              {"calibd_workers_busy", "Workers running a job."},
                              {"calibd_http_connections", "Client connections by state."},
                              {"calibd_http_refusals",
                               "Connections refused or closed by the front end since the start, by "
                               "reason."}}),
      "text/plain; version=0.0.4");
}

}  // namespace calibd::server
