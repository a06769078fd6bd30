#!/usr/bin/env bash
# The closed-form ADMM (admm-split) against restart FISTA, for docs/solver-study.md
# ("ADMM in closed form"): on a still through the measured PSF (global shutter, one
# frame: exposure = line time; every
# run from zero), a dense video (disc over texture, contrast 10) and the LED array
# (compare's default start), each at the default weight and at --tau-rel 2.5e-4. Prints
# one Markdown table row per capture and weight: the seconds each run needs to come
# within 0.01% of restart FISTA's objective after ITERS iterations (Haar map, as
# `reconstruct --tv-prox auto` picks at these weights) and within 0.01% of the lowest
# objective any run reached, the seconds per iteration, and the final objectives.
# Usage: scripts/admm-split-study.sh [rows cols psf-downsample still-iters video-iters]
# (default 120 160 10 1000 600: the measured PSF is 1200 x 1600).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/study-captures.sh "$@"

RUNS=fista-restart,fista-restart:tv_prox=dual10,admm-split
echo "| capture | tau_rel | iterations | s to restart FISTA's objective +0.01%: fista-restart / dual10 / admm-split | s to the lowest objective +0.01% | s/iteration | final objective over the lowest |"
echo "|---|---|---|---|---|---|---|"
for name in still dense led; do
  iters=$VIDEO_ITERS; start=()
  [ "$name" = still ] && iters=$STILL_ITERS && start=(--start zero)
  for tau in default 2.5e-4; do
    tau_flag=()
    [ "$tau" != default ] && tau_flag=(--tau-rel "$tau")
    out="$WORK/cmp-$name-$tau"
    $BIN compare --raw "$WORK/$name/raw.tiff" --psf "$WORK/$name/psf.tiff" --config "$WORK/$name/capture.toml" \
      --truth "$WORK/$name/truth.npy" --solvers "$RUNS" --iters "$iters" --out "$out" "${tau_flag[@]}" "${start[@]}" >"$out.txt"
    python3 scripts/admm-split-summary.py "$out" "$name" "$tau" "$iters"
  done
done
echo
echo "Sizes (from compare): $(for n in still dense led; do grep -m1 -o 'Problem: [^;]*' "$WORK/cmp-$n-default/summary.md" | sed "s/^/$n: /"; done | paste -sd';')"
echo "Load average before: $LOAD_BEFORE; after: $(cut -d' ' -f1-3 /proc/loadavg). Raw outputs in $WORK"
