"""Runs every row of the peer comparison, motorbench and its Python peer
alternating on the same data, and prints `ratio <name> <median> same=<yes|no>`
per row and a table (ratio = Python time / motorbench time, per round, the
median over the rounds). Called by compare.sh, which builds motorbench,
installs the peers and pins their BLAS to one thread.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
MCAP_SAMPLES = 1_540_000
TARGETS = {"dc_fit": 30.0, "im_fit": 50.0, "mcap_write": 10.0, "mcap_read": 20.0}


def run_json(cmd):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def same_params(a, b, tol=1e-6):
    worst = max(abs(x - y) / abs(y) for x, y in zip(a, b))
    return worst <= tol, worst


class Rows:
    def __init__(self, args):
        self.peers = args.peers
        self.motorbench = args.motorbench
        self.work = args.work
        self.py = sys.executable
        self.rounds = args.rounds
        os.makedirs(self.work, exist_ok=True)

    def path(self, name):
        return os.path.join(self.work, name)

    def alternate(self, ours, theirs):
        """`rounds` times: motorbench's side, then the peer's."""
        pairs = []
        for k in range(self.rounds):
            a = run_json(ours)
            b = run_json(theirs)
            pairs.append((a, b))
            print(f"  round {k + 1}: motorbench {a['seconds']:.4f} s, Python {b['seconds']:.4f} s",
                  file=sys.stderr)
        return pairs

    def dc_record(self):
        out = self.path("dc")
        if not os.path.isdir(out) or not any(f.endswith(".mcap") for f in os.listdir(out)):
            subprocess.run([self.motorbench, "run", "--no-diagnose", "--out", out],
                           check=True, capture_output=True)
        return os.path.join(out, sorted(f for f in os.listdir(out) if f.endswith(".mcap"))[0])

    def fit_row(self, subcommand, args, script, problem):
        """A fit row: motorbench's side writes the problem, then both
        alternate on it; the last round's answers."""
        run_json([self.peers, subcommand, *args, problem])  # writes the problem
        pairs = self.alternate([self.peers, subcommand, *args, problem],
                               [self.py, os.path.join(HERE, script), problem])
        return pairs, pairs[-1]

    def dc_fit(self):
        pairs, (a, b) = self.fit_row("dc-fit", [self.dc_record()], "dc_fit.py",
                                     self.path("dc_problem.json"))
        ok, worst = same_params(b["params"], a["params"])
        # The row times the optimisers alone; the whole fit a user calls
        # (noise estimate, segment starts, intervals, plot traces) beside.
        whole = sorted(p[0]["whole_fit_seconds"] for p in pairs)[len(pairs) // 2]
        peer = sorted(p[1]["seconds"] for p in pairs)[len(pairs) // 2]
        what = (f"{a['segments']} segments, {a['samples']} samples; "
                f"largest relative difference of the optimum {worst:.1e}; "
                f"motorbench's whole fit (intervals and all) {whole * 1e3:.1f} ms, "
                f"{peer / whole:.1f}x")
        return pairs, ok, what

    def im_fit(self):
        pairs, (a, b) = self.fit_row("im-fit", [], "im_fit.py", self.path("im_problem.json"))
        ok, worst = same_params(b["prediction"], a["prediction"])
        what = (f"{a['points']} points, {a['starts']} starts each side; largest relative "
                f"difference of the fitted current and power {worst:.1e}")
        return pairs, ok, what

    def mcap_write(self):
        ours, theirs = self.path("write_motorbench.mcap"), self.path("write_python.mcap")
        reference = self.path("write_reference.mcap")
        run_json([self.peers, "mcap-write", reference, "4"])
        pairs = self.alternate(
            [self.peers, "mcap-write", ours, str(MCAP_SAMPLES)],
            [self.py, os.path.join(HERE, "mcap_write.py"), reference, theirs, str(MCAP_SAMPLES)])
        # Both files read back by motorbench's reader (the contract's
        # checks included): the same samples, the same values.
        a = run_json([self.peers, "mcap-read", ours])
        b = run_json([self.peers, "mcap-read", theirs])
        ok = a["samples"] == b["samples"] == MCAP_SAMPLES and a["sum"] == b["sum"]
        what = (f"{a['samples']} samples each, read back; values summed in file order "
                f"{a['sum']:.6f} / {b['sum']:.6f}")
        return pairs, ok, what

    def mcap_read(self):
        record = self.path("write_motorbench.mcap")
        if not os.path.exists(record):
            run_json([self.peers, "mcap-write", record, str(MCAP_SAMPLES)])
        pairs = self.alternate([self.peers, "mcap-read", record],
                               [self.py, os.path.join(HERE, "mcap_read.py"), record])
        a, b = pairs[-1]
        ok = a["samples"] == b["samples"] and a["sum"] == b["sum"]
        what = f"{a['samples']} samples decoded each; sums {a['sum']:.6f} / {b['sum']:.6f}"
        return pairs, ok, what


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--peers", required=True)
    ap.add_argument("--motorbench", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--only", nargs="*", default=list(TARGETS))
    args = ap.parse_args()
    rows = Rows(args)
    table = []
    for name in args.only:
        print(f"{name}: {args.rounds} rounds, alternating", file=sys.stderr)
        pairs, ok, what = getattr(rows, name)()
        ratios = [b["seconds"] / a["seconds"] for a, b in pairs]
        med = statistics.median(ratios)
        ours = statistics.median(a["seconds"] for a, _ in pairs)
        theirs = statistics.median(b["seconds"] for _, b in pairs)
        print(f"ratio {name} {med:.1f} same={'yes' if ok else 'no'}", flush=True)
        table.append((name, ours, theirs, med, min(ratios), max(ratios), TARGETS[name], ok, what))
    print()
    print("| row | motorbench (median) | Python (median) | ratio (median, min–max) | target | same answer |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, ours, theirs, med, lo, hi, target, ok, what in table:
        print(f"| {name} | {ours * 1e3:.1f} ms | {theirs * 1e3:.1f} ms | {med:.1f}× ({lo:.1f}–{hi:.1f}) "
              f"| ≥ {target:.0f}× | {'yes' if ok else 'NO'}: {what} |")


if __name__ == "__main__":
    main()
