#!/usr/bin/env bash
# Regenerates fixtures/captures/: small recorded sessions of the simulated camera
# (48 x 64 dual rolling shutter, line time 220 us, exposure 660 us, reconstructed at
# downsample 2) for the pipeline's replay tests. Each folder is a capture folder
# (capture.json, frame_NNNNNN.tiff + .json) plus psf.tiff, capture.toml and the
# ground truth truth_NNNNNN.npy of every frame. Fixed seeds: the TIFF, PSF and truth
# files come out byte-identical on every run (the JSON sidecars carry host times).
#
#   scripts/make-fixtures.sh [rollcam binary]
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-}
if [ -z "$bin" ]; then
    cargo build --release --quiet
    bin=target/release/rollcam
fi
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

make() { # name frames run-args...
    local name=$1 frames=$2
    shift 2
    ROLLCAM_CACHE_DIR=off "$bin" run --camera sim --sim-size 48x64 --downsample 2 --frames "$frames" \
        --seed 7 --iters 1 --out "$tmp/$name" "$@" >/dev/null
    local dest=fixtures/captures/$name
    rm -rf "$dest"
    mkdir -p "$dest"
    cp "$tmp/$name"/raw/capture.json "$tmp/$name"/raw/frame_* "$dest/"
    cp "$tmp/$name/psf.tiff" "$tmp/$name/capture.toml" "$dest/"
    cp "$tmp/$name"/sim/truth_*.npy "$dest/"
    echo "$dest: $(ls "$dest" | wc -l) files, $(du -sk "$dest" | cut -f1) KB"
}

# Four LEDs flashing in unison at 505 Hz (period 1980 us), three frames 50 ms apart.
make led-505hz 3 --scene led-array --sim-period-us 1980
# A bright disc crossing the field, two frames 10 ms apart.
make moving-disc 2 --scene moving-disc --frame-rate-hz 100
