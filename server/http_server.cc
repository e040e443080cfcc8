#include "server/http_server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <malloc.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <thread>
#include <unordered_map>
#include <vector>

namespace calibd::server {

namespace {

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// Waits until `fd` is ready for `events` (POLLIN / POLLOUT) or `timeout_ms` passes.
bool WaitFd(int fd, short events, int timeout_ms) {
  pollfd p{fd, events, 0};
  const int64_t end = NowMs() + timeout_ms;
  while (true) {
    const int64_t left = std::max<int64_t>(0, end - NowMs());
    const int n = ::poll(&p, 1, static_cast<int>(left));
    if (n > 0) return true;
    if (n == 0) return false;
    if (errno != EINTR) return false;
  }
}

void AddressOf(const sockaddr_storage& addr, std::string* ip, int* port) {
  char text[INET6_ADDRSTRLEN] = "";
  if (addr.ss_family == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(&addr);
    inet_ntop(AF_INET, &a->sin_addr, text, sizeof text);
    *port = ntohs(a->sin_port);
  } else if (addr.ss_family == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(&addr);
    inet_ntop(AF_INET6, &a->sin6_addr, text, sizeof text);
    *port = ntohs(a->sin6_port);
  }
  *ip = text;
}

// A complete request head (request line + headers + blank line) at the start of `buf`?
bool HeadComplete(const std::string& buf, size_t from) {
  return buf.find("\r\n\r\n", from) != std::string::npos;
}

// A short answer written directly on the socket (no httplib), for refusals made before a request
// reaches httplib. Best effort: the socket is non-blocking and the answer is small.
void WriteRefusal(int fd, int status, const char* reason, const std::string& code,
                  const std::string& message) {
  const std::string body =
      JsonBody(nlohmann::json{{"error", {{"code", code}, {"message", message}}}});
  std::string head = "HTTP/1.1 " + std::to_string(status) + " " + reason +
                     "\r\nContent-Type: application/json\r\nConnection: close\r\n";
  if (status == 503) head += "Retry-After: 1\r\n";
  head += "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n";
  const std::string all = head + body;
  size_t off = 0;
  while (off < all.size()) {
    const ssize_t n = ::send(fd, all.data() + off, all.size() - off, MSG_NOSIGNAL | MSG_DONTWAIT);
    if (n > 0) {
      off += static_cast<size_t>(n);
    } else if (n < 0 && errno == EINTR) {
      continue;
    } else if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
      if (!WaitFd(fd, POLLOUT, 1000)) return;
    } else {
      return;
    }
  }
}

}  // namespace

// One client connection. Owned by exactly one place at a time: the epoll thread (while its head
// arrives, while idle, or while lingering), a request queue, or a request thread.
struct Connection {
  enum class State { kHead, kLinger };
  int fd = -1;
  std::string peer_ip, local_ip;
  int peer_port = 0, local_port = 0;
  std::string buf;  // received, not yet consumed by httplib: buf[pos..]
  size_t pos = 0;
  State state = State::kHead;
  bool head_started = false;  // a byte of the next head has arrived
  int64_t deadline_ms = 0;    // steady clock: head or idle deadline, or end of lingering
  int requests = 0;           // answered on this connection
  bool close_after = false;   // set by the access-log hook: end the connection after this answer
  bool large = false;         // set by the access-log hook: a body or answer over 1 MiB

  size_t buffered() const { return buf.size() - pos; }
  void Compact() {
    if (pos == buf.size()) {
      buf.clear();
      pos = 0;
    } else if (pos > (64u << 10)) {
      buf.erase(0, pos);
      pos = 0;
    }
  }
};

namespace {

thread_local Connection* t_connection = nullptr;

// httplib's view of a connection while a request thread serves it: reads come from the
// connection's buffer first (the head is already there), then from the socket with the read
// timeout; writes wait for the socket with the write timeout.
class ConnectionStream : public httplib::Stream {
 public:
  ConnectionStream(Connection* c, const HttpLimits& limits) : c_(c), limits_(limits) {}

