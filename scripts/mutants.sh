#!/usr/bin/env bash
# Mutation testing with cargo-mutants (installed at a pinned version when missing).
#
#   bash scripts/mutants.sh          # CI: the register encodings (chip-plan/src/regs.rs)
#                                    # against their fast tests (vendor check, pin table)
#   bash scripts/mutants.sh --full   # chip-plan and protocol whole, with all their tests
#
# Mutants listed as equivalent in chip-plan/MUTANTS.md (the `regex` column) are skipped; any
# other mutant that no test catches fails the run (cargo-mutants exits non-zero).
set -euo pipefail
cd "$(dirname "$0")/.."
version=27.1.0
if ! command -v cargo-mutants >/dev/null || [ "$(cargo mutants --version)" != "cargo-mutants $version" ]; then
    echo "mutants: installing cargo-mutants $version" >&2
    # A debug build: it compiles in about half the time, and the tool only runs cargo.
    cargo install --locked --quiet --debug "cargo-mutants@$version"
fi
# The equivalent mutants: the backquoted regex in the first column of each table row of
# MUTANTS.md's "Equivalent" section.
excludes=()
while IFS= read -r re; do
    excludes+=(--exclude-re "$re")
done < <(sed -n '/^## Equivalent/,/^## /p' chip-plan/MUTANTS.md | sed -n 's/^| `\([^`]*\)`.*/\1/p')
out=target/mutants
mkdir -p "$out"
# Each mutant rebuilds and relinks the mutated crate's tests: without optimisation and debug
# information that takes about half the time, and the tests check the same values. Only the
# workspace's own crates take these settings (dependencies keep theirs, already built).
export CARGO_PROFILE_DEV_OPT_LEVEL=0 CARGO_PROFILE_DEV_DEBUG=false
case "${1:-}" in
    --full)
        cargo mutants --no-shuffle -j 2 -p meb-chip-plan -o "$out/chip-plan" "${excludes[@]}"
        cargo mutants --no-shuffle -j 2 -p meb-protocol -o "$out/protocol" "${excludes[@]}"
        ;;
    "")
        # In place (mutating this checkout and restoring it) so the build reuses target/; only
        # chip-plan's library tests named vendor* and outputs* run for each mutant.
        # Exit code 3 means only timeouts besides caught mutants: a mutant that makes a loop
        # endless (`i += 1` into `i *= 1`) hangs the tests, which is a failure they detect.
        rc=0
        cargo mutants --no-shuffle --in-place --timeout 10 -p meb-chip-plan -o "$out/ci" \
            "${excludes[@]}" -f chip-plan/src/regs.rs -- --lib -- vendor outputs || rc=$?
        if [ "$rc" -ne 0 ] && [ "$rc" -ne 3 ]; then exit "$rc"; fi
        ;;
    *) echo "mutants: unknown argument $1 (known: --full)" >&2; exit 2 ;;
esac
