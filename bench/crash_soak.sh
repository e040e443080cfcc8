#!/usr/bin/env bash
# Crash soak (SPEC §6): `calibd serve` on a temporary database under steady pca upload load is
# killed with SIGKILL KILLS times at random moments (restarted each time). Then:
#   - `sqlite3 DB 'PRAGMA integrity_check'` is ok (on the file as the last SIGKILL left it),
#   - every upload answered 201 is there byte-exact (GET /api/v1/recordings/{id}/data) with the
#     sha256 the answer gave, and no recording row is half-written (data length = bytes),
#   - every job ends succeeded (acknowledged or not), each acknowledged job has its result,
#   - no result is stored twice (one results row per job, and as many rows as succeeded jobs).
# Prints the figures (uploads acknowledged, kills, time, jobs re-run after a kill, losses) and
# exits non-zero on any violation.
#
#   bench/crash_soak.sh [KILLS=200]        # CALIBD_BIN=build/calibd, CALIBD_SOAK_UPLOADERS=3
set -euo pipefail
cd "$(dirname "$0")/.."
kills=${1:-200}
bin=${CALIBD_BIN:-build/calibd}
[ -x "$bin" ] || { echo "crash_soak: $bin not built (scripts/build.sh --target calibd)" >&2; exit 2; }
command -v sqlite3 >/dev/null || { echo "crash_soak: needs the sqlite3 command" >&2; exit 2; }
work=$(mktemp -d "${TMPDIR:-/tmp}/calibd-soak-XXXXXX")
trap 'rm -rf "$work"' EXIT
"$bin" simulate pca --out "$work/sim" --seed 7 --positions 24 >/dev/null 2>&1

exec python3 - "$bin" "$work" "$kills" "${CALIBD_SOAK_UPLOADERS:-3}" <<'PY'
import hashlib, http.client, json, os, random, signal, socket, subprocess, sys, threading, time

binary, work, kills, uploaders = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
db = os.path.join(work, "calibd.db")
base_csv = open(os.path.join(work, "sim", "recording.csv"), "rb").read()
rng = random.Random(20261122)
log = open(os.path.join(work, "server.log"), "ab")

def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]

port = free_port()

def request(method, path, body=None, headers=None, timeout=10):
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=timeout)
    try:
        conn.request(method, path, body=body, headers=headers or {})
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()

def start():
    p = subprocess.Popen([binary, "serve", "--db", db, "--listen", f"127.0.0.1:{port}",
                          "--workers", "2", "--no-access-log"], stdout=log, stderr=log)
    deadline = time.time() + 30
    while time.time() < deadline:
        if p.poll() is not None:
            sys.exit(f"crash_soak: the server exited with {p.returncode} at start (see {work}/server.log)")
        try:
            if request("GET", "/healthz", timeout=1)[0] == 200:
                return p
        except (OSError, http.client.HTTPException):
            pass
        time.sleep(0.01)
    sys.exit("crash_soak: the server did not start within 30 s")

acked = {}   # recording id -> (sha256, bytes, job id)
lock = threading.Lock()
counter = [0]
attempts = [0]
stop = threading.Event()

alive_ok = [True]

def uploader(k):
    try:
        upload_loop()
    except BaseException:
        alive_ok[0] = False
        raise

def upload_loop():
    while not stop.is_set():
        with lock:
            counter[0] += 1
            n = counter[0]
        # Unique bytes per upload (a comment line), so every 201 is a new recording.
        body = b"# soak upload %d\n" % n + base_csv
        sha = hashlib.sha256(body).hexdigest()
        try:
            attempts[0] += 1
            status, answer = request(
                "POST", f"/api/v1/recordings?method=pca&device=SOAK-{n % 5}&magnitude=1", body,
                {"Content-Type": "text/csv"})
        except (OSError, http.client.HTTPException):
            time.sleep(0.005)   # killed mid-request, or down: retry after the restart
            continue
        if status == 201:
            a = json.loads(answer)
            if a["recording"]["sha256"] != sha:
                sys.exit(f"crash_soak: the server's sha256 of upload {n} is wrong")
            with lock:
                acked[a["recording"]["id"]] = (sha, body, a["job"]["id"])
        elif status >= 500 or status in (400, 422):
            print(f"crash_soak: upload {n} answered {status}: {answer[:300]!r}", file=sys.stderr)

t0 = time.time()
server = start()
threads = [threading.Thread(target=uploader, args=(k,), daemon=True) for k in range(uploaders)]
for t in threads:
    t.start()
