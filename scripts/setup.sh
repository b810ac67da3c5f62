#!/usr/bin/env bash
# Installs what building and testing meb needs on a fresh Debian machine. Idempotent.
#   - FFmpeg: video capture (meb decode on video files) and its tests;
#   - Node.js + npm: three.js for report.html's 3-D view, pinned in host/cli/viewer/package-lock.json;
#   - Chromium: the test that opens report.html headless and checks the 3-D view draws;
#   - OpenCV, clang, libclang: the opencv crate behind meb's `opencv` feature (chequerboard
#     corners for `meb tof calibrate`), which the tests and CI build; `--without-opencv` skips
#     them (scripts/demo.sh: the default build needs no OpenCV).
set -euo pipefail
opencv=1
for arg in "$@"; do
    case "$arg" in
        --without-opencv) opencv=0 ;;
        *) echo "setup: unknown argument $arg (known: --without-opencv)" >&2; exit 2 ;;
    esac
done
cd "$(dirname "$0")/.."
# The toolchain, its thumbv7em target and llvm-tools come from rust-toolchain.toml.
rustup toolchain install >/dev/null 2>&1 || rustup show active-toolchain >/dev/null
if [ "$(id -u)" = 0 ]; then sudo=""; else sudo="sudo"; fi
missing=()
if ! command -v ffmpeg >/dev/null || ! command -v ffprobe >/dev/null; then missing+=(ffmpeg); fi
if ! command -v npm >/dev/null; then missing+=(npm); fi
if ! command -v chromium >/dev/null; then missing+=(chromium); fi
# OpenCV (and clang, which the opencv crate's binding generator needs): chequerboard corners.
if [ "$opencv" = 1 ]; then
    for p in libopencv-dev clang libclang-dev; do
        if ! dpkg -s "$p" >/dev/null 2>&1; then missing+=("$p"); fi
    done
fi
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing Debian packages: ${missing[*]}" >&2
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null
fi
# three.js at the version the lock file pins (host/cli/build.rs runs the same when it is missing).
if [ ! -f host/cli/viewer/node_modules/three/build/three.module.min.js ]; then
    echo "setup: installing three.js (npm ci in host/cli/viewer)" >&2
    (cd host/cli/viewer && npm ci --ignore-scripts --no-audit --no-fund >/dev/null)
fi
