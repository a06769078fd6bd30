#!/usr/bin/env bash
# The solvers on a CUDA device (`device=cuda`) against restart FISTA on the same
# machine's CPU cores, for docs/gpu.md: the three study captures
# (scripts/study-captures.sh: a still through the measured PSF, a dense video, the LED
# array) at --tau-rel 2.5e-4 (the default when the study ran; the default is now the
# noise rule), one `rollcam compare` call each with fista-restart on
# the CPU and on the device and admm-split on the device (and on the CPU, the still
# only: on the videos it costs 13-27x restart FISTA per iteration,
# docs/solver-study.md), N iterations (still-iters on the still, from zero;
# video-iters on the videos). Then `rollcam reconstruct` of the dense video with the
# defaults, on the CPU and with `--device cuda`: what a user gets. Prints
# scripts/gpu-summary.py's table. Needs a binary built with `--features cuda`:
#   BIN=target/release/rollcam [PSF=...] scripts/gpu-study.sh [rows cols psf-downsample still-iters video-iters]
# (default 240 320 5 1000 600: the issue's sizes; the measured PSF is 1200 x 1600).
# Raw outputs stay in $WORK.
set -euo pipefail
cd "$(dirname "$0")/.."
set -- "${1:-240}" "${2:-320}" "${3:-5}" "${4:-1000}" "${5:-600}"
source scripts/study-captures.sh "$@"
echo "device: $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null || echo unknown); CPU cores: $(nproc)"
for name in still dense led; do
  iters=$VIDEO_ITERS; start=(); runs="fista-restart,fista-restart:device=cuda,admm-split:device=cuda"
  [ "$name" = still ] && iters=$STILL_ITERS && start=(--start zero) && runs="$runs,admm-split"
  $BIN compare --raw "$WORK/$name/raw.tiff" --psf "$WORK/$name/psf.tiff" --config "$WORK/$name/capture.toml" \
    --truth "$WORK/$name/truth.npy" "${start[@]}" --solvers "$runs" --iters "$iters" --tau-rel 2.5e-4 --out "$WORK/cmp-$name" >"$WORK/cmp-$name.txt"
done
python3 scripts/gpu-summary.py "$WORK"
echo "Sizes and L (from compare): $(for n in still dense led; do grep -m1 -o '^problem: [^,]*' "$WORK/cmp-$n.txt" | sed "s/^/$n: /"; done | paste -sd';')"
echo
echo "rollcam reconstruct of the dense video with the defaults:"
for device in cpu cuda; do
  $BIN reconstruct --raw "$WORK/dense/raw.tiff" --psf "$WORK/dense/psf.tiff" --config "$WORK/dense/capture.toml" \
    --truth "$WORK/dense/truth.npy" --device "$device" --out "$WORK/rec-$device" >"$WORK/rec-$device.txt" 2>&1
  echo "--device $device:"; grep -v "INFO\|WARN" "$WORK/rec-$device.txt" | tail -8
  python3 -c "import json,sys; s=json.load(open(sys.argv[1])); print({k: v for k, v in s.items() if isinstance(v, (int, float, bool, str))})" "$WORK/rec-$device/summary.json"
done
echo "Load average before: $LOAD_BEFORE; after: $(cut -d' ' -f1-3 /proc/loadavg). Raw outputs in $WORK"
