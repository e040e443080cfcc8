// The connection handling of server/http_server.h against the real server over raw loopback
// sockets: a refused request's body is never run as a request (for every refusal path), slow
// request heads neither hold threads nor starve /healthz and end with 408, oversized heads get
// 431, per-client limits answer 503, and keep-alive and pipelining still work.
#include <gtest/gtest.h>

#include <chrono>
#include <exception>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "tests/lib/sanitizer.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::RawConnection;
using testing::StatusOf;
using testing::TempDir;
using testing::TestServer;

constexpr char kToken[] = "0123456789abcdef-smuggling-test";

// A complete upload for device SMUGGLED: if any of it runs, a new recording is stored. The
// control (the same request sent on its own, to prove it would be accepted) differs by a comment,
// so the smuggled bytes are not a duplicate of it.
std::string SmuggledUpload(bool control = false) {
  const std::string csv = std::string(control ? "# control\n" : "") +
                          "position,s0,s1,s2\np0,1,0,0\np1,0,1,0\np2,0,0,1\n";
  return std::string("POST /api/v1/recordings?device=SMUGGLED HTTP/1.1\r\nHost: x\r\n") +
         "Authorization: Bearer " + kToken + "\r\nContent-Type: text/csv\r\n" +
         "Content-Length: " + std::to_string(csv.size()) + "\r\n\r\n" + csv;
}

// How many HTTP answers are in `bytes` (status lines "HTTP/1.1 DDD "; a JSON body does not end
// with a newline, so the next answer may follow it directly).
// Answers received whole (head and Content-Length body), in order from the start of `bytes`. A
// server writes the head and the body separately, so a status line can arrive before its body.
int CompleteAnswers(const std::string& bytes) {
  int n = 0;
  size_t at = 0;
  while (bytes.compare(at, 9, "HTTP/1.1 ") == 0) {
    const size_t end = bytes.find("\r\n\r\n", at);
    if (end == std::string::npos) break;
    const size_t length = bytes.find("Content-Length: ", at);
    if (length == std::string::npos || length > end) break;
    const size_t next = end + 4 + std::stoul(bytes.substr(length + 16));
    if (next > bytes.size()) break;
    ++n;
    at = next;
  }
  return n;
}

int CountAnswers(const std::string& bytes) {
  int n = 0;
  for (size_t at = 0; (at = bytes.find("HTTP/1.1 ", at)) != std::string::npos; at += 9) {
    if (at + 12 < bytes.size() && isdigit(static_cast<unsigned char>(bytes[at + 9])) &&
        isdigit(static_cast<unsigned char>(bytes[at + 10])) &&
        isdigit(static_cast<unsigned char>(bytes[at + 11])) && bytes[at + 12] == ' ') {
      ++n;
    }
  }
  return n;
}

class Smuggling : public ::testing::Test {
 protected:
  static ServeOptions Options(const std::filesystem::path& token_file) {
    std::ofstream(token_file) << kToken << "\n";
    ServeOptions options;
    options.token_file = token_file.string();
    options.max_upload_bytes = 64 << 10;
    options.max_json_body_bytes = 4 << 10;
    options.read_timeout_seconds = 2;
    return options;
  }

  void SetUp() override {
    ASSERT_EQ(server_.error(), "");
    // The smuggled request is valid: sent on its own it is stored.
    RawConnection c(server_.port());
    ASSERT_TRUE(c.Send(SmuggledUpload(/*control=*/true)));
    const std::string answer = c.Receive();
    ASSERT_EQ(StatusOf(answer), 201) << answer;
    auto res = server_.Client().Get("/api/v1/recordings/1");
    ASSERT_TRUE(res);
    control_ = json::parse(res->body);
  }

