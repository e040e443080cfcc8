#!/usr/bin/env bash
# The threaded parts under ThreadSanitizer (clang), in build-tsan/: the storage, worker, HTTP and
# process tests, and then fuzz_multipart (a real server with request and worker threads) for
# $1 seconds (default 300) from a random seed. Not part of CI (the build alone is ~6 minutes on
# 2 cores); run it after touching threads, locks or shutdown. Exits non-zero on any data race,
# lock-order inversion or test failure. Usage: scripts/tsan.sh [FUZZ_SECONDS] [ctest -R regex]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-300}
regex=${2:-'^(StoreTest|Db|QueueConcurrency|Crash|TaskPool|HttpApi|HttpApiSecurity|HttpApiLimits|HttpApiAuth|Smuggling|Frontend|FrontendLimits|HostileHttp|ServeProcess|ImuMethod|NoiseMethod)\.'}
build=${CALIBD_TSAN_BUILD_DIR:-build-tsan}
scripts/setup.sh
# libFuzzer's -fsanitize=fuzzer is added per fuzz target by tests/fuzz/CMakeLists.txt.
CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" -DCALIBD_SANITIZE=thread -DCALIBD_FUZZ=ON \
  -DCALIBD_BUILD_TESTS=ON -DCALIBD_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" -j "$(nproc)"
export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1}
[ -x /usr/lib/llvm-14/bin/llvm-symbolizer ] && export TSAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
(cd "$build" && ctest --output-on-failure -j "$(nproc)" -R "$regex")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp -r tests/fuzz/corpus/fuzz_multipart/. "$work"/
"$build"/tests/fuzz/fuzz_multipart -max_total_time="$seconds" -max_len=16384 -timeout=30 \
  -rss_limit_mb=4096 "$work"
echo "tsan.sh: no data race in the tests or in ${seconds} s of fuzz_multipart"
