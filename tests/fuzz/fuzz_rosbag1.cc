// libFuzzer target: the ROS 1 bag reader (formats/rosbag1.h) on arbitrary bytes.
//
// Input: the bag (the seeds are small bags of python3-rosbag, uncompressed, bz2 and lz4 chunks).
// Invariants: no crash, hang or sanitizer report; memory bounded by the limits (64 MB of
// decompressed chunks here); a failure is kInvalidInput with a message naming the file and a byte
// offset; after success the format is "rosbag1", every stream is a bag topic (instance -1) with
// StreamDimension values per time, within max_samples.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "formats/rosbag1.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::SensorLog;
using calibd::server::SensorLogLimits;
using calibd::server::StreamDimension;

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (ok) return;
  std::fprintf(stderr, "fuzz_rosbag1 invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  SensorLogLimits limits;
  limits.max_samples = 1'000'000;
  limits.max_decompressed_bytes = 64 << 20;
  SensorLog log;
  Status s = calibd::server::ReadRosBag1(bytes, "fuzz.bag", limits, &log);
  if (!s.ok()) {
    Check(s.code() == StatusCode::kInvalidInput, "unexpected code", s);
    Check(s.message().find("fuzz.bag") != std::string::npos, "error does not name the file", s);
    Check(log.streams.empty(), "streams returned with an error", s);
    return 0;
  }
  Check(log.format == "rosbag1", "format is not rosbag1");
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
  return 0;
}
