#!/usr/bin/env bash
# Runs the README's walkthrough block, as written, against a fresh server on a free port, so the
# README cannot drift from what calibd does. Usage: readme_walkthrough.sh CALIBD_BINARY SOURCE_DIR
set -euo pipefail
bin=$(realpath "$1")
src=$(realpath "$2")
tmp=$(mktemp -d)
# shellcheck source=/dev/null
source "$(dirname "$0")/../lib/serve.sh"
cleanup() {
  stop_calibd
  rm -rf "$tmp"
}
trap cleanup EXIT

start_calibd "$bin"

sed -n '/<!-- walkthrough:begin -->/,/<!-- walkthrough:end -->/p' "$src/README.md" |
  grep -v -e '^<!--' -e '^```' |
  sed -e "s|build/calibd|$bin|g" -e "s|127.0.0.1:8080|127.0.0.1:$port|g" \
      -e "s|/tmp/calibd-demo|$tmp/demo|g" >"$tmp/walkthrough.sh"
[ "$(wc -l <"$tmp/walkthrough.sh")" -gt 10 ] || { echo "walkthrough block not found"; exit 1; }

cd "$tmp"
timeout 300 bash -euo pipefail "$tmp/walkthrough.sh" >"$tmp/out.txt" 2>&1 || {
  echo "walkthrough failed:"; cat "$tmp/out.txt"; echo "server log:"; cat "$tmp/server.log"; exit 1; }

# What the walkthrough produced must be what it promises.
grep -q '"status": "succeeded"' "$tmp/demo/job.json"
grep -q '"method": "pca"' "$tmp/demo/pca-result.json"
grep -q 'static const double CALIBD_SN_0001_PCA_SENSITIVITY\[12\]\[3\]' "$tmp/demo/calibration.h"
grep -q '^name,x,y,z,offset_x' "$tmp/out.txt"
grep -q '^name,scale,scale_std' "$tmp/out.txt"
# No job id and no port is written into the walkthrough: it reads ids from the answers.
if sed -n '/<!-- walkthrough:begin -->/,/<!-- walkthrough:end -->/p' "$src/README.md" |
  grep -n -e '/jobs/[0-9]' -e ':[0-9][0-9]*/' | grep -v '^[0-9]*:CALIBD='; then
  echo "the walkthrough hard-codes a job id or the port"; exit 1
fi

# The walkthrough's wait_for_job stops on a failed job: prints its error, returns 1.
printf 'position,s1,s2,s3\np1,1,0,0\np2,0,1,0\n' >"$tmp/bad.csv"
sed -n '/^CALIBD=/p; /^wait_for_job() {/,/^}/p; /^job_id() {/p' "$tmp/walkthrough.sh" >"$tmp/functions.sh"
cat >>"$tmp/functions.sh" <<EOF
mkdir -p $tmp/demo
job=\$(curl -sf -H 'Content-Type: text/csv' --data-binary @$tmp/bad.csv \
  "\$CALIBD/api/v1/recordings?method=pca&device=SN-BAD" | job_id)
wait_for_job "\$job"
EOF
status=0
timeout 60 bash "$tmp/functions.sh" >"$tmp/failed.txt" 2>&1 || status=$?
if [ "$status" -ne 1 ] || ! grep -q '^job failed: 2 positions recorded' "$tmp/failed.txt"; then
  echo "wait_for_job on a failed job: exit $status (want 1), output:"; cat "$tmp/failed.txt"; exit 1
fi
echo "README walkthrough: 2 passed, 0 failed"
