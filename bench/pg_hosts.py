#!/usr/bin/env python3
"""Several calibd hosts on one PostgreSQL (issue #19), for bench/README.md.

Starts a throw-away PostgreSQL cluster (initdb into a temporary folder, as the `postgres` user
when run as root; Unix socket only; PostgreSQL's default durability: fsync on,
synchronous_commit on), then:

  throughput  durable uploads (recording + job, one transaction each, acknowledged after commit)
              per second and jobs per second end to end (first upload -> empty queue), for
              SQLite with 1 host and PostgreSQL with 1 and 3 hosts, in the same run; uploads come
              from CONCURRENCY clients spread round-robin over the hosts.
  soak        3 hosts, uploads spread over all three, kill -9 of one host every 1-2 s (restarted
              at once) for DURATION seconds; then: every acknowledged upload present byte-exact,
              every job succeeded, exactly one result per job (checked in the database too).
              Exits 1 if anything is lost or duplicated.

Usage (from the repository root, after building calibd):
  python3 bench/pg_hosts.py [--bin build/calibd] [--uploads 400] [--concurrency 8]
                            [--duration 60] [--skip-throughput] [--skip-soak]
"""
import argparse
import hashlib
import json
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request

PG_BIN = os.environ.get("CALIBD_PG_BIN", "/usr/lib/postgresql/15/bin")
AS_POSTGRES = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []


