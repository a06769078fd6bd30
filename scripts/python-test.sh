#!/usr/bin/env bash
# The Python module's tests: a venv (target/py-venv) with maturin, pytest, NumPy and
# SciPy from PyPI, the module built from this checkout and installed into it, the
# command-line tool built for the comparison test, then pytest python/tests.
# ROLLCAM_PY_PROFILE=release builds the wheel as `pip install ./python` does for
# users (default here: dev, whose dependencies are optimised; minutes less on 2 cores).
# The extension is built with the `aravis` feature (ROLLCAM_PY_FEATURES).
set -euo pipefail
cd "$(dirname "$0")/.."

venv=target/py-venv
python=${PYTHON:-python3}
if [ ! -x "$venv/bin/python" ]; then
  "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check maturin pytest numpy scipy

profile=${ROLLCAM_PY_PROFILE:-dev}
# GenICam cameras (libaravis-dev, installed by scripts/test.sh) for the fake-camera
# test; ROLLCAM_PY_FEATURES= builds without.
features=${ROLLCAM_PY_FEATURES-aravis}
# maturin's build backend takes its `maturin build` arguments from this variable.
MATURIN_PEP517_ARGS="--profile $profile${features:+ --features $features}" "$venv/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps ./python
# The CLI the comparison test runs (target/debug/rollcam, shares the library build).
cargo build --quiet --bin rollcam

export ROLLCAM_CACHE_DIR="${ROLLCAM_CACHE_DIR:-$(mktemp -d)}"
"$venv/bin/python" -m pytest python/tests -q "$@"
