#!/usr/bin/env bash
# Mutation testing with cargo-mutants (installed at a pinned version when missing).
#
#   bash scripts/mutants.sh          # CI: the register encodings (chip-plan/src/regs.rs,
#                                    # outputs.rs) against their fast tests (vendor check, pin
#                                    # table), a few minutes
#   bash scripts/mutants.sh --full   # chip-plan and protocol whole, with all their tests
#
# Mutants listed as equivalent in chip-plan/MUTANTS.md (the `regex` column) are skipped; any
# other mutant that no test catches fails the run (cargo-mutants exits non-zero).
set -euo pipefail
cd "$(dirname "$0")/.."
version=27.1.0
if ! command -v cargo-mutants >/dev/null || [ "$(cargo mutants --version)" != "cargo-mutants $version" ]; then
    echo "mutants: installing cargo-mutants $version" >&2
    cargo install --locked --quiet "cargo-mutants@$version"
fi
# The equivalent mutants: the backquoted regex in the first column of each table row of
# MUTANTS.md's "Equivalent" section.
excludes=()
while IFS= read -r re; do
    excludes+=(--exclude-re "$re")
done < <(sed -n '/^## Equivalent/,/^## /p' chip-plan/MUTANTS.md | sed -n 's/^| `\([^`]*\)`.*/\1/p')
out=target/mutants
mkdir -p "$out"
case "${1:-}" in
    --full)
        cargo mutants --no-shuffle -j 2 -p meb-chip-plan -o "$out/chip-plan" "${excludes[@]}"
        cargo mutants --no-shuffle -j 2 -p meb-protocol -o "$out/protocol" "${excludes[@]}"
        ;;
    "")
        cargo mutants --no-shuffle -j 2 -p meb-chip-plan -o "$out/ci" "${excludes[@]}" \
            -f chip-plan/src/regs.rs -f chip-plan/src/outputs.rs -- --lib -- vendor outputs
        ;;
    *) echo "mutants: unknown argument $1 (known: --full)" >&2; exit 2 ;;
esac
