#include "server/serve.h"

#include <malloc.h>
#include <pthread.h>
#include <unistd.h>

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

  std::thread watcher([&service, &options, signals] {
    int signal_number = 0;
    sigwait(&signals, &signal_number);
    if (signal_number == 0) return;
    const char* name = signal_number == SIGTERM ? "SIGTERM" : "SIGINT";
    std::cerr << "calibd: " << name << ": shutting down (running jobs get "
              << options.shutdown_grace_seconds << " s, then 1 s to stop; send it again to exit "
              << "at once)" << std::endl;
    // A second SIGINT or SIGTERM during the shutdown: exit now. Leases still held lapse, so no
    // other process computes those jobs before they would have expired anyway.
    std::thread([signals] {
      int again = 0;
      sigwait(&signals, &again);
      static const char kMessage[] = "calibd: second signal: exiting now\n";
      [[maybe_unused]] ssize_t n = ::write(STDERR_FILENO, kMessage, sizeof kMessage - 1);
      std::_Exit(128 + again);
    }).detach();
    if (!service->Shutdown()) {
      std::cerr << "calibd: running jobs were stopped; those whose computation returned were "
                   "released and run again after the restart"
                << std::endl;
    }
  });
  service->Run();
  watcher.join();
  if (service->abandoned_jobs()) {
    // A computation still runs on the store: do not wait for it (nor destroy what it uses).
    std::cerr << "calibd: stopped, leaving a job whose computation did not stop (its lease lapses)"
              << std::endl;
    std::_Exit(1);
  }
  service.reset();
  std::cerr << "calibd: stopped" << std::endl;
  return 0;
}

}  // namespace calibd::server
