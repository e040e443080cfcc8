// Forwarding header: SHA-256 lives in the base library (base/sha256.h), shared by storage (stored
// recordings, result ETags) and server (uploads hashed while they stream).
#ifndef CALIBD_STORAGE_SHA256_H_
#define CALIBD_STORAGE_SHA256_H_

#include "base/sha256.h"

namespace calibd::storage {

using ::calibd::Sha256;
using ::calibd::Sha256Hex;

}  // namespace calibd::storage

#endif  // CALIBD_STORAGE_SHA256_H_
