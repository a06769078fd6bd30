#!/usr/bin/env bash
# The per-frame preconditioner (`fista-restart:precond=frames`) against plain restart
# FISTA, for docs/solver-study.md ("A per-frame preconditioner"): on a still through
# the measured PSF (global shutter, one frame, every run from zero), a dense video
# (disc over texture, contrast 10) and the LED array (compare's default start), at the
# weight that was the default then (--tau-rel 2.5e-4, given here; the default is now
# the noise rule). Each capture is one `rollcam compare` call with the
# Haar map (the default map at this weight) and the exact map (dual10), each plain and
# preconditioned, and admm-split on the still. Prints one Markdown table row per run:
# the seconds to come within 0.01% of plain restart FISTA's objective after ITERS
# iterations (the issue's target) and of the lowest objective any run reached, the
# seconds per iteration, the final objective over the lowest, the final relative error
# (after the best scale) and the seconds to come within 1% of the best error any run
# reached.
# Usage: scripts/precond-study.sh [rows cols psf-downsample still-iters video-iters]
# (default 120 160 10 1000 600: the measured PSF is 1200 x 1600).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/study-captures.sh "$@"

RUNS=fista-restart,fista-restart:precond=frames,fista-restart:tv_prox=dual10,fista-restart:tv_prox=dual10:precond=frames
echo "| capture | run | s to plain fista-restart's final objective +0.01% | s to the lowest objective +0.01% | s/iteration | final objective / lowest | final rel. error | s to the best error +1% |"
echo "|---|---|---|---|---|---|---|---|"
for name in still dense led; do
  iters=$VIDEO_ITERS; start=(); runs=$RUNS
  [ "$name" = still ] && iters=$STILL_ITERS && start=(--start zero) && runs="$RUNS,admm-split"
  out="$WORK/cmp-$name"
  $BIN compare --raw "$WORK/$name/raw.tiff" --psf "$WORK/$name/psf.tiff" --config "$WORK/$name/capture.toml" \
    --truth "$WORK/$name/truth.npy" --solvers "$runs" --iters "$iters" --tau-rel 2.5e-4 --out "$out" "${start[@]}" >"$out.txt"
  python3 scripts/precond-summary.py "$out" "$name"
done
echo
echo "Sizes and L (from compare): $(for n in still dense led; do grep -m1 -o '^problem: [^,]*' "$WORK/cmp-$n.txt" | sed "s/^/$n: /"; done | paste -sd';')"
echo "Load average before: $LOAD_BEFORE; after: $(cut -d' ' -f1-3 /proc/loadavg). Raw outputs in $WORK"
