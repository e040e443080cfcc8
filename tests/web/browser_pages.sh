#!/usr/bin/env bash
# Renders every HTML page of a real server in Debian's headless Chromium: a screenshot per page
# (kept in $CALIBD_SCREENSHOT_DIR when set), checks of the DOM dump for the expected tables
# and plots, and of every table's width at 1280 px (table_widths.py).
# Usage: browser_pages.sh CALIBD_BINARY (KEEP_TMP=1 keeps the DOM dumps and database)
set -euo pipefail
bin=$(realpath "$1")
chromium=$(command -v chromium || true)
[ -n "$chromium" ] || { echo "chromium is not installed (scripts/setup.sh installs it)"; exit 1; }
tmp=$(mktemp -d)
# shellcheck source=/dev/null
source "$(dirname "$0")/../lib/serve.sh"
shots=${CALIBD_SCREENSHOT_DIR:-$tmp/shots}
mkdir -p "$shots"
cleanup() {
  stop_calibd
  [ -n "${KEEP_TMP:-}" ] || rm -rf "$tmp"
}
trap cleanup EXIT

start_calibd "$bin"

"$bin" simulate pca --out "$tmp/pca" --seed 3 --positions 60 2>/dev/null
"$bin" simulate array --out "$tmp/array" --seed 3 --samples 1000 2>/dev/null
upload() {  # upload DIR DEVICE -> job id
  curl -sf -F "recording=@$1/recording.csv" -F "config=@$1/config.json" \
    "$base/api/v1/recordings?device=$2" | job_id
}
job_id() { python3 -c 'import json, sys; print(json.load(sys.stdin)["job"]["id"])'; }
wait_job() {
  for _ in $(seq 1 600); do
    curl -sf "$base/api/v1/jobs/$1" | grep -q '"status": "\(succeeded\|failed\)"' && return 0
    sleep 0.1
  done
  echo "job $1 did not finish"; exit 1
}
hostile='SN-%3Cscript%3Ealert(1)'  # the device serial <script>alert(1)
j1=$(upload "$tmp/pca" "$hostile")
wait_job "$j1"
"$bin" simulate pca --out "$tmp/pca2" --seed 4 --positions 60 2>/dev/null
j2=$(upload "$tmp/pca2" "$hostile")
wait_job "$j2"
# The acceptance gate on the device page: a result the gate rejects (limits this config sets far
# tighter than any data meet) and one a person revokes; a fourth, accepted one keeps a drift pair.
"$bin" simulate pca --out "$tmp/pca3" --seed 5 --positions 60 2>/dev/null
python3 - "$tmp/pca3/config.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c["acceptance"] = {"max_scale_std": 1e-6}
json.dump(c, open(sys.argv[1], "w"))
PY
j5=$(upload "$tmp/pca3" "$hostile")
wait_job "$j5"
"$bin" simulate pca --out "$tmp/pca4" --seed 6 --positions 60 2>/dev/null
j6=$(upload "$tmp/pca4" "$hostile")
wait_job "$j6"
curl -sf -H 'Content-Type: application/json' -d '{"reason": "board <b>dropped</b> on the rig"}' \
  "$base/api/v1/jobs/$j2/revoke" >/dev/null
j3=$(upload "$tmp/array" 'ARRAY-1')
wait_job "$j3"
# An array job with model full (issue #18): the triad tables, residuals per triad, the change from
# the positions-only fit.
"$bin" simulate array --model full --out "$tmp/full" --seed 3 --samples 400 2>/dev/null
j8=$(upload "$tmp/full" 'ARRAY-FULL-1')
wait_job "$j8"
# A failed job: too few positions.
printf 'position,s1,s2,s3\np1,1,0,0\np2,0,1,0\n' >"$tmp/bad.csv"
j4=$(curl -sf -H 'Content-Type: text/csv' --data-binary @"$tmp/bad.csv" \
  "$base/api/v1/recordings?method=pca&device=%22%3E%3Cimg%20src%3Dx%20onerror%3Dalert(1)%3E" |
  job_id)
