// `calibd serve`: the HTTP API of SPEC §5 plus the calibration workers, on one SQLite file.
#ifndef CALIBD_SERVER_SERVE_H_
#define CALIBD_SERVER_SERVE_H_

#include <cstdint>
#include <string>

namespace calibd::server {

struct ServeOptions {
  std::string db_path = "data/calibd.db";  // created with its folder
  std::string listen = "127.0.0.1:8080";   // HOST:PORT; port 0 picks a free port (printed)
  int workers = 0;                         // calibration threads; 0 = one per core
  std::string token_file;                  // non-empty: writes need "Authorization: Bearer TOKEN"
  bool insecure = false;                   // allow a non-loopback address without a token
  int64_t max_upload_bytes = int64_t{512} << 20;   // larger uploads: 413
  int64_t max_json_body_bytes = int64_t{1} << 20;  // POST /jobs bodies and config parts
  // Connection threads. cpp-httplib gives each open connection a thread, so this bounds how many
  // slow or idle clients are served at once before /healthz waits; idle threads cost little
  // memory (their stacks are virtual until touched).
  int http_threads = 128;
  int read_timeout_seconds = 10;    // per read on a connection (slow clients are cut off)
  int write_timeout_seconds = 30;   // per write on a connection
  int64_t lease_ms = 30000;         // job lease; renewed every third of it while a job runs
  int shutdown_grace_seconds = 20;  // on SIGTERM, running jobs may finish within this time
  bool access_log = true;           // one line per request on stderr
  // Returns "" when the options are consistent, else what is wrong (names the flag).
  std::string Validate() const;
};

// Runs until SIGINT or SIGTERM, then shuts down gracefully. Returns the process exit code.
int RunServe(const ServeOptions& options);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SERVE_H_
