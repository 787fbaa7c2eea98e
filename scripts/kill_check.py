#!/usr/bin/env python3
"""Check one record left by a killed `motorbench run` (used by kill-loop.sh).

Opens the MCAP with the Python `mcap` package: first the seeking reader
(it needs the summary and footer a finished record ends with), else the
non-seeking reader, which reads the chunks in file order up to the first
damage (a killed writer leaves a cut chunk at the end). Prints one JSON
object:

- reader: "seeking", "non-seeking" or "none" (not even the header read)
- messages, last_sample_t_s (test time of the last /sensor/ or /command/
  sample), result (whether /bench/result is in the readable part)
- kill_t_s: the kill's wall-clock time relative to the record's start
  (metadata motorbench.test start_time_ns)
- `recovered RECORD` (after `motorbench recover`): whether the seeking
  reader now opens it and how many messages it reads
- lost_s: min(kill_t_s, test_end) - last_sample_t_s, the test time of
  data the kill lost. test_end is the length of an uninterrupted run's
  test (--test-end-s), or sooner when the readable part has an error
  event (the supervisor stopped the test: "stop" gives its message); a
  kill after the test's end loses no samples, only what was not written.
"""

import argparse
import json
import statistics
import sys

from mcap.reader import NonSeekingReader, SeekingReader
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import StreamReader


def seeking_opens(path):
    """True when the seeking reader opens the file and reads every message."""
    return seeking_count(path) is not None


def walk(path):
    """Read records in file order up to the first damage."""
    out = {
        "messages": 0,
        "start_ns": None,
        "last_sample_ns": None,
        "result": False,
        "stop_ns": None,
        "stop": None,
        "damage": None,
        "header": False,
    }
    topics = {}
    try:
        with open(path, "rb") as f:
            for record in StreamReader(f).records:
                out["header"] = True
                if isinstance(record, Metadata) and record.name == "motorbench.test":
                    out["start_ns"] = int(record.metadata["start_time_ns"])
                elif isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    out["messages"] += 1
                    topic = topics.get(record.channel_id, "")
                    if topic.startswith("/sensor/") or topic.startswith("/command/"):
                        t = record.log_time
                        if out["last_sample_ns"] is None or t > out["last_sample_ns"]:
                            out["last_sample_ns"] = t
                    elif topic == "/bench/result":
                        out["result"] = True
                    elif topic == "/bench/event" and out["stop_ns"] is None:
                        event = json.loads(record.data)
                        if event.get("level", 0) >= 4:  # error: the test stopped
                            out["stop_ns"] = record.log_time
                            out["stop"] = event.get("message", "")[:80]
    except Exception as e:  # noqa: BLE001 - the damage ends the readable part
        out["damage"] = f"{type(e).__name__}: {e}"
    return out


def nonseeking_count(path):
    """Messages the package's NonSeekingReader yields before the damage."""
    n = 0
    try:
        with open(path, "rb") as f:
            for _ in NonSeekingReader(f).iter_messages(log_time_order=False):
                n += 1
    except Exception:  # noqa: BLE001
        pass
    return n


def seeking_count(path):
    """Messages the seeking reader reads, or None when it does not open."""
    try:
        with open(path, "rb") as f:
            reader = SeekingReader(f)
            if reader.get_summary() is None:
                return None
            return sum(1 for _ in reader.iter_messages(log_time_order=False))
    except Exception:  # noqa: BLE001 - any failure means "does not open"
        return None


def recovered(a):
    """After `motorbench recover`: does the seeking reader open the record,
    and does it read as many messages as the cut file held?"""
    n = seeking_count(a.record)
    json.dump({"recovered_seeking": n is not None, "recovered_messages": n}, sys.stdout)
    print()