  bool is_readable() const override {
    return c_->buffered() > 0 || WaitFd(c_->fd, POLLIN, limits_.read_timeout_ms);
  }
  bool is_writable() const override { return WaitFd(c_->fd, POLLOUT, limits_.write_timeout_ms); }

  ssize_t read(char* ptr, size_t size) override {
    if (c_->buffered() == 0) {
      c_->buf.clear();
      c_->pos = 0;
      char chunk[16 << 10];
      while (true) {
        const ssize_t n = ::recv(c_->fd, chunk, sizeof chunk, MSG_DONTWAIT);
        if (n > 0) {
          c_->buf.assign(chunk, static_cast<size_t>(n));
          break;
        }
        if (n == 0) return 0;
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
        if (!WaitFd(c_->fd, POLLIN, limits_.read_timeout_ms)) return -1;
      }
    }
    const size_t n = std::min(size, c_->buffered());
    std::memcpy(ptr, c_->buf.data() + c_->pos, n);
    c_->pos += n;
    return static_cast<ssize_t>(n);
  }

  ssize_t write(const char* ptr, size_t size) override {
    while (true) {
      const ssize_t n = ::send(c_->fd, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n >= 0) return n;
      if (errno == EINTR) continue;
      if (errno != EAGAIN && errno != EWOULDBLOCK) return -1;
      if (!WaitFd(c_->fd, POLLOUT, limits_.write_timeout_ms)) return -1;
    }
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = c_->peer_ip;
    port = c_->peer_port;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = c_->local_ip;
    port = c_->local_port;
  }
  socket_t socket() const override { return c_->fd; }

 private:
  Connection* c_;
  const HttpLimits& limits_;
};

// httplib's accept loop hands every accepted socket to this queue: it runs the task inline, which
// only registers the socket with the Frontend (never blocks).
class InlineQueue : public httplib::TaskQueue {
 public:
  void enqueue(std::function<void()> fn) override { fn(); }
  void shutdown() override {}
};

// After a request with a large body or answer (now freed), give the freed memory back to the
// system; at most once a second, as malloc_trim walks every arena. Without it, glibc keeps the
// peak of every arena (bench/README.md, "Memory after hostile traffic").
void TrimHeap() {
  static std::atomic<int64_t> last_ms{0};
  const int64_t now = NowMs();
  int64_t last = last_ms.load();
  if (now - last < 1000 || !last_ms.compare_exchange_strong(last, now)) return;
  malloc_trim(0);
}

}  // namespace

class HttpServer::Frontend {
 public:
  using Serve = std::function<void(Connection*)>;

  Frontend(const HttpLimits& limits, Serve serve) : limits_(limits), serve_(std::move(serve)) {
    epoll_ = ::epoll_create1(EPOLL_CLOEXEC);
    wake_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    epoll_event ev{};
    ev.events = EPOLLIN;
    ev.data.fd = wake_;
    ::epoll_ctl(epoll_, EPOLL_CTL_ADD, wake_, &ev);
    reader_ = std::thread([this] { ReaderLoop(); });
    for (int i = 0; i < limits_.threads; ++i) threads_.emplace_back([this] { RequestLoop(); });
  }

  ~Frontend() { Stop(0); }

