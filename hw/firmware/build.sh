#!/bin/sh
# Builds the LED controller firmware if avr-gcc is installed; says so if not.
# Usage: hw/firmware/build.sh [make targets...]   (default: all)
set -eu
cd "$(dirname "$0")"
if ! command -v avr-gcc >/dev/null 2>&1 || ! command -v avr-objcopy >/dev/null 2>&1; then
    echo "build.sh: SKIPPED firmware build: avr-gcc/avr-objcopy not found (Debian: apt-get install -y gcc-avr binutils-avr avr-libc)" >&2
    exit 0
fi
if ! command -v make >/dev/null 2>&1; then
    echo "build.sh: SKIPPED firmware build: make not found" >&2
    exit 0
fi
make "${@:-all}"
echo "build.sh: built $(pwd)/build/rollcam-led.hex"
