// Helpers shared by the Store backends (sqlite_store.cc, pg_store.cc). Not a public interface.
#ifndef CALIBD_STORAGE_STORE_INTERNAL_H_
#define CALIBD_STORAGE_STORE_INTERNAL_H_

#include <cstddef>
#include <cstdint>
#include <string>

#include "storage/store.h"

namespace calibd::storage::internal {

// Recording bytes move in chunks of at most this size (streaming unit, 1 MiB).
inline constexpr size_t kChunkBytes = 1 << 20;

int64_t SystemNowMs();
// Whether `text` parses as a JSON array.
bool IsJsonArray(const std::string& text);
// One of "queued", "running", "succeeded", "failed".
bool IsValidStatus(const std::string& status);
// Back-off after the n-th transient failure: min(base * 2^(n-1), max) (StoreOptions).
int64_t Backoff(const StoreOptions& o, int64_t failures);
// The acceptance gate's verdict of a result: "rejected" when the JSON's verdict.status is
// "rejected", else "accepted" (no verdict, or not JSON, included).
std::string VerdictOf(const std::string& result_json);
// Validates a JobFilter's status and state (kInvalidInput naming the field).
Status ValidateFilter(const JobFilter& f);

}  // namespace calibd::storage::internal

#endif  // CALIBD_STORAGE_STORE_INTERNAL_H_
