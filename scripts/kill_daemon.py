#!/usr/bin/env python3
"""Kill loop of the daemon (`scripts/kill-loop.sh --daemon` runs it).

Starts `motorbench serve` on config/sim-dc-daemon.toml (with --im also
config/sim-im.toml, the rigs alternating) with one records directory for
the whole loop, starts a test through the HTTP API, sends the daemon
SIGKILL after a delay drawn (seeded) uniformly over a test's whole cycle
(the plan, the identification, the diagnosis, the report files, and a
tenth more: some kills find the daemon idle), restarts it on the same
records directory and checks, after every restart:

- the daemon starts and answers (`GET /v1/health` 200, every rig `idle`,
  no latch);
- the index (`index.json` and `GET /v1/records`, which must agree) is
  consistent with the files: every file an entry names exists, every
  `.mcap` in the directory has an entry, no entry is left `running`;
- no finished record is marked lost: every entry that was `completed`
  or `aborted` before the kill keeps its outcome and key results; the
  killed test's entry is `interrupted` only when its record is cut before
  the plan's end, `unanalysed` (or finished) when the plan had ended;
- the killed test's record replays (`motorbench replay --no-diagnose`,
  exit 0, or 4 when too little was flushed to identify from); a copy
  finished by `motorbench recover --out` opens in the Python seeking
  reader; `kill_check.py` measures the data lost.

Writes one JSON line per kill to WORK/results.jsonl and prints a summary.
The simulated power stage runs inside the daemon: the SIGKILL ends it
with the process, so its watchdog (the heartbeat) cannot be observed
from outside here; see docs/reliability.md.
"""

import argparse
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import time
import urllib.error
import urllib.request

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
FINISHED = ("completed", "aborted")
# The IM sweep shortened as in the soak (the full sweep takes minutes).
IM_OVERRIDE = {"voltages_V": [100], "points": 6, "cooldown_s": 1}


def request(url, method="GET", body=None, timeout=30):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method)
    if data is not None:
        req.add_header("Content-Type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"null")


class Daemon:
    """One `motorbench serve` process on the loop's records directory."""

    def __init__(self, a, life):
        self.log = open(os.path.join(a.work, f"serve-{life}.log"), "w")
        cmd = [a.bin, "serve", "--records", a.records, "--listen", "127.0.0.1:0"]
        for c in a.configs:
            cmd += ["--config", c]
        t0 = time.monotonic()
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.log, text=True)
        line = self.proc.stdout.readline()
        if not line.startswith("listening on "):
            self.proc.kill()
            raise SystemExit(f"kill-loop: the daemon announced no address ({line!r}); "
                             f"see {self.log.name}")
        self.url = line.split("listening on ", 1)[1].strip()
        self.start_s = time.monotonic() - t0

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        self.proc.stdout.close()
        self.log.close()

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait()
        self.proc.stdout.close()
        self.log.close()


def start_test(d, rig):
    body = {"test": IM_OVERRIDE} if rig == "sim-im" else None
    code, started = request(f"{d.url}/v1/rigs/{rig}/tests", "POST", body)
    if code != 201:
        raise SystemExit(f"kill-loop: starting a test on {rig} answered {code}: {started}")
    return started["id"]


def state_of(d, tid):
    code, st = request(f"{d.url}/v1/tests/{tid}", timeout=5)
    return st.get("state") if code == 200 else None


def read_index(records):
    with open(os.path.join(records, "index.json")) as f:
        return {e["name"]: e for e in json.load(f)["records"]}


def consistency(d, records, before, killed_name):
    """Problems with the index after a restart (empty: consistent)."""
    problems = []
    index = read_index(records)
    code, listed = request(f"{d.url}/v1/records")
    api = {e["name"]: e for e in listed["records"]} if code == 200 else {}
    if api != index:
        problems.append("GET /v1/records differs from index.json")
    for name, e in index.items():
        for key in ("mcap", "report", "svg", "residuals_svg"):
            f = e.get(key)
            if f and not os.path.exists(os.path.join(records, f)):
                problems.append(f"{name}: {key} {f} does not exist")
        if e["outcome"] == "running":
            problems.append(f"{name}: still running after the restart")
    for f in os.listdir(records):
        if f.endswith(".mcap") and f[:-5] not in index:
            problems.append(f"{f}: no index entry")
    for name, e in before.items():
        if e["outcome"] in FINISHED:
            now = index.get(name)
            if now is None:
                problems.append(f"{name}: finished before the kill, gone from the index")
            elif now["outcome"] != e["outcome"] or now.get("key_results") != e.get("key_results"):
                problems.append(f"{name}: finished ({e['outcome']}) before the kill, "
                                f"now {now['outcome']}")
    return problems, index.get(killed_name) if killed_name else None


