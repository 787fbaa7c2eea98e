"""A blind suite's two index files, for the scripts that add third-party
cases to one (blind_gem.py, blind_motulator.py): `cases.json` (what to
run) and `truth.json` (what the score compares with), created with the
suite or read from it, and written back once the cases are added."""

import json
import os
import sys


class Suite:
    """The index files of the suite in `out` (created when missing, with
    `seed`); refuses a suite that already holds cases named `prefix`*."""

    def __init__(self, out, seed, prefix, source):
        self.manifest_path = os.path.join(out, "cases.json")
        self.truth_path = os.path.join(out, "truth.json")
        if os.path.exists(self.manifest_path):
            with open(self.manifest_path) as f:
                self.manifest = json.load(f)
            with open(self.truth_path) as f:
                self.truth = json.load(f)
        else:
            os.makedirs(out, exist_ok=False)
            self.manifest = {"seed": seed, "cases": []}
            self.truth = {"seed": seed, "cases": []}
        if any(c["id"].startswith(prefix) for c in self.manifest["cases"]):
            sys.exit(f"{self.manifest_path}: already holds {source} cases; give a new suite")

    def add(self, entry, truth):
        """One case: its manifest entry and its truth."""
        self.manifest["cases"].append(entry)
        self.truth["cases"].append([entry["id"], truth])

    def save(self):
        """Write both index files."""
        for path, value in [(self.manifest_path, self.manifest), (self.truth_path, self.truth)]:
            with open(path, "w") as f:
                json.dump(value, f, indent=2)
                f.write("\n")
