#!/usr/bin/env bash
# The whole test suite under AddressSanitizer + UndefinedBehaviorSanitizer (g++), in build-asan/.
# Usage: scripts/sanitize.sh [extra ctest args]. Exits non-zero on any failure or sanitizer report.
# The slowest statistical tests (Monte-Carlo coverage and accuracy sweeps of the methods, which
# only re-run the same arithmetic many times) are excluded to keep CI time bounded; every server,
# storage, parser, web and HTTP test runs.
set -euo pipefail
cd "$(dirname "$0")/.."
build=${CALIBD_ASAN_BUILD_DIR:-build-asan}
start=$(date +%s)
# -O1 -g1: g++ -O2 with ASan needs minutes and 3 GB per Eigen-heavy file; -O1 keeps the tests fast
# enough. No NDEBUG: assert() and Eigen's index checks are on too.
cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" \
  -DCALIBD_SANITIZE=address,undefined -DCALIBD_BUILD_BENCH=OFF >/dev/null
cmake --build "$build" -j "$(nproc)"
built=$(date +%s)
# A small quarantine: the RSS-bound tests (HostileHttp, HttpApiLimits: < 64 MiB growth) would
# otherwise count the 256 MB of freed memory ASan holds back.
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:strict_string_checks=1:detect_stack_use_after_return=1:quarantine_size_mb=16:thread_local_quarantine_size_kb=256
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
# Monte-Carlo / accuracy sweeps of the methods (1-2 min each under ASan, covered by the normal
# build); CALIBD_ASAN_EXCLUDE='^$' runs everything.
slow='^(ArrayCalibration\.(BcdRecoversPositionsExactlyWithoutNoise|BothSolversReachTheSameEstimate'
slow+='|RmseFallsAsInverseSquareRootOfN|EfficientAtTheCramerRaoBound.*|PaperHeadlineMicrometre.*)'
slow+='|PcaCalibration\.(MatchesReferenceMedianErrorOnPaperSetup|MedianError.*'
slow+='|ReportedUncertaintyMatchesMonteCarloSpread)'
slow+='|PcaBiasEstimate\.(MedianErrorIsProportionalToNoise|ReportedUncertainty.*'
slow+='|CostsLittleAccuracyOnBiasFreeData)|PcaRefine\.NeverWorseThanClosedForm.*)$'
exclude=${CALIBD_ASAN_EXCLUDE:-$slow}
args=(--output-on-failure -j "$(nproc)")
[ -n "$exclude" ] && args+=(-E "$exclude")
status=0
(cd "$build" && ctest "${args[@]}" "$@") || status=$?
end=$(date +%s)
echo "sanitize.sh: build $((built - start)) s, tests $((end - built)) s, total $((end - start)) s"
exit $status