wait_job "$j4"
# A failed imu job: 5 statics where 9 are needed; its page shows the statics found.
"$bin" simulate imu --out "$tmp/imu-few" --seed 3 --statics 5 2>/dev/null
j9=$(upload "$tmp/imu-few" 'IMU-FEW')
wait_job "$j9"
# An inertial log: its recording page has the timeline with the statics.
"$bin" simulate imu --out "$tmp/imu" --seed 3 --statics 12 2>/dev/null
j7=$(upload "$tmp/imu" 'IMU-1')
wait_job "$j7"
r7=$(curl -sf "$base/api/v1/jobs/$j7" |
  python3 -c 'import json, sys; print(json.load(sys.stdin)["recording_id"])')
# Two accepted imu and two accepted noise calibrations of one device: its page shows how the
# IMU intrinsics and the noise terms drift.
for s in 5 6; do "$bin" simulate imu --out "$tmp/imu$s" --seed "$s" --statics 20 2>/dev/null; done
for s in 3 4; do
  "$bin" simulate noise --out "$tmp/noise$s" --seed "$s" --seconds 600 --rate 100 2>/dev/null
done
for d in imu5 imu6 noise3 noise4; do
  jd=$(upload "$tmp/$d" 'IMU-DRIFT')
  wait_job "$jd"
done
# Two accepted mag calibrations of one device (issue #26): the report's sphere projections,
# residuals with a disturbed span and coverage map; the device page's hard-iron drift.
for s in 3 4; do
  "$bin" simulate mag --out "$tmp/mag$s" --seed "$s" --turns 40 --disturbances 1 2>/dev/null
  jm=$(upload "$tmp/mag$s" 'MAG-1')
  wait_job "$jm"
done
# A magnetometer whose offsets wander: the report says what its σ predicts (core/mag.h step 3c).
"$bin" simulate mag --out "$tmp/magw" --seed 5 --turns 160 --hard-iron-walk 0.02 2>/dev/null
jw=$(upload "$tmp/magw" 'MAG-WANDER')
wait_job "$jw"
# Two accepted thermal calibrations of one device: the device page's drift of the curves.
for s in 3 4; do
  "$bin" simulate thermal --out "$tmp/therm$s" --seed "$s" --rate 20 2>/dev/null
  jt=$(upload "$tmp/therm$s" 'THERM-1')
  wait_job "$jt"
done

render() {  # render NAME PATH -> DOM dump in $tmp/NAME.html, screenshot in $shots/NAME.png
  local flags=(--headless --no-sandbox --disable-gpu --disable-background-networking
    --disable-component-update --disable-sync --no-first-run --disable-quic
    --user-data-dir="$tmp/profile-$1" --window-size=1280,2400 --hide-scrollbars)
  # The page's console (JavaScript errors would show as "Uncaught ...") goes to $tmp/NAME.log.
  timeout 120 "$chromium" "${flags[@]}" --enable-logging=stderr --v=0 --dump-dom "$base$2" \
    >"$tmp/$1.html" 2>"$tmp/$1.log"
  timeout 120 "$chromium" "${flags[@]}" --screenshot="$shots/$1.png" "$base$2" >/dev/null 2>&1
  [ -s "$shots/$1.png" ] || { echo "no screenshot of $2"; exit 1; }
}
passed=0 failed=0
expect() {  # expect NAME PATTERN...
  local name=$1; shift
  for pattern in "$@"; do
    if grep -q -- "$pattern" "$tmp/$name.html"; then passed=$((passed + 1)); else
      failed=$((failed + 1)); echo "FAIL: $name: no '$pattern'"; fi
  done
}
reject() {  # reject NAME PATTERN...: hostile markup must never reach the DOM as markup
  local name=$1; shift
  for pattern in "$@"; do
    if grep -q -- "$pattern" "$tmp/$name.html"; then
      failed=$((failed + 1)); echo "FAIL: $name: found '$pattern'"; else passed=$((passed + 1)); fi
  done
}
render history /
render pca "/jobs/$j2"
render array "/jobs/$j3"
render failed "/jobs/$j4"
render failed-imu "/jobs/$j9"
render device "/devices/$hostile"
render revoked "/jobs/$j2"
render rejected "/jobs/$j5"
render missing /jobs/999999
render devices /devices
render recording "/recordings/$r7"
# The check before fitting (issue #27) of that log on its page: verdicts and the statics' sphere.
render check "/recordings/$r7?check=imu"
render full "/jobs/$j8"
render device-drift /devices/IMU-DRIFT
render mag "/jobs/$jm"
render mag-wander "/jobs/$jw"
render mag-device /devices/MAG-1
render thermal-device /devices/THERM-1
# A product's fleet (issue #27): three units of the product "P-<b>" (escaped on the page).
for k in 1 2 3; do
  jf=$(curl -sf -F "recording=@$tmp/pca/recording.csv" -F "config=@$tmp/pca/config.json" \
    "$base/api/v1/recordings?device=FLEET-$k&product=P-%3Cb%3E" | job_id)
  wait_job "$jf"
