#!/usr/bin/env bash
# The README's test command (and CI's, .ci/run): installs dependencies, then
#   1. builds everything in build/ (Release) and runs every test;
#   2. builds again with clang + ASan + UBSan in build-sanitize/ and runs the suite there
#      (scripts/sanitize.sh), including a replay of the committed fuzz corpora;
#   3. fuzzes each libFuzzer target with a fixed budget of inputs from a fixed seed (about a minute
#      each), or for $CALIBD_FUZZ_SECONDS s each when that is set (tests/fuzz/run.sh).
# Over 30 minutes on 2 cores from a clean checkout today (README, "Tests and benchmarks": CI took
# 43 min; the builds are about half of it, with precompiled headers).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
scripts/setup.sh
scripts/build.sh
(cd build && ctest --output-on-failure -j "$(nproc)")
normal=$(date +%s)
CALIBD_FUZZ_FOLLOWS=1 scripts/sanitize.sh
sanitized=$(date +%s)
tests/fuzz/run.sh ${CALIBD_FUZZ_SECONDS:-}
end=$(date +%s)
echo "test.sh: normal build + tests $((normal - start)) s, sanitizers $((sanitized - normal)) s," \
  "fuzzing $((end - sanitized)) s, total $((end - start)) s"
