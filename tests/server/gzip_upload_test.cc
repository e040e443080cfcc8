// Gzip-compressed uploads (SPEC §2): GzipInflater on its own (pieces of any size, concatenated
// members, truncation, corruption, bombs), then through the real server: a gzip'd text/csv body
// and a .csv.gz multipart part are the same recording as the plain CSV, are stored decompressed,
// and run; bombs are 413, truncated or corrupt streams 400 naming the byte offset, nothing is
// left behind, and other encodings stay 415.
#include <gtest/gtest.h>
#include <zlib.h>

#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "methods/noise/noise_method.h"
#include "server/gzip_stream.h"
#include "tests/server/http_test_util.h"

namespace calibd::server {
namespace {

using nlohmann::json;
using testing::StagedUploads;
using testing::TestServer;

// One gzip member holding `data` (zlib's deflate with the gzip wrapper).
std::string Gzip(const std::string& data, int level = 6) {
  z_stream zs{};
  EXPECT_EQ(deflateInit2(&zs, level, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY), Z_OK);
  std::string out(deflateBound(&zs, data.size()), '\0');
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data.data()));
  zs.avail_in = static_cast<uInt>(data.size());
  zs.next_out = reinterpret_cast<Bytef*>(out.data());
  zs.avail_out = static_cast<uInt>(out.size());
  EXPECT_EQ(deflate(&zs, Z_FINISH), Z_STREAM_END);
  out.resize(zs.total_out);
  deflateEnd(&zs);
  return out;
}

// A small noise log as CSV (deterministic).
std::string NoiseCsv(double seconds = 20, double rate = 100) {
  NoiseSimulationFileOptions sim;
  sim.rate = rate;
  sim.seconds = seconds;
  sim.seed = 3;
  std::string csv;
  json config, truth;
  EXPECT_TRUE(SimulateNoiseFiles(sim, &csv, &config, &truth).ok());
  return csv;
}

// Inflates `compressed` in pieces of `piece` bytes; returns the output or the first error.
Status Inflate(const std::string& compressed, size_t piece, std::string* out,
               GzipLimits limits = {}) {
  GzipInflater inflater(limits, "the test data");
  auto sink = [&](const char* d, size_t n) {
    out->append(d, n);
    return true;
  };
  for (size_t at = 0; at < compressed.size(); at += piece) {
    Status s = inflater.Feed(compressed.data() + at, std::min(piece, compressed.size() - at), sink);
    if (!s.ok()) return s;
  }
  return inflater.Finish();
}

TEST(GzipInflater, RecoversTheDataFedInPiecesOfAnySize) {
  const std::string csv = NoiseCsv();
  const std::string gz = Gzip(csv);
  ASSERT_LT(gz.size(), csv.size());
  for (size_t piece : {size_t{1}, size_t{7}, size_t{4096}, gz.size()}) {
    std::string out;
    ASSERT_TRUE(Inflate(gz, piece, &out).ok()) << piece;
    EXPECT_EQ(out, csv) << "pieces of " << piece;
  }
}

TEST(GzipInflater, ConcatenatedMembersAreOneStream) {
  std::string out;
  ASSERT_TRUE(Inflate(Gzip("t,a\n1,2\n") + Gzip("2,3\n"), 5, &out).ok());
  EXPECT_EQ(out, "t,a\n1,2\n2,3\n");
}

TEST(GzipInflater, TruncatedStreamNamesWhereItStops) {
  const std::string gz = Gzip(NoiseCsv());
  for (size_t keep : {size_t{5}, gz.size() / 2, gz.size() - 1}) {
    std::string out;
    Status s = Inflate(gz.substr(0, keep), 1000, &out);
    EXPECT_EQ(s.code(), StatusCode::kInvalidInput) << keep;
    EXPECT_NE(s.message().find("stops at byte " + std::to_string(keep)), std::string::npos)
        << s.message();
    EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();
  }
}

TEST(GzipInflater, CorruptDataNamesTheByteOffset) {
  std::string gz = Gzip(NoiseCsv());
  gz[gz.size() / 2] = static_cast<char>(gz[gz.size() / 2] ^ 0x55);
  std::string out;
  Status s = Inflate(gz, 4096, &out);
  ASSERT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("corrupt gzip data in the test data at byte "), std::string::npos)
      << s.message();
  // Not gzip at all: refused at byte 0.
  s = Inflate("t,a\n1,2\n", 100, &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("at byte 0"), std::string::npos) << s.message();
  // Garbage after the end of the stream.
  s = Inflate(Gzip("t,a\n") + "garbage", 100, &out);
  EXPECT_EQ(s.code(), StatusCode::kInvalidInput);
  EXPECT_NE(s.message().find("after the end of the gzip stream"), std::string::npos) << s.message();
}

