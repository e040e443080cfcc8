#!/usr/bin/env bash
# The README's server command: installs dependencies, builds calibd, serves on the default
# SQLite file data/calibd.db at 127.0.0.1:8080. Extra arguments go to `calibd serve`.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh --target calibd
exec build/calibd serve "$@"
