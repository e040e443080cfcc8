#!/usr/bin/env bash
# Configures and builds the sanitizer build in build-sanitize/ (or $CALIBD_SANITIZE_BUILD_DIR):
# clang, AddressSanitizer + UndefinedBehaviorSanitizer, -O1, no NDEBUG (assert() and Eigen's index
# checks are on), libraries instrumented for coverage so that the same directory holds both the
# sanitized test suite (scripts/sanitize.sh) and the libFuzzer targets (tests/fuzz/run.sh). The
# test programs' own files at -O0 (CALIBD_TEST_COMPILE_OPTIONS): they are set-up and assertions
# around the libraries' code, and compile 2.5 times faster so (bench/README.md, "CI time").
# core's tests are not built here: they are numerics, and CI runs every one of them in the Release
# build (tests/CMakeLists.txt, CALIBD_TEST_LAYERS); the core code runs under the sanitizers in
# every other layer's tests and in the fuzz targets. Through ccache when installed
# (scripts/ccache.sh). Extra arguments go to cmake --build (e.g. --target fuzz).
set -euo pipefail
cd "$(dirname "$0")/.."
build=${CALIBD_SANITIZE_BUILD_DIR:-build-sanitize}
source scripts/ccache.sh
CC=clang CXX=clang++ cmake -S . -B "$build" -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" -DCALIBD_SANITIZE=address,undefined -DCALIBD_FUZZ=ON \
  -DCALIBD_TEST_COMPILE_OPTIONS=-O0 -DCALIBD_BUILD_TESTS=ON -DCALIBD_BUILD_BENCH=OFF \
  "-DCALIBD_TEST_LAYERS=base;storage;results;formats;methods;web;server" "${launcher[@]}" >/dev/null
cmake --build "$build" -j "$(nproc)" "$@"
