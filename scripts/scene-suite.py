#!/usr/bin/env python3
"""The scene suite: captures with known truth spanning what benches see, each solved
with the defaults and over a sweep of TV weight x iterations (the "oracle": the best
the tool reaches on that scene), and the candidate default rules scored by their worst
regret against the oracles: a scene's regret is its relative error over the oracle's,
and for a video the worse of that and its motion error over the motion oracle's. With --defaults, the default weight's rule (the noise
rule, tau = c sigma / frames^p, src/solve/tau.rs) is also scored over c x p x stop rule
on the same traces, with each scene left out in turn. Writes DIR/suite.json and
DIR/scene-suite.md (the report docs/scene-suite.md quotes).

    python3 -m venv /tmp/suite && /tmp/suite/bin/pip install numpy tifffile scikit-image
    cargo build --release
    /tmp/suite/bin/python scripts/scene-suite.py --out /tmp/suite-run

Needs ../shared/data/diffusercam-tutorial/ (the measured PSF and the real hand) beside
the checkout, or --tutorial DIR. numpy and tifffile compose the colour capture;
scikit-image brings the natural images (its `data` module). Every seed is fixed here.
"""
import argparse
import csv
import itertools
import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import tifffile

ROOT = Path(__file__).resolve().parent.parent
# The TV weights of the sweep (relative to max(A^T b)) and the longest run.
TAUS = [3.125e-5, 6.25e-5, 1.25e-4, 2.5e-4, 5e-4, 1e-3, 2e-3, 4e-3, 8e-3, 1.6e-2, 3.2e-2]
MAX_ITERS = 800
# Candidate stop rules: the solver's obj_tol rule (the objective's relative change below
# tol and the iterate's below ITERATE * tol for 5 iterations in a row, and the data
# term's average relative fall over the last DATA_WINDOW iterations below DATA_FALL * tol
# per iteration: src/solve/optimize/types.rs), or the cap.
TOLS = [0.0, 1e-3, 3e-4, 1e-4, 3e-5]
CAPS = [200, 400, 500, 600, 800]
PATIENCE = 5
ITERATE = 2.0
DATA_WINDOW = 20
DATA_FALL = 3.0
# The noise rule's family, tau = c * sigma / frames**p (sigma the raw's noise as
# reconstruct measures it, read from each scene's defaults run): scored offline at the
# sweep's weight nearest (in ratio) to the rule's.
NOISE_C = [0.003, 0.005, 0.007, 0.01, 0.014, 0.02, 0.03, 0.04, 0.06, 0.08]
NOISE_P = [0.0, 0.25, 0.5, 0.75, 1.0]
# A video's weight at least this relative to max(A^T b) (0: none): a video's best weight
# follows its signal more than its noise (the oracles' tau_rel of the videos span 8x, the
# noise rule's 13x).
VIDEO_FLOORS = [0.0, 6.25e-5, 1.25e-4, 2.5e-4]


def run(cmd, log):
    with open(log, "w") as f:
        r = subprocess.run([str(c) for c in cmd], stdout=f, stderr=subprocess.STDOUT)
    if r.returncode != 0:
        sys.exit(f"failed ({r.returncode}): {' '.join(map(str, cmd))}\n  see {log}")


def natural(name, rows, cols):
    """A scikit-image sample image, grey (or RGB), resized to rows x cols, in [0, 1]."""
    from skimage import data, transform

    img = getattr(data, name)().astype(np.float64)
    img /= img.max()
    out = transform.resize(img, (rows, cols) + img.shape[2:], anti_aliasing=True)
    return np.clip(out, 0, None).astype(np.float32)


def simulate(exe, out, scene, extra, log):
    run([exe, "simulate", "--scene", scene, "--out", out, "--force"] + extra, log)


