"""One row of scripts/admm-split-study.sh's table from a `rollcam compare` folder:
the seconds each run needs to come within 0.01% of restart FISTA's final objective
and of the lowest objective any run reached, its seconds per iteration, and its final
objective over the lowest. Usage: admm-split-summary.py DIR CAPTURE TAU ITERS."""
import sys

from compare_traces import Traces

out, name, tau, iters = sys.argv[1:]
t = Traces(out)
cols = [
    " / ".join(t.reach(l, t.finals["fista-restart"]) for l in t.labels),
    " / ".join(t.reach(l, t.lowest) for l in t.labels),
    " / ".join(f"{t.summary[l]['seconds_per_iteration']:.4f}" for l in t.labels),
    " / ".join(f"{t.finals[l] / t.lowest:.5f}" for l in t.labels),
]
print(f"| {name} | {tau} | {iters} | " + " | ".join(cols) + " |")
