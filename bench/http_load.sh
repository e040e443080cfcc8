#!/usr/bin/env bash
# HTTP load figures for bench/README.md: GET latest calibration with wrk at 1/16/64 connections
# beside nginx serving the same bytes as a static file; upload throughput for 1 MB and 100 MB
# recordings with the server's peak RSS. Installs wrk and nginx from Debian if missing.
# Usage: bench/http_load.sh [build/calibd]   (as root)
set -euo pipefail
bin=$(realpath "${1:-build/calibd}")
for p in wrk nginx-light curl; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
    { apt-get update -qq && apt-get install -y -qq wrk nginx-light curl >/dev/null; break; }
done
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
nginx_started=
# shellcheck source=tests/lib/serve.sh
source tests/lib/serve.sh
cleanup() {
  stop_calibd
  [ -n "$nginx_started" ] && nginx -c "$tmp/nginx.conf" -s stop 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
start_calibd "$bin"
"$bin" simulate pca --out "$tmp/pca" --seed 1 --positions 100 2>/dev/null
curl -sf -F "recording=@$tmp/pca/recording.csv" -F "config=@$tmp/pca/config.json" \
  "$base/api/v1/recordings?device=SN-LOAD" >/dev/null
until curl -sf "$base/api/v1/jobs/1" | grep -q '"status": "succeeded"'; do sleep 0.1; done
url="$base/api/v1/devices/SN-LOAD/calibration?method=pca"
curl -sf "$url" >"$tmp/latest.json"

mkdir -p "$tmp/www"
cp "$tmp/latest.json" "$tmp/www/latest.json"
cat >"$tmp/nginx.conf" <<NGINX
worker_processes 2;
pid $tmp/nginx.pid;
error_log $tmp/nginx-error.log;
events { worker_connections 1024; }
http {
  access_log off;
  server { listen 127.0.0.1:18089; root $tmp/www; }
}
NGINX
nginx -c "$tmp/nginx.conf" && nginx_started=1

echo "## GET latest calibration ($(wc -c <"$tmp/latest.json") bytes JSON), wrk -t2 (-t1 for one connection) -d10s --latency"
for c in 1 16 64; do
  for target in calibd nginx; do
    u=$url; [ $target = nginx ] && u=http://127.0.0.1:18089/latest.json
    t=2; [ "$c" -lt 2 ] && t=1
    out=$(wrk -t$t -c$c -d10s --latency "$u")
    rps=$(echo "$out" | sed -n 's/^Requests\/sec: *//p')
    p50=$(echo "$out" | awk '$1=="50%"{print $2}')
    p99=$(echo "$out" | awk '$1=="99%"{print $2}')
    echo "$target c=$c: $rps req/s, p50 $p50, p99 $p99"
  done
done

echo "## Uploads (validate + store + enqueue), curl, one at a time"
python3 - "$tmp" <<'PY'
import sys, random
tmp = sys.argv[1]
random.seed(1)
for name, size in (("1mb", 1 << 20), ("100mb", 100 << 20)):
    with open(f"{tmp}/{name}.csv", "w") as f:
        f.write("position," + ",".join(f"s{i}" for i in range(12)) + "\n")
        written, p = 0, 0
        while written < size:
            line = f"p{p // 1000}," + ",".join(f"{random.gauss(0, 1):.9f}" for _ in range(12)) + "\n"
            f.write(line); written += len(line); p += 1
PY
for name in 1mb 100mb; do
  bytes=$(wc -c <"$tmp/$name.csv")
  t=$(curl -sf -o /dev/null -w '%{time_total}' -H 'Content-Type: text/csv' \
    --data-binary @"$tmp/$name.csv" "$base/api/v1/recordings?device=UP")
  echo "$name: $bytes bytes in ${t}s: $(python3 -c "print(round($bytes/1e6/$t,1))") MB/s"
done
echo "server peak RSS: $(grep VmHWM /proc/$server_pid/status | awk '{print $2/1024 " MiB"}')"
