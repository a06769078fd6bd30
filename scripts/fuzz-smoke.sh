#!/usr/bin/env bash
# A smoke run of every fuzz target (fuzz/, cargo-fuzz): each runs over its committed seed
# corpus and then mutates for a few seconds. Needs the nightly toolchain; installs
# cargo-fuzz when it is missing. Without nightly it says so and skips (exit 0).
#
#   scripts/fuzz-smoke.sh            # every target, FUZZ_RUNS (default 100000) from FUZZ_SEED (1), at most FUZZ_SECONDS (20) each
#   FUZZ_SECONDS=60 scripts/fuzz-smoke.sh tiff npy
#
# Built without a sanitizer (--sanitizer none): the targets are safe Rust, what the run
# looks for is a panic, an abort or memory past the limits below, and an AddressSanitizer
# build costs minutes more on CI's 2 cores. The long runs in docs/reliability.md use the
# default sanitizer (address).
set -euo pipefail
cd "$(dirname "$0")/.."

if ! cargo +nightly --version >/dev/null 2>&1; then
  echo "fuzz smoke run SKIPPED: the nightly toolchain is not installed (cargo +nightly fails); cargo-fuzz needs it"
  exit 0
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
  echo "installing cargo-fuzz (cargo install --locked cargo-fuzz)"
  if ! cargo install --locked cargo-fuzz; then
    echo "fuzz smoke run SKIPPED: cargo-fuzz could not be installed (see above)"
    exit 0
  fi
fi

seconds="${FUZZ_SECONDS:-20}"
# A fixed seed and a fixed count: the smoke run is the same mutations on every machine
# (a slower one stops at the time cap, on a prefix of them), so a test run does not fail
# by chance on an input nobody has seen; long exploratory runs are docs/reliability.md's.
runs="${FUZZ_RUNS:-100000}"
seed="${FUZZ_SEED:-1}"
# FUZZ_SANITIZER=address reuses an AddressSanitizer build (cargo +nightly fuzz build).
sanitizer="${FUZZ_SANITIZER:-none}"
targets=("$@")
[ $# -eq 0 ] && targets=(led_host led_device led_firmware tiff npy png dng jpeg jpeg_header capture_toml session_json live_request capture_timestamps calibration_folder)

cargo +nightly fuzz build --sanitizer "$sanitizer"
for t in "${targets[@]}"; do
  # A scratch corpus and artifact folder: the committed seeds are read, nothing is kept.
  scratch=$(mktemp -d)
  mkdir -p "$scratch/corpus" "$scratch/artifacts"
  echo "fuzz smoke: $t ($runs runs from seed $seed, at most ${seconds}s)"
  set +e
  cargo +nightly fuzz run --sanitizer "$sanitizer" "$t" "$scratch/corpus" "fuzz/corpus/$t" -- \
    -runs="$runs" -seed="$seed" -max_total_time="$seconds" -rss_limit_mb=2048 -max_len=65536 -print_final_stats=1 \
    -artifact_prefix="$scratch/artifacts/" >"$scratch/log" 2>&1
  status=$?
  set -e
  grep -E 'stat::number_of_executed_units|Done [0-9]+ runs' "$scratch/log" || true
  if [ "$status" -ne 0 ]; then
    tail -n 40 "$scratch/log"
    mkdir -p "fuzz/artifacts/$t"
    cp "$scratch"/artifacts/* "fuzz/artifacts/$t/" 2>/dev/null || true
    echo "fuzz smoke: $t FAILED (exit $status); the input is under fuzz/artifacts/$t/"
    exit 1
  fi
  rm -rf "$scratch"
done
echo "fuzz smoke: ${#targets[@]} targets, no crash"
