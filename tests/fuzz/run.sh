#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan + UBSan) in build-fuzz/ and runs each for DURATION
# seconds (default 60) on a temporary copy of its committed corpus (tests/fuzz/corpus/<target>),
# so the repository is never modified. Exits non-zero when any target finds a crash, a sanitizer
# report, a broken invariant, a timeout or an out-of-memory; the reproducers are kept in
# build-fuzz/artifacts/ (replay one: build-fuzz/tests/fuzz/<target> <file>).
#
#   tests/fuzz/run.sh [DURATION]
#   CALIBD_FUZZ_TARGETS="fuzz_config fuzz_recording" tests/fuzz/run.sh 30
#   CALIBD_FUZZ_MERGE=1 tests/fuzz/run.sh 600   # also merge new coverage into the committed corpus
set -euo pipefail
cd "$(dirname "$0")/../.."
duration=${1:-60}
build=${CALIBD_FUZZ_BUILD_DIR:-build-fuzz}
targets=${CALIBD_FUZZ_TARGETS:-fuzz_recording fuzz_config fuzz_calibrate fuzz_multipart}

command -v clang++ >/dev/null && dpkg-query -W libclang-rt-14-dev >/dev/null 2>&1 ||
  { apt-get update -qq && apt-get install -y -qq clang libclang-rt-14-dev >/dev/null; }
CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCALIBD_FUZZ=ON \
  -DCALIBD_SANITIZE=address,undefined -DCALIBD_BUILD_TESTS=OFF -DCALIBD_BUILD_BENCH=OFF >/dev/null
# shellcheck disable=SC2086
cmake --build "$build" -j "$(nproc)" --target $targets

# Per target: the largest input, the time one input may take (ASan builds are slow).
max_len() {
  case $1 in
    fuzz_config) echo 4096 ;;
    fuzz_calibrate) echo 4096 ;;
    *) echo 16384 ;;
  esac
}

artifacts=$PWD/$build/artifacts
mkdir -p "$artifacts"
work=$(mktemp -d "${TMPDIR:-/tmp}/calibd-fuzz-run-XXXXXX")
trap 'rm -rf "$work"' EXIT
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

failed=()
for t in $targets; do
  corpus=$work/$t
  mkdir -p "$corpus"
  cp -r tests/fuzz/corpus/"$t"/. "$corpus"/
  echo "=== $t: ${duration} s, corpus $(find "$corpus" -type f | wc -l) files"
  status=0
  # TMPDIR: fuzz_multipart's server database lives there and goes away with $work.
  TMPDIR=$work "$build/tests/fuzz/$t" "$corpus" -max_total_time="$duration" \
    -max_len="$(max_len "$t")" -timeout=20 -rss_limit_mb=2560 -print_final_stats=1 \
    -artifact_prefix="$artifacts/$t-" -close_fd_mask=0 2>"$work/$t.log" || status=$?
  grep -E "^(stat::number_of_executed_units|stat::average_exec_per_sec|stat::peak_rss_mb)|#[0-9]+ +DONE" \
    "$work/$t.log" || true
  if [ $status -ne 0 ]; then
    failed+=("$t")
    echo "!!! $t found a problem (exit $status); log tail:"
    tail -n 60 "$work/$t.log"
  fi
  if [ "${CALIBD_FUZZ_MERGE:-0}" = 1 ] && [ $status -eq 0 ]; then
    "$build/tests/fuzz/$t" -merge=1 -max_len="$(max_len "$t")" tests/fuzz/corpus/"$t" "$corpus" \
      2>/dev/null
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: findings in ${failed[*]}; reproducers in $artifacts"
  ls -la "$artifacts"
  exit 1
fi
echo "fuzz: no findings ($targets, ${duration} s each)"
