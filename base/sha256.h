// Incremental SHA-256 (OpenSSL EVP), for recordings streamed in chunks (stored and uploaded)
// and result ETags.
//
// Thread-compatible: one Sha256 per thread.
#ifndef CALIBD_BASE_SHA256_H_
#define CALIBD_BASE_SHA256_H_

#include <string>
#include <string_view>

struct evp_md_ctx_st;

namespace calibd {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Update(std::string_view bytes);
  // Lower-case hex digest (64 characters). Call once; the object is then reset for reuse.
  std::string HexDigest();

 private:
  evp_md_ctx_st* ctx_;
};

// Lower-case hex SHA-256 of `bytes`.
std::string Sha256Hex(std::string_view bytes);

}  // namespace calibd

#endif  // CALIBD_BASE_SHA256_H_
