#!/usr/bin/env python3
"""The control loop beside a large job history (BENCHMARKS.md, "Trust, round five").

`edmd serve` cuts a long program in real time to the null output while CLIENTS threads read
`GET /api/jobs` as fast as they are answered from a history of MEGABYTES (copies of the line a
real job wrote); meanwhile `GET /api/status` is timed every 100 ms and a hold and its release
are timed three times. Prints the medians and the slowest.

    scripts/history-load.py [BINARY] [MEGABYTES] [CLIENTS] [SECONDS]
        defaults: target/release/edmd 41 4 10
"""
import http.client
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time

repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
binary = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else f"{repo}/target/release/edmd")
megabytes = float(sys.argv[2]) if len(sys.argv) > 2 else 41
clients = int(sys.argv[3]) if len(sys.argv) > 3 else 4
seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 10
port = 18318
work = tempfile.mkdtemp()
os.makedirs(f"{work}/programs")
with open(f"{work}/programs/short.ngc", "w") as f:
    f.write("G21 G90\nG1 X0.2 F600\nM2\n")
with open(f"{work}/programs/long.ngc", "w") as f:
    f.write("G21 G90\n" + "G1 X10 Y0 F120\nG1 X0 Y0\n" * 20 + "M2\n")


def serve():
    sets = {
        "daemon.socket": f'"{work}/edmd.sock"',
        "daemon.program_dir": f'"{work}/programs"',
        "daemon.state_dir": f'"{work}/state"',
        "daemon.http": f'"127.0.0.1:{port}"',
        "daemon.http_token_file": f'"{work}/token"',
        "fine.virtual_time": "false",
        "gap.kind": '"none"',
        "output.kind": '"null"',
        "homing.required": "false",
        "log.format": '"plain"',
    }
    args = [binary, "serve"]
    for k, v in sets.items():
        args += ["--set", f"{k}={v}"]
    log = open(f"{work}/serve.log", "a")
    daemon = subprocess.Popen(args, stderr=log, stdout=subprocess.DEVNULL)
    for _ in range(200):
        if os.path.exists(f"{work}/token"):
            try:
                ask("GET", "/api/status")
                return daemon
            except OSError:
                pass
        time.sleep(0.05)
    raise SystemExit(f"no daemon:\n{open(work + '/serve.log').read()}")


def ask(method, path, body=None):
    token = open(f"{work}/token").read().strip()
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=60)
    headers = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    conn.request(method, path, body=body, headers=headers)
    reply = conn.getresponse()
    data = reply.read()
    conn.close()
    return reply.status, data


def state():
    return json.loads(ask("GET", "/api/status")[1])["status"]["state"]


def wait(what):
    for _ in range(600):
        if state() == what:
            return
        time.sleep(0.05)
    raise SystemExit(f"never {what}: {state()}\n" + open(work + "/serve.log").read()[-3000:])


daemon = None
try:
    # One real job's line, then the history made of its copies.
    daemon = serve()
    ask("POST", "/api/run", json.dumps({"program": "short.ngc"}))
    time.sleep(0.5)
    wait("idle")
    daemon.terminate()
    daemon.wait()
    line = open(f"{work}/state/jobs.jsonl").readline()
    with open(f"{work}/state/jobs.jsonl", "w") as f:
        f.write(line * int(megabytes * 1e6 / len(line)))
    daemon = serve()
    ask("POST", "/api/run", json.dumps({"program": "long.ngc"}))
    wait("running")
    stop = threading.Event()
    pages = [0]

    def reader():
        while not stop.is_set():
            ask("GET", "/api/jobs")
            pages[0] += 1

    threads = [threading.Thread(target=reader) for _ in range(clients)]
    for t in threads:
        t.start()
    statuses, holds = [], []
    started = time.time()
    while time.time() - started < seconds:
        asked = time.time()
        ask("GET", "/api/status")
        statuses.append(time.time() - asked)
        if len(statuses) % 10 == 3:
            asked = time.time()
            ask("POST", "/api/hold", "{}")
            holds.append(time.time() - asked)
            wait("held")
            ask("POST", "/api/resume", json.dumps({"force": False}))
        time.sleep(0.1)
    stop.set()
    for t in threads:
        t.join()
    def ms(xs):
        if not xs:
            return "none answered"
        return f"median {1e3 * statistics.median(xs):.1f} ms, slowest {1e3 * max(xs):.1f} ms"

    print(f"{binary}: "
          f"{megabytes:.0f} MB history, {clients} clients, {pages[0] / (time.time() - started):.1f} job pages/s; "
          f"status {ms(statuses)} ({len(statuses)}); hold {ms(holds)} ({len(holds)})")
    daemon.terminate()
    daemon.wait()
finally:
    if daemon is not None and daemon.poll() is None:
        daemon.kill()
        daemon.wait()
    shutil.rmtree(work, ignore_errors=True)
