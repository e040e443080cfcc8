#!/usr/bin/env bash
# The test suite under AddressSanitizer + UndefinedBehaviorSanitizer (clang), in build-sanitize/
# (scripts/build-sanitize.sh), including a replay of every committed fuzz corpus. Part of
# scripts/test.sh. Usage: scripts/sanitize.sh [extra ctest args]. Exits non-zero on any failure
# or sanitizer report.
#
# Not built here: core's tests (scripts/build-sanitize.sh), every one of which CI runs in the
# Release build; the core code runs here in the methods', server's and fuzz tests.
# Left out, because their subject is statistics or timing, which the Release build checks, while
# the code they run is run here by other tests:
#   - the Monte-Carlo chain over boards (CalibrationChain.ArrayReachesTheCramerRaoBound...) and
#     the array and mag plans' sweeps against simulated fits (below);
#   - browser_pages (its time is Chromium's; every page's rendering runs here in the web tests)
#     and the StopProcess timing test (a job of several seconds made of BCD sweeps, 143 s under
#     ASan; the other StopProcess tests run the same shutdown code here).
# CALIBD_SANITIZE_EXCLUDE='^$' runs everything.
#
# CALIBD_FUZZ_FOLLOWS=1 (scripts/test.sh) also leaves out the replays of the committed fuzz corpora
# (fuzz_corpus.*, 100 s): tests/fuzz/run.sh, which runs next, executes every corpus file first
# (all of them fit its -max_len) with the same binaries and checks.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${CALIBD_SANITIZE_BUILD_DIR:-build-sanitize}
start=$(date +%s)
scripts/setup.sh
scripts/build-sanitize.sh
built=$(date +%s)
# A small quarantine: the RSS-bound tests (HostileHttp, HttpApiLimits) would otherwise count the
# 256 MB of freed memory ASan holds back.
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1:quarantine_size_mb=16:thread_local_quarantine_size_kb=256
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# Readable stack traces in reports (Debian installs the symbolizer under a versioned name).
[ -x /usr/lib/llvm-14/bin/llvm-symbolizer ] && export ASAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
slow='^(CalibrationChain\.ArrayReachesTheCramerRaoBoundOnlyWithTheCalibration'
slow+='|StopProcess\.SigtermPastTheGraceStopsTheJobExitsWithinOneSecondAndTheRestartCompletesIt'
slow+='|browser_pages'
# The plans' Monte-Carlo sweeps against simulated fits (70-115 s each here, 1-5 s in Release, which
# runs them: tests/CMakeLists.txt release_test_executables); the plans' code runs here in their
# other tests (ArrayPlanTest.SigmaMatches..., ArrayFullPlanTest.AMotionAboutOneAxis..., whose
# suggestion runs the full model's predictions, MagPlanTest.Suggestion..., the errors).
slow+='|ArrayPlanTest\.(ReplayCapKeepsTheInformation|SuggestionMeetsTheLimit)'
slow+='|ArrayFullPlanTest\.(SigmaMatchesCalibrationsOfTheProtocol|TheCappedReplayKeepsTheProtocolsInformation|TheSuggestionIsTheShortestProtocolMeetingTheLimits)'
slow+='|MagPlanTest\.(SigmaMatchesWhatTheMethodReportsOnTheProtocol|TurnsAboutOneAxisNameTheMissingDirection))$'
[ "${CALIBD_FUZZ_FOLLOWS:-0}" = 1 ] && slow+='|^fuzz_corpus\.'
exclude=${CALIBD_SANITIZE_EXCLUDE:-$slow}
args=(--output-on-failure -j "$(nproc)")
[ -n "$exclude" ] && args+=(-E "$exclude")
status=0
(cd "$build" && ctest "${args[@]}" "$@") || status=$?
end=$(date +%s)
echo "sanitize.sh: build $((built - start)) s, tests $((end - built)) s, total $((end - start)) s"
exit $status