  // A newly accepted socket (httplib's accept thread).
  void Adopt(int fd) {
    auto c = std::make_unique<Connection>();
    c->fd = fd;
    sockaddr_storage addr{};
    socklen_t len = sizeof addr;
    if (::getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
      AddressOf(addr, &c->peer_ip, &c->peer_port);
    }
    len = sizeof addr;
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0) {
      AddressOf(addr, &c->local_ip, &c->local_port);
    }
    const int flags = ::fcntl(fd, F_GETFL, 0);
    ::fcntl(fd, F_SETFL, flags | O_NONBLOCK);
    int yes = 1;
    ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &yes, sizeof yes);
    {
      std::lock_guard<std::mutex> lock(mu_);
      int& per_client = connections_per_client_[c->peer_ip];
      if (stopping_ || open_ >= limits_.max_connections ||
          per_client >= limits_.max_connections_per_client) {
        ++counters_.refused_connections;
        if (per_client == 0) connections_per_client_.erase(c->peer_ip);
        const bool stopping = stopping_;
        // Not counted as open: answer and close at once (nothing of a request was read).
        WriteRefusal(fd, 503, "Service Unavailable", "overloaded",
                     stopping ? "the server is shutting down"
                              : "too many open connections; try again shortly");
        ::close(fd);
        return;
      }
      ++per_client;
      ++open_;
    }
    c->state = Connection::State::kHead;
    c->deadline_ms = NowMs() + limits_.keep_alive_timeout_ms;
    ToReader(std::move(c));
  }

  // Called by a request thread after it answered: the connection goes back to the epoll thread
  // (idle, or lingering), or is closed.
  void ToReader(std::unique_ptr<Connection> c) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (reader_running_) {
        inbox_.push_back(std::move(c));
        const uint64_t one = 1;
        [[maybe_unused]] ssize_t n = ::write(wake_, &one, sizeof one);
        return;
      }
    }
    Close(std::move(c));  // shutting down
  }

  void Close(std::unique_ptr<Connection> c) {
    ::close(c->fd);
    std::lock_guard<std::mutex> lock(mu_);
    --open_;
    auto it = connections_per_client_.find(c->peer_ip);
    if (it != connections_per_client_.end() && --it->second <= 0) {
      connections_per_client_.erase(it);
    }
  }

  // Ends a connection after an answer that may have left part of a request unread.
  void Linger(std::unique_ptr<Connection> c) {
    ::shutdown(c->fd, SHUT_WR);
    c->state = Connection::State::kLinger;
    c->deadline_ms = NowMs() + limits_.linger_ms;
    c->buf.clear();
    c->pos = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++counters_.lingering_closes;
    }
    ToReader(std::move(c));
  }

  bool stopping() const { return stopping_flag_.load(); }

  void Stop(int grace_ms) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopped_) return;
      stopped_ = true;
      stopping_ = true;
      stopping_flag_ = true;
      reader_running_ = false;
      const uint64_t one = 1;
      [[maybe_unused]] ssize_t n = ::write(wake_, &one, sizeof one);
    }
    reader_.join();
    // Requests in progress may finish within the grace period; then their sockets are cut so
    // that reads and writes fail at once.
    {
      std::unique_lock<std::mutex> lock(mu_);
      for (auto& [peer, line] : waiting_) {
        for (auto& c : line) queue_.push_back(std::move(c));
      }
      waiting_.clear();
      work_cv_.notify_all();
      idle_cv_.wait_for(lock, std::chrono::milliseconds(grace_ms),
                        [this] { return serving_.empty() && queue_.empty(); });
      for (int fd : serving_) ::shutdown(fd, SHUT_RDWR);
      for (auto& c : queue_) ::shutdown(c->fd, SHUT_RDWR);
      work_cv_.notify_all();
    }
    for (auto& t : threads_) t.join();
    threads_.clear();
    // Whatever came back to the inbox after the reader stopped.
    std::deque<std::unique_ptr<Connection>> rest;
    {
      std::lock_guard<std::mutex> lock(mu_);
      rest.swap(inbox_);
    }
    for (auto& c : rest) Close(std::move(c));
    ::close(epoll_);
    ::close(wake_);
  }

  HttpCounters counters() const {
    std::lock_guard<std::mutex> lock(mu_);
    HttpCounters c = counters_;
    c.open_connections = open_;
    c.pending_heads = static_cast<int64_t>(pending_heads_);
    c.requests_in_progress = static_cast<int64_t>(serving_.size() + queue_.size());
    for (const auto& [peer, line] : waiting_) c.requests_in_progress += line.size();
    return c;
  }

 private:
  // The epoll thread: reads request heads, keeps idle keep-alive connections, lingers.
  void ReaderLoop() {
    std::unordered_map<int, std::unique_ptr<Connection>> conns;
    std::vector<epoll_event> events(128);
    int64_t last_sweep = NowMs();
    while (!stopping_flag_.load()) {
      int64_t next = NowMs() + 1000;
      for (const auto& [fd, c] : conns) next = std::min(next, c->deadline_ms);
      const int timeout = static_cast<int>(std::clamp<int64_t>(next - NowMs(), 0, 1000));
      const int n = ::epoll_wait(epoll_, events.data(), static_cast<int>(events.size()), timeout);
      // New and returned connections.
      std::deque<std::unique_ptr<Connection>> inbox;
      {
        std::lock_guard<std::mutex> lock(mu_);
        inbox.swap(inbox_);
      }
      for (auto& c : inbox) {
        if (c->state == Connection::State::kHead && c->buffered() > 0) {
          // Part of the next head came with the previous request: keep reading it here.
          c->head_started = true;
          c->deadline_ms = NowMs() + limits_.head_timeout_ms;
        }
        epoll_event ev{};
        ev.events = EPOLLIN | EPOLLRDHUP;
        ev.data.fd = c->fd;
        if (::epoll_ctl(epoll_, EPOLL_CTL_ADD, c->fd, &ev) != 0) {
          Close(std::move(c));
          continue;
        }
        const int fd = c->fd;
        conns[fd] = std::move(c);
      }
      for (int i = 0; i < n; ++i) {
        const int fd = events[i].data.fd;
        if (fd == wake_) {
          uint64_t v;
          while (::read(wake_, &v, sizeof v) > 0) {
          }
          continue;
        }
        auto it = conns.find(fd);
        if (it == conns.end()) continue;
        if (it->second->state == Connection::State::kLinger) {
          if (Discard(it->second.get())) continue;
          Release(&conns, it);
          continue;
        }
        switch (ReadHead(it->second.get())) {
          case HeadState::kIncomplete:
            break;
          case HeadState::kClosed:
            Release(&conns, it);
            break;
          case HeadState::kTooLarge: {
            std::unique_ptr<Connection> c = Detach(&conns, it);
            {
              std::lock_guard<std::mutex> lock(mu_);
              ++counters_.heads_too_large;
            }
            WriteRefusal(c->fd, 431, "Request Header Fields Too Large", "header_too_large",
                         "the request line and headers are larger than " +
                             std::to_string(limits_.max_head_bytes) + " bytes");
            Linger(std::move(c));
            break;
          }
          case HeadState::kComplete:
            Dispatch(Detach(&conns, it));
            break;
        }
      }
      // Deadlines: heads not complete in time, idle keep-alive connections, lingering ends.
      const int64_t now = NowMs();
      if (now - last_sweep >= 50) {
        last_sweep = now;
        for (auto it = conns.begin(); it != conns.end();) {
          Connection* c = it->second.get();
          if (c->deadline_ms > now) {
            ++it;
            continue;
          }
          auto next_it = std::next(it);
          if (c->state == Connection::State::kHead && c->head_started) {
            std::unique_ptr<Connection> owned = Detach(&conns, it);
            {
              std::lock_guard<std::mutex> lock(mu_);
              ++counters_.head_timeouts;
            }
            WriteRefusal(owned->fd, 408, "Request Timeout", "timeout",
                         "the request line and headers did not arrive within " +
                             std::to_string(limits_.head_timeout_ms) + " ms");
            Linger(std::move(owned));
          } else {
            Release(&conns, it);
          }
          it = next_it;
        }
      }
      {
        std::lock_guard<std::mutex> lock(mu_);
        pending_heads_ = 0;
        for (const auto& [fd, c] : conns) {
          if (c->state == Connection::State::kHead && c->head_started) ++pending_heads_;
        }
      }
    }
    for (auto it = conns.begin(); it != conns.end();) {
      auto next_it = std::next(it);
      Release(&conns, it);
      it = next_it;
    }
  }

  enum class HeadState { kIncomplete, kComplete, kClosed, kTooLarge };

  HeadState ReadHead(Connection* c) {
    char chunk[16 << 10];
    while (true) {
      const ssize_t n = ::recv(c->fd, chunk, sizeof chunk, MSG_DONTWAIT);
      if (n > 0) {
        if (!c->head_started) {
          c->head_started = true;
          c->deadline_ms = NowMs() + limits_.head_timeout_ms;
        }
        const size_t from = c->buf.size() >= c->pos + 3 ? c->buf.size() - 3 : c->pos;
        c->buf.append(chunk, static_cast<size_t>(n));
        if (HeadComplete(c->buf, from)) return HeadState::kComplete;
        if (static_cast<int64_t>(c->buffered()) > limits_.max_head_bytes) {
          return HeadState::kTooLarge;
        }
        continue;
      }
      if (n == 0) return HeadState::kClosed;
      if (errno == EINTR) continue;
      if (errno == EAGAIN || errno == EWOULDBLOCK) return HeadState::kIncomplete;
      return HeadState::kClosed;
    }
  }

  // Lingering: reads and drops. False when the client has closed (or the socket failed).
  static bool Discard(Connection* c) {
    char chunk[64 << 10];
    while (true) {
      const ssize_t n = ::recv(c->fd, chunk, sizeof chunk, MSG_DONTWAIT);
      if (n > 0) continue;
      if (n == 0) return false;
      if (errno == EINTR) continue;
      return errno == EAGAIN || errno == EWOULDBLOCK;
    }
  }

  using ConnMap = std::unordered_map<int, std::unique_ptr<Connection>>;

  std::unique_ptr<Connection> Detach(ConnMap* conns, ConnMap::iterator it) {
    ::epoll_ctl(epoll_, EPOLL_CTL_DEL, it->first, nullptr);
    std::unique_ptr<Connection> c = std::move(it->second);
    conns->erase(it);
    return c;
  }

  void Release(ConnMap* conns, ConnMap::iterator it) { Close(Detach(conns, it)); }

  // A complete head: to a request thread, or, when its client already has
  // max_requests_per_client requests in progress, to that client's waiting line (holding no
  // thread), so one client cannot take every thread from the others.
  void Dispatch(std::unique_ptr<Connection> c) {
    c->head_started = false;
    std::lock_guard<std::mutex> lock(mu_);
    int& active = requests_per_client_[c->peer_ip];
    if (active < limits_.max_requests_per_client) {
      ++active;
      queue_.push_back(std::move(c));
      work_cv_.notify_one();
      return;
    }
    ++counters_.delayed_requests;
    waiting_[c->peer_ip].push_back(std::move(c));
  }

  void RequestLoop() {
    while (true) {
      std::unique_ptr<Connection> c;
      {
        std::unique_lock<std::mutex> lock(mu_);
        work_cv_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
        if (queue_.empty()) return;  // stopping
        c = std::move(queue_.front());
        queue_.pop_front();
        serving_.insert(c->fd);
      }
      const std::string peer = c->peer_ip;
      const int fd = c->fd;
      serve_(c.release());  // takes ownership: back to the reader, lingering, or closed
      {
        std::lock_guard<std::mutex> lock(mu_);
        serving_.erase(fd);
        auto w = waiting_.find(peer);
        if (w != waiting_.end()) {
          // The client's next waiting request takes this one's place.
          queue_.push_back(std::move(w->second.front()));
          w->second.pop_front();
          if (w->second.empty()) waiting_.erase(w);
          work_cv_.notify_one();
        } else {
          auto it = requests_per_client_.find(peer);
          if (it != requests_per_client_.end() && --it->second <= 0) {
            requests_per_client_.erase(it);
          }
        }
        if (serving_.empty() && queue_.empty()) idle_cv_.notify_all();
      }
    }
  }

  const HttpLimits limits_;
  const Serve serve_;
  int epoll_ = -1;
  int wake_ = -1;
  std::thread reader_;
  std::vector<std::thread> threads_;
  std::atomic<bool> stopping_flag_{false};

  mutable std::mutex mu_;
  bool stopping_ = false;  // guarded by mu_
  bool stopped_ = false;
  bool reader_running_ = true;  // inbox_ is read; false once Stop began
  int open_ = 0;
  std::map<std::string, int> connections_per_client_;
  std::map<std::string, int> requests_per_client_;
  std::deque<std::unique_ptr<Connection>> inbox_;  // to the reader
  std::deque<std::unique_ptr<Connection>> queue_;  // complete heads, to request threads
  // Complete heads of clients at max_requests_per_client, in arrival order per client.
  std::map<std::string, std::deque<std::unique_ptr<Connection>>> waiting_;
  std::set<int> serving_;  // fds being served by request threads
  size_t pending_heads_ = 0;
  std::condition_variable work_cv_, idle_cv_;
  HttpCounters counters_;
};

