#include "storage/pg_conn.h"

#include <libpq-fe.h>

#include <cstdlib>
#include <cstring>
#include <utility>

namespace calibd::storage {

PgParam PgInt(int64_t v) {
  PgParam p;
  p.text = std::to_string(v);
  return p;
}
PgParam PgText(std::string_view v) {
  PgParam p;
  p.text = std::string(v);
  return p;
}
PgParam PgTextOrNull(std::string_view v) {
  PgParam p;
  p.text = std::string(v);
  p.is_null = v.empty();
  return p;
}
PgParam PgBytes(std::string_view v) {
  PgParam p;
  p.bytes = v;
  p.is_binary = true;
  return p;
}

PgResult::~PgResult() {
  if (res_ != nullptr) PQclear(res_);
}
PgResult::PgResult(PgResult&& o) noexcept : res_(o.res_) { o.res_ = nullptr; }
PgResult& PgResult::operator=(PgResult&& o) noexcept {
  if (this != &o) {
    if (res_ != nullptr) PQclear(res_);
    res_ = o.res_;
    o.res_ = nullptr;
  }
  return *this;
}
int PgResult::rows() const { return res_ == nullptr ? 0 : PQntuples(res_); }
bool PgResult::IsNull(int row, int col) const { return PQgetisnull(res_, row, col) != 0; }
std::string PgResult::Text(int row, int col) const {
  if (IsNull(row, col)) return std::string();
  return std::string(PQgetvalue(res_, row, col), static_cast<size_t>(PQgetlength(res_, row, col)));
}
int64_t PgResult::Int(int row, int col) const {
  if (IsNull(row, col)) return 0;
  return std::strtoll(PQgetvalue(res_, row, col), nullptr, 10);
}
std::string_view PgResult::Bytes(int row, int col) const {
  return std::string_view(PQgetvalue(res_, row, col),
                          static_cast<size_t>(PQgetlength(res_, row, col)));
}
int64_t PgResult::Affected() const {
  const char* n = res_ == nullptr ? "" : PQcmdTuples(res_);
  return *n == '\0' ? 0 : std::strtoll(n, nullptr, 10);
}

namespace {
void IgnoreNotice(void*, const char*) {}  // "relation already exists, skipping" and the like

// libpq's messages span lines ("...\n\tThis probably means..."): one line, single spaces.
std::string OneLine(const char* text) {
  std::string out;
  for (const char* p = text; *p != '\0'; ++p) {
    const bool space = *p == '\n' || *p == '\t' || *p == '\r' || *p == ' ';
    if (space && (out.empty() || out.back() == ' ')) continue;
    out += space ? ' ' : *p;
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

bool Starts(const char* state, const char* prefix) {
  return std::strncmp(state, prefix, std::strlen(prefix)) == 0;
}
}  // namespace

Status PgConn::Connect(const std::string& target, const std::string& display,
                       std::unique_ptr<PgConn>* out) {
  std::unique_ptr<PgConn> c(new PgConn());
  c->display_ = display;
  // Earlier keywords are overridden by the expanded target's own (expand_dbname = 1).
  const char* keys[] = {"connect_timeout", "fallback_application_name", "dbname", nullptr};
  const char* values[] = {"5", "calibd", target.c_str(), nullptr};
  c->conn_ = PQconnectdbParams(keys, values, /*expand_dbname=*/1);
  if (c->conn_ == nullptr) return Status::Internal("storage: libpq could not allocate");
  if (PQstatus(c->conn_) != CONNECTION_OK) {
    const std::string why = OneLine(PQerrorMessage(c->conn_));
    return Status::Busy("storage: cannot connect to PostgreSQL at " + display + ": " + why);
  }
  PQsetNoticeProcessor(c->conn_, &IgnoreNotice, nullptr);
  *out = std::move(c);
  return Status::Ok();
}

PgConn::~PgConn() {
  if (conn_ != nullptr) PQfinish(conn_);
}

bool PgConn::broken() const { return broken_ || PQstatus(conn_) != CONNECTION_OK; }

bool PgConn::InTransaction() const {
  PGTransactionStatusType t = PQtransactionStatus(conn_);
  return t == PQTRANS_INTRANS || t == PQTRANS_INERROR || t == PQTRANS_ACTIVE;
}

Status PgConn::StatusFrom(pg_result* res, std::string_view what) {
  std::string msg = OneLine(res != nullptr ? PQresultErrorMessage(res) : "");
  if (msg.empty()) msg = OneLine(PQerrorMessage(conn_));
  const char* state = res != nullptr ? PQresultErrorField(res, PG_DIAG_SQLSTATE) : nullptr;
  std::string text = "storage: " + std::string(what) + ": " + msg;
  if (PQstatus(conn_) != CONNECTION_OK || state == nullptr) {
    broken_ = PQstatus(conn_) != CONNECTION_OK || broken_;
    if (broken_) {
      return Status::Busy("storage: lost the connection to PostgreSQL at " + display_ + " (" +
                          std::string(what) + "): " + msg);
    }
    if (state == nullptr) return Status::Internal(text);
  }
  text += " [SQLSTATE " + std::string(state) + "]";
  if (Starts(state, "08") || Starts(state, "57P0")) {
    broken_ = true;
    return Status::Busy(text);
  }
  if (!std::strcmp(state, "40001") || !std::strcmp(state, "40P01") ||
      !std::strcmp(state, "55P03") || !std::strcmp(state, "57014")) {
    return Status::Busy(text);
  }
  if (Starts(state, "23")) return Status::Conflict(text);
  if (!std::strcmp(state, "53100")) return Status::IoError(text).WithReason(Reason::kDiskFull);
  if (Starts(state, "53") || Starts(state, "58") || !std::strcmp(state, "25006")) {
    return Status::IoError(text);
  }
  if (!std::strcmp(state, "54000")) return Status(StatusCode::kTooLarge, text);
  if (Starts(state, "22")) return Status::InvalidInput(text);
  if (!std::strcmp(state, "XX001") || !std::strcmp(state, "XX002")) {
    return Status::Corruption(text).WithReason(Reason::kStorageDamaged);
  }
  return Status::Internal(text);
}

Status PgConn::Exec(const char* sql, const std::vector<PgParam>& params, PgResult* out,
                    bool binary_result) {
  std::vector<const char*> values(params.size());
  std::vector<int> lengths(params.size()), formats(params.size());
  for (size_t i = 0; i < params.size(); ++i) {
    const PgParam& p = params[i];
    if (p.is_null) {
      values[i] = nullptr;
    } else if (p.is_binary) {
      values[i] = p.bytes.data() != nullptr ? p.bytes.data() : "";
      lengths[i] = static_cast<int>(p.bytes.size());
      formats[i] = 1;
    } else {
      values[i] = p.text.c_str();
    }
  }
  PGresult* res = PQexecParams(conn_, sql, static_cast<int>(params.size()), nullptr, values.data(),
                               lengths.data(), formats.data(), binary_result ? 1 : 0);
  ExecStatusType st = res != nullptr ? PQresultStatus(res) : PGRES_FATAL_ERROR;
  if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
    Status s = StatusFrom(res, "query");
    if (res != nullptr) PQclear(res);
    return s;
  }
  if (out != nullptr) {
    if (out->res_ != nullptr) PQclear(out->res_);
    out->res_ = res;
  } else {
    PQclear(res);
  }
  return Status::Ok();
}

Status PgConn::ExecScript(const char* sql) {
  PGresult* res = PQexec(conn_, sql);
  ExecStatusType st = res != nullptr ? PQresultStatus(res) : PGRES_FATAL_ERROR;
  Status s;
  if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) s = StatusFrom(res, "statement");
  if (res != nullptr) PQclear(res);
  return s;
}

}  // namespace calibd::storage
