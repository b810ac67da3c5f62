#!/usr/bin/env bash
# The README's main job on a fresh machine: installs what the build needs (OpenCV and clang for
# the ToF chequerboard detector, npm for the report's inlined 3-D view, FFmpeg), then runs
# `meb demo` (a simulated capture of the thesis' out-of-plane rig, end to end). Arguments are
# passed to `meb demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo run --release --locked -p meb -- demo "$@"
