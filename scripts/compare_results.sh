#!/usr/bin/env bash
# The result JSON of every method, byte for byte, between two calibd binaries on the simulated
# set-ups (issue #23: a refactor keeps every result as it was). Uses `calibd simulate` of the NEW
# binary to write the recordings, then `calibd calibrate --compact` with each binary.
#
#   scripts/compare_results.sh OLD_CALIBD NEW_CALIBD
#
# Exit 0 when every result is identical; 1 naming the set-ups that differ (with a diff).
set -euo pipefail
old=$1 new=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
differ=0
# NAME SIMULATE-ARGS...: one set-up; every config file the simulation wrote is calibrated.
case_() {
  local name=$1; shift
  local dir=$work/$name
  mkdir -p "$dir"
  "$new" simulate "$@" --out "$dir" >/dev/null 2>&1
  for cfg in "$dir"/*config.json; do
    local rec=$dir/recording.csv
    [ "$(basename "$cfg")" = static_config.json ] && rec=$dir/static.csv
    local a=0 b=0
    "$old" calibrate --compact --config "$cfg" "$rec" >"$cfg.old" 2>/dev/null || a=$?
    "$new" calibrate --compact --config "$cfg" "$rec" >"$cfg.new" 2>/dev/null || b=$?
    if [ "$a" != "$b" ] || ! cmp -s "$cfg.old" "$cfg.new"; then
      echo "DIFFERENT: $name $(basename "$cfg") (exit $a vs $b)"
      diff <(python3 -m json.tool "$cfg.old" 2>/dev/null || cat "$cfg.old") \
           <(python3 -m json.tool "$cfg.new" 2>/dev/null || cat "$cfg.new") | head -20 || true
      differ=1
    else
      echo "identical: $name $(basename "$cfg") (exit $a, $(wc -c <"$cfg.new") bytes)"
    fi
  done
}
case_ pca pca --seed 1
case_ pca_bias pca --seed 2 --bias 0.05 -n 60
case_ array array --seed 3 -N 400
case_ array_static array --seed 4 -N 300 --static-positions 24
case_ array_full array --seed 5 --model full -N 600
case_ imu imu --seed 6
case_ imu_drift imu --seed 8 --gyro-bias-drift 1e-4 --initial-motion 2
case_ noise noise --seed 7
case_ mag mag --seed 9
case_ mag_disturbed mag --seed 10 --turns 380 --disturbances 2
case_ mag_coloured mag --seed 11 --ar1 0.98 --turns 160
exit $differ