up_times = []
for i in range(kills):
    time.sleep(rng.uniform(0.05, 1.0))
    server.send_signal(signal.SIGKILL)
    server.wait()
    t1 = time.time()
    server = start()
    up_times.append(time.time() - t1)
stop.set()
for t in threads:
    t.join()
    if not alive_ok[0]:
        sys.exit("crash_soak: an uploader thread died")
soak_seconds = time.time() - t0

# Drain: every job (acknowledged or committed but unanswered) must end; a job whose lease was
# held by a killed process runs again once the lease (30 s) lapses.
deadline = time.time() + 300
while True:
    h = json.loads(request("GET", "/healthz")[1])
    if h.get("queued", 0) == 0 and h.get("running", 0) == 0:
        break
    if time.time() > deadline:
        sys.exit(f"crash_soak: jobs still queued/running after 300 s: {h}")
    time.sleep(0.2)
drain_seconds = time.time() - t0 - soak_seconds

problems = []
for rid, (sha, body, job) in sorted(acked.items()):
    status, data = request("GET", f"/api/v1/recordings/{rid}/data", timeout=30)
    if status != 200:
        problems.append(f"recording {rid}: GET data answered {status}")
    elif data != body:
        problems.append(f"recording {rid}: bytes differ ({len(data)} vs {len(body)})")
    status, j = request("GET", f"/api/v1/jobs/{job}")
    j = json.loads(j) if status == 200 else {}
    if j.get("status") != "succeeded" or not j.get("result"):
        problems.append(f"job {job}: {status} {j.get('status')} {j.get('error')}")

# The last SIGKILL, then the file as it was left.
server.send_signal(signal.SIGKILL)
server.wait()
def sql(q):
    return subprocess.run(["sqlite3", db, q], capture_output=True, text=True, check=True).stdout.strip()
integrity = sql("PRAGMA integrity_check")
if integrity != "ok":
    problems.append(f"integrity_check: {integrity[:500]}")
not_succeeded = sql("SELECT status || ' ' || COALESCE(error_code, '') || ': ' || count(*) FROM jobs "
                    "WHERE status <> 'succeeded' GROUP BY status, error_code")
if not_succeeded:
    problems.append(f"jobs not succeeded: {not_succeeded}")
dup = sql("SELECT count(*) FROM (SELECT job_id FROM results GROUP BY job_id HAVING count(*) > 1)")
if dup != "0":
    problems.append(f"{dup} jobs with more than one stored result")
jobs_total = int(sql("SELECT count(*) FROM jobs"))
succeeded = int(sql("SELECT count(*) FROM jobs WHERE status = 'succeeded'"))
results = int(sql("SELECT count(*) FROM results"))
if results != succeeded:
    problems.append(f"{results} results for {succeeded} succeeded jobs")
orphans = sql("SELECT count(*) FROM results r LEFT JOIN jobs j ON j.id = r.job_id "
              "WHERE j.id IS NULL OR j.status <> 'succeeded'")
if orphans != "0":
    problems.append(f"{orphans} results without a succeeded job")
half = sql("SELECT count(*) FROM recordings r LEFT JOIN recording_data d ON d.recording_id = r.id "
           "WHERE d.data IS NULL OR length(d.data) <> r.bytes")
if half != "0":
    problems.append(f"{half} half-written recordings")
recordings = int(sql("SELECT count(*) FROM recordings"))
rerun = int(sql("SELECT count(*) FROM jobs WHERE attempts > 1"))
acked_jobs = len({v[2] for v in acked.values()})

print(f"crash_soak: {kills} SIGKILLs in {soak_seconds:.0f} s (+{drain_seconds:.0f} s to drain the queue), "
      f"{uploaders} uploaders, restart to /healthz median {sorted(up_times)[len(up_times)//2]*1000:.0f} ms")
print(f"crash_soak: uploads attempted {attempts[0]}, answered 201 {len(acked)} "
      f"(recordings stored {recordings}: {recordings - len(acked)} committed but unanswered)")
print(f"crash_soak: jobs {jobs_total} (acknowledged {acked_jobs}), succeeded {succeeded}, "
      f"ran more than once {rerun}, results {results}; integrity_check {integrity}")
if problems:
    print(f"crash_soak: FAILED, {len(problems)} problem(s):")
    for p in problems[:50]:
        print("  " + p)
    sys.exit(1)
print("crash_soak: ok: no acknowledged upload lost or changed, every job succeeded once")
PY
