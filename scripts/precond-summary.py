"""Rows of scripts/precond-study.sh's table from a `rollcam compare` folder, one per
run: the seconds to come within 0.01% of plain restart FISTA's final objective and of
the lowest objective any run reached, the seconds per iteration, the final objective
over the lowest, the final relative error (after the best scale) and the seconds to
come within 1% of the best error any run reached. Usage: precond-summary.py DIR CAPTURE."""
import csv
import json
import sys

out, name = sys.argv[1:]
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
for l in labels:
    s = summary[l]
    err = s.get("final_rel_error_scaled")
    t_err = dict((tol, t) for tol, t in s.get("time_to_error_s", [])).get(0.01)
    cols = [
        reach(l, finals["fista-restart"]),
        reach(l, lowest),
        f"{s['seconds_per_iteration']:.4f}",
        f"{finals[l] / lowest:.5f}",
        "-" if err is None else f"{err:.4f}",
        "never" if t_err is None else f"{t_err:.2f}",
    ]
    print(f"| {name} | {l} | " + " | ".join(cols) + " |")
