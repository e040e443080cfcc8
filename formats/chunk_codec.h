// Decompression of log chunks (ROS bag bz2/lz4 chunks, MCAP lz4/zstd chunks) to a stated size.
#ifndef CALIBD_FORMATS_CHUNK_CODEC_H_
#define CALIBD_FORMATS_CHUNK_CODEC_H_

#include <cstdint>
#include <string>
#include <string_view>

namespace calibd::server {

enum class ChunkCodec { kBz2, kLz4Frame, kZstd };

// Decompresses `in` into `*out` (replaced); true when it decompresses to exactly `size` bytes
// and the stream ends there. The buffer grows with the real output (a stated size alone
// allocates nothing) to at most size + 1 bytes. Stateless, thread-safe.
bool DecompressExactly(ChunkCodec codec, std::string_view in, uint64_t size, std::string* out);

}  // namespace calibd::server

#endif  // CALIBD_FORMATS_CHUNK_CODEC_H_
