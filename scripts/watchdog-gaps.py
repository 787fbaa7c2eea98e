#!/usr/bin/env python3
"""Measure the systemd watchdog's petting gaps of `motorbench serve`.

Starts the daemon (the release build by default) on the simulated rig
with a fake systemd notification socket and the shipped unit's
WatchdogSec=5s (WATCHDOG_USEC=5000000, so the daemon pets every 2.5 s),
runs N tests back to back through the API (the full default plan unless
--levels is given), and prints the largest gap between two WATCHDOG=1
messages per test and over the whole run. systemd would kill the daemon
at a gap of 5 s.

    scripts/watchdog-gaps.py [--bin target/release/motorbench] [--tests 50]

Standard library only; loopback only.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

WATCHDOG_USEC = 5_000_000


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default="target/release/motorbench")
    ap.add_argument("--config", default="config/sim-dc.toml")
    ap.add_argument("--tests", type=int, default=50)
    ap.add_argument("--levels", help="comma-separated levels in V (default: the full plan)")
    args = ap.parse_args()

    work = tempfile.mkdtemp(prefix="watchdog-gaps-")
    notify_path = os.path.join(work, "notify")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(notify_path)
    pets = []
    stop = threading.Event()

    def listen():
        sock.settimeout(0.2)
        while not stop.is_set():
            try:
                msg = sock.recv(4096).decode(errors="replace")
            except socket.timeout:
                continue
            if "WATCHDOG=1" in msg:
                pets.append(time.monotonic())

    threading.Thread(target=listen, daemon=True).start()
    env = dict(os.environ, NOTIFY_SOCKET=notify_path, WATCHDOG_USEC=str(WATCHDOG_USEC))
    rig = os.path.join(work, "rig.toml")
    with open(args.config) as src, open(rig, "w") as dst:
        dst.write(src.read())
    daemon = subprocess.Popen(
        [args.bin, "serve", "--config", rig, "--records", os.path.join(work, "records"),
         "--listen", "127.0.0.1:0"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    line = daemon.stdout.readline()
    if not line.startswith("listening on http://"):
        sys.exit(f"the daemon did not start: {line!r}")
    base = line.split("listening on ", 1)[1].strip()

    def call(method, path, body=None):
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(base + path, data=data, method=method,
                                     headers={"content-type": "application/json"})
        with urllib.request.urlopen(req, timeout=30) as r:
            return json.loads(r.read() or b"null")

    plan = None
    if args.levels:
        plan = {"test": {"levels_V": [float(v) for v in args.levels.split(",")],
                         "coastdown": False}}
    worst = []
    try:
        for k in range(args.tests):
            first = len(pets)
            t = call("POST", "/v1/rigs/rig/tests", plan)
            while call("GET", f"/v1/tests/{t['id']}")["state"] != "finished":
                time.sleep(0.2)
            mine = pets[max(first - 1, 0):]
            gap = max((b - a for a, b in zip(mine, mine[1:])), default=0.0)
            worst.append(gap)
            print(f"test {k}: largest gap {gap:.3f} s", flush=True)
    finally:
        daemon.terminate()
        daemon.wait(timeout=60)
        stop.set()
    gaps = [b - a for a, b in zip(pets, pets[1:])]
    print(f"WATCHDOG GAPS over {args.tests} tests (WatchdogSec=5s, petting every 2.5 s): "
          f"{len(pets)} pets, largest gap {max(gaps, default=0):.3f} s, "
          f"over 2.6 s: {sum(g > 2.6 for g in gaps)}, over 5 s: {sum(g > 5 for g in gaps)}")
    sys.exit(1 if any(g > 5 for g in gaps) else 0)


if __name__ == "__main__":
    main()
