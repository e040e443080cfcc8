// libFuzzer target: the ArduPilot DataFlash reader (formats/dataflash.h) on arbitrary bytes.
//
// Input: the log. Read whole and cut (at 7/11 of its length, as a power-off cuts a log), with a
// small sample limit so that the limit's path is reached too. Invariants: no crash, hang or
// sanitizer report; a failure is kInvalidInput with a short message naming the file and leaves
// the log empty; after success every stream has samples, whole rows (values = samples ×
// dimension), a name and a time source, and the samples stay within the limit; when the whole log
// reads, the cut one reads too unless the cut leaves no whole FMT message, and never holds more
// samples in a stream.
//
// Seeds (tests/fuzz/corpus/fuzz_dataflash/): small logs of tests/lib/dataflash_writer.h — three
// IMUs with FMTU/UNIT/MULT/PARM and two MAGs, an older log (IMU2, TimeMS), ACC with SampleUS,
// batch sampler batches (ISBH/ISBD), junk between messages, and a cut log; and the reproducers
// of earlier findings (crash-*).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <string_view>

#include "formats/dataflash.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::SensorLog;
using calibd::server::SensorLogLimits;

[[noreturn]] void Fail(const char* what, const Status& s) {
  std::fprintf(stderr, "fuzz_dataflash invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (!ok) Fail(what, s);
}

void CheckOutcome(const Status& s, const SensorLog& log, const SensorLogLimits& limits) {
  if (!s.ok()) {
    Check(s.code() == StatusCode::kInvalidInput, "unexpected error code", s);
    Check(!s.message().empty() && s.message().size() < 1024, "error message empty or long", s);
    Check(s.file() == "fuzz.bin", "error does not name the file", s);
    Check(log.streams.empty() && log.warnings.empty(), "failure left a partial log", s);
    return;
  }
  Check(log.format == "dataflash", "format not dataflash");
  int64_t samples = 0;
  for (const auto& stream : log.streams) {
    const int dim = calibd::server::StreamDimension(stream.kind);
    Check(stream.samples() > 0, "empty stream");
    Check(stream.values.size() == stream.t_ns.size() * static_cast<size_t>(dim), "ragged stream");
    Check(!stream.topic.empty() && !stream.time_source.empty() && !stream.unit.empty(),
          "stream without topic, time source or unit");
    Check(stream.instance >= 0 && stream.instance < 256, "instance out of range");
    for (const int64_t t : stream.t_ns) Check(t >= 0, "negative time");
    samples += stream.samples();
  }
  Check(samples <= limits.max_samples, "more samples than the limit");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  SensorLogLimits limits;
  limits.max_samples = 20'000;
  SensorLog whole, cut;
  const Status s_whole = calibd::server::ReadDataFlash(bytes, "fuzz.bin", limits, &whole);
  CheckOutcome(s_whole, whole, limits);
  const Status s_cut =
      calibd::server::ReadDataFlash(bytes.substr(0, size * 7 / 11), "fuzz.bin", limits, &cut);
  CheckOutcome(s_cut, cut, limits);
  if (s_whole.ok() && !s_cut.ok())
    Check(s_cut.message().find("no FMT message") != std::string::npos,
          "the whole log reads but its cut fails", s_cut);
  if (s_whole.ok() && s_cut.ok()) {
    std::map<std::string, int64_t> samples;
    for (const auto& stream : whole.streams)
      samples[stream.Name() + calibd::server::StreamKindName(stream.kind)] = stream.samples();
    for (const auto& stream : cut.streams) {
      const auto found = samples.find(stream.Name() + calibd::server::StreamKindName(stream.kind));
      // A stream the whole log drops (its FMTU, read later, gives another unit) may be in the cut.
      if (found != samples.end())
        Check(stream.samples() <= found->second, "the cut log has more samples than the whole");
    }
  }
  return 0;
}
