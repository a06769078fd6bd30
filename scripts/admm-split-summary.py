"""One row of scripts/admm-split-study.sh's table from a `rollcam compare` folder:
the seconds each run needs to come within 0.01% of restart FISTA's final objective
and of the lowest objective any run reached, its seconds per iteration, and its final
objective over the lowest. Usage: admm-split-summary.py DIR CAPTURE TAU ITERS."""
import csv
import json
import sys

out, name, tau, iters = sys.argv[1:]
with open(f"{out}/traces.csv") as f:
    labels = f.readline().split(": ", 1)[1].strip().split(",")
    rows = {}
    for r in csv.DictReader(f):
        rows.setdefault(labels[int(r["channel"])], []).append((float(r["seconds"]), float(r["objective"])))
finals = {l: rows[l][-1][1] for l in labels}
lowest = min(f for l in labels for _, f in rows[l])


def reach(label, target):
    t = next((s for s, f in rows[label] if f <= target * (1 + 1e-4)), None)
    return "never" if t is None else f"{t:.2f}"


with open(f"{out}/summary.json") as f:
    summary = {s["solver"]: s for s in json.load(f)["solvers"]}
cols = [
    " / ".join(reach(l, finals["fista-restart"]) for l in labels),
    " / ".join(reach(l, lowest) for l in labels),
    " / ".join(f"{summary[l]['seconds_per_iteration']:.4f}" for l in labels),
    " / ".join(f"{finals[l] / lowest:.5f}" for l in labels),
]
print(f"| {name} | {tau} | {iters} | " + " | ".join(cols) + " |")
