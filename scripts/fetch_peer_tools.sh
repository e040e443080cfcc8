#!/usr/bin/env bash
# Installs the peers' readers some tests compare calibd with, outside the repository (never
# committed, not run by CI or scripts/test.sh; the tests that need them skip when they are absent):
#   node packages (tests/formats/bag_peer_test.cc, tests/formats/bag_reference.js): foxglove's
#   @mcap/core (MCAP), lz4js (its lz4 chunks), sql.js (SQLite in WebAssembly, for ROS 2 .db3),
#   @foxglove/rosmsg and @foxglove/rosmsg2-serialization (CDR of sensor_msgs/msg/Imu), into
#   $CALIBD_NODE_DIR (default /work/data/node; the tests read $CALIBD_NODE_MODULES, default
#   /work/data/node/node_modules). Needs node and npm (Debian: apt-get install -y nodejs npm)
#   and the npm registry.
# pyulog and pymavlink (the ULog and DataFlash comparisons) come from snapshots of their
# repositories (README.md, the ULog and DataFlash sections: CALIBD_PYULOG_PATH, CALIBD_PYMAVLINK).
set -euo pipefail
dir=${CALIBD_NODE_DIR:-/work/data/node}
command -v npm >/dev/null || { echo "fetch_peer_tools: npm not found (apt-get install -y nodejs npm)" >&2; exit 2; }
mkdir -p "$dir"
cd "$dir"
[ -f package.json ] || echo '{"private": true}' > package.json
npm install --no-audit --no-fund @mcap/core@2 lz4js sql.js @foxglove/rosmsg \
  @foxglove/rosmsg2-serialization@3
echo "fetch_peer_tools: installed into $dir/node_modules"
