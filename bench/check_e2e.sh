#!/usr/bin/env bash
# bench/check_e2e.sh CALIBD LABEL [serve flags]: a fresh server, the hour of 400 Hz uploaded
# ($CSV, default big/recording.csv from `calibd simulate imu --out big --rate 400 --statics 200
# --static-seconds 12 --rotation-seconds 6 --seed 42`), $WAIT s (default 5), then GET /check?method=imu
# three times and /segments twice (curl %{time_total}), the answers' SHA-256 and the server's RSS.
set -euo pipefail
bin=$1; label=$2; shift 2
dir=$(mktemp -d)
port=$((20000 + RANDOM % 20000))
"$bin" serve --db "$dir/calibd.db" --listen 127.0.0.1:$port --workers 1 --no-access-log "$@" 2>"$dir/log" &
pid=$!
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$dir"' EXIT
for i in $(seq 100); do curl -sf http://127.0.0.1:$port/healthz >/dev/null && break; sleep 0.1; done
up=$(curl -s -w ' %{time_total}' -H 'Content-Type: text/csv' --data-binary @${CSV:-big/recording.csv} http://127.0.0.1:$port/api/v1/recordings)
echo "$label upload: ${up##* } s"
id=$(echo "${up% *}" | python3 -c 'import json,sys; print(json.load(sys.stdin)["recording"]["id"])')
sleep ${WAIT:-5}
for i in 1 2 3; do
  curl -s -o "$dir/check$i.json" -w "$label check $i: %{time_total} s (HTTP %{http_code})\n" "http://127.0.0.1:$port/api/v1/recordings/$id/check?method=imu"
done
for i in 1 2; do
  curl -s -o "$dir/seg$i.json" -w "$label segments $i: %{time_total} s (HTTP %{http_code})\n" "http://127.0.0.1:$port/api/v1/recordings/$id/segments"
done
python3 -c "import json,sys; c=json.load(open('$dir/check1.json')); print('$label statics', len(c['statics']), 'saturation', json.dumps(c['saturation'])[:200])"
sha256sum "$dir/check1.json" "$dir/seg1.json" | sed "s|$dir/||;s|^|$label |"
ps -o rss= -p $pid | awk -v l="$label" '{print l, "server RSS", $1/1024, "MiB"}'
cat "$dir/log" | head -5
