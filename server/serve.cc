#include "server/serve.h"

#include <malloc.h>
#include <pthread.h>

#include <csignal>
#include <cstdlib>
#include <iostream>
#include <thread>

#include "server/service.h"
#include "storage/pg_store.h"

namespace calibd::server {

int RunServe(const ServeOptions& options) {
  // SIGINT/SIGTERM are handled by a dedicated thread with sigwait, so that the shutdown runs as
  // ordinary code (not in a signal handler). Block them before any other thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  // glibc gives each thread that allocates an arena of its own, up to 8 per core, and keeps the
  // peak of every one: after rounds of hostile requests the server held 105 MiB and growing,
  // with 2 arenas 53 MiB and flat (bench/README.md, "Memory after hostile traffic"). Calibration
  // threads allocate little after parsing, so 2 arenas cost no measurable speed. MALLOC_ARENA_MAX
  // in the environment still wins.
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 2);

  std::unique_ptr<Service> service;
  Status s = Service::Create(options, &service);
  if (!s.ok()) {
    std::cerr << "calibd: " << s.ToString() << "\n";
    return s.code() == StatusCode::kInvalidInput ? 2 : 1;
  }
  s = service->Bind();
  if (!s.ok()) {
    std::cerr << "calibd: " << s.ToString() << "\n";
    return 1;
  }
  std::cerr << "calibd: listening on http://" << options.listen.substr(0, options.listen.rfind(':'))
            << ":" << service->port() << " (database "
            << storage::RedactConnectionTarget(options.db_path) << ")" << std::endl;

  std::thread watcher([&] {
    int signal_number = 0;
    sigwait(&signals, &signal_number);
    if (signal_number == 0) return;
    std::cerr << "calibd: " << (signal_number == SIGTERM ? "SIGTERM" : "SIGINT")
              << ": shutting down (running jobs get " << options.shutdown_grace_seconds << " s)"
              << std::endl;
    if (!service->Shutdown()) {
      std::cerr << "calibd: a running job was released; it runs again after the restart"
                << std::endl;
    }
  });
  service->Run();
  watcher.join();
  service.reset();
  std::cerr << "calibd: stopped" << std::endl;
  return 0;
}

}  // namespace calibd::server
