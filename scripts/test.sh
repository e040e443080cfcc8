#!/usr/bin/env bash
# The README's test command (and CI's, .ci/run): installs dependencies, then
#   1. builds in build/ (Release) calibd and the tests whose subject is
#      numerics or timing (ctest label *-release, tests/CMakeLists.txt: every core/ test, the
#      Monte-Carlo chain, real-data fits, shutdown timing, the walkthrough, browser and structure
#      scripts) and runs them;
#   2. builds everything but core's tests with clang + ASan + UBSan in build-sanitize/ and runs
#      the suite there (scripts/sanitize.sh; its exclusions are Monte-Carlo and timing tests that
#      step 1 runs), so every test runs at least once;
#   3. fuzzes each libFuzzer target with a fixed budget of inputs from a fixed seed (about 30 s
#      each), or for $CALIBD_FUZZ_SECONDS s each when that is set (tests/fuzz/run.sh).
# Both builds go through ccache (scripts/ccache.sh): from a cold cache the two builds of every
# library are most of the time (bench/README.md, "CI time"); with the machine's cache warm only
# what changed is compiled. The bench programs are not built here (scripts/build.sh without a
# target builds them, as the README's server command does).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
scripts/setup.sh
scripts/build.sh --target calibd_release_tests
(cd build && ctest --output-on-failure -j "$(nproc)" -L release)
normal=$(date +%s)
CALIBD_FUZZ_FOLLOWS=1 scripts/sanitize.sh
sanitized=$(date +%s)
tests/fuzz/run.sh ${CALIBD_FUZZ_SECONDS:-}
end=$(date +%s)
echo "test.sh: normal build + tests $((normal - start)) s, sanitizers $((sanitized - normal)) s," \
  "fuzzing $((end - sanitized)) s, total $((end - start)) s"
