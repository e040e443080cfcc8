#!/usr/bin/env bash
# End-to-end job throughput for bench/README.md: recordings uploaded over HTTP (curl, 4 at a
# time, each with its method config), calibrated by the server's workers (one per core), until
# the last result is stored. The clock runs from the first upload to the empty queue.
#   pca:   the paper's set-up (4 triads = 12 sensors, 100 positions, known magnitude)
#   array: K = 32 triads, N = 10 000 samples (the paper's board), joint ML + CRB
# Every job must succeed, or the script fails. Usage (from the repository root):
#   bench/jobs_e2e.sh [build/calibd] [PCA_JOBS=400] [ARRAY_JOBS=20]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=$(realpath "${1:-build/calibd}")
pca_jobs=${2:-400}
array_jobs=${3:-20}
tmp=$(mktemp -d)
# shellcheck source=tests/lib/serve.sh
source tests/lib/serve.sh
trap 'stop_calibd; rm -rf "$tmp"' EXIT
start_calibd "$bin"

# The value of one sample of /metrics, e.g. metric 'calibd_jobs{state="queued"}'.
metric() { curl -sf "$base/metrics" | awk -v k="$1" '$1 == k { print $2 }'; }
now() { date +%s.%N; }

# run METHOD JOBS SIMULATE-ARGS...: 10 distinct simulated recordings (seeds 1..10), uploaded
# round-robin JOBS times under distinct device serials.
run() {
  local method=$1 jobs=$2
  shift 2
  for seed in $(seq 1 10); do
    "$bin" simulate "$method" --out "$tmp/$method-$seed" --seed "$seed" "$@" >/dev/null 2>&1
  done
  local bytes
  bytes=$(wc -c <"$tmp/$method-1/recording.csv")
  local t0 t_up t1
  t0=$(now)
  seq 1 "$jobs" | xargs -P 4 -I{} sh -c \
    'd='"$tmp/$method"'-$(( ({} - 1) % 10 + 1 )); curl -sf -o /dev/null \
       -F "recording=@$d/recording.csv" -F "config=@$d/config.json" \
       "'"$base"'/api/v1/recordings?device=E2E-'"$method"'-{}" || echo "upload {} failed" >&2'
  t_up=$(now)
  while :; do
    local q r
    q=$(metric 'calibd_jobs{state="queued"}')
    r=$(metric 'calibd_jobs{state="running"}')
    [ "${q%.*}" = 0 ] && [ "${r%.*}" = 0 ] && break
    sleep 0.05
  done
  t1=$(now)
  local ok sum count
  ok=$(metric "calibd_jobs_finished_total{method=\"$method\",outcome=\"succeeded\"}")
  sum=$(metric "calibd_job_duration_seconds_sum{method=\"$method\"}")
  count=$(metric "calibd_job_duration_seconds_count{method=\"$method\"}")
  python3 - "$method" "$jobs" "$bytes" "$t0" "$t_up" "$t1" "${ok:-0}" "${sum:-0}" "${count:-1}" <<'PY'
import sys
method, jobs, size = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
t0, t_up, t1, ok, s, n = map(float, sys.argv[4:])
print(f"{method}: {jobs} jobs of {size / 1e3:.0f} kB recordings; uploads took {t_up - t0:.2f} s "
      f"({jobs / (t_up - t0):.0f} uploads/s); all results stored after {t1 - t0:.2f} s: "
      f"{jobs / (t1 - t0):.1f} jobs/s end to end; worker run time per job {1e3 * s / n:.1f} ms "
      f"(mean of {n:.0f}); succeeded {ok:.0f}")
if ok != jobs:
    sys.exit(f"{method}: only {ok:.0f} of {jobs} jobs succeeded")
PY
}

echo "calibd $("$bin" --version 2>/dev/null || true), $(nproc) cores, workers: one per core"
run pca "$pca_jobs" --positions 100
run array "$array_jobs" --samples 10000
echo "server peak RSS: $(awk '/VmHWM/ { print $2 / 1024 " MiB" }' /proc/"$server_pid"/status)"
