// A parsed array recording as a binary, columnar file (the parsed-columns cache of a stored
// recording, server/column_cache.h): the RecordingSummary and the ArrayRecording a parse gave,
// read back bit for bit in one pass at disk speed instead of parsing the CSV or log again.
//
// Layout (host byte order; a file of another byte order reads as damaged):
//   "calibd-columns\n" '\0'         16 bytes: magic
//   u32 0x01020304, u32 version     byte-order mark, kColumnFileVersion
//   u64 H                           header bytes
//   H bytes                         header: JSON text (the key, the summary with its doubles as
//                                   bit patterns, names, rows, data bytes)
//   u32 CRC-32 of the header
//   data                            t (N), accel (N × 3K), gyro (N × 3G), temperature (N × T),
//                                   mag (N × 3M): doubles, each matrix column-major (Eigen's)
//   u32 CRC-32 of the data
// The file's size must be exactly what the header says: a torn (cut) file, a flipped bit, a
// different key or version all read as kCorruption naming what, never as numbers.
#ifndef CALIBD_FORMATS_COLUMN_FILE_H_
#define CALIBD_FORMATS_COLUMN_FILE_H_

#include <cstdint>
#include <string>

#include "base/status.h"
#include "formats/recording.h"

namespace calibd::server {

// Bumped whenever the parser could give other numbers for the same bytes and rules, or the
// layout changes: files of another version are not read (and are rebuilt by the cache).
// 2: the magnetometers' device ids (mag_device_ids) in the header.
inline constexpr uint32_t kColumnFileVersion = 2;

// The longest header (names, the summary, the log's description) written or read.
inline constexpr uint64_t kMaxColumnFileHeaderBytes = uint64_t{16} << 20;

// What a file is of: the recording's bytes (their SHA-256) and the reading rules they were
// parsed with (any text that determines the parse, compared verbatim).
struct ColumnFileKey {
  std::string recording_sha256;
  std::string rules;
};

// Writes `log` (array layout) and `summary` atomically: to a new temporary file beside `path`,
// fsync'd, then renamed over `path` (and the folder fsync'd). After a crash `path` is either
// absent, the old file or the whole new one. kIoError naming the path (disk full, ...); the
// temporary file is removed on every error. kInvalidInput (nothing written) for a header over
// kMaxColumnFileHeaderBytes, which ReadColumnFile would refuse. *bytes (may be null): the file's
// size.
Status WriteColumnFile(const std::string& path, const ColumnFileKey& key,
                       const RecordingSummary& summary, const ArrayRecording& log,
                       int64_t* bytes = nullptr);

// Reads a file written by WriteColumnFile, verifying magic, version, byte order, key, sizes and
// both checksums. kNotFound: no file; kCorruption naming what does not hold (cut, checksum,
// other key or version); kIoError: the read failed. Outputs written only on OK.
Status ReadColumnFile(const std::string& path, const ColumnFileKey& expected,
                      RecordingSummary* summary, ArrayRecording* log);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_COLUMN_FILE_H_