std::string HttpLimits::Validate() const {
  if (threads < 1) return "http threads must be >= 1";
  if (head_timeout_ms < 1) return "head timeout must be >= 1 ms";
  if (keep_alive_timeout_ms < 1) return "keep-alive timeout must be >= 1 ms";
  if (max_head_bytes < 1024) return "max head bytes must be >= 1024";
  if (max_connections < 1 || max_connections > 900) {
    return "max connections must be in 1..900 (httplib refuses sockets >= FD_SETSIZE)";
  }
  if (max_connections_per_client < 1) return "max connections per client must be >= 1";
  if (max_requests_per_client < 1) return "max requests per client must be >= 1";
  if (read_timeout_ms < 1 || write_timeout_ms < 1) return "timeouts must be >= 1 ms";
  if (linger_ms < 0) return "linger must be >= 0 ms";
  if (keep_alive_max_count < 1) return "keep-alive max count must be >= 1";
  return "";
}

// Whether the request's body, if it has one, was read whole into req.body (httplib reads the body
// of a request for a regular handler before calling it; an upload's streamed body, a body refused
// before routing, or one cut short is not). Without a body: true.
static bool BodyReadWhole(const httplib::Request& req) {
  if (req.has_header("Transfer-Encoding")) return false;  // chunked: only uploads stream them
  if (!req.has_header("Content-Length")) return true;
  const std::string text = req.get_header_value("Content-Length");
  if (text.empty() || text.size() > 18 ||
      text.find_first_not_of("0123456789") != std::string::npos) {
    return false;
  }
  return req.body.size() == static_cast<size_t>(std::stoll(text));
}

