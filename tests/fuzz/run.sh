#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan + UBSan) in build-sanitize/ (scripts/build-sanitize.sh)
# and runs each, $CALIBD_FUZZ_JOBS at a time (default: the number of cores), on a temporary copy
# of its committed corpus (tests/fuzz/corpus/<target>), so the repository is never modified.
#   Without DURATION (CI): a fixed budget of inputs per target (about 30 s each on this
#   machine) from a fixed seed, so two CI runs of one commit try the same inputs: CI cannot pass
#   or fail by luck. (fuzz_multipart's server threads make its coverage feedback, and so its later
#   inputs, depend a little on timing.)
#   With DURATION: that many seconds per target from a random seed, to explore. Part of scripts/test.sh. Exits non-zero when any target finds
# a crash, a sanitizer report, a broken invariant, a timeout or an out-of-memory; the reproducers
# are kept in build-sanitize/artifacts/. A finding becomes a regression test by adding its
# reproducer to the target's corpus: ctest replays every corpus file (fuzz_corpus.<target>).
#
#   tests/fuzz/run.sh [DURATION]
#   CALIBD_FUZZ_TARGETS="fuzz_config fuzz_recording" tests/fuzz/run.sh 30
#   CALIBD_FUZZ_MERGE=1 tests/fuzz/run.sh 600   # also merge new coverage into the committed corpus
#   build-sanitize/tests/fuzz/<target> <file>    # replay one input
set -euo pipefail
cd "$(dirname "$0")/../.."
duration=${1:-}
build=${CALIBD_SANITIZE_BUILD_DIR:-build-sanitize}
targets=${CALIBD_FUZZ_TARGETS:-fuzz_recording fuzz_config fuzz_calibrate fuzz_multipart fuzz_dataflash fuzz_ulog fuzz_bags}
jobs=${CALIBD_FUZZ_JOBS:-$(nproc)}

scripts/setup.sh
# shellcheck disable=SC2086
scripts/build-sanitize.sh --target $targets

# Per target, for the fixed budget: inputs to run (about 30 s each at the speeds measured in
# bench/README.md, two targets at a time on 2 cores) and the seed.
runs() {
  case $1 in
    fuzz_recording) echo 150000 ;;
    fuzz_config) echo 250000 ;;
    fuzz_calibrate) echo 10000 ;;
    fuzz_multipart) echo 3000 ;;
    fuzz_dataflash) echo 60000 ;;
    fuzz_ulog) echo 150000 ;;
    fuzz_bags) echo 150000 ;;
  esac
}

# Per target: the largest input.
max_len() {
  case $1 in
    fuzz_config | fuzz_calibrate) echo 4096 ;;
    fuzz_bags) echo 32768 ;;  # a ROS 1 bag's connection headers carry message definitions (4 KB)
    *) echo 16384 ;;
  esac
}

artifacts=$PWD/$build/artifacts
mkdir -p "$artifacts"
work=$(mktemp -d "${TMPDIR:-/tmp}/calibd-fuzz-run-XXXXXX")
trap 'rm -rf "$work"' EXIT
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
[ -x /usr/lib/llvm-14/bin/llvm-symbolizer ] && export ASAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer

# Fuzzes one target; its exit status goes to $work/<target>.status, its log to <target>.log.
fuzz_one() {
  local t=$1 corpus=$work/$1 status=0
  mkdir -p "$corpus" "$work/tmp-$t"
  cp -r tests/fuzz/corpus/"$t"/. "$corpus"/
  # -timeout: one input may take 20 s (ASan); TMPDIR: fuzz_multipart's server database.
  local budget
  if [ -n "$duration" ]; then
    budget=(-max_total_time="$duration")
  else
    # The time cap only guards against a machine far slower than expected.
    budget=(-runs="$(runs "$t")" -seed=20261123 -max_total_time=600)
  fi
  TMPDIR=$work/tmp-$t "$build/tests/fuzz/$t" "$corpus" "${budget[@]}" \
    -max_len="$(max_len "$t")" -timeout=20 -rss_limit_mb=2560 -print_final_stats=1 \
    -artifact_prefix="$artifacts/$t-" -close_fd_mask=0 >"$work/$t.log" 2>&1 || status=$?
  if [ "${CALIBD_FUZZ_MERGE:-0}" = 1 ] && [ $status -eq 0 ]; then
    TMPDIR=$work/tmp-$t "$build/tests/fuzz/$t" -merge=1 -max_len="$(max_len "$t")" \
      tests/fuzz/corpus/"$t" "$corpus" >>"$work/$t.merge.log" 2>&1
  fi
  echo $status >"$work/$t.status"
}

echo "fuzz: $targets, ${duration:-fixed budget,} ${duration:+s each,} $jobs at a time"
for t in $targets; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
  fuzz_one "$t" &
done
wait

failed=()
for t in $targets; do
  status=$(cat "$work/$t.status" 2>/dev/null || echo 1)
  echo "=== $t: corpus $(find tests/fuzz/corpus/"$t" -type f | wc -l) files, exit $status"
  grep -E "^(stat::number_of_executed_units|stat::average_exec_per_sec|stat::peak_rss_mb)|#[0-9]+ +DONE" \
    "$work/$t.log" || true
  if [ "$status" -ne 0 ]; then
    failed+=("$t")
    echo "!!! $t found a problem (exit $status); log tail:"
    tail -n 60 "$work/$t.log"
  fi
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: findings in ${failed[*]}; reproducers in $artifacts"
  ls -la "$artifacts"
  exit 1
fi
echo "fuzz: no findings ($targets)"
