"""scripts/gpu-study.sh's table from its work folder: per capture and run, the
iterations, the seconds per iteration, the final objective over restart FISTA's (CPU),
the final relative error (after the best scale), and the seconds (and iterations) to
come within 0.01% of restart FISTA's final objective, with restart FISTA's own seconds
to that point over them (the speed-up). Usage: gpu-summary.py WORK."""
import sys

from compare_traces import Traces


def reach(rows, target):
    """(seconds, iterations) to come within 0.01% of target, or None."""
    for i, (s, f) in enumerate(rows):
        if f <= target * (1 + 1e-4):
            return s, i + 1
    return None


work = sys.argv[1]
print("| capture | run | iterations | s/iteration | final objective / fista-restart's | final rel. error | s (iterations) to fista-restart's final objective +0.01% | speed-up |")
print("|---|---|---|---|---|---|---|---|")
for name in ["still", "dense", "led"]:
    t = Traces(f"{work}/cmp-{name}")
    target = t.finals["fista-restart"]
    base = reach(t.rows["fista-restart"], target)
    for l in t.labels:
        s = t.summary[l]
        err = s.get("final_rel_error_scaled")
        r = reach(t.rows[l], target)
        cols = [
            str(len(t.rows[l])),
            f"{s['seconds_per_iteration']:.4f}",
            f"{t.finals[l] / target:.5f}",
            "-" if err is None else f"{err:.4f}",
            "never" if r is None else f"{r[0]:.2f} ({r[1]})",
            "-" if r is None or base is None else f"{base[0] / max(r[0], 1e-9):.1f}x",
        ]
        print(f"| {name} | {l} | " + " | ".join(cols) + " |")