  // Sends `first` (which must be refused with `status`) followed by `rest`; expects exactly one
  // answer, then the connection closed by the server, and nothing of `rest` run.
  void ExpectRefusedAndClosed(const std::string& name, int status, const std::string& first,
                              const std::string& rest) {
    RawConnection c(server_.port());
    ASSERT_TRUE(c.ok());
    (void)c.Send(first + rest);  // the server may close before all is sent
    std::string bytes = c.Receive();
    EXPECT_EQ(StatusOf(bytes), status) << name << ": " << bytes.substr(0, 400);
    // It says so before closing: a keep-alive client must not send its next request into it.
    const std::string head = bytes.substr(0, bytes.find("\r\n\r\n"));
    EXPECT_NE(head.find("Connection: close"), std::string::npos) << name << ": " << head;
    EXPECT_EQ(head.find("Keep-Alive"), std::string::npos) << name << ": " << head;
    EXPECT_TRUE(c.ClosedByPeer(5000 * static_cast<int>(sanitizer::kTimeBoundScale), &bytes))
        << name << ": the connection stayed open after the refusal";
    EXPECT_EQ(CountAnswers(bytes), 1) << name << ": " << bytes.substr(0, 800);
    ExpectNothingSmuggled(name);
  }

  void ExpectNothingSmuggled(const std::string& after) {
    auto client = server_.Client();
    auto res = client.Get("/api/v1/recordings/2");
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 404) << after << ": a second recording was stored: " << res->body;
    res = client.Get("/api/v1/jobs");
    ASSERT_TRUE(res);
    EXPECT_EQ(json::parse(res->body)["jobs"].size(), 0u) << after;
  }

  TempDir token_dir_;
  TestServer server_{Options(token_dir_.path() / "token")};
  json control_;
};

std::string Head(const std::string& request_line, const std::string& headers) {
  return request_line + "\r\nHost: x\r\nAuthorization: Bearer " + kToken + "\r\n" + headers +
         "\r\n";
}

TEST_F(Smuggling, CompressedBodyRefused415NeverRunsTheBody) {
  const std::string body = SmuggledUpload();
  ExpectRefusedAndClosed("415", 415,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: text/csv\r\nContent-Encoding: br\r\n"
                              "Content-Length: " +
                                  std::to_string(body.size()) + "\r\n"),
                         body);
}

// Uploads may be gzip'd: a body that says gzip and is not is refused part-way (400) and closed.
TEST_F(Smuggling, NotReallyGzipBodyRefused400NeverRunsTheBody) {
  const std::string body = SmuggledUpload();
  ExpectRefusedAndClosed("400", 400,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: text/csv\r\nContent-Encoding: gzip\r\n"
                              "Content-Length: " +
                                  std::to_string(body.size()) + "\r\n"),
                         body);
}

TEST_F(Smuggling, TooLargeContentLengthRefused413NeverRunsTheBody) {
  ExpectRefusedAndClosed("413", 413,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: text/csv\r\nContent-Length: 600000000\r\n"),
                         SmuggledUpload());
}

// 19 digits and more: beyond std::stoll's range (it threw, and the request was answered 500 as
// an internal error), and beyond any limit.
TEST_F(Smuggling, ContentLengthBeyondInt64Refused413NeverRunsTheBody) {
  for (const char* length : {"9999999999999999999", "99999999999999999999999"}) {
    ::testing::internal::CaptureStderr();
    ExpectRefusedAndClosed(length, 413,
                           Head("POST /api/v1/jobs HTTP/1.1",
                                "Content-Type: application/json\r\n"
                                "Content-Length: " +
                                    std::string(length) + "\r\n"),
                           SmuggledUpload());
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(log.find("internal error"), std::string::npos) << log;
  }
}

