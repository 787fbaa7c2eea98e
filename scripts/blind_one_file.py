#!/usr/bin/env python3
"""The blind suite's DC cases as a lab often keeps them: each case's
segments concatenated into one CSV file. Runs `motorbench diagnose` on the
segmented case and on the one file, and prints per source (own cases,
gym-electric-motor) how many verdicts are right each way, how many one-file
records are refused and how many false alarms they give.

    python3 scripts/blind_one_file.py target/blind/seed-7 --bin target/release/motorbench

(generate the suite first with scripts/blind-benchmark.sh SEED). The
one-file CSVs go to SUITE/one-file/.
"""
import argparse
import json
import os
import subprocess


def one_file(suite, case, out):
    rows, last, header = [], float("-inf"), None
    for f in case["files"]:
        for line in open(os.path.join(suite, f)):
            if line.startswith("#"):
                continue
            first = line.split(",")[0]
            try:
                t = float(first)
            except ValueError:
                header = header or line
                continue
            if t > last:  # segments that share their boundary sample give it once
                last = t
                rows.append(line)
    path = os.path.join(out, case["id"] + ".csv")
    with open(path, "w") as fh:
        fh.write(header + "".join(rows))
    return path


def verdict(binary, files):
    r = subprocess.run([binary, "diagnose", "--kind", "dc_step", "--json", *files],
                       capture_output=True, text=True)
    if r.returncode != 0:
        return "refused: " + r.stderr.strip()[:100]
    return json.loads(r.stdout)["verdict"]["effect"]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("suite")
    ap.add_argument("--bin", default="target/release/motorbench")
    a = ap.parse_args()
    cases = json.load(open(os.path.join(a.suite, "cases.json")))["cases"]
    truth = dict(json.load(open(os.path.join(a.suite, "truth.json")))["cases"])
    out = os.path.join(a.suite, "one-file")
    os.makedirs(out, exist_ok=True)
    rows = []
    for c in cases:
        if c["kind"] != "dc_step":
            continue
        want = truth[c["id"]]["effect"]
        seg = verdict(a.bin, [os.path.join(a.suite, f) for f in c["files"]])
        one = verdict(a.bin, [one_file(a.suite, c, out)])
        rows.append((c["id"], want, seg, one))
        print(f"{c['id']:10} truth {want:22} segmented {seg:22} one file {one}", flush=True)
    print()
    for name, prefix in (("motorbench", "case"), ("gym-electric-motor", "gem")):
        r = [x for x in rows if x[0].startswith(prefix)]
        right_seg = sum(x[1] == x[2] for x in r)
        right_one = sum(x[1] == x[3] for x in r)
        refused = sum(x[3].startswith("refused") for x in r)
        alarms = sum(x[1] == "none" and x[3] not in ("none",) and not x[3].startswith("refused")
                     for x in r)
        print(f"{name:20} cases {len(r):3}  right segmented {right_seg:3}  right one file "
              f"{right_one:3}  one-file refused {refused:3}  one-file false alarms {alarms}")


if __name__ == "__main__":
    main()
