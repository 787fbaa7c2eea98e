#!/usr/bin/env python3
"""Drive a running `motorbench serve` through its HTTP API (used by soak.sh).

Runs N tests back to back, alternating over the rigs given (`--rig NAME`
with an optional JSON `[test]` override per rig, `--override NAME=JSON`),
waits for each to finish, then samples the daemon's RSS (VmRSS, and its
anonymous and file-backed parts RssAnon and RssFile), thread count
(/proc/PID/status), open descriptors (/proc/PID/fd) and, when its
/metrics has it, the tasks alive in its runtime
(motorbench_runtime_alive_tasks; -1 when not). Writes one CSV row per
test and prints the RSS slopes per test over the second half (least
squares) and the fd, thread and task counts first vs last.
"""

import argparse
import csv
import json
import os
import sys
import time
import urllib.error
import urllib.request


def request(url, method="GET", body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")


def sample(pid):
    status = open(f"/proc/{pid}/status").read().splitlines()
    fields = dict(line.split(":", 1) for line in status if ":" in line)
    kb = lambda key: int(fields[key].split()[0])  # noqa: E731
    threads = int(fields["Threads"])
    fds = len(os.listdir(f"/proc/{pid}/fd"))
    return kb("VmRSS"), threads, fds, kb("RssAnon"), kb("RssFile")


def alive_tasks(api):
    """motorbench_runtime_alive_tasks from /metrics, or -1."""
    try:
        with urllib.request.urlopen(f"{api}/metrics", timeout=30) as r:
            for line in r.read().decode().splitlines():
                if line.startswith("motorbench_runtime_alive_tasks "):
                    return int(float(line.split()[1]))
    except (urllib.error.URLError, ValueError):
        pass
    return -1


def slope(xs, ys):
    n = len(xs)
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    if sxx == 0:
        return 0.0
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx


def run_one(api, rig, override):
    body = {"test": override} if override else None
    while True:
        code, started = request(f"{api}/v1/rigs/{rig}/tests", "POST", body)
        if code == 201:
            break
        if code == 409 and started.get("error") == "busy":
            time.sleep(0.1)
            continue
        if code == 409 and started.get("error") == "tripped":
            # A supervisor trip latched the rig (e.g. the winding estimate
            # reached its limit): say so, clear the latch, go on.
            print(f"soak: {rig} tripped: {started['trip']['message']}; reset", file=sys.stderr)
            request(f"{api}/v1/rigs/{rig}/reset", "POST")
            continue
        raise SystemExit(f"soak: start on {rig} answered {code}: {started}")
    tid = started["id"]
    while True:
        code, st = request(f"{api}/v1/tests/{tid}")
        if code == 200 and st["state"] == "finished":
            return tid, st.get("outcome"), st.get("reason")
        time.sleep(0.1)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--url", required=True, help="http://127.0.0.1:PORT")
    p.add_argument("--pid", type=int, required=True, help="the daemon's process id")
    p.add_argument("--rig", action="append", required=True)
    p.add_argument("--override", action="append", default=[], help="RIG=JSON")
    p.add_argument("--tests", type=int, default=1000)
    p.add_argument("--minutes", type=float, default=None, help="stop after this long")
    p.add_argument("--csv", required=True)
    a = p.parse_args()
    overrides = {}
    for o in a.override:
        rig, js = o.split("=", 1)
        overrides[rig] = json.loads(js)

    rows = []
    rss0, th0, fd0, anon0, file0 = sample(a.pid)
    print(f"before the first test: RSS {rss0} kB (anon {anon0}, file {file0}), threads {th0}, "
          f"fds {fd0}, tasks {alive_tasks(a.url)}")
    t0 = time.monotonic()
    outcomes = {}
    with open(a.csv, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["test", "rig", "id", "outcome", "seconds", "rss_kb", "threads", "fds",
                    "rss_anon_kb", "rss_file_kb", "tasks"])
        for i in range(1, a.tests + 1):
            if a.minutes is not None and time.monotonic() - t0 > a.minutes * 60:
                break
            rig = a.rig[(i - 1) % len(a.rig)]
            ts = time.monotonic()
            tid, outcome, reason = run_one(a.url, rig, overrides.get(rig))
            tasks = alive_tasks(a.url)
            rss, th, fds, anon, file_kb = sample(a.pid)
            key = f"{rig}:{outcome}"
            outcomes[key] = outcomes.get(key, 0) + 1
            if outcome != "completed":
                print(f"test {i} ({rig}) {outcome}: {reason}", file=sys.stderr)
            row = [i, rig, tid, outcome, round(time.monotonic() - ts, 2), rss, th, fds,
                   anon, file_kb, tasks]
            w.writerow(row)
            f.flush()
            rows.append(row)
            if i % 25 == 0:
                print(f"test {i}: RSS {rss} kB (anon {anon}), threads {th}, fds {fds}, "
                      f"tasks {tasks}", flush=True)

    n = len(rows)
    print(f"\ntests run: {n} in {time.monotonic() - t0:.0f} s; outcomes: {outcomes}")
    if n == 0:
        return
    half = rows[n // 2:]
    s = slope([r[0] for r in half], [r[5] for r in half])
    print(f"RSS: first {rows[0][5]} kB, last {rows[-1][5]} kB, max {max(r[5] for r in rows)} kB")
    print(f"RSS slope over tests {half[0][0]}..{half[-1][0]} (least squares): {s:.2f} kB/test")
    sa = slope([r[0] for r in half], [r[8] for r in half])
    print(f"RssAnon: first {rows[0][8]} kB, last {rows[-1][8]} kB; slope {sa:.2f} kB/test; "
          f"RssFile: first {rows[0][9]} kB, last {rows[-1][9]} kB")
    print(f"tasks: first {rows[0][10]}, last {rows[-1][10]}, max {max(r[10] for r in rows)}")
    print(f"threads: first {rows[0][6]}, last {rows[-1][6]}, max {max(r[6] for r in rows)}")
    print(f"fds: first {rows[0][7]}, last {rows[-1][7]}, max {max(r[7] for r in rows)}")


if __name__ == "__main__":
    main()