class Cluster:
    def __init__(self, root):
        self.dir = os.path.join(root, "pg")
        os.mkdir(self.dir)
        if os.geteuid() == 0:
            shutil.chown(self.dir, "postgres", "postgres")
        subprocess.run(AS_POSTGRES + [f"{PG_BIN}/initdb", "-D", f"{self.dir}/data", "-U",
                                      "postgres", "--auth=trust", "--locale=C", "-E", "UTF8"],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        subprocess.run(AS_POSTGRES + [f"{PG_BIN}/pg_ctl", "-D", f"{self.dir}/data", "-l",
                                      f"{self.dir}/log", "-w", "-o",
                                      f"-k {self.dir} -c listen_addresses='' "
                                      "-c max_connections=300", "start"],
                       check=True, stdout=subprocess.DEVNULL)
        self.databases = 0

    def new_database(self):
        self.databases += 1
        name = f"bench{self.databases}"
        self.psql("postgres", f"CREATE DATABASE {name}")
        return f"postgresql:///{name}?host={self.dir}&user=postgres"

    def psql(self, db, sql):
        out = subprocess.run([f"{PG_BIN}/psql", "-h", self.dir, "-U", "postgres", "-d", db,
                              "-At", "-c", sql], check=True, capture_output=True, text=True)
        return out.stdout.strip()

    def stop(self):
        subprocess.run(AS_POSTGRES + [f"{PG_BIN}/pg_ctl", "-D", f"{self.dir}/data", "-m",
                                      "immediate", "stop"],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


class Server:
    def __init__(self, binary, db, workers):
        self.proc = subprocess.Popen(
            [binary, "serve", "--db", db, "--listen", "127.0.0.1:0", "--no-access-log",
             "--workers", str(workers)], stderr=subprocess.PIPE, text=True)
        self.port = None
        for line in self.proc.stderr:
            m = re.search(r"listening on http://127\.0\.0\.1:(\d+)", line)
            if m:
                self.port = int(m.group(1))
                break
        if self.port is None:
            raise RuntimeError("calibd did not start")
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for _ in self.proc.stderr:
            pass

    def kill9(self):
        self.proc.kill()
        self.proc.wait()

    def term(self):
        self.proc.terminate()
        self.proc.wait()


def multipart(csv, config):
    boundary = "calibdbench" + hashlib.sha1(csv).hexdigest()[:16]
    parts = []
    for name, filename, ctype, data in (("recording", "r.csv", "text/csv", csv),
                                        ("config", None, "application/json", config)):
        disp = f'form-data; name="{name}"' + (f'; filename="{filename}"' if filename else "")
        parts.append(f"--{boundary}\r\nContent-Disposition: {disp}\r\n"
                     f"Content-Type: {ctype}\r\n\r\n".encode() + data + b"\r\n")
    return b"".join(parts) + f"--{boundary}--\r\n".encode(), boundary


def request(port, path, body=None, boundary=None, timeout=30):
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=body)
    if boundary:
        req.add_header("Content-Type", f"multipart/form-data; boundary={boundary}")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as res:
            return res.status, res.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()
    except (OSError, urllib.error.URLError):
        return None, b""


def simulate(binary, root, count):
    recordings = []
    for seed in range(1, count + 1):
        out = os.path.join(root, f"sim{seed}")
        subprocess.run([binary, "simulate", "pca", "--out", out, "--seed", str(seed),
                        "--positions", "30"], check=True, capture_output=True)
        with open(f"{out}/recording.csv", "rb") as f:
            csv = f.read()
        with open(f"{out}/config.json", "rb") as f:
            config = f.read()
        recordings.append((csv, config))
    return recordings


def unique_bytes(recording, i):
    """The recording with upload number i in its comment line: distinct bytes, a new recording."""
    csv, config = recording
    return csv.replace(b"\n", f" (upload {i})\n".encode(), 1), config


def wait_drained(ports, timeout=600):
    deadline = time.time() + timeout
    while time.time() < deadline:
        for port in ports:
            status, body = request(port, "/healthz", timeout=5)
            if status == 200:
                h = json.loads(body)
                if h["queued"] == 0 and h["running"] == 0:
                    return True
                break
        time.sleep(0.05)
    return False


def throughput(args, cluster, recordings, root, label, db, hosts):
    servers = [Server(args.bin, db, args.workers) for _ in range(hosts)]
    ports = [s.port for s in servers]
    counter = iter(range(args.uploads))
    lock = threading.Lock()
    failures = []

    def client():
        while True:
            with lock:
                i = next(counter, None)
            if i is None:
                return
            csv, config = unique_bytes(recordings[i % len(recordings)], i)
            body, boundary = multipart(csv, config)
            status, out = request(ports[i % hosts], f"/api/v1/recordings?device=B-{i}", body,
                                  boundary)
            if status != 201:
                failures.append((status, out[:200]))

    t0 = time.time()
    threads = [threading.Thread(target=client) for _ in range(args.concurrency)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    t_up = time.time()
    drained = wait_drained(ports)
    t1 = time.time()
    for s in servers:
        s.term()
    ok = len(failures) == 0 and drained
    print(f"{label}: {args.uploads} uploads in {t_up - t0:.2f} s = "
          f"{args.uploads / (t_up - t0):.0f} durable uploads+jobs/s; all jobs done after "
          f"{t1 - t0:.2f} s = {args.uploads / (t1 - t0):.0f} jobs/s end to end"
          + ("" if ok else f"  FAILED: {len(failures)} uploads refused {failures[:3]}"),
          flush=True)
    return ok


def soak(args, cluster, recordings):
    db = cluster.new_database()
    hosts = [Server(args.bin, db, 2) for _ in range(3)]
    hosts_lock = threading.Lock()
    acknowledged = {}  # recording id -> sha256 of the bytes
    jobs = set()
    attempts = [0]
    stop = threading.Event()
    lock = threading.Lock()

    uploaders = 6

    def uploader(u):
        i = u
        while not stop.is_set():
            with hosts_lock:
                port = hosts[i % 3].port
            csv, config = unique_bytes(recordings[random.Random(i).randrange(len(recordings))], i)
            body, boundary = multipart(csv, config)
            status, out = request(port, f"/api/v1/recordings?device=SOAK-{i % 7}", body, boundary,
                                  timeout=10)
            with lock:
                attempts[0] += 1
                if status == 201:
                    r = json.loads(out)
                    acknowledged[r["recording"]["id"]] = hashlib.sha256(csv).hexdigest()
                    jobs.add(r["job"]["id"])
            i += uploaders

    threads = [threading.Thread(target=uploader, args=(u,)) for u in range(uploaders)]
    for t in threads:
        t.start()
    rng = random.Random(20261124)
    kills = 0
    end = time.time() + args.duration
    while time.time() < end:
        time.sleep(1 + rng.random())
        h = kills % 3
        fresh = Server(args.bin, db, 2)
        with hosts_lock:
            old, hosts[h] = hosts[h], fresh
        old.kill9()
        kills += 1
    stop.set()
    for t in threads:
        t.join()
    ports = [s.port for s in hosts]
    drained = wait_drained(ports)
    lost = [rid for rid, sha in acknowledged.items()
            if hashlib.sha256(request(ports[0], f"/api/v1/recordings/{rid}/data")[1]).hexdigest()
            != sha]
    not_succeeded = []
    for jid in jobs:
        status, out = request(ports[0], f"/api/v1/jobs/{jid}")
        if status != 200 or json.loads(out)["status"] != "succeeded":
            not_succeeded.append(jid)
    for s in hosts:
        s.term()
    dbname = re.search(r"///(\w+)", db).group(1)
    total, succeeded, results, distinct = cluster.psql(
        dbname, "SELECT COUNT(*), COUNT(*) FILTER (WHERE status = 'succeeded'), "
        "(SELECT COUNT(*) FROM results), (SELECT COUNT(DISTINCT job_id) FROM results) FROM jobs"
    ).split("|")
    ok = (drained and len(acknowledged) > kills and not lost and not not_succeeded
          and total == succeeded == results == distinct)
    print(f"soak: 3 hosts, {args.duration:.0f} s, {kills} kill -9; {attempts[0]} upload attempts, "
          f"{len(acknowledged)} recordings and {len(jobs)} jobs acknowledged; "
          f"lost recordings {len(lost)}, acknowledged jobs not succeeded {len(not_succeeded)}; "
          f"database: {total} jobs, {succeeded} succeeded, {results} results for {distinct} jobs"
          f" -> {'OK' if ok else 'FAILED'}", flush=True)
    return ok


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="build/calibd")
    p.add_argument("--uploads", type=int, default=400)
    p.add_argument("--concurrency", type=int, default=8)
    p.add_argument("--workers", type=int, default=2, help="workers per host (throughput)")
    p.add_argument("--duration", type=float, default=60)
    p.add_argument("--skip-throughput", action="store_true")
    p.add_argument("--skip-soak", action="store_true")
    args = p.parse_args()
    args.bin = os.path.realpath(args.bin)
    root = tempfile.mkdtemp(prefix="calibd-pg-bench-")
    os.chmod(root, 0o755)
    os.environ["TMPDIR"] = root  # calibd on PostgreSQL stages uploads there: removed with it
    cluster = None
    ok = True
    try:
        cluster = Cluster(root)
        recordings = simulate(args.bin, root, 50)
        if not args.skip_throughput:
            ok &= throughput(args, cluster, recordings, root, "sqlite, 1 host",
                             os.path.join(root, "sqlite", "calibd.db"), 1)
            ok &= throughput(args, cluster, recordings, root, "postgresql, 1 host",
                             cluster.new_database(), 1)
            ok &= throughput(args, cluster, recordings, root, "postgresql, 3 hosts",
                             cluster.new_database(), 3)
        if not args.skip_soak:
            ok &= soak(args, cluster, recordings)
    finally:
        if cluster:
            cluster.stop()
        shutil.rmtree(root, ignore_errors=True)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
