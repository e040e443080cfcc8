// libFuzzer target: the incremental CSV parser (formats/recording.h) on arbitrary bytes.
//
// Input: byte 0 picks the chunking seed and, by its top two bits, the reading rules every parser
// gets (formats/csv_dialect.h): 0 calibd's CSV, 1 ';'-separated, 2 ';' with decimal commas, 3
// tab-separated with a column mapping (t ← time, a0_* ← ax.., g0_* ← gx..); the rest is the
// recording. The bytes are parsed four
// ways: whole by a collecting parser, whole by a collecting parser without the one-pass row
// reader (RecordingLimits::one_pass_rows = false), in pseudo-random chunks (1..64 bytes) by a
// collecting parser, and in other chunks by a validating (non-collecting) parser, as an upload is.
// Invariants: no crash or sanitizer report; the four give the same outcome (status code,
// message, line, column) and the same summary, and the one-pass and general readers collect
// bit-identical numbers; a failure is kInvalidInput or kTooLarge with a
// message, and a line > 0 unless the message is about the whole file; after success, Take*() of
// the summary's layout succeeds with dimensions matching the summary, the other layout fails
// cleanly, and every array number collected is finite (pca means may overflow; the
// calibration target covers what the methods make of that).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "formats/csv_dialect.h"
#include "formats/recording.h"

namespace {

using calibd::Status;
using calibd::StatusCode;
using calibd::server::ArrayRecording;
using calibd::server::Layout;
using calibd::server::PcaRecording;
using calibd::server::RecordingParser;
using calibd::server::RecordingSummary;

[[noreturn]] void Fail(const char* what, const Status& s) {
  std::fprintf(stderr, "fuzz_recording invariant broken: %s\n  status: %s\n", what,
               s.ToString().c_str());
  std::abort();
}

void Check(bool ok, const char* what, const Status& s = Status::Ok()) {
  if (!ok) Fail(what, s);
}

// Feeds `bytes` in chunks whose sizes come from a small LCG seeded by `seed` (0: one chunk).
Status Parse(std::string_view bytes, uint32_t seed, RecordingParser* parser) {
  if (seed == 0) {
    Status s = parser->Feed(bytes);
    if (!s.ok()) return s;
    return parser->Finish();
  }
  uint32_t state = seed;
  size_t pos = 0;
  while (pos < bytes.size()) {
    state = state * 1664525u + 1013904223u;
    const size_t n = 1 + (state >> 24) % 64;
    const std::string_view chunk = bytes.substr(pos, n);
    pos += chunk.size();
    Status s = parser->Feed(chunk);
    if (!s.ok()) {
      // Sticky: feeding more after an error returns the same error.
      Status again = parser->Feed("1,2,3\n");
      Check(again.code() == s.code() && again.message() == s.message() && again.line() == s.line(),
            "error is not sticky", again);
      return s;
    }
  }
  return parser->Finish();
}

bool SameStatus(const Status& a, const Status& b) {
  return a.code() == b.code() && a.message() == b.message() && a.line() == b.line() &&
         a.column() == b.column() && a.field() == b.field();
}

bool SameSummary(const RecordingSummary& a, const RecordingSummary& b) {
  return a.layout == b.layout && a.rows == b.rows && a.columns == b.columns &&
         a.sensors == b.sensors && a.positions == b.positions;
}

// The reading rules of input byte `b` (top two bits).
calibd::server::CsvDialect DialectOf(uint8_t b) {
  calibd::server::CsvDialect d;
  switch (b >> 6) {
    case 1:
      d.delimiter = ';';
      break;
    case 2:
      d.delimiter = ';';
      d.decimal = ',';
      break;
    case 3:
      d.delimiter = '\t';
      d.columns = {{"t", "time"},  {"a0_x", "ax"}, {"a0_y", "ay"}, {"a0_z", "az"},
                   {"g0_x", "gx"}, {"g0_y", "gy"}, {"g0_z", "gz"}};
      break;
    default:
      break;
  }
  return d;
}

bool AllFinite(const Eigen::MatrixXd& m) { return m.size() == 0 || m.allFinite(); }

template <typename A, typename B>
bool SameBits(const A& a, const B& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint32_t seed = data[0] | 1u;
  const std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);