def check(a):
    w = walk(a.record)
    if seeking_opens(a.record):
        reader = "seeking"
    elif w["header"] and nonseeking_count(a.record) > 0:
        reader = "non-seeking"
    else:
        reader = "none"
    res = {
        "reader": reader,
        "messages": w["messages"],
        "result": w["result"],
        "damage": w["damage"],
    }
    if w["start_ns"] is not None:
        kill_t = (a.kill_unix_ns - w["start_ns"]) / 1e9
        test_end = a.test_end_s
        if w["stop_ns"] is not None:
            test_end = min(test_end, (w["stop_ns"] - w["start_ns"]) / 1e9)
            res["stop"] = w["stop"]
        res["kill_t_s"] = round(kill_t, 3)
        res["test_end_s"] = round(test_end, 3)
        res["after_test"] = kill_t >= test_end
        last = 0.0  # no sample yet: all the test time before the kill is lost
        if w["last_sample_ns"] is not None:
            last = (w["last_sample_ns"] - w["start_ns"]) / 1e9
            res["last_sample_t_s"] = round(last, 3)
        res["lost_s"] = round(max(0.0, min(kill_t, test_end) - last), 3)
    json.dump(res, sys.stdout)
    print()


def summary(a):
    rows = [json.loads(line) for line in open(a.results) if line.strip()]
    killed = [r for r in rows if r["status"] == "killed"]
    with_rec = [r for r in killed if r.get("record")]
    replayed = [r for r in with_rec if r.get("replay_rc") in (0, 4)]
    readers = {}
    for r in with_rec:
        readers[r.get("reader", "none")] = readers.get(r.get("reader", "none"), 0) + 1
    during = [r for r in with_rec if "lost_s" in r and not r.get("after_test")]
    after = [r for r in with_rec if r.get("after_test")]
    print(f"{'#':>3} {'kill at s':>9} {'test t s':>8} {'last s':>7} {'lost s':>6} "
          f"{'replay':>6} {'reader':>11} {'result':>6} files")
    for r in rows:
        if r["status"] != "killed":
            print(f"{r['i']:>3} {r['delay_s']:>9.3f}  {r['status']}")
            continue
        print(f"{r['i']:>3} {r['delay_s']:>9.3f} {r.get('kill_t_s', float('nan')):>8.3f} "
              f"{r.get('last_sample_t_s', float('nan')):>7.3f} {r.get('lost_s', float('nan')):>6.3f} "
              f"{str(r.get('replay_rc', '-')):>6} {r.get('reader', '-'):>11} "
              f"{'yes' if r.get('result') else 'no':>6} {r.get('files', '')}"
              + (f" [stopped: {r['stop']}]" if r.get("stop") else ""))
    print()
    print(f"runs: {len(rows)}; killed: {len(killed)}; finished before the kill: "
          f"{sum(r['status'] == 'finished' for r in rows)}")
    print(f"killed before the record existed: {len(killed) - len(with_rec)}")
    print(f"records recovered (motorbench replay reads them, exit 0 or 4): "
          f"{len(replayed)} / {len(with_rec)}")
    print("python mcap reader that opens them: "
          + ", ".join(f"{k} {v}" for k, v in sorted(readers.items())))
    rec = [r for r in with_rec if "recover_rc" in r]
    if rec:
        opens = sum(bool(r.get("recovered_seeking")) for r in rec)
        same = sum(r.get("recovered_messages") == r.get("messages") for r in rec)
        print(f"after motorbench recover: seeking reader opens {opens} / {len(rec)}; "
              f"same message count as the cut file in {same} / {len(rec)}")
    if during:
        lost = [r["lost_s"] for r in during]
        print(f"kills during the test: {len(during)}; data lost per kill, s: "
              f"min {min(lost):.3f}, median {statistics.median(lost):.3f}, max {max(lost):.3f}")
    stopped = [r for r in with_rec if r.get("stop")]
    if stopped:
        print(f"runs the safety supervisor stopped before the kill (test end taken "
              f"from the stop event): {len(stopped)}")
    if after:
        res = sum(bool(r.get("result")) for r in after)
        print(f"kills after the test ended: {len(after)}; /bench/result present in {res}; "
              f"samples lost: max {max(r.get('lost_s', 0) for r in after):.3f} s")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("check", help="check one record")
    c.add_argument("record")
    c.add_argument("--kill-unix-ns", type=int, required=True)
    c.add_argument("--test-end-s", type=float, required=True)
    r = sub.add_parser("recovered", help="check one record after motorbench recover")
    r.add_argument("record")
    s = sub.add_parser("summary", help="summarise kill-loop results (JSON lines)")
    s.add_argument("results")
    a = p.parse_args()
    {"check": check, "recovered": recovered, "summary": summary}[a.cmd](a)


if __name__ == "__main__":
    main()
