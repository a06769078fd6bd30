"""Rows of scripts/precond-study.sh's table from a `rollcam compare` folder, one per
run: the seconds to come within 0.01% of plain restart FISTA's final objective and of
the lowest objective any run reached, the seconds per iteration, the final objective
over the lowest, the final relative error (after the best scale) and the seconds to
come within 1% of the best error any run reached. Usage: precond-summary.py DIR CAPTURE."""
import sys

from compare_traces import Traces

out, name = sys.argv[1:]
t = Traces(out)
for l in t.labels:
    s = t.summary[l]
    err = s.get("final_rel_error_scaled")
    t_err = dict((tol, secs) for tol, secs in s.get("time_to_error_s", [])).get(0.01)
    cols = [
        t.reach(l, t.finals["fista-restart"]),
        t.reach(l, t.lowest),
        f"{s['seconds_per_iteration']:.4f}",
        f"{t.finals[l] / t.lowest:.5f}",
        "-" if err is None else f"{err:.4f}",
        "never" if t_err is None else f"{t_err:.2f}",
    ]
    print(f"| {name} | {l} | " + " | ".join(cols) + " |")
