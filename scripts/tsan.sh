#!/usr/bin/env bash
# The threaded parts under ThreadSanitizer (clang), in build-tsan/: the storage, worker, HTTP and
# process tests, and then fuzz_multipart (a real server with request and worker threads) for
# $1 seconds (default 300) from a random seed. Not part of CI (the build alone takes minutes on
# 2 cores); run it after touching threads, locks or shutdown. Exits non-zero on any data race,
# lock-order inversion or test failure. Usage: scripts/tsan.sh [FUZZ_SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-300}
build=${CALIBD_TSAN_BUILD_DIR:-build-tsan}
# The test programs with threads in them (storage's group commit and two-process queue, the
# shared task pool, the HTTP front end, the server with its workers, kill -9 and SIGTERM of the
# real binary). Not storage_crash_test: it fork()s a writer from a threaded process and kills it,
# which ThreadSanitizer's runtime does not survive in the child (its output pipe breaks); the
# process tests cover kill -9 with exec'd servers instead.
tests=(storage_store_test storage_queue_concurrency_test core_task_pool_test
  server_http_api_test server_http_frontend_test server_hostile_http_test server_process_test
  server_imu_method_test server_noise_method_test server_worker_pool_test server_job_budget_test
  storage_pg_store_test server_pg_process_test server_storage_damage_test server_column_cache_test
  server_check_test)
scripts/setup.sh
# libFuzzer's -fsanitize=fuzzer is added per fuzz target by tests/fuzz/CMakeLists.txt.
CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" -DCALIBD_SANITIZE=thread -DCALIBD_FUZZ=ON \
  -DCALIBD_BUILD_TESTS=ON -DCALIBD_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" -j "$(nproc)" --target calibd fuzz_multipart "${tests[@]}"
# scripts/tsan.supp: the fuzz build's coverage counters, which every thread bumps by design.
export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/scripts/tsan.supp}
[ -x /usr/lib/llvm-14/bin/llvm-symbolizer ] && export TSAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
# The two-process queue test forks children that start threads; ThreadSanitizer does not support
# a forked child of a process it has instrumented (its report there names no real location:
# "global '__interceptor_pthread_create'", a thread "created" inside the test's own function), so
# that case runs in the Release and ASan suites only.
filter() { [ "$1" = storage_queue_concurrency_test ] && echo '--gtest_filter=-*TwoProcesses*' || echo '--gtest_filter=*'; }
for t in "${tests[@]}"; do
  echo "tsan.sh: $t"
  "$build/tests/$t" --gtest_brief=1 "$(filter "$t")"
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp -r tests/fuzz/corpus/fuzz_multipart/. "$work"/
"$build"/tests/fuzz/fuzz_multipart -max_total_time="$seconds" -max_len=16384 -timeout=30 \
  -rss_limit_mb=4096 "$work"
echo "tsan.sh: no data race in the tests or in ${seconds} s of fuzz_multipart"
