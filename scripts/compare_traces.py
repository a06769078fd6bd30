"""What the solver-study summaries read from a `rollcam compare` folder: each run's
(seconds, objective) trace from traces.csv, its final and the lowest objective of any
run, summary.json's entry per run, and the seconds a run needs to come within 0.01% of
a target objective. Imported by admm-split-summary.py and precond-summary.py."""
import csv
import json


class Traces:
    def __init__(self, out):
        with open(f"{out}/traces.csv") as f:
            self.labels = f.readline().split(": ", 1)[1].strip().split(",")
            self.rows = {}
            for r in csv.DictReader(f):
                self.rows.setdefault(self.labels[int(r["channel"])], []).append((float(r["seconds"]), float(r["objective"])))
        self.finals = {l: self.rows[l][-1][1] for l in self.labels}
        self.lowest = min(f for l in self.labels for _, f in self.rows[l])
        with open(f"{out}/summary.json") as f:
            self.summary = {s["solver"]: s for s in json.load(f)["solvers"]}

    def reach(self, label, target):
        """Seconds for run `label` to come within 0.01% of `target`, as text ("never")."""
        t = next((s for s, f in self.rows[label] if f <= target * (1 + 1e-4)), None)
        return "never" if t is None else f"{t:.2f}"
