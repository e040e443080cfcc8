// `calibd serve`: the HTTP API of SPEC §5 plus the calibration workers, on one SQLite file.
#ifndef CALIBD_SERVER_SERVE_H_
#define CALIBD_SERVER_SERVE_H_

#include <cstdint>
#include <string>

namespace calibd::server {

struct ServeOptions {
  std::string db_path = "data/calibd.db";  // SQLite file (created with its folder) or a
                                           // postgresql:// URI (storage::Store::Open)
  std::string listen = "127.0.0.1:8080";   // HOST:PORT; port 0 picks a free port (printed)
  int workers = 0;                         // calibration threads; 0 = one per core
  std::string token_file;                  // non-empty: writes need "Authorization: Bearer TOKEN"
  bool insecure = false;                   // allow a non-loopback address without a token
  // Non-empty: a JSON file of server-wide acceptance limits per method (methods/acceptance.h),
  // {"<method>": {"<limit>": value, ...}, ...}; a config's own `acceptance` overrides them per key.
  std::string acceptance_file;
  // Larger uploads: 413. For a gzip-compressed recording, the limit applies to the compressed
  // body and to the decompressed CSV (what is stored).
  int64_t max_upload_bytes = int64_t{512} << 20;
  // A gzip-compressed recording that expands more than this many times is refused (413) as a
  // decompression bomb (checked past its first MiB). CSV logs compress 3-20 times.
  double max_gzip_ratio = 200;
  // Memory one job may use (server/job_budget.h): a job whose recording would need more is
  // refused with 422 at upload or POST /jobs (and failed by a worker if queued before).
  // 0 = half the machine's memory shared among the workers, 256 MiB to 8 GiB each.
  int64_t job_memory_bytes = 0;
  int64_t max_json_body_bytes = int64_t{1} << 20;  // POST /jobs bodies and config parts
  // Threads that process requests. A connection gets one only once its request line and headers
  // have arrived (server/http_server.h), so slow or idle clients do not hold threads.
  int http_threads = 128;
  int read_timeout_seconds = 10;         // per read of a request body (slow clients are cut off)
  int write_timeout_seconds = 30;        // per write on a connection
  int head_timeout_seconds = 10;         // request line + headers must arrive within this (408)
  int max_connections_per_client = 256;  // open connections per remote address (503 beyond)
  int max_requests_per_client = 64;      // requests in progress per remote address (more wait)
  int64_t lease_ms = 30000;              // job lease; renewed every third of it while a job runs
  int shutdown_grace_seconds = 20;       // on SIGTERM, running jobs may finish within this time
  // The time limit of every job (a job past it fails with reason deadline); 0 = the default,
  // DefaultJobSeconds(per-job memory budget) (server/job_budget.h). A config's job_seconds may
  // only lower it.
  int64_t job_seconds = 0;
  bool access_log = true;  // one line per request on stderr
  // How often the database's structure is checked (Store::QuickCheck: SQLite PRAGMA
  // quick_check), besides once at start; a damaged database makes /healthz answer 503 naming
  // the damage. 0 = only at start. Default 3600 s.
  int64_t check_seconds = 3600;
  // > 0: a quota on the SQLite file in pages of 4 KiB (PRAGMA max_page_count); writes beyond it
  // answer 507 like a full disk. 0 = none (default). SQLite only.
  int64_t db_max_pages = 0;
  // The parsed-columns cache of stored inertial logs (server/column_cache.h): at most this many
  // bytes of entries (least recently used removed first), in the folder `columns` beside the
  // SQLite file (PostgreSQL: $TMPDIR/calibd-columns-<hash of the URI>, per host). 0 = no cache:
  // every job, check and /segments parses the stored bytes. Default 2 GiB.
  int64_t column_cache_bytes = int64_t{2} << 30;
  // Returns "" when the options are consistent, else what is wrong (names the flag).
  std::string Validate() const;
};

// Runs until SIGINT or SIGTERM, then shuts down gracefully: stops accepting, lets running jobs
// finish within the grace period, stops the rest and releases their leases once their
// computations have returned (within 1 s more), and exits. A second SIGINT or SIGTERM exits at
// once (leases still held lapse). Returns the process exit code.
int RunServe(const ServeOptions& options);

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SERVE_H_
