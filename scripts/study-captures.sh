# The three captures of the solver studies (scripts/admm-split-study.sh,
# scripts/precond-study.sh), sourced by each from the checkout's root with the study's
# arguments [rows cols psf-downsample still-iters video-iters]: a still through the
# measured PSF (global shutter, one frame), a dense video (disc over texture, contrast
# 10) and the LED array, simulated into $WORK by the release binary $BIN, with the
# Lipschitz cache in $WORK and the load average before the runs in $LOAD_BEFORE.
# $BIN and $PSF given in the environment are used as they are (no build): the GPU
# study runs a binary built elsewhere.
ROWS="${1:-120}"; COLS="${2:-160}"; DOWN="${3:-10}"; STILL_ITERS="${4:-1000}"; VIDEO_ITERS="${5:-600}"
PSF="${PSF:-../shared/data/diffusercam-tutorial/psf_sample.tif}"
if [ -z "${BIN:-}" ]; then
  cargo build --release --bin rollcam
  BIN="${CARGO_TARGET_DIR:-target}/release/rollcam"
fi
WORK="$(mktemp -d)"
export ROLLCAM_CACHE_DIR="$WORK/lipschitz"
LOAD_BEFORE="$(cut -d' ' -f1-3 /proc/loadavg)"

sim() { # name scene extra-args...
  local name=$1 scene=$2; shift 2
  $BIN simulate --scene "$scene" --psf "$PSF" --psf-downsample "$DOWN" --rows "$ROWS" --cols "$COLS" --out "$WORK/$name" "$@" >"$WORK/$name.sim.txt"
}
sim still disc-over-texture --shutter global --exposure-us 220
sim dense disc-over-texture --disc-contrast 10
sim led led-array