TEST(GzipInflater, DecompressedSizeOverTheLimitIsTooLarge) {
  const std::string csv = NoiseCsv();
  GzipLimits limits;
  limits.max_output_bytes = static_cast<int64_t>(csv.size()) - 1;
  std::string out;
  Status s = Inflate(Gzip(csv), 4096, &out, limits);
  EXPECT_EQ(s.code(), StatusCode::kTooLarge);
  EXPECT_NE(s.message().find("limit of " + std::to_string(csv.size() - 1)), std::string::npos)
      << s.message();
  EXPECT_LE(out.size(), csv.size() - 1);  // nothing beyond the limit reached the sink
  limits.max_output_bytes = static_cast<int64_t>(csv.size());
  out.clear();
  EXPECT_TRUE(Inflate(Gzip(csv), 4096, &out, limits).ok());
}

TEST(GzipInflater, ABombIsRefusedByItsRatioLongBeforeTheSizeLimit) {
  // 64 MiB of one repeated line compress ~1000 times.
  std::string bomb_text;
  while (bomb_text.size() < (64u << 20)) bomb_text += "0,0,0,0,0,0,0\n";
  const std::string bomb = Gzip(bomb_text, 9);
  GzipLimits limits;  // default ratio 200, size 512 MiB
  int64_t delivered = 0;
  GzipInflater inflater(limits, "the bomb");
  Status s = inflater.Feed(bomb.data(), bomb.size(), [&](const char*, size_t n) {
    delivered += static_cast<int64_t>(n);
    return true;
  });
  EXPECT_EQ(s.code(), StatusCode::kTooLarge);
  EXPECT_NE(s.message().find("decompression bomb"), std::string::npos) << s.message();
  // Stopped within a buffer of the ratio limit, not after 64 MiB.
  EXPECT_LT(delivered, limits.ratio_grace_bytes + 200 * static_cast<int64_t>(bomb.size()));
  EXPECT_LT(delivered, int64_t{4} << 20);
}

TEST(GzipInflater, ASinkThatStopsStopsTheStream) {
  GzipInflater inflater({}, "x");
  const std::string gz = Gzip(NoiseCsv());
  Status s = inflater.Feed(gz.data(), gz.size(), [](const char*, size_t) { return false; });
  EXPECT_TRUE(GzipInflater::IsSinkStopped(s));
}

json Post(TestServer& server, const std::string& path, const httplib::Headers& headers,
          const std::string& body, const std::string& type, int* status) {
  auto res = server.Client().Post(path.c_str(), headers, body, type.c_str());
  EXPECT_TRUE(res);
  if (!res) return json();
  *status = res->status;
  return json::parse(res->body);
}

TEST(GzipUpload, CompressedBodyAndPartAreTheSameRecordingStoredDecompressed) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  const std::string csv = NoiseCsv();
  const std::string gz = Gzip(csv);
  int status = 0;
  json plain = Post(server, "/api/v1/recordings?device=Z", {}, csv, "text/csv", &status);
  ASSERT_EQ(status, 201) << plain.dump();
  EXPECT_TRUE(plain["recording"]["compressed_bytes"].is_null());

  json zipped = Post(server, "/api/v1/recordings?method=noise&device=Z",
                     {{"Content-Encoding", "gzip"}}, gz, "text/csv", &status);
  ASSERT_EQ(status, 201) << zipped.dump();
  EXPECT_EQ(zipped["recording"]["id"], plain["recording"]["id"]);
  EXPECT_EQ(zipped["recording"]["sha256"], plain["recording"]["sha256"]);
  EXPECT_EQ(zipped["recording"]["bytes"], csv.size());
  EXPECT_EQ(zipped["recording"]["compressed_bytes"], gz.size());
  EXPECT_TRUE(zipped["recording"]["existed"].get<bool>());
  EXPECT_EQ(server.WaitForJob(zipped["job"]["id"])["status"], "succeeded");

  // A .csv.gz part (detected by its magic bytes, whatever the part's type).
  httplib::MultipartFormDataItems items = {
      {"recording", gz, "log.csv.gz", "application/gzip"},
      {"config", R"({"method": "noise", "device": "Z"})", "", "application/json"}};
  auto res = server.Client().Post("/api/v1/recordings", items);
  ASSERT_TRUE(res);
  ASSERT_EQ(res->status, 201) << res->body;
  json part = json::parse(res->body);
  EXPECT_EQ(part["recording"]["sha256"], plain["recording"]["sha256"]);
  EXPECT_EQ(server.WaitForJob(part["job"]["id"])["status"], "succeeded");

  // The stored bytes are the CSV.
  auto data = server.Client().Get(
      ("/api/v1/recordings/" + plain["recording"]["id"].dump() + "/data").c_str());
  ASSERT_TRUE(data);
  EXPECT_EQ(data->body, csv);
}

