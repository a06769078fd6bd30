#!/usr/bin/env python3
"""The fit report's PSF orientation check on natural stills: each scikit-image
photograph simulated as a one-frame global-shutter capture through the measured PSF,
then reconstructed with the PSF as simulated, flipped upside down and mirrored left
to right; one line per run from summary.json's `fit.psf_orientation` (the still's chi2
as given and with each flip, the flip named, the warnings). docs/usage.md "The fit
report" quotes it.

    python3 -m venv /tmp/sk && /tmp/sk/bin/pip install numpy tifffile scikit-image
    cargo build --release
    /tmp/sk/bin/python scripts/orientation-study.py --out /tmp/orientation

Needs ../shared/data/diffusercam-tutorial/psf_sample.tif beside the checkout, or
--psf FILE. Every seed is fixed here.
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import tifffile
from skimage import color, data, transform

ROOT = Path(__file__).resolve().parent.parent
IMAGES = "rocket,moon,coins,hubble_deep_field,retina,page,immunohistochemistry,grass,text"
# (rows, cols, --psf-downsample): the suite's size and a larger one.
SIZES = [(120, 160, 10), (150, 200, 8)]
# Photo-electrons per microsecond in the brightest scene pixel: bright, and the suite's
# photon-starved light (at the first size only).
LIGHTS = [4000.0, 8.0]


def natural(name, rows, cols):
    img = getattr(data, name)().astype(np.float64)
    if img.ndim == 3:
        img = color.rgb2gray(img[..., :3])
    img /= img.max()
    return np.clip(transform.resize(img, (rows, cols), anti_aliasing=True), 0, None).astype(np.float32)


def run(cmd):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"failed ({r.returncode}): {' '.join(map(str, cmd))}\n{r.stdout[-2000:]}{r.stderr[-2000:]}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="work folder (new or empty)")
    ap.add_argument("--exe", type=Path, default=ROOT / "target/release/rollcam")
    ap.add_argument("--psf", type=Path, default=ROOT.parent / "shared/data/diffusercam-tutorial/psf_sample.tif")
    ap.add_argument("--images", default=IMAGES, help="scikit-image data names, comma-separated")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if any(args.out.iterdir()):
        sys.exit(f"{args.out}: not empty (the study writes its captures there)")
    rows_out = []
    for name in args.images.split(","):
        for i, (rows, cols, ds) in enumerate(SIZES):
            for light in LIGHTS if i == 0 else LIGHTS[:1]:
                d = args.out / f"{name}-{rows}x{cols}-{light:g}"
                d.mkdir()
                np.save(d / "stack.npy", natural(name, rows, cols)[None] * light)
                sim = d / "sim"
                run([args.exe, "simulate", "--scene", "stack", "--stack", d / "stack.npy", "--psf", args.psf,
                     "--psf-downsample", ds, "--shutter", "global", "--line-time-us", "10", "--exposure-us", "10",
                     "--seed", "7", "--out", sim])
                psf = tifffile.imread(sim / "psf.tiff")
                for label, p in [("as simulated", psf), ("upside down", psf[::-1]), ("left-right", psf[:, ::-1])]:
                    tag = label.replace(" ", "-")
                    pf = d / f"psf-{tag}.tiff"
                    tifffile.imwrite(pf, np.ascontiguousarray(p))
                    rec = d / f"rec-{tag}"
                    run([args.exe, "reconstruct", "--raw", sim / "raw.tiff", "--psf", pf, "--config", sim / "capture.toml",
                         "--out", rec])
                    fit = json.loads((rec / "summary.json").read_text())["fit"]
                    o = fit["psf_orientation"]
                    line = {"image": name, "size": f"{rows} x {cols}", "light": light, "psf": label,
                            "chi2_given": o["chi2_given"], "flips": {f["flip"]: f["chi2"] for f in o["flips"]},
                            "better": o["better"], "seconds": o["seconds"], "warnings": fit["warnings"]}
                    rows_out.append(line)
                    flips = ", ".join(f"{k} {v:.3f}" for k, v in line["flips"].items())
                    said = "; ".join(w.split(":")[0] for w in fit["warnings"]) or "no warning"
                    print(f"{name:22s} {rows}x{cols} light {light:6g}  PSF {label:12s} given {o['chi2_given']:.3f} ({flips})"
                          f"  named: {o['better']}  {o['seconds']:.2f} s  {said}", flush=True)
    (args.out / "orientation.json").write_text(json.dumps(rows_out, indent=1))


if __name__ == "__main__":
    main()
