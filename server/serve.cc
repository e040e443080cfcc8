#include "server/serve.h"

#include <pthread.h>

#include <csignal>
#include <cstdlib>
#include <iostream>
#include <thread>

#include "server/service.h"

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
            << ":" << service->port() << " (database " << options.db_path << ")" << std::endl;

  bool clean = true;
  std::thread watcher([&] {
    int signal_number = 0;
    sigwait(&signals, &signal_number);
    if (signal_number == 0) return;
    std::cerr << "calibd: " << (signal_number == SIGTERM ? "SIGTERM" : "SIGINT")
              << ": shutting down (running jobs get " << options.shutdown_grace_seconds << " s)"
              << std::endl;
    clean = service->Shutdown();
  });
  service->Run();
  watcher.join();
  if (!clean) {
    // A job was still computing: its lease was released and it runs again after restart. Its
    // thread still uses the database, so end the process here without running destructors.
    std::cerr << "calibd: stopped (a running job was released)" << std::endl;
    std::_Exit(0);
  }
  service.reset();
  std::cerr << "calibd: stopped" << std::endl;
  return 0;
}

}  // namespace calibd::server