done
render fleet '/products/P-%3Cb%3E?method=pca'

# The plan page (issue #27 item 1): three ticked directions and three typed ones, then a planar set.
plan_config='config=%7B%22nominal%22%3A%5B%5B1%2C0%2C0%5D%2C%5B0%2C1%2C0%5D%2C%5B0%2C0%2C1%5D%5D%2C%22noise_std%22%3A0.01%7D'
render plan "/plan?method=pca&o=%2Bx&o=%2By&o=%2Bz&orientations=-x+-y+-z+%2Bx%2By%2Bz&$plan_config"
render plan-planar "/plan?method=pca&orientations=%2Bx+-x+%2By+-y+%2Bx%2By+-x-y&$plan_config"
# imu: a suggestion cut by a scale σ limit, with the one-position-less line.
imu_plan_config='config=%7B%22accel_noise%22%3A0.05%2C%22gyro_noise%22%3A0.01%2C%22acceptance%22%3A%7B%22max_scale_std%22%3A0.0005%7D%7D'
render plan-imu "/plan?method=imu&orientations=%2Bz+-z+%2Bx+-x+%2By+-y+%2Bx%2By+%2By%2Bz+-x%2Bz+-y-z+%2Bx-z+-x-y&$imu_plan_config"
# thermal: a warm-up 20 -> 50 degC at 1 degC/min, without orientations (issue #27 item 1).
thermal_plan_config='config=%7B%22accel_noise%22%3A0.02%2C%22gyro_noise%22%3A0.002%7D'
render plan-thermal "/plan?method=thermal&t_min=20&t_max=50&temperature_rate=1&rate=100&$thermal_plan_config"
# array: 4 triads turning about z only (their z undetermined), then the suggestion about all axes.
array_plan_config='config=%7B%22geometry%22%3A%7B%22positions%22%3A%5B%5B0%2C0%2C0%5D%2C%5B0.01%2C0%2C0%5D%2C%5B0%2C0.01%2C0%5D%2C%5B0%2C0%2C0.002%5D%5D%7D%2C%22accel_noise%22%3A0.04%2C%22gyro_noise%22%3A0.001%7D'
render plan-array "/plan?method=array&angular_rate=10&angular_acceleration=30&rotation_axis=%2Bz&duration=10&rate=100&$array_plan_config"
# The array's full model: twelve statics, then the motion about z only (the gyroscope across z named).
array_full_plan_config='config=%7B%22model%22%3A%22full%22%2C%22geometry%22%3A%7B%22positions%22%3A%5B%5B0%2C0%2C0%5D%2C%5B0.01%2C0%2C0%5D%2C%5B0%2C0.01%2C0%5D%2C%5B0%2C0%2C0.002%5D%5D%7D%2C%22accel_noise%22%3A0.04%2C%22gyro_noise%22%3A0.0035%2C%22static_window%22%3A0.25%2C%22min_static%22%3A0.5%7D'
render plan-array-full "/plan?method=array&orientations=%2Bz+-z+%2Bx+-x+%2By+-y+%2Bx%2By%2Bz+-x-y%2Bz+%2Bx-y-z+-x%2By-z+%2Bx%2Bz+-y-z&static_duration=1.5&angular_rate=10&angular_acceleration=50&rotation_axis=%2Bz&duration=4&rate=100&$array_full_plan_config"
# The mag plan (issue 33 item 1): field, noise, eight held orientations with the turns between them.
mag_plan_config='config=%7B%22field%22%3A50%2C%22mag_noise%22%3A0.3%7D'
render plan-mag "/plan?method=mag&orientations=%2Bz+-z+%2Bx+-x+%2By+-y+%2Bx%2By+-x%2Bz&static_duration=2&rotation_duration=2&rate=50&$mag_plan_config"

