#!/usr/bin/env bash
# Every test of the project: formatting, lints, the firmware cross-builds
# (flash/RAM budget and the QEMU instruction-count bench), and the host tests
# of all crates (unit, property, real-data and end-to-end, QEMU included).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# Interop tests check our files with Python packages from the virtual environment.
export OCM_PYTHON="$PWD/.venv/bin/python3"
# A one-off build gains nothing from the incremental cache, which would double the disk it
# takes (several GiB); a user who rebuilds often can set CARGO_INCREMENTAL=1.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"

# Free disk is printed so that a link that dies for lack of space can be told from a bug.
echo "== free disk: $(df -h --output=avail . | tail -1 | tr -d ' ') available"

echo "== cargo fmt --check"
cargo fmt --all -- --check

echo "== cargo clippy"
cargo clippy -q --workspace --all-targets -- -D warnings

if [ -x firmware/boards/build.sh ]; then
    echo "== firmware cross-builds"
    bash firmware/boards/build.sh
fi

echo "== cargo test"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
cargo test --workspace 2>&1 | tee "$log"
echo "== build size: $(du -sh target 2>/dev/null | cut -f1), free disk: $(df -h --output=avail . | tail -1 | tr -d ' ')"
# One closing line with the totals over every test binary.
awk '/^test result:/ { for (i = 1; i <= NF; i++) { if ($(i+1) ~ /^passed/) p += $i; if ($(i+1) ~ /^failed/) f += $i } }
     END { printf "tests: %d passed, %d failed\n", p, f }' "$log"