TEST(GzipUpload, BombIs413TruncatedOrCorruptIs400AndNothingIsLeftBehind) {
  ServeOptions options;
  options.max_upload_bytes = 32 << 20;
  TestServer server(options);
  ASSERT_EQ(server.error(), "");
  const std::string csv = NoiseCsv();
  const std::string gz = Gzip(csv);
  int status = 0;

  std::string bomb_text = "t,a0_x,a0_y,a0_z,g0_x,g0_y,g0_z\n";
  for (int i = 0; bomb_text.size() < (48u << 20); ++i) bomb_text += "1,0,0,0,0,0,0\n";
  json e = Post(server, "/api/v1/recordings?method=noise", {{"Content-Encoding", "gzip"}},
                Gzip(bomb_text, 9), "text/csv", &status);
  EXPECT_EQ(status, 413) << e.dump();
  EXPECT_EQ(e["error"]["code"], "too_large");
  EXPECT_NE(e["error"]["message"].get<std::string>().find("decompression bomb"), std::string::npos);

  // Within the ratio but over the decompressed size limit: 413 naming the limit.
  ServeOptions small = options;
  small.max_upload_bytes = static_cast<int64_t>(csv.size()) - 10;
  TestServer tight(small);
  ASSERT_EQ(tight.error(), "");
  e = Post(tight, "/api/v1/recordings", {{"Content-Encoding", "gzip"}}, gz, "text/csv", &status);
  EXPECT_EQ(status, 413) << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find(std::to_string(csv.size() - 10)),
            std::string::npos)
      << e.dump();

  const std::string half = gz.substr(0, gz.size() / 2);
  e = Post(server, "/api/v1/recordings", {{"Content-Encoding", "gzip"}}, half, "text/csv", &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_NE(
      e["error"]["message"].get<std::string>().find("stops at byte " + std::to_string(half.size())),
      std::string::npos)
      << e.dump();

  // A wrong CRC-32 in the trailer (the CSV itself decodes and parses): found at the end.
  std::string corrupt = gz;
  corrupt[corrupt.size() - 6] = static_cast<char>(corrupt[corrupt.size() - 6] ^ 0x55);
  e = Post(server, "/api/v1/recordings", {}, corrupt, "application/gzip", &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find("corrupt gzip data in the recording "
                                                          "at byte "),
            std::string::npos)
      << e.dump();

  // Content-Encoding: gzip on a body that is not gzip.
  e = Post(server, "/api/v1/recordings", {{"Content-Encoding", "gzip"}}, csv, "text/csv", &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find("at byte 0"), std::string::npos);

  // A CSV error inside a compressed log names its line in the decompressed CSV.
  std::string bad = csv;
  const size_t line3 = bad.find('\n', bad.find('\n', bad.find('\n') + 1) + 1) + 1;
  bad.insert(line3, "x");
  e = Post(server, "/api/v1/recordings", {{"Content-Encoding", "gzip"}}, Gzip(bad), "text/csv",
           &status);
  EXPECT_EQ(status, 400) << e.dump();
  EXPECT_EQ(e["error"]["line"], 4) << e.dump();

  EXPECT_EQ(StagedUploads(server.dir()), 0);
  auto list = server.Client().Get("/api/v1/recordings/1");
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 404) << "a refused upload was stored";
}

TEST(GzipUpload, OtherEncodingsAndCompressedJsonOrMultipartBodiesAre415) {
  TestServer server;
  ASSERT_EQ(server.error(), "");
  int status = 0;
  for (const char* enc : {"br", "deflate", "compress", "gzip, br"}) {
    json e =
        Post(server, "/api/v1/recordings", {{"Content-Encoding", enc}}, "xx", "text/csv", &status);
    EXPECT_EQ(status, 415) << enc << " " << e.dump();
  }
  json e = Post(server, "/api/v1/jobs", {{"Content-Encoding", "gzip"}}, Gzip("{}"),
                "application/json", &status);
  EXPECT_EQ(status, 415) << e.dump();
  e = Post(server, "/api/v1/recordings", {{"Content-Encoding", "gzip"}}, Gzip("--x--\r\n"),
           "multipart/form-data; boundary=x", &status);
  EXPECT_EQ(status, 415) << e.dump();
  EXPECT_NE(e["error"]["message"].get<std::string>().find(".csv.gz"), std::string::npos);
}

}  // namespace
}  // namespace calibd::server