# A running job's page: its elapsed time and the Cancel form (issue #20); then it is cancelled.
python3 - "$tmp/array/config.json" "$tmp/endless.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
c.update({"solver": "bcd", "max_iterations": 1000000, "tolerance": 0})
json.dump(c, open(sys.argv[2], "w"))
PY
j10=$(curl -sf -F "recording=@$tmp/array/recording.csv" -F "config=@$tmp/endless.json" \
  "$base/api/v1/recordings?device=ENDLESS" | job_id)
for _ in $(seq 1 300); do
  curl -sf "$base/api/v1/jobs/$j10" | grep -q '"status": "running"' && break
  sleep 0.1
done
render running "/jobs/$j10"
curl -sf -H 'Content-Type: application/json' -d '{"reason": "end of the browser test"}' \
  "$base/api/v1/jobs/$j10/cancel" >/dev/null
wait_job "$j10"
expect running 'badge-running' 'class="elapsed"' 'form class="cancel-job"' \
  "action=\"/api/v1/jobs/$j10/cancel\"" 'name="reason"'

expect history 'class="page-history' 'table-history' 'form class="filters\|class="filters' \
  ' statics' 'gyro N '  # imu and noise key figures
expect pca 'class="page-job' 'table-pca-parameters' 'plot-singular-values' 'plot-magnitude-error' \
  'plot-residual-rms' 'plot-axes-xy' 'plot-axes-xz' 'table-diagnostics'
expect array 'table-array-parameters' 'plot-cost' 'plot-positions-xy' 'plot-positions-xz'
expect failed 'callout-error' 'badge-failed'
# The reason, its advice once, and what the method found before failing (issue #14).
expect failed 'failure-code' 'too_few_positions' 'failure-advice' 'id="partial"' \
  '2 (minimum 6)' 'table-diagnostics'
expect failed-imu 'badge-failed' 'too_few_statics' 'failure-advice' 'id="partial"' \
  'plot-imu-statics-found' 'coverage-verdict' 'table-diagnostics'
expect full 'badge-succeeded' 'table-array-full-accelerometer' 'table-array-full-gyroscope' \
  'table-array-full-misalignment' 'table-array-full-change' \
  'plot-array-full-residuals-accelerometer' 'plot-array-full-residuals-gyroscope' \
  'plot-array-full-position-change' 'plot-positions-xy' 'table-array-parameters' \
  'id="triads"' 'id="triad-residuals"' 'id="full-vs-positions"'
# Eight triads: eight rows in each sensor table (the DOM dump puts each table on one line).
rows=$(grep -o '<table class="table-array-full table-array-full-gyroscope">.*' "$tmp/full.html" |
  sed 's|</table>.*||' | grep -o '<tr><td class="name">' | wc -l)
if [ "$rows" -eq 8 ]; then passed=$((passed + 1)); else
  failed=$((failed + 1)); echo "FAIL: full: $rows gyroscope rows, expected 8"; fi
expect device 'class="page-device' 'table-calibrations' 'table-drift-pca'
expect device '<span class="badge badge-rejected"' '<span class="badge badge-revoked"' \
  'scale factor too uncertain' 'board &lt;b&gt;dropped&lt;/b&gt; on the rig' '2 accepted calibrations'
expect revoked 'Revoked' 'table-events' 'board &lt;b&gt;dropped'
expect rejected 'Rejected by the acceptance gate' 'scale factor too uncertain'
expect missing 'class="page-error'
expect devices 'class="page-devices' 'table-devices' 'first seen (UTC)'
expect fleet 'class="page-fleet' 'table-fleet' 'href="/devices/FLEET-1"' 'P-&lt;b&gt;' 'class="hist"'
expect plan 'class="page-plan' 'table-plan' 'table-plan-suggested' 'class="sphere' 'greedy D-optimal'
expect plan-planar 'class="undetermined' 'no orientation with a component along z'
expect plan-thermal 'class="page-plan' 'table-plan-suggested' 'suggested-ramp' 'one orientation'
expect plan-array 'class="page-plan' 'table-plan-suggested' 'suggested-motion' \
  'maps z to 0' 'undetermined: positions'
