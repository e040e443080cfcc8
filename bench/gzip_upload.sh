#!/usr/bin/env bash
# A 2-hour 400 Hz log of one IMU (6 channels, 2.88 M rows, ~262 MB of CSV) uploaded to a fresh
# `calibd serve` end to end: gzip'd (Content-Encoding: gzip) and plain, each followed by its noise
# job. Prints the sizes, the upload time (curl's time_total: send + decompress + parse + hash +
# stage + commit), the job's run time, and the server's peak RSS (VmHWM) after the upload and
# after the job.
#
#   bench/gzip_upload.sh [SECONDS=7200] [RATE=400]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-7200}
rate=${2:-400}
bin=${CALIBD_BIN:-build/calibd}
[ -x "$bin" ] || { echo "gzip_upload: $bin not built" >&2; exit 2; }
tmp=$(mktemp -d "${TMPDIR:-/tmp}/calibd-gzip-XXXXXX")
# shellcheck source=tests/lib/serve.sh
. tests/lib/serve.sh
trap 'stop_calibd; rm -rf "$tmp"' EXIT

"$bin" simulate noise --out "$tmp/log" --seconds "$seconds" --rate "$rate" >/dev/null 2>&1
start=$(date +%s.%N)
gzip -6 -k "$tmp/log/recording.csv"
end=$(date +%s.%N)
csv_bytes=$(stat -c %s "$tmp/log/recording.csv")
gz_bytes=$(stat -c %s "$tmp/log/recording.csv.gz")
echo "log: $csv_bytes bytes of CSV, $gz_bytes gzip'd (-6, $(echo "$end - $start" | bc) s)"

hwm() { sed -n 's/^VmHWM:[[:space:]]*\([0-9]*\) kB/\1/p' "/proc/$server_pid/status"; }

run() {  # run NAME FILE [curl header args...]
  local name=$1 file=$2; shift 2
  rm -f "$tmp/calibd.db"*
  start_calibd "$bin" --workers 1
  local out
  out=$(curl -sf -w '\n%{time_total}' -H 'Content-Type: text/csv' "$@" --data-binary "@$file" \
    "$base/api/v1/recordings?method=noise&device=BENCH")
  local upload_s job
  upload_s=$(echo "$out" | tail -n 1)
  job=$(echo "$out" | sed '$d' | python3 -c 'import json,sys; print(json.load(sys.stdin)["job"]["id"])')
  local rss_upload
  rss_upload=$(hwm)
  local t0 t1
  t0=$(date +%s.%N)
  until curl -sf "$base/api/v1/jobs/$job" | grep -q '"status": "succeeded"'; do
    curl -sf "$base/api/v1/jobs/$job" | grep -q '"status": "failed"' && { echo "job failed"; exit 1; }
    sleep 0.05
  done
  t1=$(date +%s.%N)
  echo "$name: upload ${upload_s} s, peak RSS after upload $((rss_upload / 1024)) MiB;" \
    "job (queue to succeeded) $(echo "$t1 - $t0" | bc) s, peak RSS $(( $(hwm) / 1024 )) MiB"
  stop_calibd
}

run "gzip'd" "$tmp/log/recording.csv.gz" -H 'Content-Encoding: gzip'
run "plain " "$tmp/log/recording.csv"
