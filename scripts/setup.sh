#!/usr/bin/env bash
# Installs what building and testing meb needs on a fresh Debian machine. Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
# The toolchain, its thumbv7em target and llvm-tools come from rust-toolchain.toml.
rustup toolchain install >/dev/null 2>&1 || rustup show active-toolchain >/dev/null
if ! command -v ffmpeg >/dev/null || ! command -v ffprobe >/dev/null; then
    echo "setup: installing FFmpeg (Debian package ffmpeg) for video capture" >&2
    if [ "$(id -u)" = 0 ]; then sudo=""; else sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq ffmpeg >/dev/null
fi
if ! dpkg -s libopencv-dev clang libclang-dev >/dev/null 2>&1; then
    echo "setup: installing OpenCV and clang (Debian libopencv-dev, clang, libclang-dev) for chequerboard detection (the opencv crate)" >&2
    if [ "$(id -u)" = 0 ]; then sudo=""; else sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libopencv-dev clang libclang-dev >/dev/null
fi