expect plan-array-full 'class="page-plan' 'table-plan-suggested' 'suggested-motion' 'each static held' \
  'too little rotation about the body axis' 'undetermined: gyroscope gains and misalignments' 'misalignment_std'
expect plan-mag 'class="page-plan' 'table-plan' 'table-plan-suggested' 'hard_iron_std' 'the mag method on the simulated logs'
expect plan-imu 'class="page-plan' 'table-plan-suggested' 'starting flat (+z up)' \
  'class="fewer small"' 'positions the limits are not met'
expect pca 'class="model"'
expect array 'class="model"'
reject failed 'class="advice"'
expect recording '|a| (m/s²)'
expect recording 'class="page-recording' 'plot-timeline-accel' 'plot-timeline-gyro' \
  'table-intervals' 'table-thresholds' "href=\"/jobs/$j7\""
expect recording 'id="check"' 'Check before fitting' '<option'
expect check 'id="check"' 'plot-check-upper' 'plot-check-lower' 'Saturation: 0 sample' \
  'Coverage of IMU 0' 'Timing: 100.0 Hz' 'class="check-predicted"' 'IMU 0 accelerometer.'
expect device-drift 'imu (2 accepted calibrations' 'noise (2 accepted calibrations' \
  'table-drift-imu' 'table-drift-noise' 'data-sensor="accelerometer"' 'data-sensor="gyroscope"' \
  'plot-drift-imu-scale' 'plot-drift-noise-accel' 'plot-drift-noise-gyro'
expect mag 'plot-mag-sphere' 'plot-mag-residuals' 'plot-mag-coverage' 'Hard and soft iron' \
  'ArduPilot COMPASS parameters' 'PX4 CAL_MAG parameters'
expect mag-device 'mag: hard-iron drift'
expect mag-wander 'class="wander"' 'predicts the next log as long as this one' 'uT/sqrt(s)'
expect thermal-device 'thermal (2 accepted calibrations' 'table-drift-thermal' \
  'plot-drift-thermal-accel' 'plot-drift-thermal-gyro'
for page in history pca array failed failed-imu device devices revoked rejected recording check \
  full device-drift running fleet plan plan-planar plan-imu plan-thermal plan-array plan-array-full plan-mag mag mag-device mag-wander thermal-device; do
  reject "$page" '<script' '<img'
  if grep -q 'Uncaught\|CONSOLE.*[Ee]rror' "$tmp/$page.log"; then
    failed=$((failed + 1)); echo "FAIL: $page: console errors:"; grep 'CONSOLE' "$tmp/$page.log"
  else passed=$((passed + 1)); fi
done
# Every table fits a 1280 px wide window (a laptop screen): none scrolls sideways in its
# .table-wrap, no page scrolls sideways. table_widths.py measures them in the same Chromium.
if python3 "$(dirname "$0")/table_widths.py" "$chromium" "$tmp/profile-widths" "$base/" \
  "$base/jobs/$j2" "$base/jobs/$j3" "$base/jobs/$j4" "$base/jobs/$j5" "$base/jobs/$j8" \
  "$base/devices" "$base/devices/$hostile" "$base/devices/IMU-DRIFT" "$base/recordings/$r7" \
  "$base/recordings/$r7?check=imu" "$base/jobs/$jm" "$base/devices/MAG-1" "$base/devices/THERM-1" \
  "$base/products/P-%3Cb%3E?method=pca" >"$tmp/widths.log" 2>&1; then
  passed=$((passed + 1))
else
  failed=$((failed + 1)); echo "FAIL: a table is wider than 1280 px allows:"; cat "$tmp/widths.log"
fi
# At 400 px (a phone) the history, device and devices tables stack each row's cells: none
# scrolls sideways and no status or verdict badge is out of sight (issue 27).
if python3 "$(dirname "$0")/table_widths.py" --width 400 \
  --tables table-history,table-calibrations,table-devices "$chromium" "$tmp/profile-narrow" \
  "$base/" "$base/devices" "$base/devices/$hostile" >"$tmp/narrow.log" 2>&1; then
  passed=$((passed + 1))
else
  failed=$((failed + 1)); echo "FAIL: a table does not fit 400 px or hides a badge:"
  cat "$tmp/narrow.log"
fi
echo "browser pages: screenshots in $shots"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