def run_check(a, cmd):
    r = subprocess.run([a.python, os.path.join(HERE, "kill_check.py")] + cmd,
                       capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def check_record(a, i, rec, kill_ns, test_end_s):
    """Replay the killed test's record, measure the loss, recover a copy."""
    out = {}
    with open(os.path.join(a.work, f"replay-{i}.out"), "w") as f:
        out["replay_rc"] = subprocess.run([a.bin, "replay", "--no-diagnose", rec],
                                          stdout=f, stderr=subprocess.STDOUT).returncode
    out.update(run_check(a, ["check", rec, "--kill-unix-ns", str(kill_ns),
                             "--test-end-s", str(test_end_s)]))
    copy = os.path.join(a.work, f"recovered-{i}.mcap")
    with open(os.path.join(a.work, f"recover-{i}.out"), "w") as f:
        out["recover_rc"] = subprocess.run([a.bin, "recover", rec, "--out", copy],
                                           stdout=f, stderr=subprocess.STDOUT).returncode
    # A whole record is left as it is (no copy): open the record itself.
    out.update(run_check(a, ["recovered", copy if os.path.exists(copy) else rec]))
    if os.path.exists(copy):
        os.remove(copy)
    return out


def reference(a, rigs):
    """One uninterrupted test per rig: its cycle (start to finished) and
    its test's length (data time of the last sample)."""
    d = Daemon(a, 0)
    cycles, ends = {}, {}
    for rig in rigs:
        t0 = time.monotonic()
        tid = start_test(d, rig)
        while state_of(d, tid) != "finished":
            time.sleep(0.1)
        cycles[rig] = time.monotonic() - t0
        rec = os.path.join(a.records, read_index(a.records)[tid]["mcap"])
        ends[rig] = run_check(a, ["check", rec, "--kill-unix-ns", "0",
                                  "--test-end-s", "1e9"])["last_sample_t_s"]
        print(f"reference {rig}: {cycles[rig]:.1f} s start to finished, test {ends[rig]} s "
              f"of data; daemon start {d.start_s:.2f} s", flush=True)
    d.stop()
    return cycles, ends


def summary(a, rows, restart_s):
    print()
    print(f"{'#':>3} {'rig':>13} {'kill s':>7} {'state':>11} {'entry':>11} {'lost s':>6} "
          f"{'replay':>6} {'seek':>5} problems")
    for r in rows:
        print(f"{r['i']:>3} {r['rig']:>13} {r['delay_s']:>7.3f} {str(r['state']):>11} "
              f"{str(r['entry_outcome']):>11} {r.get('lost_s', float('nan')):>6.3f} "
              f"{str(r.get('replay_rc', '-')):>6} "
              f"{'yes' if r.get('recovered_seeking') else 'no':>5} "
              + "; ".join(r["problems"]))
    with_rec = [r for r in rows if r.get("record")]
    replayed = [r for r in with_rec if r.get("replay_rc") in (0, 4)]
    seek = sum(bool(r.get("recovered_seeking")) for r in with_rec)
    during = [r for r in with_rec if r["state"] == "running" and "lost_s" in r]
    outcomes = {}
    for r in rows:
        outcomes[str(r["entry_outcome"])] = outcomes.get(str(r["entry_outcome"]), 0) + 1
    states = {}
    for r in rows:
        states[str(r["state"])] = states.get(str(r["state"]), 0) + 1
    print()
    print(f"kills: {len(rows)}; test state at the kill: "
          + ", ".join(f"{k} {v}" for k, v in sorted(states.items())))
    print(f"daemon restarts that answered: {sum(r['restart_ok'] for r in rows)} / {len(rows)}; "
          f"restart to listening, s: min {min(restart_s):.2f}, median "
          f"{statistics.median(restart_s):.2f}, max {max(restart_s):.2f}")
    print(f"killed test's index entry after the restart: "
          + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    print(f"records replayed (motorbench replay, exit 0 or 4): {len(replayed)} / {len(with_rec)}")
    print(f"seeking reader opens the record after motorbench recover --out: {seek} / {len(with_rec)}")
    if during:
        lost = [r["lost_s"] for r in during]
        print(f"kills during the plan: {len(during)}; data lost per kill, s: min {min(lost):.3f}, "
              f"median {statistics.median(lost):.3f}, max {max(lost):.3f}")
    after = [r for r in with_rec if r["state"] != "running"]
    if after:
        res = sum(bool(r.get("result")) for r in after)
        outs = {}
        for r in after:
            outs[str(r["entry_outcome"])] = outs.get(str(r["entry_outcome"]), 0) + 1
        print(f"kills after the plan ended (identifying or finished): {len(after)}; "
              f"/bench/result in the record: {res}; their entries: "
              + ", ".join(f"{k} {v}" for k, v in sorted(outs.items())))
    bad = [r for r in rows if r["problems"]]
    print(f"index checks failed after {len(bad)} / {len(rows)} restarts")
    final = read_index(a.records)
    by = {}
    for e in final.values():
        by[e["outcome"]] = by.get(e["outcome"], 0) + 1
    print(f"index at the end: {len(final)} entries: "
          + ", ".join(f"{k} {v}" for k, v in sorted(by.items())))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin", required=True)
    p.add_argument("--python", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--kills", type=int, default=50)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--im", action="store_true", help="alternate the DC and the IM rig")
    a = p.parse_args()
    a.records = os.path.join(a.work, "records")
    os.makedirs(a.records, exist_ok=True)
    a.configs = [os.path.join(ROOT, "config", "sim-dc-daemon.toml")]
    rigs = ["sim-dc-daemon"]
    if a.im:
        a.configs.append(os.path.join(ROOT, "config", "sim-im.toml"))
        rigs.append("sim-im")
    cycles, ends = reference(a, rigs)
    rng = random.Random(a.seed)
    rows, restart_s = [], []
    results = open(os.path.join(a.work, "results.jsonl"), "w")
    d = Daemon(a, 1)
    restart_s.append(d.start_s)
    for i in range(1, a.kills + 1):
        rig = rigs[(i - 1) % len(rigs)]
        delay = rng.uniform(0, cycles[rig] * 1.1)
        tid = start_test(d, rig)
        t0 = time.monotonic()
        state = "running"
        # Poll the state until the kill: the last one seen is the state at the kill.
        while time.monotonic() - t0 < delay:
            s = state_of(d, tid)
            state = s or state
            time.sleep(min(0.05, max(0.0, delay - (time.monotonic() - t0))))
        before = read_index(a.records)
        kill_ns = time.time_ns()
        d.kill()
        row = {"i": i, "rig": rig, "delay_s": round(delay, 3), "state": state, "name": tid}
        d = Daemon(a, i + 1)
        restart_s.append(d.start_s)
        code, health = request(f"{d.url}/v1/health")
        _, rl = request(f"{d.url}/v1/rigs")
        idle = all(r["state"] == "idle" and r["trip"] is None for r in rl["rigs"])
        row["restart_ok"] = code == 200 and idle
        problems, entry = consistency(d, a.records, before, tid)
        if not row["restart_ok"]:
            problems.append(f"after the restart: health {code}, rigs {rl}")
        row["entry_outcome"] = entry["outcome"] if entry else None
        rec = os.path.join(a.records, f"{tid}.mcap")
        row["record"] = os.path.exists(rec)
        if row["record"]:
            row.update(check_record(a, i, rec, kill_ns, ends[rig]))
            cut = bool(row.get("damage"))
            # Finished data marked lost: a plan that had ended (the record
            # holds the test's end) must not be marked interrupted.
            if entry and entry["outcome"] == "interrupted" and state != "running":
                problems.append(f"{tid}: the plan had ended ({state}) but marked interrupted")
            # A cut record is indexed as finished only when it holds its
            # result (the identification, written before the diagnosis),
            # with a reason saying what is missing; one that holds its
            # result is never indexed as if it had none.
            if entry and entry["outcome"] in FINISHED and cut and not (
                    row.get("result") and entry.get("reason")):
                problems.append(f"{tid}: marked {entry['outcome']} but the record is cut "
                                f"(result in it: {row.get('result')})")
            if entry and entry["outcome"] in ("unanalysed", "interrupted") and row.get("result"):
                problems.append(f"{tid}: its record holds /bench/result but it is marked "
                                f"{entry['outcome']}")
            if entry and entry["outcome"] in FINISHED and not entry.get("key_results") \
                    and row.get("result"):
                problems.append(f"{tid}: {entry['outcome']} without key results")
            if row.get("replay_rc") not in (0, 4):
                problems.append(f"{tid}: replay exit {row.get('replay_rc')}")
            if not row.get("recovered_seeking"):
                problems.append(f"{tid}: the seeking reader does not open the recovered copy")
        elif entry:
            problems.append(f"{tid}: entry without a record")
        row["problems"] = problems
        results.write(json.dumps(row) + "\n")
        results.flush()
        rows.append(row)
        print(f"kill {i} ({rig}) at {delay:.3f} s, {state}: entry {row['entry_outcome']}, "
              f"lost {row.get('lost_s', '-')} s, replay {row.get('replay_rc', '-')}, "
              f"seeking reader after recover: {row.get('recovered_seeking')}"
              + (f"; PROBLEMS: {'; '.join(problems)}" if problems else ""), flush=True)
    d.stop()
    results.close()
    summary(a, rows, restart_s)
    print(f"results: {os.path.join(a.work, 'results.jsonl')}; records: {a.records}")
    if any(r["problems"] for r in rows):
        sys.exit(1)


if __name__ == "__main__":
    main()