def prepare(exe, tut, work):
    """Each scene: a folder holding raw.tiff, psf.tiff, capture.toml and truth.npy."""
    psf = tut / "psf_sample.tif"
    meas = ["--psf", psf, "--psf-downsample", "10"]  # 120 x 160
    scenes = {}

    def sim(name, scene, extra, desc, measure):
        d = work / "scenes" / name
        d.mkdir(parents=True, exist_ok=True)
        simulate(exe, d, scene, extra, d / "simulate.log")
        scenes[name] = {"dir": d, "desc": desc, "measure": measure}

    sim("led-synthetic", "led-array", ["--rows", "96", "--cols", "128", "--shutter", "rolling", "--seed", "11"],
        "4 LEDs flashing, synthetic diffuser, rolling shutter, 96 x 128", "led")
    sim("led-measured", "led-array", meas + ["--shutter", "dual", "--seed", "12", "--spacing-px", "10"],
        "4 LEDs flashing, measured PSF, dual shutter", "led")
    sim("disc-over-texture", "disc-over-texture", meas + ["--shutter", "dual", "--seed", "13"],
        "bright disc over a textured still scene, measured PSF, dual shutter", "track")
    sim("occluder", "disc-over-texture", meas + ["--shutter", "rolling", "--seed", "14", "--disc-contrast", "0.1", "--e-per-us", "150"],
        "dark disc over a bright textured scene (the moving part is a loss of light), rolling shutter", "track")
    # The two dense scenes again with key frames of a second, global-shutter camera at
    # the first and the last frame (its own gain, unknown to the solve, dark level and
    # noise; docs/keyframes.md).
    keys = ["--keyframes", "first,last"]
    sim("disc-over-texture-keys", "disc-over-texture", meas + ["--shutter", "dual", "--seed", "13"] + keys,
        "disc-over-texture with key frames at the first and last frame", "track")
    sim("occluder-keys", "disc-over-texture", meas + ["--shutter", "rolling", "--seed", "14", "--disc-contrast", "0.1", "--e-per-us", "150"] + keys,
        "occluder with key frames at the first and last frame", "track")
    sim("moving-disc", "moving-disc", meas + ["--shutter", "dual-center-out", "--seed", "15"],
        "bright disc on black, measured PSF, dual shutter centre-out", "track")

    # Stills and stacks from natural images: a one-frame global-shutter exposure.
    def stack(name, frames, desc, extra, measure, interval_us=None):
        d = work / "scenes" / name
        d.mkdir(parents=True, exist_ok=True)
        np.save(d / "stack.npy", frames.astype(np.float32))
        args = meas + ["--stack", d / "stack.npy"] + extra
        if interval_us:
            args += ["--stack-interval-us", str(interval_us)]
        simulate(exe, d, "stack", args, d / "simulate.log")
        scenes[name] = {"dir": d, "desc": desc, "measure": measure}

    still_timing = ["--shutter", "global", "--line-time-us", "10", "--exposure-us", "10"]
    cam = natural("camera", 120, 160)
    stack("natural-still", cam[None] * 4000.0, "natural photograph (cameraman), global shutter, Poisson noise",
          still_timing + ["--seed", "16"], "still")
    stack("photon-starved", cam[None] * 8.0, "the same photograph at ~70 photo-electrons in the brightest raw pixel",
          still_timing + ["--seed", "17"], "still")
    # A blocky still (waves, blocks and a bright square: sparse gradients, TV's own
    # prior) at the photograph's two light levels: where the best weight depends on
    # the scene as much as on the noise.
    rr, cc = np.mgrid[0:120, 0:160].astype(np.float32)
    blocks = 1.0 + 0.5 * np.sin(rr / 10.0) * np.cos(cc / 14.0) + 0.4 * (((rr // 32) + (cc // 40)) % 2)
    blocks[40:80, 60:100] += 0.8
    blocks /= blocks.max()
    stack("blocks", blocks[None] * 4000.0, "a blocky still (waves, blocks, a bright square), global shutter",
          still_timing + ["--seed", "18"], "still")
    stack("blocks-dim", blocks[None] * 8.0, "the same blocky still at the photon-starved photograph's light",
          still_timing + ["--seed", "19"], "still")

    # Colour: the astronaut panning across the field, rolling shutter; each colour
    # plane simulated through the same PSF (seeds differ), raws stacked as RGB.
    ast = natural("astronaut", 120, 200)
    pans = np.stack([ast[:, s:s + 160] for s in range(0, 40, 2)])  # 20 frames, 2 px each
    d = work / "scenes" / "colour"
    d.mkdir(parents=True, exist_ok=True)
    raws, truths = [], []
    for c in range(3):
        dc = d / f"plane{c}"
        dc.mkdir(exist_ok=True)
        np.save(dc / "stack.npy", (pans[..., c] * 50.0).astype(np.float32))
        simulate(exe, dc, "stack", meas + ["--stack", dc / "stack.npy", "--shutter", "rolling", "--seed", str(20 + c),
                                          "--stack-interval-us", "1350"], dc / "simulate.log")
        raws.append(tifffile.imread(dc / "raw.tiff"))
        truths.append(np.load(dc / "truth.npy"))
    tifffile.imwrite(d / "raw.tiff", np.stack(raws, axis=-1))
    psf_grey = tifffile.imread(d / "plane0" / "psf.tiff")
    tifffile.imwrite(d / "psf.tiff", np.stack([psf_grey] * 3, axis=-1))
    shutil.copy(d / "plane0" / "capture.toml", d / "capture.toml")
    truth = np.concatenate([t if t.ndim == 4 else t[..., None] for t in truths], axis=-1)
    np.save(d / "truth.npy", truth)
    scenes["colour"] = {"dir": d, "desc": "colour photograph panning across the field, rolling shutter", "measure": "none"}

    # The real hand (no truth): the tutorial's raw and PSF, a global-shutter still,
    # judged against a long, lightly regularised reference solve (HAND_REFERENCE).
    d = work / "scenes" / "hand"
    d.mkdir(parents=True, exist_ok=True)
    (d / "capture.toml").write_text(HAND_CONFIG)
    ref = d / "reference"
    if not (ref / "video.npy").exists():
        run([exe, "reconstruct", "--raw", tut / "rawdata_hand_sample.tif", "--psf", psf, "--config", d / "capture.toml",
             "--tau-rel", f"{HAND_REFERENCE[0]:g}", "--iters", str(HAND_REFERENCE[1]), "--obj-tol", "0", "--out", ref, "--force"],
            d / "reference.log")
    scenes["hand"] = {"dir": d, "raw": tut / "rawdata_hand_sample.tif", "psf": psf, "truth": ref / "video.npy",
                      "desc": f"the real DiffuserCam hand, downsampled 4 (300 x 400), against a {HAND_REFERENCE[1]}-iteration reference at tau_rel {HAND_REFERENCE[0]:g}",
                      "measure": "reference"}
    return scenes


# The hand: a global-shutter still (one frame: exposure = line time), the tutorial's
# dark level.
HAND_CONFIG = """rows = 1200
cols = 1600
line_time_us = 10.0
exposure_us = 10.0
shutter = "global"
downsample = 4
dark_level = 41.0
"""
# The hand's reference: tau_rel and iterations (the weight the held-out search chose).
HAND_REFERENCE = (3e-5, 3000)


def read_trace(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    # One series per channel; the report's error is the worst channel's, the time the
    # slowest channel's, at each iteration.
    by = {}
    for r in rows:
        by.setdefault(r["channel"], []).append(r)
    chans = list(by.values())
    n = min(len(c) for c in chans)
    out = []
    for i in range(n):
        out.append({
            "iteration": int(chans[0][i]["iteration"]),
            "seconds": max(float(c[i]["seconds"]) for c in chans),
            "objective": [float(c[i]["objective"]) for c in chans],
            "data_term": [float(c[i]["data_term"]) for c in chans],
            "rel_change": [float(c[i]["rel_change"]) for c in chans],
            "err": max(float(c[i]["rel_error_scaled"] or "nan") for c in chans),
            # The motion error (worst channel) where the trace has it (traces written
            # since it was added; a still's column is empty).
            "motion": max(float(c[i].get("motion_error") or "nan") for c in chans),
        })
    return out


def stop_at(trace, tol, cap, floor=None):
    """The iteration (index) where the obj_tol rule with `cap` ends the run, for every
    channel: the objective's relative change below tol and the iterate's below
    ITERATE * tol for PATIENCE iterations in a row, and the data term settled (its fall
    over the last DATA_WINDOW iterations below DATA_FALL * tol per iteration; the
    trace's first row stands for the start while fewer have run), or at or below the
    noise floor `floor` (per channel: half the sensor model's noise variance summed
    over the kept pixels, read from the scene's defaults run; None: no floor)."""
    last = min(cap, len(trace)) - 1
    if tol <= 0:
        return last, False
    calm = 0
    for i in range(1, last + 1):
        prev, cur = trace[i - 1], trace[i]
        small = all(abs(c - p) <= tol * abs(c) for c, p in zip(cur["objective"], prev["objective"]))
        quiet = all(r < ITERATE * tol for r in cur["rel_change"])
        calm = calm + 1 if small and quiet else 0
        if calm >= PATIENCE:
            j = max(0, i - DATA_WINDOW)
            n = max(i - j, 1)
            floors = floor or [None] * len(cur["data_term"])
            if all((f is not None and b <= f) or (a - b) / max(abs(b), 1e-300) < DATA_FALL * tol * n
                   for a, b, f in zip(trace[j]["data_term"], cur["data_term"], floors)):
                return i, True
    return last, False


def sweep(exe, scene, name, work, taus, iters, truth):
    traces = {}
    for tau in taus:
        out = work / "runs" / name / f"tau-{tau:g}"
        out.parent.mkdir(parents=True, exist_ok=True)
        if not (out / "trace.csv").exists():
            cmd = [exe, "reconstruct", "--raw", scene.get("raw", scene["dir"] / "raw.tiff"), "--psf", scene.get("psf", scene["dir"] / "psf.tiff"),
                   "--config", scene["dir"] / "capture.toml", "--truth", truth, "--tau-rel", f"{tau:g}",
                   "--iters", str(iters), "--obj-tol", "0", "--out", out, "--force"]
            run(cmd, work / "runs" / name / f"tau-{tau:g}.log")
        traces[tau] = read_trace(out / "trace.csv")
    return traces


def default_run(exe, scene, name, work, truth):
    """The defaults as a user meets them (no tuning flag): error, iterations, converged,
    seconds, and the scene's own measure (`rollcam analyze`: the object's track and the
    still scene's correlation; the LEDs' time-course correlation)."""
    out = work / "defaults" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    run([exe, "reconstruct", "--raw", scene.get("raw", scene["dir"] / "raw.tiff"), "--psf", scene.get("psf", scene["dir"] / "psf.tiff"),
         "--config", scene["dir"] / "capture.toml", "--truth", truth, "--out", out, "--force"], work / "defaults" / f"{name}.log")
    s = json.loads((out / "summary.json").read_text())
    ch = s["channels"]
    choice = s["params"].get("tau_choice") or {}
    fit = s.get("fit") or {}
    # The solver's noise floor per channel (src/solve/fit.rs, noise_floor): half the
    # sensor model's variance over the kept pixels, from the fit report's rms noise.
    # Not with key frames: their solve has no floor (its data term holds theirs too).
    floor = ([0.5 * fit["pixels"] / len(ch) * fit["noise_sigma"] ** 2] * len(ch)
             if fit.get("noise") == "sensor-model" and fit.get("pixels") and not any(c.get("keyframes") for c in ch) else None)
    rec = {"err": s["rel_error_scaled"], "iterations": max(c["iterations"] for c in ch), "converged": s["converged"],
           "seconds": s["seconds"], "measure": None, "tau": s["params"]["tau"], "tau_choice": choice,
           "motion_error": s.get("motion_error"), "floor": floor}
    if scene["measure"] == "track":
        run([exe, "analyze", out, "--truth", truth, "--out", out / "analysis", "--force"], work / "defaults" / f"{name}-analyze.log")
        t = json.loads((out / "analysis" / "track.json").read_text())
        tr = t["track"]
        rec["measure"] = {"motion error": s.get("motion_error"), "track median px": tr["median_px"], "track p90 px (lost as misses)": tr["p90_px_with_lost"],
                          "lost": tr["frames_lost"], "still corr.": t["static_correlation"]}
    elif scene["measure"] == "led":
        v, t = np.load(out / "video.npy"), np.load(truth)
        v = v.reshape(v.shape[0], -1) if v.ndim == 3 else v[..., 0].reshape(v.shape[0], -1)
        t = t.reshape(t.shape[0], -1) if t.ndim == 3 else t[..., 0].reshape(t.shape[0], -1)
        # Each LED: the truth's brightest pixels that flash; their time course in both.
        lit = np.argsort(t.max(0))[-16:]
        rs = [float(np.corrcoef(v[:, p], t[:, p])[0, 1]) for p in lit if t[:, p].std() > 0 and v[:, p].std() > 0]
        rec["measure"] = {"led_pixel_correlation_median": float(np.median(rs)) if rs else None}
        # The same over the frames the data see, when the sources' fit names some it
        # does not (summary.json support.sources.unseen_frames: the brightness there is
        # a guess).
        src = (ch[0].get("support") or {}).get("sources") or {}
        unseen = (src.get("unseen_frames") or []) if src.get("kept") else []
        if unseen:
            seen = [k for k in range(t.shape[0]) if not any(a <= k < b for a, b in unseen)]
            vs, ts = v[seen], t[seen]
            rs = [float(np.corrcoef(vs[:, p], ts[:, p])[0, 1]) for p in lit if ts[:, p].std() > 0 and vs[:, p].std() > 0]
            rec["measure"]["led_pixel_correlation_median_seen"] = float(np.median(rs)) if rs else None
            rec["measure"]["seen_frames"] = len(seen)
    return rec


def noise_rules(result, traces_of):
    """The noise rule's family scored on the stored traces: per scene the sweep weight
    nearest the rule's, stopped by each stop rule. Needs each scene's defaults run (its
    measured noise, frames and max(A^T b) = tau / tau_rel)."""
    inputs = {}
    for name, sc in result["scenes"].items():
        d = sc.get("defaults") or {}
        ch = d.get("tau_choice") or {}
        if ch.get("rule") != "noise" or not ch.get("tau_rel"):
            return None
        inputs[name] = (ch["sigma"], ch["frames"], d["tau"] / ch["tau_rel"])
    rules = {}
    for c, p, vf, tol, cap in itertools.product(NOISE_C, NOISE_P, VIDEO_FLOORS, TOLS, CAPS):
        key = f"noise {c:g}/{p:g}/{vf:g}/{tol:g}/{cap}"
        per = {}
        for name, (sigma, frames, peak) in inputs.items():
            want = c * sigma / max(frames, 1) ** p / peak
            if frames > 1:
                want = max(want, vf)
            tau = min(TAUS, key=lambda t: abs(math.log(t / want)) if want > 0 else t)
            tr = traces_of[name][tau]
            i, conv = stop_at(tr, tol, cap, result["scenes"][name]["defaults"].get("floor"))
            per[name] = {"tau_rel": tau, "err": tr[i]["err"], "iterations": tr[i]["iteration"],
                         "seconds": tr[i]["seconds"], "converged": conv,
                         "motion": motion_at(tr[i])}
        rules[key] = per
    return rules


def motion_at(row):
    """A trace row's motion error, None where the trace has none (a still; NaN)."""
    return row["motion"] if row["motion"] == row["motion"] else None


def rel_regret(result, per, n):
    """Scene `n`'s relative error under a rule (`per[n]`) over its oracle's, minus one."""
    return per[n]["err"] / result["scenes"][n]["oracle"]["err"] - 1


def regret(result, per, n):
    """Scene `n`'s regret under a rule (`per[n]`: its error, and its motion error for a
    video whose traces carry it): its relative error over the oracle's, and for a
    video its motion error over the motion oracle's, the worse of the two. The relative
    error alone rewards a still (docs/scene-suite.md)."""
    o = result["scenes"][n]["oracle"]
    r = rel_regret(result, per, n)
    m, mo = per[n].get("motion"), o.get("motion")
    if m is not None and mo:
        r = max(r, m / mo - 1)
    return r


def leave_one_out(result, rules, names):
    """For each scored scene: the rule of least worst regret over the others (ties: the
    least mean regret), and that rule's regret on the scene left out."""
    out = {}
    for held in names:
        best = None
        for key, per in rules.items():
            regrets = [regret(result, per, n) for n in names if n != held]
            score = (max(regrets), sum(regrets) / len(regrets))
            if best is None or score < best[0]:
                best = (score, key)
        best = (best[0][0], best[1])
        out[held] = {"rule": best[1], "train_worst_regret": best[0],
                     "held_out_regret": regret(result, rules[best[1]], held)}
    return out


def markdown(result, rule):
    """The report's tables: per scene the oracle, the old default and `rule`; then the
    rules by worst regret."""
    md = ["| scene | oracle: rel. error (tau_rel, iterations, s) | old default (2e-3, 200 it) | "
          f"`{rule}` (iterations, converged) | regret | time vs old |", "|---|---|---|---|---|---|"]
    for name, sc in result["scenes"].items():
        o, old, new = sc["oracle"], sc["old_default"], sc["rules"][rule]
        motion = f"; motion {o['motion']:.3f} ({o['motion_tau_rel']:g}, {o['motion_iterations']})" if o.get("motion") is not None else ""
        md.append(f"| {name}: {sc['desc']} | {o['err']:.4f} ({o['tau_rel']:g}, {o['iterations']}, {o['seconds']:.1f}){motion} | "
                  f"{old['err']:.4f} ({100 * (old['err'] / o['err'] - 1):+.0f}%) | {new['err']:.4f} ({new['iterations']}, "
                  f"{'yes' if new['converged'] else 'no'}) | {100 * (new['err'] / o['err'] - 1):+.1f}% | "
                  f"{new['seconds'] / max(old['seconds'], 1e-9):.2f}x |")
    if any("defaults" in sc for sc in result["scenes"].values()):
        md += ["", "| scene | defaults: rel. error | regret | motion error (oracle) | tau_rel (noise sigma, frames) | iterations | converged | s | scene measure |",
               "|---|---|---|---|---|---|---|---|---|"]
        for name, sc in result["scenes"].items():
            d = sc.get("defaults")
            if d:
                m = ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in (d["measure"] or {}).items())
                ch = d.get("tau_choice") or {}
                rule = (f"{ch['tau_rel']:.3g} ({ch['sigma']:.3g}, {ch['frames']})" if ch.get("rule") == "noise"
                        else f"{ch.get('tau_rel', float('nan')):.3g} ({ch.get('rule', '?')})")
                mo = sc["oracle"].get("motion")
                motion = f"{d['motion_error']:.3f} ({mo:.3f})" if d.get("motion_error") is not None and mo else "-"
                md.append(f"| {name} | {d['err']:.4f} | {100 * (d['err'] / sc['oracle']['err'] - 1):+.1f}% | {motion} | {rule} | {d['iterations']} | "
                          f"{'yes' if d['converged'] else 'no'} | {d['seconds']:.1f} | {m} |")
    md += ["", "| rule tau_rel/obj_tol/cap | worst regret | worst time vs old default |", "|---|---|---|"]
    for r in result["rules_by_worst_regret"][:20]:
        md.append(f"| {r['rule']} | {100 * r['worst_regret']:.1f}% | {r['worst_time_ratio']:.2f}x |")
    if result.get("noise_rules_by_worst_regret"):
        md += ["", "| noise rule c/p/video floor/obj_tol/cap (tau = c sigma / frames^p, a video's tau_rel at least the floor) | worst regret (rel. or motion) | at | worst rel. regret | mean regret | total s |",
               "|---|---|---|---|---|---|"]
        for r in result["noise_rules_by_worst_regret"][:12]:
            md.append(f"| {r['rule']} | {100 * r['worst_regret']:.1f}% | {r['worst_at']} | {100 * r['worst_rel_regret']:.1f}% | "
                      f"{100 * r['mean_regret']:.1f}% | {r['total_seconds']:.0f} |")
        md += ["", "| left out | rule chosen on the others | their worst regret | regret of the scene left out |", "|---|---|---|---|"]
        for name, r in result["noise_leave_one_out"].items():
            md.append(f"| {name} | {r['rule']} | {100 * r['train_worst_regret']:.1f}% | {100 * r['held_out_regret']:.1f}% |")
    return "\n".join(md) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "release" / "rollcam")
    ap.add_argument("--tutorial", type=Path, default=ROOT.parent / "shared" / "data" / "diffusercam-tutorial")
    ap.add_argument("--iters", type=int, default=MAX_ITERS)
    ap.add_argument("--only", help="comma-separated scene names")
    ap.add_argument("--defaults", action="store_true", help="also run each scene with no tuning flag and its own measure")
    ap.add_argument("--rule", default="0.00025/0.001/400", help="the rule the report's first table shows (tau_rel/obj_tol/cap)")
    args = ap.parse_args()
    exe = args.bin.resolve()
    work = args.out.resolve()
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    scenes = prepare(exe, args.tutorial.resolve(), work)
    if args.only:
        keep = args.only.split(",")
        scenes = {k: v for k, v in scenes.items() if k in keep}
    result = {"taus": TAUS, "max_iters": args.iters, "scenes": {}}
    traces_of = {}
    for name, sc in scenes.items():
        truth = sc.get("truth", sc["dir"] / "truth.npy")
        traces = sweep(exe, sc, name, work, TAUS, args.iters, truth)
        traces_of[name] = traces
        best = min(((t["err"], tau, t["iteration"], t["seconds"]) for tau, tr in traces.items() for t in tr),
                   key=lambda x: x[0])
        # The motion oracle: the lowest motion error over the same sweep (videos whose
        # traces have the column; NaN otherwise).
        motions = [(t["motion"], tau, t["iteration"]) for tau, tr in traces.items() for t in tr if motion_at(t) is not None]
        best_motion = min(motions, key=lambda x: x[0]) if motions else (None, None, None)
        defaults = default_run(exe, sc, name, work, truth) if args.defaults else None
        floor = defaults.get("floor") if defaults else None
        rules = {}
        for tau, tr in traces.items():
            for tol in TOLS:
                for cap in CAPS:
                    i, conv = stop_at(tr, tol, cap, floor)
                    rules[f"{tau:g}/{tol:g}/{cap}"] = {"err": tr[i]["err"], "iterations": tr[i]["iteration"],
                                                       "seconds": tr[i]["seconds"], "converged": conv,
                                                       "motion": motion_at(tr[i])}
        base = rules[f"{2e-3:g}/0/200"]
        result["scenes"][name] = {"desc": sc["desc"], "measure": sc["measure"],
                                  "oracle": {"err": best[0], "tau_rel": best[1], "iterations": best[2], "seconds": best[3],
                                             "motion": best_motion[0], "motion_tau_rel": best_motion[1], "motion_iterations": best_motion[2]},
                                  "old_default": base, "rules": rules}
        if defaults:
            result["scenes"][name]["defaults"] = defaults
        motion = f"; motion oracle {best_motion[0]:.3f} at tau_rel {best_motion[1]:g}, {best_motion[2]} it" if best_motion[0] is not None else ""
        print(f"{name}: oracle {best[0]:.4f} at tau_rel {best[1]:g}, {best[2]} it; old default {base['err']:.4f}{motion}", flush=True)
    # The worst regret of each rule over the scenes.
    # The hand has no truth: its reference is itself one setting's solve, so it is
    # reported, not scored.
    names = [n for n, sc in result["scenes"].items() if sc["measure"] != "reference"]
    table = []
    for key in result["scenes"][names[0]]["rules"]:
        regrets = [regret(result, {n: result["scenes"][n]["rules"][key]}, n) for n in names]
        slow = [result["scenes"][n]["rules"][key]["seconds"] / max(result["scenes"][n]["old_default"]["seconds"], 1e-9) for n in names]
        table.append((max(regrets), key, max(slow)))
    table.sort()
    result["rules_by_worst_regret"] = [{"rule": k, "worst_regret": r, "worst_time_ratio": s} for r, k, s in table]
    noise = noise_rules(result, traces_of) if args.defaults else None
    if noise:
        ranked = []
        for key, per in noise.items():
            regrets = [regret(result, per, n) for n in names]
            rel = [rel_regret(result, per, n) for n in names]
            ranked.append({"rule": key, "worst_regret": max(regrets), "mean_regret": sum(regrets) / len(regrets),
                           "worst_rel_regret": max(rel), "worst_at": names[regrets.index(max(regrets))],
                           "total_seconds": sum(per[n]["seconds"] for n in names)})
        ranked.sort(key=lambda r: (r["worst_regret"], r["total_seconds"]))
        result["noise_rules_by_worst_regret"] = ranked
        result["noise_leave_one_out"] = leave_one_out(result, noise, names)
    result["seconds"] = time.time() - t0
    (work / "suite.json").write_text(json.dumps(result, indent=1, default=str))
    (work / "scene-suite.md").write_text(markdown(result, args.rule))
    for r, k, s in table[:15]:
        print(f"{k:>22}: worst regret {100 * r:6.1f}%  worst time {s:5.2f}x old default")


if __name__ == "__main__":
    main()
