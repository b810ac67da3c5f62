#!/usr/bin/env bash
# Runs every test of the workspace on a fresh machine: installs what the tests need
# (FFmpeg for the video-container tests, OpenCV for the chequerboard tests, the pinned Rust
# toolchain with the thumb target for the firmware build test), then `cargo test` over the
# default members with meb's `opencv` feature (so the ToF calibration tests run too), then the
# Python package's pytest suite (scripts/python-test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cargo test --locked --features meb/opencv "$@"
bash scripts/python-test.sh
