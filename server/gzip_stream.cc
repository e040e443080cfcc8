#include "server/gzip_stream.h"

#include <zlib.h>

#include <cstdio>
#include <vector>

namespace calibd::server {

namespace {
constexpr size_t kOutputBuffer = 64 << 10;
constexpr const char* kSinkStoppedMessage = "gzip sink stopped";

std::string Bytes(int64_t n) { return std::to_string(n); }
std::string Ratio(double r) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", r);
  return buf;
}
}  // namespace

bool LooksLikeGzip(const char* data, size_t len) {
  return len >= 2 && static_cast<unsigned char>(data[0]) == 0x1f &&
         static_cast<unsigned char>(data[1]) == 0x8b;
}

struct GzipInflater::State {
  z_stream zs{};
  bool initialized = false;
  std::vector<char> out = std::vector<char>(kOutputBuffer);
};

GzipInflater::GzipInflater(GzipLimits limits, std::string what)
    : state_(std::make_unique<State>()), limits_(limits), what_(std::move(what)) {
  // 16 + MAX_WBITS: gzip wrapper only (zlib checks the header, CRC-32 and length).
  state_->initialized = inflateInit2(&state_->zs, 16 + MAX_WBITS) == Z_OK;
}

GzipInflater::~GzipInflater() {
  if (state_->initialized) inflateEnd(&state_->zs);
}

Status GzipInflater::SinkStopped() { return Status(StatusCode::kConflict, kSinkStoppedMessage); }

bool GzipInflater::IsSinkStopped(const Status& s) {
  return s.code() == StatusCode::kConflict && s.message() == kSinkStoppedMessage;
}

Status GzipInflater::Feed(const char* data, size_t len, const Sink& sink) {
  if (!state_->initialized) return Status::Internal("zlib could not be initialised");
  if (failed_) return Status::InvalidInput("gzip stream already failed");
  z_stream& zs = state_->zs;
  zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(data));
  zs.avail_in = static_cast<uInt>(len);
  auto offset = [&] { return compressed_ + static_cast<int64_t>(len - zs.avail_in); };
  // The magic bytes, checked here so that data that is not gzip at all is named as such.
  for (size_t i = 0; i < len && compressed_ + static_cast<int64_t>(i) < 2; ++i) {
    const unsigned char expected = compressed_ + static_cast<int64_t>(i) == 0 ? 0x1f : 0x8b;
    if (static_cast<unsigned char>(data[i]) != expected) {
      failed_ = true;
      return Status::InvalidInput(what_ +
                                  " is not gzip data: it does not start with the gzip magic "
                                  "bytes 1f 8b (at byte 0)");
    }
  }
  Status result;
  bool output_pending = false;  // the last inflate filled the buffer: it may hold more
  while (zs.avail_in > 0 || output_pending) {
    if (member_ended_) {
      if (zs.avail_in == 0) break;
      // Another member may follow (gzip files may be concatenated); anything else is an error.
      if (static_cast<unsigned char>(*zs.next_in) != 0x1f) {
        result =
            Status::InvalidInput("unexpected data after the end of the gzip stream of " + what_ +
                                 " at byte " + Bytes(offset()) + " of the compressed data");
        break;
      }
      inflateReset(&zs);
      member_ended_ = false;
    }
    zs.next_out = reinterpret_cast<Bytef*>(state_->out.data());
    zs.avail_out = static_cast<uInt>(state_->out.size());
    const int ret = inflate(&zs, Z_NO_FLUSH);
    if (ret != Z_OK && ret != Z_STREAM_END && ret != Z_BUF_ERROR) {
      const std::string why = zs.msg != nullptr ? zs.msg : "error " + std::to_string(ret);
      result = Status::InvalidInput("corrupt gzip data in " + what_ + " at byte " +
                                    Bytes(offset()) + " of the compressed data (" + why + ")");
      break;
    }
    const size_t produced = state_->out.size() - zs.avail_out;
    output_pending = zs.avail_out == 0;
    if (ret == Z_STREAM_END) member_ended_ = true;
    if (produced > 0) {
      decompressed_ += static_cast<int64_t>(produced);
      if (decompressed_ > limits_.max_output_bytes) {
        result = Status(StatusCode::kTooLarge, what_ + " decompresses to more than the limit of " +
                                                   Bytes(limits_.max_output_bytes) +
                                                   " bytes (--max-upload-bytes)");
        break;
      }
      if (decompressed_ > limits_.ratio_grace_bytes &&
          static_cast<double>(decompressed_) > limits_.max_ratio * static_cast<double>(offset())) {
        result = Status(StatusCode::kTooLarge,
                        what_ + " expands more than " + Ratio(limits_.max_ratio) + " times (" +
                            Bytes(decompressed_) + " bytes from " + Bytes(offset()) +
                            " compressed): refused as a decompression bomb (--max-gzip-ratio)");
        break;
      }
      if (!sink(state_->out.data(), produced)) {
        result = SinkStopped();
        break;
      }
    } else if (ret == Z_BUF_ERROR) {
      break;  // no progress possible: all input consumed into zlib's window
    }
  }
  compressed_ += static_cast<int64_t>(len);
  if (!result.ok()) failed_ = true;
  return result;
}

Status GzipInflater::Finish() {
  if (failed_) return Status::InvalidInput("gzip stream already failed");
  if (compressed_ == 0) return Status::InvalidInput(what_ + " is empty: no gzip data");
  if (!member_ended_) {
    return Status::InvalidInput("the gzip stream of " + what_ + " stops at byte " +
                                Bytes(compressed_) +
                                " before its end (a truncated upload or file?)");
  }
  return Status::Ok();
}

}  // namespace calibd::server
