// Service: the running server — the Store, the WorkerPool and the HTTP routes of SPEC §5.
//
// Lifecycle: Create() opens the database and takes back lapsed leases; Bind() binds the listen
// address (port 0: any free port, see port()); Run() serves until Shutdown() is called from any
// thread (e.g. a signal watcher); Shutdown() stops accepting, lets running jobs finish within
// the grace period or releases their leases, and closes the database.
#ifndef CALIBD_SERVER_SERVICE_H_
#define CALIBD_SERVER_SERVICE_H_

#include <memory>
#include <string>

#include "base/status.h"
#include "server/serve.h"

namespace calibd::server {

class Service {
 public:
  static Status Create(const ServeOptions& options, std::unique_ptr<Service>* out);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  Status Bind();
  int port() const;
  // Serves until Shutdown(). Returns after the HTTP server has stopped.
  void Run();
  // Graceful stop; safe from any thread, idempotent. Waits for requests in progress and running
  // jobs (within the grace period; then their computations are stopped and, once returned,
  // their leases released: WorkerPool::Stop), and closes the database: afterwards no thread of
  // the service runs. Returns false when some job was stopped rather than finished.
  bool Shutdown();
  // After Shutdown: true when a job's computation did not return within 1 s of being stopped.
  // Its thread still runs and uses the store, so the service was not closed: exit the process
  // without destroying the Service (its lease lapses; nobody computes the job meanwhile).
  bool abandoned_jobs() const;

 private:
  struct Impl;
  explicit Service(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SERVICE_H_
