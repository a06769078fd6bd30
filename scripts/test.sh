#!/usr/bin/env bash
# The test command: installs the system packages the hardware backends, the
# firmware build and the live page's browser test need (Debian), checks formatting,
# runs every test of the workspace with all features on, the Python module's tests
# (scripts/python-test.sh), then clippy with warnings as errors. Usage: scripts/test.sh [extra cargo test args]
set -euo pipefail
# One build per run: incremental caches would only take disk (gigabytes on a CI machine).
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
cd "$(dirname "$0")/.."

mapfile -t packages < <(grep -v -e '^#' -e '^$' scripts/debian-packages.txt)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# Formatting first: a quick, clear failure (rustfmt.toml holds the line length).
cargo fmt --all --check

# Keep the solver's Lipschitz cache out of the user's home during tests.
export ROLLCAM_CACHE_DIR="${ROLLCAM_CACHE_DIR:-$(mktemp -d)}"
log=$(mktemp)
set +e
cargo test --workspace --all-features --no-fail-fast "$@" 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e
# One closing line over every test binary (cargo prints one per binary, doc-tests last).
awk '/^test result:/ { for (i = 1; i <= NF; i++) { if ($(i) ~ /^passed;?$/) p += $(i-1); if ($(i) ~ /^failed;?$/) f += $(i-1); if ($(i) ~ /^ignored;?$/) s += $(i-1) } }
     END { printf "total: %d passed, %d failed, %d skipped\n", p, f, s }' "$log"
rm -f "$log"
[ "$status" -ne 0 ] && exit "$status"
# The Python module: built from this checkout into a venv, its pytest suite.
bash scripts/python-test.sh
# Lints on every target with every feature; a warning fails the run.
cargo clippy --workspace --all-features --all-targets -- -D warnings
# Every fuzz target for a few seconds (skipped, with a line saying why, without nightly).
bash scripts/fuzz-smoke.sh
