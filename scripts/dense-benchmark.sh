#!/usr/bin/env bash
# The dense-scene benchmark of docs/dense-scenes.md: a bright disc crossing a textured
# still scene (simulate --scene disc-over-texture) through the measured DiffuserCam PSF
# at 240 x 320, reconstructed as a plain video and with the static + dynamic model,
# judged against the truth by `rollcam analyze --truth`.
# Usage: scripts/dense-benchmark.sh [WORK_DIR] (default: a new temporary folder).
# START=zero|still|auto (default auto) sets every reconstruction's --start.
set -euo pipefail
cd "$(dirname "$0")/.."
psf=../shared/data/diffusercam-tutorial/psf_sample.tif
[ -f "$psf" ] || { echo "missing the measured PSF $psf" >&2; exit 1; }
work=${1:-$(mktemp -d)}
mkdir -p "$work"
export ROLLCAM_CACHE_DIR="${ROLLCAM_CACHE_DIR:-$work/cache}"
cargo build --release -q
bin=target/release/rollcam
start=${START:-auto}
for contrast in 4 10; do
  sim="$work/dense-$contrast"
  [ -d "$sim" ] || $bin simulate --scene disc-over-texture --disc-contrast "$contrast" --psf "$psf" --psf-downsample 5 --out "$sim" > /dev/null 2>&1
  for model in plain static static-noreweight; do
    for stop in "--iters 200" "--iters 600 --obj-tol 1e-4"; do
      tag="$model-$(echo "$stop" | tr -d ' -')"
      rec="$work/rec-$contrast-$tag"
      [ -d "$rec" ] && continue
      extra=()
      [ "$model" = static ] && extra=(--scene static_background=true)
      [ "$model" = static-noreweight ] && extra=(--scene static_background=true --l1-reweight 0)
      # shellcheck disable=SC2086
      line=$($bin reconstruct --raw "$sim/raw.tiff" --psf "$sim/psf.tiff" --config "$sim/capture.toml" --truth "$sim/truth.npy" $stop --start "$start" "${extra[@]}" --out "$rec" 2>/dev/null | grep '^channel 0: ')
      track=$($bin analyze "$rec" --truth "$sim/truth.npy" 2>/dev/null | grep '^track')
      echo "contrast $contrast, $model, $stop"
      echo "  $line"
      echo "  $track"
    done
  done
done
