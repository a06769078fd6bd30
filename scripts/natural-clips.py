#!/usr/bin/env python3
"""Natural clips: real photographs with real-looking motion through the measured PSF,
each solved with the defaults (no tuning flag), with and without key frames at the
first and last frame, and scored against the truth beside the baselines a user has
without rollcam: the best still (`--scene static=true`), the truth's own temporal mean
and the two key frames linearly interpolated. Writes DIR/natural-clips.md (the table
docs/keyframes.md and docs/limits.md quote) and DIR/natural-clips.json.

    python3 -m venv /tmp/nat && /tmp/nat/bin/pip install numpy scikit-image
    cargo build --release
    /tmp/nat/bin/python scripts/natural-clips.py --out /tmp/natural

The clips (scikit-image's `data` images, grey, `--rows` x `--cols`, 40 stack frames over
the capture): `object`, a face cut out of `camera` crossing `coffee` on an arc; `pan`,
the camera panning 40 px across `astronaut` (everything moves); `deform`, a face-sized
disc of `camera` rotating 30 degrees and growing 30% in place. Dual shutter, Poisson and
read noise, fixed seeds. Needs ../shared/data/diffusercam-tutorial/ beside the checkout.
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FRAMES = 40


def grey(name, rows, cols):
    from skimage import data, transform

    img = getattr(data, name)().astype(np.float64)
    if img.ndim == 3:
        img = img[..., :3].mean(-1)
    img /= img.max()
    return transform.resize(img, (rows, cols), anti_aliasing=True)


def clips(rows, cols, t=FRAMES):
    from skimage import transform

    s = rows / 120.0
    out = {}
    bg = grey("coffee", rows, cols)
    face = grey("camera", 256, 256)[40:110, 90:160]
    d = int(round(36 * s))
    obj = transform.resize(face, (d, d), anti_aliasing=True)
    yy, xx = np.mgrid[0:d, 0:d]
    mask = ((yy - (d - 1) / 2) ** 2 + (xx - (d - 1) / 2) ** 2) < (d / 2 - 1) ** 2
    v = np.empty((t, rows, cols))
    for f in range(t):
        frame = bg.copy()
        r0 = int(round(40 * s + 10 * s * np.sin(f / t * np.pi)))
        c0 = int(round(10 * s + (cols - d - 20 * s) * f / (t - 1)))
        frame[r0:r0 + d, c0:c0 + d][mask] = obj[mask]
        v[f] = frame
    out["object"] = v
    wide = grey("astronaut", rows, cols + int(40 * s))
    out["pan"] = np.stack([wide[:, int(round(x)):int(round(x)) + cols] for x in np.linspace(0, 40 * s, t)])
    base = grey("camera", rows, cols)
    p = int(round(60 * s))
    r0, c0 = int(30 * s), int(50 * s)
    yy, xx = np.mgrid[0:p, 0:p]
    disc = ((yy - (p - 1) / 2) ** 2 + (xx - (p - 1) / 2) ** 2) < (p / 2 - 2) ** 2
    v = np.empty((t, rows, cols))
    for f in range(t):
        patch = base[r0:r0 + p, c0:c0 + p]
        grown = transform.rotate(transform.rescale(patch, 1 + 0.3 * f / (t - 1), anti_aliasing=True), 30 * f / (t - 1), mode="edge")
        o = (grown.shape[0] - p) // 2
        frame = base.copy()
        frame[r0:r0 + p, c0:c0 + p][disc] = grown[o:o + p, o:o + p][disc]
        v[f] = frame
    out["deform"] = v
    return out


def run(cmd, log):
    with open(log, "w") as f:
        r = subprocess.run([str(c) for c in cmd], stdout=f, stderr=subprocess.STDOUT)
    if r.returncode != 0:
        sys.exit(f"failed ({r.returncode}): {' '.join(map(str, cmd))}\n  see {log}")


def interpolation(truth):
    """The first and last truth frames linearly interpolated, and their scores."""
    t = truth.reshape(truth.shape[0], -1).astype(np.float64)
    w = np.linspace(0, 1, len(t))[:, None]
    return scores(t[0][None] * (1 - w) + t[-1][None] * w, t)


def scores(x, t):
    """(relative error after the best scale, motion error): src/solve/trace.rs."""
    s = (x * t).sum() / max((x * x).sum(), 1e-300)
    rel = np.linalg.norm(s * x - t) / np.linalg.norm(t)
    dt = t - t.mean(0)
    motion = np.linalg.norm(s * (x - x.mean(0)) - dt) / np.linalg.norm(dt)
    return rel, motion


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--rows", type=int, default=120)
    ap.add_argument("--cols", type=int, default=160)
    ap.add_argument("--tutorial", type=Path, default=ROOT.parent / "shared" / "data" / "diffusercam-tutorial")
    ap.add_argument("--exe", type=Path, default=ROOT / "target" / "release" / "rollcam")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    down = 1200 // a.rows
    # The capture spans (rows/2 + exposure lines) line times on a dual shutter; the stack
    # is spread over it.
    span_us = (a.rows // 2 + 2) * 220.0
    rows = []
    for name, video in clips(a.rows, a.cols).items():
        stack = a.out / f"{name}.npy"
        np.save(stack, video.astype(np.float32))
        for keys in (False, True):
            d = a.out / (name + ("-keys" if keys else ""))
            sim = [a.exe, "simulate", "--scene", "stack", "--stack", stack, "--stack-e-per-us", "60",
                   "--stack-interval-us", f"{span_us / FRAMES:.1f}", "--psf", a.tutorial / "psf_sample.tif",
                   "--psf-downsample", str(down), "--shutter", "dual", "--seed", "5", "--out", d, "--force"]
            run(sim + (["--keyframes", "first,last"] if keys else []), a.out / f"{d.name}.simulate.log")
            base = [a.exe, "reconstruct", "--raw", d / "raw.tiff", "--psf", d / "psf.tiff", "--config", d / "capture.toml",
                    "--truth", d / "truth.npy", "--force"]
            run(base + ["--out", d / "default"], a.out / f"{d.name}.default.log")
            s = json.load(open(d / "default" / "summary.json"))
            ch = s["channels"][0]
            row = {"clip": name, "keyframes": keys, "mode": s["plan"]["mode"], "rel": s["rel_error_scaled"],
                   "motion": s["motion_error"], "seconds": s["seconds"], "converged": s["converged"],
                   "temporal_mean": ch["baseline"]["temporal_mean_rel_error_scaled"]}
            if keys:
                row["interp_rel"], row["interp_motion"] = interpolation(np.load(d / "truth.npy"))
            else:
                run(base + ["--out", d / "still", "--scene", "static=true"], a.out / f"{d.name}.still.log")
                row["still_rel"] = json.load(open(d / "still" / "summary.json"))["rel_error_scaled"]
            rows.append(row)
            print(row, flush=True)
    json.dump(rows, open(a.out / "natural-clips.json", "w"), indent=1)
    f = lambda v: "-" if v is None else f"{v:.3f}"
    lines = [f"Natural clips at {a.rows} x {a.cols} (`scripts/natural-clips.py --rows {a.rows} --cols {a.cols}`), defaults:", "",
             "| clip | key frames | mode | relative error | motion error | seconds | best still | truth's temporal mean | interpolated key frames |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        interp = f"{f(r.get('interp_rel'))} / {f(r.get('interp_motion'))}" if r["keyframes"] else "-"
        lines.append(f"| {r['clip']} | {'first, last' if r['keyframes'] else 'none'} | {r['mode']} | {f(r['rel'])} | {f(r['motion'])} | "
                     f"{r['seconds']:.1f}{'' if r['converged'] else ' (cap)'} | {f(r.get('still_rel'))} | {f(r['temporal_mean'])} | {interp} |")
    (a.out / "natural-clips.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