HttpServer::HttpServer(HttpLimits limits) : limits_(limits) {
  new_task_queue = [] { return new InlineQueue(); };
  set_keep_alive_timeout(std::max(1, limits_.keep_alive_timeout_ms / 1000));
  set_keep_alive_max_count(static_cast<size_t>(limits_.keep_alive_max_count));
  set_read_timeout(limits_.read_timeout_ms / 1000, (limits_.read_timeout_ms % 1000) * 1000);
  set_write_timeout(limits_.write_timeout_ms / 1000, (limits_.write_timeout_ms % 1000) * 1000);
  // Before the answer's head is written: an answer after which request bytes may be left unread
  // ends the connection, and says so (`Connection: close`, no Keep-Alive), so a keep-alive client
  // never sends its next request into a socket about to close. Error answers to requests whose
  // body httplib read whole (JSON bodies of POST /jobs, revoke, accept, unknown routes) keep the
  // connection like any other answer.
  set_post_routing_handler([](const httplib::Request& req, httplib::Response& res) {
    if (ToLower(res.get_header_value("Connection")) == "close" ||
        (res.status >= 400 && !BodyReadWhole(req)) || req.method.empty()) {
      res.set_header("Connection", "close");
      res.headers.erase("Keep-Alive");
    }
  });
  set_logger([this](const httplib::Request& req, const httplib::Response& res) {
    Connection* c = t_connection;
    if (c != nullptr) {
      const std::string length = req.get_header_value("Content-Length");
      c->large = res.body.size() > (1u << 20) || req.body.size() > (1u << 20) ||
                 length.size() > 6 || req.has_header("Transfer-Encoding");
      // The post-routing hook above decided (an answer httplib wrote without it, e.g. to a
      // request it could not parse, is judged the same way here).
      if (ToLower(res.get_header_value("Connection")) == "close" ||
          (res.status >= 400 && !BodyReadWhole(req)) || req.method.empty()) {
        c->close_after = true;
      }
    }
    if (logger_) logger_(req, res);
  });
  frontend_ = std::make_unique<Frontend>(limits_, [this](Connection* raw) {
    std::unique_ptr<Connection> c(raw);
    t_connection = c.get();
    ConnectionStream stream(c.get(), limits_);
    enum { kIdle, kClose, kLinger } next = kClose;
    while (true) {
      c->close_after = false;
      bool client_closes = false;
      ++c->requests;
      const bool last = frontend_->stopping() || c->requests >= limits_.keep_alive_max_count;
      c->large = false;
      const bool ok = process_request(stream, last, client_closes, nullptr);
      c->Compact();
      if (c->large) TrimHeap();
      if (c->close_after) {
        next = kLinger;
        break;
      }
      if (!ok || client_closes || last || frontend_->stopping()) {
        next = kClose;
        break;
      }
      if (!HeadComplete(c->buf, c->pos)) {
        next = kIdle;
        break;
      }
      // A pipelined request is already here: serve it on this thread.
    }
    t_connection = nullptr;
    switch (next) {
      case kIdle:
        c->state = Connection::State::kHead;
        c->head_started = false;
        c->deadline_ms = NowMs() + limits_.keep_alive_timeout_ms;
        frontend_->ToReader(std::move(c));
        break;
      case kLinger:
        frontend_->Linger(std::move(c));
        break;
      case kClose:
        frontend_->Close(std::move(c));
        break;
    }
  });
}

