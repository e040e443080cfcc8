#!/usr/bin/env bash
# Configures and builds calibd in build/ (Release), through ccache when installed
# (scripts/ccache.sh). Extra arguments go to cmake --build.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/ccache.sh
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" >/dev/null
cmake --build build -j "$(nproc)" "$@"
