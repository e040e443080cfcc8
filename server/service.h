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
  // jobs (within the grace period; then jobs are released and cancelled), and closes the
  // database: afterwards no thread of the service runs. Returns false when some job was
  // released rather than finished.
  bool Shutdown();

 private:
  struct Impl;
  explicit Service(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_SERVICE_H_