HttpServer::~HttpServer() { Shutdown(0); }

void HttpServer::SetAccessLogger(AccessLogger logger) { logger_ = std::move(logger); }

// Debian builds cpp-httplib 0.11.4 with zlib and brotli, so it would decompress a request body
// with `Content-Encoding: gzip`, `deflate` or `br` itself, with no limit on the decompressed
// size. Before anything else sees a request, its Content-Encoding is moved to
// kBodyEncodingHeader (a client's own copy of that header is dropped first), so bodies reach the
// handlers as sent and the handlers decode them under their own limits. `req` is httplib's own
// non-const Request object (Server::process_request), handed to the hooks as const.
static void MoveContentEncoding(const httplib::Request& const_req) {
  auto& req = const_cast<httplib::Request&>(const_req);
  if (req.has_header("Content-Encoding")) {
    req.headers.erase(kBodyEncodingHeader);
    std::string encodings;
    for (auto [it, end] = req.headers.equal_range("Content-Encoding"); it != end; ++it) {
      encodings += (encodings.empty() ? "" : ", ") + it->second;
    }
    req.headers.erase("Content-Encoding");
    req.headers.emplace(kBodyEncodingHeader, encodings);
  }
}

void HttpServer::SetRequestFilter(HandlerWithResponse filter) {
  filter_ = std::move(filter);
  set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
    MoveContentEncoding(req);
    return filter_(req, res);
  });
  // httplib answers `Expect: 100-continue` before routing; a request we refuse gets its error
  // instead of "100 Continue", so the client does not send the body at all.
  set_expect_100_continue_handler([this](const httplib::Request& req, httplib::Response& res) {
    MoveContentEncoding(req);
    if (filter_(req, res) == HandlerResponse::Handled) {
      res.set_header("Connection", "close");
      return res.status;
    }
    return 100;
  });
}

void HttpServer::Shutdown(int grace_ms) {
  stop();
  if (frontend_) frontend_->Stop(grace_ms);
}

HttpCounters HttpServer::counters() const { return frontend_->counters(); }

bool HttpServer::process_and_close_socket(socket_t sock) {
  frontend_->Adopt(sock);
  return true;
}

}  // namespace calibd::server
