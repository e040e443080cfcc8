// libFuzzer target: the PX4 ULog reader (formats/ulog.h) on arbitrary bytes.
//
// Input: the log itself (the seeds in corpus/fuzz_ulog are small logs of tests/lib/ulog_writer.h:
// sensor topics, fifo bursts, sensor_combined, nested formats, appended data).
// Invariants: no crash, hang or sanitizer report; a failure is kInvalidInput with the file name
// and a message naming the byte offset and message index (or saying it is not a ULog), and
// leaves the log empty; after success every stream has StreamDimension values per time, at most
// max_samples samples in all, and a time source; the log cut at a point derived from the input
// reads too (a cut is never an error) and no stream of it has more samples than the same
// stream of the whole log, nor other times.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>

#include "formats/ulog.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::ReadULog;
using calibd::server::SensorLog;
using calibd::server::SensorLogLimits;
using calibd::server::SensorStream;
using calibd::server::StreamDimension;

[[noreturn]] void Fail(const char* what, const Status& s) {
  std::fprintf(stderr, "fuzz_ulog invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (!ok) Fail(what, s);
}

constexpr int64_t kMaxSamples = 50'000;  // small, so that the limit is reached too

// Reads `bytes` and checks the invariants of one reading; returns its status.
Status ReadAndCheck(std::string_view bytes, SensorLog* log) {
  SensorLogLimits limits;
  limits.max_samples = kMaxSamples;
  const Status s = ReadULog(bytes, "fuzz.ulg", limits, log);
  if (!s.ok()) {
    Check(s.code() == StatusCode::kInvalidInput, "failure is not kInvalidInput", s);
    Check(s.file() == "fuzz.ulg", "failure without the file name", s);
    const std::string& m = s.message();
    Check(m.find("at byte ") != std::string::npos || m.find("not a ULog") != std::string::npos,
          "failure names no byte offset", s);
    Check(m.find("at byte ") == std::string::npos || m.find("(message ") != std::string::npos,
          "failure names no message index", s);
    Check(log->streams.empty() && log->warnings.empty(), "failure left a log", s);
    return s;
  }
  Check(log->format == "ulog", "format is not ulog", s);
  int64_t total = 0;
  for (const SensorStream& stream : log->streams) {
    Check(stream.samples() > 0, "an empty stream", s);
    Check(static_cast<int64_t>(stream.values.size()) ==
              stream.samples() * StreamDimension(stream.kind),
          "values do not match the times", s);
    Check(!stream.time_source.empty() && !stream.topic.empty(), "unnamed stream or time", s);
    total += stream.samples();
  }
  Check(total <= kMaxSamples, "more samples than max_samples", s);
  return s;
}

const SensorStream* Find(const SensorLog& log, const SensorStream& like) {
  for (const SensorStream& s : log.streams)
    if (s.Name() == like.Name() && s.kind == like.kind) return &s;
  return nullptr;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  SensorLog whole;
  if (!ReadAndCheck(bytes, &whole).ok() || size < 17) return 0;
  // A cut somewhere after the header, chosen by the input's last byte.
  const size_t cut = 16 + (static_cast<size_t>(data[size - 1]) * (size - 16)) / 256;
  SensorLog part;
  const Status s = ReadAndCheck(bytes.substr(0, cut), &part);
  Check(s.ok(), "a cut log is an error though the whole log reads", s);
  for (const SensorStream& stream : part.streams) {
    const SensorStream* same = Find(whole, stream);
    if (same == nullptr) continue;  // another source chosen for the shorter log
    Check(stream.samples() <= same->samples(), "a cut log has more samples", s);
    for (int64_t i = 0; i < stream.samples(); ++i)
      if (stream.t_ns[i] != same->t_ns[i] && stream.time_source == same->time_source)
        Fail("a cut log has other times", s);
  }
  return 0;
}
