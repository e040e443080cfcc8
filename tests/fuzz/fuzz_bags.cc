// libFuzzer target: the bag readers, ROS 1 (formats/rosbag1.h) and MCAP (formats/mcap.h), on
// arbitrary bytes.
//
// Input: the file; its magic picks the reader (anything else goes to both, which must refuse it).
// Seeds: small bags of python3-rosbag (uncompressed, bz2, lz4 chunks) and MCAP files of
// tests/formats/mcap_test.cc's writer (uncompressed, lz4, zstd chunks; big-endian CDR).
// Invariants: no crash, hang or sanitizer report; memory bounded by the limits (64 MB of
// decompressed chunks here); a failure is kInvalidInput with a message naming the file and a byte
// offset; after success the format is the reader's, every stream is a bag topic (instance -1) with
// StreamDimension values per time, within max_samples.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "formats/mcap.h"
#include "formats/rosbag1.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::LogFormat;
using calibd::server::SensorLog;
using calibd::server::SensorLogLimits;
using calibd::server::StreamDimension;

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_bags invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

// Reads `bytes` with `read` and checks the invariants above.
template <typename Reader>
void CheckReader(Reader read, std::string_view bytes, const char* format) {
  SensorLogLimits limits;
  limits.max_samples = 1'000'000;
  limits.max_decompressed_bytes = 64 << 20;
  SensorLog log;
  Status s = read(bytes, "fuzz.bag", limits, &log);
  if (!s.ok()) {
    Check(s.code() == StatusCode::kInvalidInput, "unexpected code", s);
    Check(s.message().find("fuzz.bag") != std::string::npos, "error does not name the file", s);
    Check(log.streams.empty(), "streams returned with an error", s);
    return;
  }
  Check(log.format == format, "wrong format");
  int64_t total = 0;
  for (const auto& stream : log.streams) {
    Check(stream.instance == -1, "a bag stream with an instance");
    Check(stream.samples() > 0, "an empty stream");
    Check(stream.values.size() ==
              static_cast<size_t>(stream.samples() * StreamDimension(stream.kind)),
          "values do not match the times");
    total += stream.samples();
  }
  Check(total <= limits.max_samples, "more samples than max_samples");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  const LogFormat format = calibd::server::SniffLogFormat(bytes);
  if (format != LogFormat::kMcap) CheckReader(calibd::server::ReadRosBag1, bytes, "rosbag1");
  if (format != LogFormat::kRosBag1) CheckReader(calibd::server::ReadMcap, bytes, "mcap");
  return 0;
}
