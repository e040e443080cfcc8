// PgStore (pg_store.h): SqlStore's connection over libpq (PgSqlConn, the dialect), connections
// and their pool, transactions, LISTEN/NOTIFY, maintenance. Recordings' bytes are in
// pg_store_recordings.cc (see pg_store_internal.h).
#include "storage/pg_store.h"

#include <libpq-fe.h>
#include <poll.h>

#include <chrono>
#include <exception>
#include <utility>

#include "storage/pg_store_internal.h"

namespace calibd::storage {
namespace {

constexpr const char* kJobsChannel = "calibd_jobs";

}  // namespace

namespace pg {

const SqlDialect kDialect = {
    /*ping=*/"SELECT 1",
    /*lock_job=*/" FOR UPDATE OF j",
    /*skip_locked=*/" FOR UPDATE SKIP LOCKED",
    /*db_now_ms=*/CALIBD_PG_NOW_MS,  // hosts whose clocks disagree measure leases on one clock
    /*result_seq_column=*/"",        // its default: the sequence results_seq
    /*result_seq_value=*/"",
    // Concurrent completions on several hosts each see the other's committed result (READ
    // COMMITTED: every statement after the lock takes a fresh snapshot) and never insert the
    // same key twice.
    /*lock_latest=*/"SELECT pg_advisory_xact_lock(hashtextextended($1 || chr(31) || $2, 0))",
    // Byte order, as SQLite sorts, whatever the database's locale (the page is a range scan of
    // index devices_by_serial_bytes).
    /*byte_order=*/" COLLATE \"C\"",
    // An inner join, so the planner may start from index results_by_state. PostgreSQL keeps a
    // LEFT JOIN whose WHERE tests COALESCE(r...) (it cannot tell the test rejects a missing
    // result), and then can only scan the jobs: every succeeded job for a rare verdict.
    /*state_from=*/" FROM jobs j JOIN results r ON r.job_id = j.id ",
    /*state_from_with_device=*/true,
    /*state_id_column=*/"j.id",
};

std::vector<PgParam> PgParams(const SqlParams& params) {
  std::vector<PgParam> out;
  for (const SqlValue& v : params) {
    switch (v.kind) {
      case SqlValue::Kind::kNull:
        out.push_back(PgTextOrNull(""));
        break;
      case SqlValue::Kind::kInt:
        out.push_back(PgInt(v.integer));
        break;
      case SqlValue::Kind::kText:
        out.push_back(PgText(v.text));
        break;
    }
  }
  return out;
}

Status PgSqlConn::Run(std::string_view sql, const SqlParams& params, const SqlRowFn& on_row,
                      int64_t* changed) {
  PgResult res;
  Status s = c_->Exec(std::string(sql).c_str(), PgParams(params), &res);
  if (!s.ok()) return s;
  if (on_row) {
    for (int i = 0; i < res.rows(); ++i) on_row(PgRow(res, i));
  }
  if (changed != nullptr) *changed = res.Affected();
  return Status::Ok();
}

std::string ListJobsSql(const JobFilter& filter, std::vector<PgParam>* params) {
  SqlParams sql_params;
  std::string sql = internal::ListJobsSql(kDialect, filter, &sql_params);
  *params = PgParams(sql_params);
  return sql;
}

std::string CountJobsSql(const JobFilter& filter, std::vector<PgParam>* params) {
  SqlParams sql_params;
  std::string sql = internal::CountJobsSql(kDialect, filter, &sql_params);
  *params = PgParams(sql_params);
  return sql;
}

}  // namespace pg

std::string RedactConnectionTarget(const std::string& target) {
  std::string out = target;
  // URI: scheme://user:password@host...
  size_t scheme = out.find("://");
  if (scheme != std::string::npos) {
    size_t start = scheme + 3;
    size_t at = out.find('@', start);
    size_t slash = out.find('/', start);
    if (at != std::string::npos && (slash == std::string::npos || at < slash)) {
      size_t colon = out.find(':', start);
      if (colon != std::string::npos && colon < at) out.replace(colon + 1, at - colon - 1, "***");
    }
  }
  // password=... in a keyword string or a URI's query.
  for (size_t pos = 0; (pos = out.find("password=", pos)) != std::string::npos;) {
    size_t start = pos + 9;
    size_t end = out.find_first_of(" &", start);
    if (end == std::string::npos) end = out.size();
    out.replace(start, end - start, "***");
    pos = start + 3;
  }
  return out;
}

// ---- connections ----------------------------------------------------------------------------

PgStore::PgStore(std::string target, StoreOptions options)
    : SqlStore(RedactConnectionTarget(target), std::move(options), pg::kDialect),
      target_(std::move(target)),
      pool_(
          options_.max_idle_connections,
          [this](std::unique_ptr<PgConn>* out) { return NewConnection(out); },
          [](PgConn* conn) {
            if (!conn->broken() && conn->InTransaction()) (void)conn->ExecScript("ROLLBACK");
            return !conn->broken();
          }) {}

PgStore::~PgStore() { SetJobListener(nullptr); }

Status PgStore::NewConnection(std::unique_ptr<PgConn>* out) {
  std::unique_ptr<PgConn> c;
  Status s = PgConn::Connect(target_, path_, &c);
  if (!s.ok()) return s;
  // Lock waits end with kBusy after busy_timeout_ms, as with SQLite; UTC, plain strings.
  std::string setup =
      "SET lock_timeout = " + std::to_string(std::max(options_.busy_timeout_ms, 1)) +
      "; SET client_encoding = 'UTF8'";
  if (options_.read_only) setup += "; SET default_transaction_read_only = on";
  s = c->ExecScript(setup.c_str());
  if (!s.ok()) return s;
  *out = std::move(c);
  return Status::Ok();
}

Status PgStore::Connect(const std::string& target, StoreOptions options,
                        std::unique_ptr<Store>* out) {
  out->reset();
  if (options.max_attempts < 1) return Status::InvalidInput("storage: max_attempts must be >= 1");
  if (options.max_page_count > 0) {
    return Status::InvalidInput("storage: max_page_count is not supported with PostgreSQL");
  }
  std::unique_ptr<PgStore> store(new PgStore(target, std::move(options)));
  Lease conn(store.get());
  Status s = conn.Open();
  if (!s.ok()) return s;
  s = MigratePgSchema(conn.get(), store->path_, store->options_.read_only);
  if (!s.ok()) return s;
  *out = std::move(store);
  return Status::Ok();
}

Status PgStore::Write(const SqlOp& op) {
  for (int attempt = 1;; ++attempt) {
    Lease lease(this);
    Status s = lease.Open();
    if (!s.ok()) return s;
    PgConn* c = lease.get();
    pg::PgSqlConn sql(c);
    c->notify_after_commit = false;
    s = c->ExecScript("BEGIN");
    // A connection that died in the pool (server restarted): nothing was done, run it afresh.
    if (!s.ok() && lease.StaleFromPool() && attempt < 3) continue;
    if (s.ok()) {
      try {
        s = op(&sql);
      } catch (const std::exception& e) {
        s = Status::Internal(std::string("storage: unexpected exception: ") + e.what());
      }
      if (s.ok()) {
        s = c->ExecScript("COMMIT");
        // Best effort: a lost notification only delays workers until their next poll.
        if (s.ok() && c->notify_after_commit) {
          (void)c->Exec("SELECT pg_notify($1, '')", {PgText(kJobsChannel)});
        }
      } else if (!c->broken()) {
        (void)c->ExecScript("ROLLBACK");
      }
    }
    // A deadlock or serialization failure rolled the transaction back: run it again.
    const bool retry = s.code() == StatusCode::kBusy && !c->broken() && attempt < 3 &&
                       (s.message().find("SQLSTATE 40P01") != std::string::npos ||
                        s.message().find("SQLSTATE 40001") != std::string::npos);
    if (!retry) return s;
  }
}

Status PgStore::Read(const SqlOp& op) {
  for (int attempt = 1;; ++attempt) {
    Lease lease(this);
    Status s = lease.Open();
    if (!s.ok()) return s;
    pg::PgSqlConn sql(lease.get());
    s = op(&sql);
    // Reads change nothing: one that met a connection that died in the pool runs again.
    if (s.ok() || !lease.StaleFromPool() || attempt > 1) return s;
  }
}

// ---- maintenance -------------------------------------------------------------------------------

Status PgStore::IntegrityCheck(std::string* result) {
  std::vector<std::string> damaged;
  Status s = Read([&](SqlConn* c) {
    damaged.clear();
    return c->Run(
        "SELECT r.id FROM recordings r LEFT JOIN (SELECT recording_id, SUM(length(data)) AS n, "
        "COUNT(*) AS k, MAX(seq) AS last FROM recording_chunks GROUP BY recording_id) c "
        "ON c.recording_id = r.id WHERE r.bytes <> COALESCE(c.n, 0) "
        "OR COALESCE(c.k, 0) <> COALESCE(c.last + 1, 0) ORDER BY r.id LIMIT 100",
        {}, [&](const internal::Row& row) { damaged.push_back(row.Text(0)); });
  });
  if (!s.ok()) return s;
  *result = damaged.empty() ? "ok" : "recordings whose stored bytes do not add up to their size:";
  for (const std::string& id : damaged) *result += " " + id;
  return Status::Ok();
}

Status PgStore::Checkpoint() { return Status::Ok(); }

// ---- LISTEN/NOTIFY ---------------------------------------------------------------------------

bool PgStore::SetJobListener(std::function<void()> on_job) {
  std::lock_guard<std::mutex> lock(listen_mu_);
  if (listener_.joinable()) {
    listen_stop_ = true;
    listener_.join();
  }
  on_job_ = std::move(on_job);
  if (on_job_) {
    listen_stop_ = false;
    listener_ = std::thread([this] { ListenLoop(); });
  }
  return true;
}

void PgStore::ListenLoop() {
  std::unique_ptr<PgConn> conn;
  while (!listen_stop_) {
    if (!conn || conn->broken()) {
      conn.reset();
      std::unique_ptr<PgConn> fresh;
      if (PgConn::Connect(target_, path_, &fresh).ok() &&
          fresh->ExecScript("LISTEN calibd_jobs").ok()) {
        conn = std::move(fresh);
        on_job_();  // jobs may have been enqueued while not listening
      } else {
        for (int i = 0; i < 10 && !listen_stop_; ++i) {
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        continue;
      }
    }
    pollfd p{};
    p.fd = PQsocket(conn->handle());
    p.events = POLLIN;
    if (p.fd < 0) {
      conn.reset();
      continue;
    }
    int n = ::poll(&p, 1, 200);  // wakes to check listen_stop_
    if (n <= 0) continue;
    if (PQconsumeInput(conn->handle()) == 0) {
      conn.reset();  // the connection failed: reconnect
      continue;
    }
    bool any = false;
    while (PGnotify* note = PQnotifies(conn->handle())) {
      any = true;
      PQfreemem(note);
    }
    if (any) on_job_();
  }
}

}  // namespace calibd::storage
