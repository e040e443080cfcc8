// GzipInflater: decompresses a gzip stream (RFC 1952, one or more members) piece by piece, as an
// upload arrives, handing the decompressed bytes to a sink; never holds more than one 64 KiB
// output buffer. Guards against decompression bombs: the decompressed size is limited, and so is
// the expansion ratio (decompressed / compressed bytes consumed so far), so a small body cannot
// make the server write gigabytes before the size limit is reached.
//
// Errors (Status, for the HTTP answer):
//  - kTooLarge (413): the decompressed data passed GzipLimits::max_output_bytes, or expanded more
//    than GzipLimits::max_ratio; the message says which limit and its value.
//  - kInvalidInput (400): not gzip, corrupt data, or a stream that ends before its end
//    (Finish); the message names the byte offset in the compressed data.
// Thread-compatible; one object per stream.
#ifndef CALIBD_SERVER_GZIP_STREAM_H_
#define CALIBD_SERVER_GZIP_STREAM_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "base/status.h"

namespace calibd::server {

struct GzipLimits {
  int64_t max_output_bytes = int64_t{512} << 20;  // decompressed bytes in all; beyond: 413
  double max_ratio = 200;  // decompressed / compressed; beyond: 413 (a CSV log gives 3-20)
  // The ratio is checked only past this many decompressed bytes (tiny, very regular files may
  // expand more than max_ratio and are harmless).
  int64_t ratio_grace_bytes = int64_t{1} << 20;
};

// True when `data` starts with the gzip magic bytes 1f 8b.
bool LooksLikeGzip(const char* data, size_t len);

class GzipInflater {
 public:
  // Receives decompressed bytes; returns false to stop (Feed then returns kSinkStopped()).
  using Sink = std::function<bool(const char* data, size_t len)>;

  // `what` names the data in messages ("the recording").
  GzipInflater(GzipLimits limits, std::string what);
  ~GzipInflater();
  GzipInflater(const GzipInflater&) = delete;
  GzipInflater& operator=(const GzipInflater&) = delete;

  // Decompresses `len` more compressed bytes into `sink`. Returns Ok, an error (above), or
  // SinkStopped() when the sink returned false (the sink knows why).
  Status Feed(const char* data, size_t len, const Sink& sink);
  // The compressed data has ended: Ok only if the last gzip member ended (with its CRC-32 and
  // length checked by zlib); else a 400 naming the offset where the data stopped.
  Status Finish();

  static Status SinkStopped();
  static bool IsSinkStopped(const Status& s);

  int64_t compressed_bytes() const { return compressed_; }
  int64_t decompressed_bytes() const { return decompressed_; }

 private:
  struct State;
  std::unique_ptr<State> state_;
  GzipLimits limits_;
  std::string what_;
  int64_t compressed_ = 0;     // consumed by zlib, over all members
  int64_t decompressed_ = 0;   // handed to the sink
  bool member_ended_ = false;  // the last member ended; more bytes must start a new member
  bool failed_ = false;
};

}  // namespace calibd::server

#endif  // CALIBD_SERVER_GZIP_STREAM_H_
