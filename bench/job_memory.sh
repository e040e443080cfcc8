#!/usr/bin/env bash
# The server's peak memory for one job: a fresh `calibd serve --workers 1` on a temporary
# database, one upload of DIR/recording.csv with DIR/config.json (as `calibd simulate` writes
# them), and the server's VmHWM after the upload and after the job.
#   bench/job_memory.sh DIR        e.g. after build/calibd simulate array --out /tmp/a100k --samples 100000
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:?usage: bench/job_memory.sh DIR}
bin=${CALIBD_BIN:-build/calibd}
# shellcheck source=tests/lib/serve.sh
. tests/lib/serve.sh
tmp=$(mktemp -d "${TMPDIR:-/tmp}/calibd-mem-XXXXXX")
trap 'stop_calibd; rm -rf "$tmp"' EXIT
start_calibd "$bin" --workers 1
hwm() { sed -n 's/^VmHWM:[[:space:]]*\([0-9]*\) kB/\1/p' "/proc/$server_pid/status"; }
echo "server at start: $(($(hwm) / 1024)) MiB"
curl -sf -F "recording=@$dir/recording.csv" -F "config=@$dir/config.json" \
  "$base/api/v1/recordings?device=BENCH" >"$tmp/upload.json"
job=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["job"]["id"])' "$tmp/upload.json")
echo "after the upload: $(($(hwm) / 1024)) MiB"
until curl -sf "$base/api/v1/jobs/$job" | grep -q '"status": "\(succeeded\|failed\)"'; do sleep 0.2; done
curl -sf "$base/api/v1/jobs/$job" | python3 -c '
import datetime, json, sys
j = json.load(sys.stdin)
def t(s): return datetime.datetime.fromisoformat(s.replace("Z", "+00:00"))
ran = (t(j["finished_at"]) - t(j["started_at"])).total_seconds() if j.get("started_at") else float("nan")
print("job", j["status"], "ran %.2f s (started_at to finished_at: parse and method)" % ran,
      (j.get("error") or {}).get("message", ""))'
echo "after the job: $(($(hwm) / 1024)) MiB"
