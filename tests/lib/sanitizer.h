// What the tests must know about the build they run in. AddressSanitizer builds (scripts/
// sanitize.sh) and ThreadSanitizer builds (scripts/tsan.sh) run 10 to 50 times slower and hold
// extra memory (shadow, quarantine, allocator caches). Tests that bound time or memory scale their
// bounds by these; the unsanitized build, which CI also runs, enforces the real bounds.
#ifndef CALIBD_TESTS_LIB_SANITIZER_H_
#define CALIBD_TESTS_LIB_SANITIZER_H_

namespace calibd::sanitizer {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

#if defined(__SANITIZE_THREAD__)
inline constexpr bool kThreadSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
inline constexpr bool kThreadSanitizer = true;
#else
inline constexpr bool kThreadSanitizer = false;
#endif
#else
inline constexpr bool kThreadSanitizer = false;
#endif

// Any sanitizer that slows the code and holds shadow memory (scripts/sanitize.sh, scripts/tsan.sh).
inline constexpr bool kSanitizer = kAddressSanitizer || kThreadSanitizer;

// Factor for memory bounds such as "RSS grows by < 64 MiB": ASan's own bookkeeping is not ours.
inline constexpr int kMemoryBoundScale = kThreadSanitizer ? 4 : kAddressSanitizer ? 2 : 1;

// Factor for wall-clock bounds on work the server does (not on timeouts it must honour).
inline constexpr double kTimeBoundScale = kSanitizer ? 2 : 1;

// Divisor for the work a test gives a job that must merely be running "for a while".
inline constexpr int kComputeSlowdown = kSanitizer ? 20 : 1;

}  // namespace calibd::sanitizer

#endif  // CALIBD_TESTS_LIB_SANITIZER_H_
