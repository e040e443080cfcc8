// Helpers shared by the storage tests: temporary folders, a fake clock, deterministic bytes.
#ifndef CALIBD_TESTS_STORAGE_STORAGE_TEST_UTIL_H_
#define CALIBD_TESTS_STORAGE_STORAGE_TEST_UTIL_H_

#include <stdlib.h>

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <random>
#include <string>

namespace calibd::storage::testing {

// A fresh folder under $TMPDIR (or /tmp), removed with its contents on destruction.
class TempDir {
 public:
  TempDir() {
    const char* base = getenv("TMPDIR");
    std::string templ = std::string(base != nullptr ? base : "/tmp") + "/calibd-storage-XXXXXX";
    char* made = mkdtemp(templ.data());
    path_ = made != nullptr ? made : "";
  }
  ~TempDir() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// A clock the test moves by hand (thread-safe).
class FakeClock {
 public:
  explicit FakeClock(int64_t start_ms = 1'790'000'000'000) : now_(start_ms) {}
  int64_t Now() const { return now_.load(); }
  void Advance(int64_t ms) { now_ += ms; }
  std::function<int64_t()> Fn() {
    return [this] { return now_.load(); };
  }

 private:
  std::atomic<int64_t> now_;
};

// n pseudo-random bytes (all 256 values, including NUL), fixed by seed.
inline std::string RandomBytes(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (size_t i = 0; i < n; ++i) s[i] = static_cast<char>(rng() & 0xff);
  return s;
}

}  // namespace calibd::storage::testing

#endif  // CALIBD_TESTS_STORAGE_STORAGE_TEST_UTIL_H_
