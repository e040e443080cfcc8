// A clock-skew shim for the clock tests (tests/storage/clock_test.cc): loaded with LD_PRELOAD, it
// shifts the wall clock of the process by CALIBD_CLOCK_SKEW_MS milliseconds (signed: -600000 is a
// host 10 minutes behind), as a host whose clock disagrees with the others would see it.
//
// Shifted: clock_gettime(CLOCK_REALTIME, CLOCK_REALTIME_COARSE), gettimeofday(), time() (the calls
// std::chrono::system_clock, SQLite and libc's date functions make). Not shifted: the monotonic
// clocks (CLOCK_MONOTONIC, CLOCK_BOOTTIME, ...), which a skewed host still runs at the right rate.
// Unset or empty: no shift. A value that is not an integer number of milliseconds (or beyond
// +-10 years) ends the process at load with exit status 86 and a message naming the variable and
// the value, so that a test never runs unshifted by mistake.
#include <dlfcn.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

namespace {

using ClockGettimeFn = int (*)(clockid_t, struct timespec*);

int64_t skew_ns = 0;
ClockGettimeFn real_clock_gettime = nullptr;

__attribute__((constructor)) void CalibdClockSkewInit() {
  real_clock_gettime = reinterpret_cast<ClockGettimeFn>(dlsym(RTLD_NEXT, "clock_gettime"));
  if (real_clock_gettime == nullptr) {
    fprintf(stderr, "calibd clock skew shim: no clock_gettime after the shim: %s\n", dlerror());
    _exit(86);
  }
  const char* text = getenv("CALIBD_CLOCK_SKEW_MS");
  if (text == nullptr || text[0] == '\0') return;
  char* end = nullptr;
  errno = 0;
  const long long ms = strtoll(text, &end, 10);
  const long long kTenYearsMs = 10LL * 366 * 24 * 3600 * 1000;
  if (errno != 0 || end == text || *end != '\0' || ms > kTenYearsMs || ms < -kTenYearsMs) {
    fprintf(stderr,
            "calibd clock skew shim: CALIBD_CLOCK_SKEW_MS=\"%s\" is not a whole number of "
            "milliseconds within +-10 years (e.g. -600000 for 10 minutes behind)\n",
            text);
    _exit(86);
  }
  skew_ns = static_cast<int64_t>(ms) * 1000000;
}

void Shift(struct timespec* ts) {
  int64_t ns = static_cast<int64_t>(ts->tv_sec) * 1000000000 + ts->tv_nsec + skew_ns;
  int64_t sec = ns / 1000000000;
  int64_t rem = ns % 1000000000;
  if (rem < 0) {
    rem += 1000000000;
    sec -= 1;
  }
  ts->tv_sec = static_cast<time_t>(sec);
  ts->tv_nsec = static_cast<long>(rem);
}

int RealNow(clockid_t id, struct timespec* ts) {
  if (real_clock_gettime == nullptr) CalibdClockSkewInit();  // called before the constructor ran
  return real_clock_gettime(id, ts);
}

}  // namespace

extern "C" {

int clock_gettime(clockid_t id, struct timespec* ts) __THROW {
  const int rc = RealNow(id, ts);
  if (rc == 0 && ts != nullptr && (id == CLOCK_REALTIME || id == CLOCK_REALTIME_COARSE)) Shift(ts);
  return rc;
}

int gettimeofday(struct timeval* __restrict tv, void* __restrict tz) __THROW {
  (void)tz;  // obsolete; glibc fills it with zeros, callers do not read it
  if (tv == nullptr) return 0;
  struct timespec ts;
  const int rc = clock_gettime(CLOCK_REALTIME, &ts);
  if (rc != 0) return rc;
  tv->tv_sec = ts.tv_sec;
  tv->tv_usec = ts.tv_nsec / 1000;
  return 0;
}

time_t time(time_t* out) __THROW {
  struct timespec ts;
  if (clock_gettime(CLOCK_REALTIME, &ts) != 0) return static_cast<time_t>(-1);
  if (out != nullptr) *out = ts.tv_sec;
  return ts.tv_sec;
}

}  // extern "C"
