#!/usr/bin/env bash
# The README's main job on a fresh machine: installs what the build needs (npm for the report's
# inlined 3-D view, FFmpeg; not OpenCV, which only the optional `opencv` feature behind
# `meb tof calibrate` uses), then runs `meb demo` (a simulated capture of the thesis'
# out-of-plane rig, end to end). Arguments are passed to `meb demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --without-opencv
cargo run --release --locked -p meb -- demo "$@"
