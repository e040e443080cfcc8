# Sourced by the shell tests and load scripts: starts `calibd serve` on a free loopback port with
# a database in $tmp, and stops it on exit.
#   start_calibd BIN [extra serve flags...]   sets $port, $base and $server_pid; needs $tmp
# The caller's EXIT trap should call stop_calibd (and then remove $tmp).
server_pid=
stop_calibd() {
  if [ -n "$server_pid" ]; then
    kill "$server_pid" 2>/dev/null && wait "$server_pid" 2>/dev/null
    server_pid=
  fi
  return 0
}
start_calibd() {
  local bin=$1; shift
  "$bin" serve --db "$tmp/calibd.db" --listen 127.0.0.1:0 --no-access-log "$@" \
    2>"$tmp/server.log" &
  server_pid=$!
  port=
  for _ in $(seq 1 100); do
    port=$(sed -n 's|.*listening on http://127.0.0.1:\([0-9]*\).*|\1|p' "$tmp/server.log" \
      2>/dev/null || true)
    [ -n "$port" ] && break
    sleep 0.1
  done
  [ -n "$port" ] || { echo "calibd did not start:"; cat "$tmp/server.log"; return 1; }
  base=http://127.0.0.1:$port
}
