#!/usr/bin/env bash
# Memory after hostile traffic: `calibd serve` gets ROUNDS rounds of hostile requests from 64
# concurrent clients (oversized heads, refused and truncated uploads, 1 MiB JSON and config bodies,
# slow heads, malformed multipart, pipelined GETs); the server's RSS is printed after each round
# (once the round's connections are closed). Run it with different allocators to compare:
#
#   bench/hostile_rss.sh [ROUNDS=10]
#   CALIBD_PRELOAD=/usr/lib/x86_64-linux-gnu/libjemalloc.so.2 bench/hostile_rss.sh
#   MALLOC_ARENA_MAX=8 bench/hostile_rss.sh    # glibc's default on 2 cores is 16 arenas
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-10}
bin=${CALIBD_BIN:-build/calibd}
[ -x "$bin" ] || { echo "hostile_rss: $bin not built (scripts/build.sh --target calibd)" >&2; exit 2; }
tmp=$(mktemp -d "${TMPDIR:-/tmp}/calibd-rss-XXXXXX")
# shellcheck source=tests/lib/serve.sh
. tests/lib/serve.sh
trap 'stop_calibd; rm -rf "$tmp"' EXIT
if [ -n "${CALIBD_PRELOAD:-}" ]; then
  LD_PRELOAD=$CALIBD_PRELOAD start_calibd "$bin" --head-timeout-seconds 1
else
  start_calibd "$bin" --head-timeout-seconds 1
fi

python3 - "$port" "$server_pid" "$rounds" <<'PY'
import socket, sys, threading, time

port, pid, rounds = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])

def rss_mib():
    for line in open(f"/proc/{pid}/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024

def send(data, slow=False, read=True):
    try:
        s = socket.create_connection(("127.0.0.1", port), timeout=10)
        if slow:  # a trickled head, abandoned after 1 KiB
            for i in range(0, min(len(data), 1024), 64):
                s.sendall(data[i:i + 64]); time.sleep(0.05)
            s.close()
            return
        else:
            s.sendall(data)
        if read:
            while s.recv(65536):
                pass
        s.close()
    except OSError:
        pass

csv = b"position,s0,s1,s2\n" + b"".join(b"p%d,1,0,0\n" % i for i in range(20000))
bad_csv = csv[:200000] + b"p,x,y,z\n" + csv[200000:]
big_json = b'{"recording_id": 1, "config": {"x": "' + b"a" * (1 << 20) + b'"}}'
cases = [
    b"GET / HTTP/1.1\r\nHost: x\r\nX: " + b"a" * (60 << 10) + b"\r\n\r\n",
    b"POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nContent-Type: text/csv\r\n"
    b"Content-Length: %d\r\nConnection: close\r\n\r\n" % len(bad_csv) + bad_csv,
    b"POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nContent-Type: text/csv\r\n"
    b"Content-Length: %d\r\n\r\n" % (len(csv) * 2) + csv,
    b"POST /api/v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
    b"Content-Length: %d\r\n\r\n" % len(big_json) + big_json,
    b"POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nContent-Type: multipart/form-data; boundary=b\r\n"
    b"Content-Length: 2000000\r\n\r\n--b\r\nContent-Disposition: form-data; name=\"config\"\r\n\r\n"
    + b"{" * 1500000,
    b"POST /api/v1/recordings HTTP/1.1\r\nHost: x\r\nContent-Encoding: gzip\r\n"
    b"Content-Length: 100000\r\n\r\n" + b"\x1f\x8b" * 50000,
    b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n" * 50 + b"GET /healthz HTTP/1.1\r\nConnection: close\r\n\r\n",
]
print(f"start: RSS {rss_mib():.1f} MiB")
for r in range(rounds):
    threads = []
    for i in range(64):
        data = cases[i % len(cases)]
        threads.append(threading.Thread(target=send, args=(data, i % 16 == 15)))
    for t in threads: t.start()
    for t in threads: t.join()
    time.sleep(0.5)
    print(f"round {r + 1}: RSS {rss_mib():.1f} MiB")
PY
