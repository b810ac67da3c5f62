#!/usr/bin/env bash
# Tests the Python package (host/python): builds it with maturin into a virtual environment
# under target/ and runs its pytest suite, which compares it with the `meb` command.
#   - Python tools pinned in host/python/requirements.txt (maturin, numpy, pytest);
#   - the wheel is built with the workspace's `dev` profile (dependencies at -O3, Cargo.toml)
#     and the feature set `cargo test --features meb/opencv` gives the library crates, so the
#     crates the Rust tests compiled are reused rather than rebuilt in another profile;
#   - `meb` itself (target/debug/meb, what the tests compare with) comes from `cargo test`'s
#     build (`--no-run` here: nothing to do after a `cargo test`, whose feature set it shares).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
venv=$root/target/python-venv
started=$SECONDS
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/pip" install --quiet --disable-pip-version-check -r host/python/requirements.txt
cargo test --locked --features meb/opencv --no-run --quiet
(
    cd host/python
    VIRTUAL_ENV=$venv "$venv/bin/maturin" develop --quiet --locked --profile dev \
        --features meb-pipeline/opencv,meb-core/testing
)
echo "python-test: package built in $((SECONDS - started)) s" >&2
MEB_BIN=$root/target/debug/meb "$venv/bin/python" -m pytest -q -p no:cacheprovider host/python/tests
echo "python-test: done in $((SECONDS - started)) s" >&2
