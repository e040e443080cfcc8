#!/usr/bin/env bash
# Slow clients (slowloris) against `calibd serve`: SLOW connections each send a request head one
# byte per second (never finishing it within the head deadline), while a prober asks /healthz
# every 100 ms for SECONDS seconds. Prints the /healthz latency (p50, p99, max), how many probes
# failed, and how the slow connections ended (408 after the head deadline, or still open).
#
#   bench/slow_clients.sh [SLOW=200] [SECONDS=20]
set -euo pipefail
cd "$(dirname "$0")/.."
slow=${1:-200}
seconds=${2:-20}
bin=${CALIBD_BIN:-build/calibd}
[ -x "$bin" ] || { echo "slow_clients: $bin not built (scripts/build.sh --target calibd)" >&2; exit 2; }
tmp=$(mktemp -d "${TMPDIR:-/tmp}/calibd-slow-XXXXXX")
# shellcheck source=tests/lib/serve.sh
. tests/lib/serve.sh
trap 'stop_calibd; rm -rf "$tmp"' EXIT
start_calibd "$bin"

python3 - "$port" "$slow" "$seconds" <<'PY'
import socket, sys, threading, time

port, slow, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
ended = {"408": 0, "other": 0, "open": 0}
lock = threading.Lock()
stop = time.time() + seconds

def trickle():
    head = b"POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nX-Slow: " + b"a" * 10000
    s = socket.create_connection(("127.0.0.1", port))
    s.settimeout(0.01)
    got = b""
    i = 0
    while time.time() < stop:
        try:
            s.send(head[i:i + 1]); i += 1
        except OSError:
            pass
        try:
            chunk = s.recv(4096)
            if not chunk:
                break
            got += chunk
        except socket.timeout:
            pass
        except OSError:
            break
        time.sleep(1)
    with lock:
        if got.startswith(b"HTTP/1.1 408"):
            ended["408"] += 1
        elif got:
            ended["other"] += 1
        else:
            ended["open"] += 1
    s.close()

threads = [threading.Thread(target=trickle) for _ in range(slow)]
for t in threads:
    t.start()
time.sleep(1)
latencies, failures = [], 0
while time.time() < stop - 0.5:
    t0 = time.time()
    try:
        c = socket.create_connection(("127.0.0.1", port), timeout=30)
        c.settimeout(30)
        c.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        data = b""
        while True:
            chunk = c.recv(4096)
            if not chunk:
                break
            data += chunk
        c.close()
        if data.startswith(b"HTTP/1.1 200"):
            latencies.append(time.time() - t0)
        else:
            failures += 1
    except OSError:
        failures += 1
    time.sleep(0.1)
for t in threads:
    t.join()
latencies.sort()
q = lambda p: latencies[min(len(latencies) - 1, int(p * len(latencies)))] * 1e3
print(f"{slow} slow clients, {seconds:.0f} s: /healthz probes {len(latencies)} ok, {failures} failed; "
      f"latency p50 {q(0.5):.2f} ms, p99 {q(0.99):.2f} ms, max {latencies[-1] * 1e3:.2f} ms")
print(f"slow connections: {ended['408']} ended with 408, {ended['other']} other answers, "
      f"{ended['open']} still open at the end")
PY
