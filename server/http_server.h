// HttpServer: cpp-httplib's Server with connection handling of our own, because the handling in
// Debian's cpp-httplib 0.11.4 cannot be made safe by configuration alone:
//
//  - Request smuggling. httplib keeps a connection open after any answer unless the *client*
//    asked to close, so when a handler refuses a request before reading its body (413, 415, 401,
//    a CSV error part-way through an upload), the unread body was parsed as the next request.
//    Here, an answer that says `Connection: close`, and every error answer to a request that has
//    a body, ends the connection for real: our FIN goes out after the answer, and whatever the
//    client still sends is read and discarded (a "lingering close", for at most
//    HttpLimits::linger_ms, so the answer is not destroyed by a TCP reset), never parsed.
//  - Slow clients (slowloris). httplib gives every connection a thread from the first byte, and a
//    client that trickles its headers holds that thread for as long as it likes. Here, request
//    heads (request line + headers) are read by one epoll thread, with a deadline from their
//    first byte and a size limit; a connection gets a thread only once its head has arrived, and
//    idle keep-alive connections go back to the epoll thread. Thousands of slow connections
//    cost a few kilobytes each, not a thread.
//  - Per-client limits: open connections per remote address (503 beyond), and requests in
//    progress per remote address (more wait, holding no thread, until one of theirs finishes).
//  - Unbounded header lines: the head is limited to HttpLimits::max_head_bytes (431 beyond).
//  - Decompression bombs: httplib (built by Debian with zlib and brotli) decodes compressed
//    request bodies itself, with no limit on the decoded size; here it never does
//    (SetRequestFilter).
//
// Everything else (parsing, routing, handlers, bodies, multipart) is httplib's, through its
// protected Server::process_request, called with a Stream of ours.
//
// Thread-safety: configure (routes, handlers, limits) before listening; Shutdown() from any
// thread.
#ifndef CALIBD_SERVER_HTTP_SERVER_H_
#define CALIBD_SERVER_HTTP_SERVER_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "server/http_util.h"

namespace calibd::server {

// Where the request's Content-Encoding is found once SetRequestFilter's filter runs (below).
inline constexpr const char* kBodyEncodingHeader = "X-Calibd-Content-Encoding";

struct HttpLimits {
  int threads = 128;                  // threads that process requests (heads are read by one more)
  int head_timeout_ms = 10000;        // request line + headers must arrive within this, from byte 1
  int keep_alive_timeout_ms = 5000;   // an idle keep-alive connection is closed after this
  int64_t max_head_bytes = 64 << 10;  // request line + headers; beyond: 431 and close
  int max_connections = 768;  // open connections in all (kept below FD_SETSIZE); beyond: 503
  int max_connections_per_client = 256;  // open connections per remote address; beyond: 503
  int max_requests_per_client = 64;      // requests in progress per remote address; more wait
  int read_timeout_ms = 10000;           // per read of a request body
  int write_timeout_ms = 30000;          // per write of an answer
  int linger_ms = 2000;             // lingering close: discard the unread rest for at most this
  int keep_alive_max_count = 1000;  // requests per connection
  // Returns "" when consistent, else what is wrong (names the field).
  std::string Validate() const;
};

// Counters for /metrics (monotonic unless noted).
struct HttpCounters {
  int64_t open_connections = 0;      // gauge
  int64_t pending_heads = 0;         // gauge: connections waiting for (more of) a request head
  int64_t requests_in_progress = 0;  // gauge
  int64_t refused_connections = 0;   // over max_connections / max_connections_per_client
  int64_t delayed_requests = 0;      // waited behind their client's max_requests_per_client
  int64_t head_timeouts = 0;         // 408: head not complete within head_timeout_ms
  int64_t heads_too_large = 0;       // 431
  int64_t lingering_closes = 0;      // connections closed after a refusal, rest discarded
};

class HttpServer : public httplib::Server {
 public:
  using AccessLogger = std::function<void(const httplib::Request&, const httplib::Response&)>;

  explicit HttpServer(HttpLimits limits);
  ~HttpServer() override;  // Shutdown()

  // Called after every answer has been written (the request's line and headers, the answer).
  void SetAccessLogger(AccessLogger logger);
  // Runs once the head has arrived, before any of the body is read — also for requests with
  // `Expect: 100-continue`, whose clients then never send a body that would be refused.
  // Return Handled with the error answer in `res` to refuse the request.
  // From here on, a request's `Content-Encoding` header is found as kBodyEncodingHeader, and
  // httplib never decodes the body (handlers do, under their own limits: server/gzip_stream.h).
  void SetRequestFilter(HandlerWithResponse filter);

  // Stops accepting, closes idle and half-received connections, lets requests in progress finish
  // within `grace_ms` (then cuts their sockets), and joins every thread. Idempotent; any thread.
  void Shutdown(int grace_ms = 5000);

  HttpCounters counters() const;

  class Frontend;  // the epoll head reader and the request threads (http_server.cc)

 private:
  bool process_and_close_socket(socket_t sock) override;

  HttpLimits limits_;
  AccessLogger logger_;
  HandlerWithResponse filter_;
  std::unique_ptr<Frontend> frontend_;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_HTTP_SERVER_H_