// What a route throws (no route throws on any input we know of, so the handler is driven
// directly): the client gets a generic 500, the operator's log the request and the text.
TEST(ExceptionHandler, TheTextGoesToTheLogNeverToTheClient) {
  httplib::Request req;
  req.method = "POST";
  req.path = "/api/v1/jobs/12/revoke";
  httplib::Response res;
  ::testing::internal::CaptureStderr();
  AnswerException(req, res, std::make_exception_ptr(std::out_of_range("marker-91c: stoll")));
  std::string log = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(res.status, 500);
  EXPECT_EQ(res.body.find("marker-91c"), std::string::npos) << res.body;
  const json body = json::parse(res.body);
  EXPECT_EQ(body["error"]["code"], "internal");
  EXPECT_EQ(body["error"]["message"], "internal server error");
  EXPECT_NE(log.find("internal error in POST /api/v1/jobs/12/revoke: marker-91c: stoll"),
            std::string::npos)
      << log;
  // Not a std::exception: said so; control characters never reach the log raw.
  httplib::Response other;
  req.path = "/api/v1/jobs/\n1";
  ::testing::internal::CaptureStderr();
  AnswerException(req, other, std::make_exception_ptr(42));
  log = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(other.status, 500);
  EXPECT_NE(log.find("in POST /api/v1/jobs/?1: an exception that is not a std::exception"),
            std::string::npos)
      << log;
}

TEST_F(Smuggling, ExpectContinueIsAnsweredWithTheRefusalNotContinue) {
  RawConnection c(server_.port());
  ASSERT_TRUE(c.Send(Head("POST /api/v1/recordings?device=A HTTP/1.1",
                          "Content-Type: text/csv\r\nContent-Length: 600000000\r\n"
                          "Expect: 100-continue\r\n")));
  std::string bytes = c.Receive();
  EXPECT_EQ(StatusOf(bytes), 413) << bytes.substr(0, 300);
  (void)c.Send(SmuggledUpload());  // a client that sends anyway
  EXPECT_TRUE(c.ClosedByPeer(5000, &bytes));
  EXPECT_EQ(CountAnswers(bytes), 1) << bytes.substr(0, 600);
  ExpectNothingSmuggled("expect 100-continue");
}

TEST_F(Smuggling, MissingLengthRefused411NeverRunsWhatFollows) {
  ExpectRefusedAndClosed("411", 411,
                         Head("POST /api/v1/jobs HTTP/1.1", "Content-Type: application/json\r\n"),
                         SmuggledUpload());
}

TEST_F(Smuggling, MissingTokenRefused401NeverRunsTheBody) {
  const std::string body = SmuggledUpload();
  ExpectRefusedAndClosed("401", 401,
                         "POST /api/v1/recordings?device=A HTTP/1.1\r\nHost: x\r\n"
                         "Content-Type: text/csv\r\nContent-Length: " +
                             std::to_string(body.size()) + "\r\n\r\n",
                         body);
}

TEST_F(Smuggling, CsvErrorPartWayThroughTheBodyNeverRunsTheRest) {
  const std::string bad = "position,s0\np0,not-a-number\n";
  const std::string rest = SmuggledUpload();
  ExpectRefusedAndClosed("csv 400", 400,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: text/csv\r\nContent-Length: " +
                                  std::to_string(bad.size() + rest.size()) + "\r\n") +
                             bad,
                         rest);
}

TEST_F(Smuggling, ChunkedUploadOverTheLimitNeverRunsWhatFollows) {
  std::string chunks;
  const std::string row = "p0,1\n";
  std::string data = "position,s0\n";
  while (data.size() < (100u << 10)) data += row;
  char size[32];
  std::snprintf(size, sizeof size, "%zx\r\n", data.size());
  chunks = size + data + "\r\n0\r\n\r\n";
  ExpectRefusedAndClosed("chunked 413", 413,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: text/csv\r\nTransfer-Encoding: chunked\r\n") +
                             chunks,
                         SmuggledUpload());
}

