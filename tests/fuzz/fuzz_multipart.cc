// libFuzzer target: POST /api/v1/recordings with a fuzzed multipart/form-data body, against a
// real Service (cpp-httplib's multipart reader + HandleUpload + storage) started once on
// 127.0.0.1:0 with a temporary database.
//
// Input: the first line is the boundary (a default one when the line is empty, longer than 70
// bytes or missing), the rest is the body, sent with
// "Content-Type: multipart/form-data; boundary=<first line>".
// Invariants: no crash or sanitizer report in the server; every answer is 201 (accepted) or a
// 4xx with a JSON {"error": {"code", "message"}} body — never a 5xx; when the connection is
// closed without an answer, the server still answers /healthz.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <thread>

#include "server/http_util.h"
#include "server/service.h"

namespace {

using calibd::server::ServeOptions;
using calibd::server::Service;

Service* g_service = nullptr;  // shut down and destroyed at exit (StopServer)
std::thread* g_runner = nullptr;
int g_port = 0;
std::string g_dir;

[[noreturn]] void Fail(const std::string& what) {
  std::fprintf(stderr, "fuzz_multipart invariant broken: %s\n", what.c_str());
  std::abort();
}

void RemoveDir() {
  std::error_code ec;
  if (!g_dir.empty()) std::filesystem::remove_all(g_dir, ec);
}

// At exit (libFuzzer calls exit() when its time or run budget is spent), before static objects
// are destroyed and the database folder is removed: the service stops its threads and closes
// the database, as `calibd serve` does on SIGTERM. Without this, request and worker threads ran
// on while exit() destroyed what they used.
void StopServer() {
  if (g_service == nullptr) return;
  g_service->Shutdown();
  if (g_runner != nullptr) g_runner->join();
  delete g_service;
  g_service = nullptr;
  delete g_runner;
  g_runner = nullptr;
}

httplib::Client MakeClient() {
  httplib::Client client("127.0.0.1", g_port);
  client.set_connection_timeout(5, 0);
  client.set_read_timeout(20, 0);
  client.set_write_timeout(20, 0);
  return client;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  std::string tmpl = (std::filesystem::temp_directory_path() / "calibd-fuzz-XXXXXX").string();
  if (::mkdtemp(tmpl.data()) == nullptr) Fail("mkdtemp");
  g_dir = tmpl;
  std::atexit(RemoveDir);
  ServeOptions options;
  options.db_path = g_dir + "/calibd.db";
  options.listen = "127.0.0.1:0";
  options.workers = 1;
  options.http_threads = 4;
  options.access_log = false;
  options.max_upload_bytes = 1 << 20;
  options.max_json_body_bytes = 64 << 10;
  options.shutdown_grace_seconds = 1;
  std::unique_ptr<Service> service;
  calibd::Status s = Service::Create(options, &service);
  if (!s.ok()) Fail("Service::Create: " + s.ToString());
  s = service->Bind();
  if (!s.ok()) Fail("Service::Bind: " + s.ToString());
  g_service = service.release();
  g_port = g_service->port();
  g_runner = new std::thread([] { g_service->Run(); });
  bool ready = false;
  for (int i = 0; i < 500 && !ready; ++i) {
    auto res = MakeClient().Get("/healthz");
    ready = res && res->status == 200;
    if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (!ready) Fail("the server did not become ready");
  // One multipart upload before StopServer is registered: cpp-httplib builds function-local
  // static regexes on its first multipart parse, and exit() destroys statics in the reverse order
  // of registration. Built now, they outlive StopServer; built by the first fuzz input, they were
  // destroyed while a request thread still parsed with them (ThreadSanitizer, tsan.sh).
  const std::string warm_up =
      "--b\r\nContent-Disposition: form-data; name=\"recording\"; filename=\"w.csv\"\r\n"
      "Content-Type: text/csv\r\n\r\nposition,s1\np1,1\n\r\n--b--\r\n";
  auto res = MakeClient().Post("/api/v1/recordings", warm_up, "multipart/form-data; boundary=b");
  if (!res) Fail("the warm-up upload got no answer");
  std::atexit(StopServer);  // runs before RemoveDir (registered earlier) and httplib's statics
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  std::string boundary = "calibd-fuzz-boundary";
  std::string_view body = input;
  if (const size_t nl = input.find('\n'); nl != std::string_view::npos) {
    if (nl > 0 && nl <= 70) boundary = std::string(input.substr(0, nl));
    body = input.substr(nl + 1);
  }
  // A header value cannot hold CR, LF or NUL; the client would refuse to send it.
  for (char& c : boundary) {
    if (c == '\r' || c == '\n' || c == '\0') c = '_';
  }
  const std::string content_type = "multipart/form-data; boundary=" + boundary;

  auto client = MakeClient();
  auto res = client.Post("/api/v1/recordings", body.data(), body.size(), content_type.c_str());
  if (!res) {
    // Closed without an answer: acceptable for a malformed body, if the server is still fine.
    auto health = MakeClient().Get("/healthz");
    if (!health || health->status != 200) Fail("the server stopped answering /healthz");
    return 0;
  }
  const int status = res->status;
  if (status == 201) return 0;
  if (status < 400 || status >= 500) {
    Fail("unexpected HTTP status " + std::to_string(status) + ": " + res->body.substr(0, 500));
  }
  nlohmann::json error = nlohmann::json::parse(res->body, nullptr, /*allow_exceptions=*/false);
  if (!error.is_object() || !error.contains("error") || !error["error"].is_object() ||
      !error["error"].contains("code") || !error["error"].contains("message")) {
    Fail("a " + std::to_string(status) + " without a JSON error body: " + res->body.substr(0, 500));
  }
  return 0;
}
