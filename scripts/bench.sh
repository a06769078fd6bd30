#!/usr/bin/env bash
# Regenerates the figures in docs/performance.md: builds the release binary, then runs
# every benchmark preset (each in its own process) and the time-to-30-dB run, and
# writes the table between the bench markers. Extra arguments go to `rollcam bench`
# (e.g. --iters 20, --threads 2). Kernel timings: cargo bench --bench kernels.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release
echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) CPUs; $(uptime)"
target/release/rollcam bench --all --markdown docs/performance.md "$@"