TEST_F(Smuggling, UnknownMultipartPartNeverRunsTheRest) {
  const std::string rest = SmuggledUpload();
  const std::string body =
      "--b\r\nContent-Disposition: form-data; name=\"other\"\r\n\r\nx\r\n" + rest + "\r\n--b--\r\n";
  ExpectRefusedAndClosed("multipart 400", 400,
                         Head("POST /api/v1/recordings?device=A HTTP/1.1",
                              "Content-Type: multipart/form-data; boundary=b\r\n"
                              "Content-Length: " +
                                  std::to_string(body.size()) + "\r\n") +
                             body,
                         "");
}

TEST_F(Smuggling, OversizedJsonBodyRefused413NeverRunsTheBody) {
  const std::string body = SmuggledUpload();
  ExpectRefusedAndClosed("json 413", 413,
                         Head("POST /api/v1/jobs HTTP/1.1",
                              "Content-Type: application/json\r\nContent-Length: 100000\r\n"),
                         body);
}

// Error answers to requests whose JSON body was read whole keep the connection (issue 27: a
// keep-alive client lost its next request when the server closed after a 4xx without saying
// so): the same connection then carries the next request, and the control upload is all there is.
TEST_F(Smuggling, ErrorAnswersToWholeJsonBodiesKeepTheConnection) {
  const std::string json_type = "Content-Type: application/json\r\n";
  auto post = [&](const std::string& target, const std::string& body) {
    return Head("POST " + target + " HTTP/1.1",
                json_type + "Content-Length: " + std::to_string(body.size()) + "\r\n") +
           body;
  };
  const std::vector<std::pair<std::string, int>> cases = {
      {post("/api/v1/jobs/999/revoke", R"({"reason": "wrong board"})"), 404},
      {post("/api/v1/jobs/999/accept", R"({"reason": "checked by hand"})"), 404},
      {post("/api/v1/jobs/1/revoke", "{not json"), 400},
      {post("/api/v1/jobs", R"({"recording_id": 999, "config": {"method": "pca"}})"), 404},
      {post("/api/v1/no-such-route", R"({"a": 1})"), 404},
  };
  for (const auto& [request, status] : cases) {
    RawConnection c(server_.port());
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE(c.Send(request));
    std::string bytes;
    for (int i = 0; i < 50 && CompleteAnswers(bytes) < 1; ++i) bytes += c.Receive();
    const std::string line = request.substr(0, request.find('\r'));
    EXPECT_EQ(StatusOf(bytes), status) << line << ": " << bytes.substr(0, 400);
    EXPECT_EQ(bytes.find("Connection: close"), std::string::npos) << line << ": " << bytes;
    ASSERT_TRUE(c.Send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")) << line;
    EXPECT_EQ(StatusOf(c.Receive()), 200) << line << ": the connection was closed";
  }
  ExpectNothingSmuggled("error answers kept alive");
}

class Frontend : public ::testing::Test {
 protected:
  static ServeOptions Options() {
    ServeOptions options;
    options.head_timeout_seconds = 1;
    options.http_threads = 8;  // far fewer threads than slow clients
    return options;
  }
  void SetUp() override { ASSERT_EQ(server_.error(), ""); }

  double HealthzSeconds() {
    const auto start = std::chrono::steady_clock::now();
    auto client = server_.Client();
    client.set_connection_timeout(2, 0);
    client.set_read_timeout(2, 0);
    auto res = client.Get("/healthz");
    EXPECT_TRUE(res && res->status == 200);
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  TestServer server_{Options()};
};

TEST_F(Frontend, TwoHundredSlowHeadsNeitherStarveHealthzNorStayOpen) {
  std::vector<std::unique_ptr<RawConnection>> slow;
  for (int i = 0; i < 200; ++i) {
    slow.push_back(std::make_unique<RawConnection>(server_.port()));
    ASSERT_TRUE(slow.back()->ok());
    ASSERT_TRUE(slow.back()->Send("POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nX-Slow: "));
  }
  // 8 request threads, 200 trickling heads: /healthz is still answered at once (the bound is
  // loose; bench/README.md has the latency figures).
  double slowest = 0;
  for (int round = 0; round < 4; ++round) {
    for (auto& c : slow) c->Send("a");
    slowest = std::max(slowest, HealthzSeconds());
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
  }
  EXPECT_LT(slowest, 1.0 * sanitizer::kTimeBoundScale);
  // The head deadline (1 s from the first byte) ends every slow head with 408.
  int timed_out = 0;
  for (auto& c : slow) {
    std::string bytes;
    const bool closed = c->ClosedByPeer(5000, &bytes);
    if (closed && StatusOf(bytes) == 408) ++timed_out;
  }
  EXPECT_EQ(timed_out, 200);
}

TEST_F(Frontend, OversizedHeadIsRefused431AndClosed) {
  RawConnection c(server_.port());
  (void)c.Send("GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(100 << 10, 'a'));
  std::string bytes = c.Receive();
  EXPECT_EQ(StatusOf(bytes), 431) << bytes.substr(0, 300);
  EXPECT_TRUE(c.ClosedByPeer(5000, &bytes));
  EXPECT_LT(HealthzSeconds(), 1.0 * sanitizer::kTimeBoundScale);
}

TEST_F(Frontend, KeepAliveAndPipelinedRequestsAreAllAnswered) {
  RawConnection c(server_.port());
  const std::string get = "GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_TRUE(c.Send(get + get + get));
  std::string bytes;
  // Until the third answer's body is here too (its status line can come first): a byte of it
  // left unread would start the next Receive.
  for (int i = 0; i < 50 && CompleteAnswers(bytes) < 3; ++i) bytes += c.Receive();
  EXPECT_EQ(CompleteAnswers(bytes), 3) << bytes;
  EXPECT_EQ(CountAnswers(bytes), 3) << bytes;
  EXPECT_EQ(bytes.find("HTTP/1.1 200"), 0u);
  // Idle for a while (back with the head reader), then reused.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_TRUE(c.Send(get));
  EXPECT_EQ(StatusOf(c.Receive()), 200);
}

TEST_F(Frontend, AGetAnsweredWith404KeepsTheConnection) {
  RawConnection c(server_.port());
  ASSERT_TRUE(c.Send("GET /api/v1/jobs/999 HTTP/1.1\r\nHost: x\r\n\r\n"));
  EXPECT_EQ(StatusOf(c.Receive()), 404);
  ASSERT_TRUE(c.Send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"));
  EXPECT_EQ(StatusOf(c.Receive()), 200);
}

TEST(FrontendLimits, ConnectionsOverThePerClientLimitAreRefused503) {
  ServeOptions options;
  options.max_connections_per_client = 8;
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  // 12 idle connections from one address: those over the limit of 8 are answered 503 at once
  // (the readiness check's connection may still be open too, so 4 or 5 are refused).
  std::vector<std::unique_ptr<RawConnection>> open;
  for (int i = 0; i < 12; ++i) {
    open.push_back(std::make_unique<RawConnection>(server.port()));
    ASSERT_TRUE(open.back()->ok());
  }
  // Refusals are written at once; accepted idle connections stay silent (for the 5 s keep-alive).
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  int refused = 0;
  for (auto& c : open) {
    pollfd p{c->fd(), POLLIN, 0};
    if (poll(&p, 1, 0) != 1) continue;  // accepted and idle: nothing to read
    const std::string bytes = c->Receive();
    EXPECT_EQ(StatusOf(bytes), 503) << bytes.substr(0, 300);
    EXPECT_NE(bytes.find("too many open connections"), std::string::npos);
    ++refused;
  }
  EXPECT_GE(refused, 4);
  EXPECT_LE(refused, 5);
  // Closing them makes room again.
  open.clear();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  RawConnection again(server.port());
  ASSERT_TRUE(again.Send("GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n"));
  EXPECT_EQ(StatusOf(again.Receive()), 200);
}

}  // namespace
}  // namespace calibd::server