  const calibd::server::CsvDialect dialect = DialectOf(data[0]);
  RecordingParser whole("fuzz.csv", /*collect=*/true);
  whole.SetCsvDialect(dialect);
  const Status s_whole = Parse(bytes, 0, &whole);
  calibd::server::RecordingLimits general_limits;
  general_limits.one_pass_rows = false;
  RecordingParser general("fuzz.csv", /*collect=*/true, general_limits);
  general.SetCsvDialect(dialect);
  const Status s_general = Parse(bytes, 0, &general);
  RecordingParser chunked("fuzz.csv", /*collect=*/true);
  chunked.SetCsvDialect(dialect);
  const Status s_chunked = Parse(bytes, seed, &chunked);
  RecordingParser validating("fuzz.csv", /*collect=*/false);
  validating.SetCsvDialect(dialect);
  const Status s_valid = Parse(bytes, seed * 7919u, &validating);

  Check(SameStatus(s_whole, s_general), "one-pass and general row readers disagree", s_general);
  Check(SameStatus(s_whole, s_chunked), "outcome depends on chunk boundaries", s_chunked);
  Check(SameStatus(s_whole, s_valid), "validating and collecting parsers disagree", s_valid);

  if (!s_whole.ok()) {
    Check(s_whole.code() == StatusCode::kInvalidInput || s_whole.code() == StatusCode::kTooLarge,
          "unexpected error code", s_whole);
    Check(!s_whole.message().empty(), "error without a message", s_whole);
    Check(s_whole.line() >= 0 && s_whole.column() >= 0, "negative error location", s_whole);
    Check(s_whole.message().size() < 4096, "error message echoes too much input", s_whole);
    return 0;
  }

  const RecordingSummary& sum = whole.summary();
  Check(SameSummary(sum, general.summary()), "one-pass and general summaries differ");
  Check(SameSummary(sum, chunked.summary()), "summary depends on chunk boundaries");
  Check(SameSummary(sum, validating.summary()), "validating summary differs");
  Check(sum.rows >= 0 && sum.positions >= 0, "negative counts");

  if (sum.layout == Layout::kArray) {
    ArrayRecording rec;
    Status s = whole.TakeArray(&rec);
    Check(s.ok(), "TakeArray failed after a successful array parse", s);
    Check(rec.accel.rows() == sum.rows && rec.gyro.rows() == sum.rows, "array row count", s);
    Check(rec.accel.cols() == 3 * static_cast<Eigen::Index>(rec.accel_names.size()),
          "accel columns");
    Check(rec.gyro.cols() == 3 * static_cast<Eigen::Index>(rec.gyro_names.size()), "gyro columns");
    Check(rec.t.size() == 0 || rec.t.size() == sum.rows, "t length");
    Check(AllFinite(rec.accel) && AllFinite(rec.gyro) && (rec.t.size() == 0 || rec.t.allFinite()),
          "non-finite number collected");
    ArrayRecording by_general;
    Check(general.TakeArray(&by_general).ok(), "TakeArray of the general reader failed");
    Check(SameBits(rec.accel, by_general.accel) && SameBits(rec.gyro, by_general.gyro) &&
              SameBits(rec.t, by_general.t),
          "one-pass and general readers collected different numbers");
    PcaRecording wrong;
    s = chunked.TakePca(&wrong);
    Check(!s.ok() && !s.message().empty(), "TakePca of an array recording did not fail cleanly", s);
  } else {
    PcaRecording rec;
    Status s = whole.TakePca(&rec);
    Check(s.ok(), "TakePca failed after a successful pca parse", s);
    const auto m = static_cast<Eigen::Index>(rec.sensor_names.size());
    const auto n = static_cast<Eigen::Index>(rec.position_labels.size());
    Check(rec.readings.rows() == m && rec.readings.cols() == n, "pca readings shape", s);
    Check(n == sum.positions, "pca positions count");
    Check(rec.rows_per_position.size() == static_cast<size_t>(n), "rows_per_position size");
    Check(rec.raw == (sum.layout == Layout::kPcaRaw), "raw flag");
    PcaRecording by_general;
    Check(general.TakePca(&by_general).ok(), "TakePca of the general reader failed");
    Check(SameBits(rec.readings, by_general.readings) &&
              SameBits(rec.static_means, by_general.static_means) &&
              rec.position_labels == by_general.position_labels &&
              rec.rows_per_position == by_general.rows_per_position,
          "one-pass and general readers collected different numbers");
    ArrayRecording wrong;
    s = chunked.TakeArray(&wrong);
    Check(!s.ok() && !s.message().empty(), "TakeArray of a pca recording did not fail cleanly", s);
  }
  return 0;
}
