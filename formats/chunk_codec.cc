// Chunk decompression to a stated size (formats/chunk_codec.h).
#include "formats/chunk_codec.h"

#include <bzlib.h>
#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <memory>

namespace calibd::server {
namespace {

// Grows *out towards `cap` as the decompressor fills it: memory follows the real output.
void Grow(std::string* out, size_t used, size_t cap) {
  out->resize(std::min<size_t>(cap, std::max<size_t>(used * 2, 64 << 10)));
}

// Each returns the bytes written to *out (sized >= them) and whether the stream ended.
bool Bz2(std::string_view in, size_t cap, std::string* out, size_t* used) {
  bz_stream bz{};
  if (BZ2_bzDecompressInit(&bz, 0, 0) != BZ_OK) return false;
  bz.next_in = const_cast<char*>(in.data());
  bz.avail_in = static_cast<unsigned>(std::min<size_t>(in.size(), 0xffffffffu));
  bool ended = false;
  for (;;) {
    if (*used == out->size()) {
      if (*used == cap) break;
      Grow(out, *used, cap);
    }
    bz.next_out = out->data() + *used;
    bz.avail_out = static_cast<unsigned>(std::min<size_t>(out->size() - *used, 1u << 30));
    const unsigned avail_out = bz.avail_out;
    int rc = BZ2_bzDecompress(&bz);
    *used += avail_out - bz.avail_out;
    ended = rc == BZ_STREAM_END;
    if (rc != BZ_OK || (bz.avail_in == 0 && bz.avail_out > 0)) break;  // end, error, cut
  }
  BZ2_bzDecompressEnd(&bz);
  return ended;
}

bool Lz4Frame(std::string_view in, size_t cap, std::string* out, size_t* used) {
  LZ4F_dctx* dctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&dctx, LZ4F_VERSION))) return false;
  std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> owner(
      dctx, &LZ4F_freeDecompressionContext);
  size_t in_pos = 0;
  for (;;) {
    if (*used == out->size()) {
      if (*used == cap) return false;
      Grow(out, *used, cap);
    }
    size_t out_n = out->size() - *used;
    size_t in_n = in.size() - in_pos;
    size_t hint =
        LZ4F_decompress(dctx, out->data() + *used, &out_n, in.data() + in_pos, &in_n, nullptr);
    *used += out_n;
    in_pos += in_n;
    if (hint == 0) return true;
    if (LZ4F_isError(hint) || (in_n == 0 && out_n == 0)) return false;
  }
}

bool Zstd(std::string_view in, size_t cap, std::string* out, size_t* used) {
  std::unique_ptr<ZSTD_DCtx, decltype(&ZSTD_freeDCtx)> dctx(ZSTD_createDCtx(), &ZSTD_freeDCtx);
  if (!dctx) return false;
  ZSTD_inBuffer input{in.data(), in.size(), 0};
  for (;;) {
    if (*used == out->size()) {
      if (*used == cap) return false;
      Grow(out, *used, cap);
    }
    ZSTD_outBuffer output{out->data(), out->size(), *used};
    size_t rc = ZSTD_decompressStream(dctx.get(), &output, &input);
    const bool progress = output.pos != *used;
    *used = output.pos;
    if (ZSTD_isError(rc)) return false;
    if (rc == 0) return input.pos == input.size;             // one frame, nothing after it
    if (!progress && input.pos == input.size) return false;  // cut
  }
}

}  // namespace

bool DecompressExactly(ChunkCodec codec, std::string_view in, uint64_t size, std::string* out) {
  out->clear();
  if (size >= (uint64_t{1} << 62)) return false;
  // Room for one byte more than stated, so that a chunk decompressing to more shows.
  const size_t cap = static_cast<size_t>(size) + 1;
  size_t used = 0;
  bool ended = false;
  switch (codec) {
    case ChunkCodec::kBz2:
      ended = Bz2(in, cap, out, &used);
      break;
    case ChunkCodec::kLz4Frame:
      ended = Lz4Frame(in, cap, out, &used);
      break;
    case ChunkCodec::kZstd:
      ended = Zstd(in, cap, out, &used);
      break;
  }
  out->resize(used);
  return ended && used == size;
}

}  // namespace calibd::server
