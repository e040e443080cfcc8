// ConnectionPool and Borrowed: a store's idle connections kept for reuse, and one connection
// borrowed from them for the length of a call (SqliteStore: Db, PgStore: PgConn). Not a public
// interface.
//
// Thread-safety: a ConnectionPool is thread-safe; a Borrowed belongs to one thread.
#ifndef CALIBD_STORAGE_CONN_POOL_H_
#define CALIBD_STORAGE_CONN_POOL_H_

#include <functional>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "core/status.h"

namespace calibd::storage {

template <typename T>
class ConnectionPool {
 public:
  // Makes a fresh connection.
  using Open = std::function<Status(std::unique_ptr<T>* out)>;
  // Readies a connection given back for reuse (e.g. rolls back a transaction left open); false
  // when it is broken: then it is dropped with every idle one (the server most likely went away,
  // so the next calls connect afresh instead of failing one by one).
  using Reset = std::function<bool(T* conn)>;

  // Keeps at most `max_idle` idle connections.
  ConnectionPool(int max_idle, Open open, Reset reset)
      : max_idle_(max_idle), open_(std::move(open)), reset_(std::move(reset)) {}

  // An idle connection (*pooled = true), else a fresh one.
  Status Take(std::unique_ptr<T>* out, bool* pooled) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      *pooled = !idle_.empty();
      if (*pooled) {
        *out = std::move(idle_.back());
        idle_.pop_back();
        return Status::Ok();
      }
    }
    return open_(out);
  }

  void Give(std::unique_ptr<T> conn) {
    const bool reusable = reset_(conn.get());
    std::lock_guard<std::mutex> lock(mu_);
    if (!reusable) {
      idle_.clear();
    } else if (static_cast<int>(idle_.size()) < max_idle_) {
      idle_.push_back(std::move(conn));
    }
  }

 private:
  const int max_idle_;
  const Open open_;
  const Reset reset_;
  std::mutex mu_;
  std::vector<std::unique_ptr<T>> idle_;  // guarded by mu_
};

// One connection of a pool for the length of a call, given back on destruction.
template <typename T>
class Borrowed {
 public:
  explicit Borrowed(ConnectionPool<T>* pool) : pool_(pool) {}
  ~Borrowed() {
    if (conn_) pool_->Give(std::move(conn_));
  }
  Borrowed(const Borrowed&) = delete;
  Borrowed& operator=(const Borrowed&) = delete;

  Status Open() { return pool_->Take(&conn_, &pooled_); }
  T* get() const { return conn_.get(); }
  // Whether it was idle in the pool (where it may have died: a restarted server).
  bool pooled() const { return pooled_; }

 private:
  ConnectionPool<T>* pool_;
  std::unique_ptr<T> conn_;
  bool pooled_ = false;
};

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_CONN_POOL_H_
