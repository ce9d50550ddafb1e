#!/usr/bin/env bash
# Every test of the project: formatting, lints, the firmware cross-builds
# (flash/RAM budget and the QEMU instruction-count bench), and the host tests
# of all crates (unit, property, real-data and end-to-end, QEMU included).
set -euo pipefail
cd "$(dirname "$0")/.."
# Each phase's heading says when it started, so that a slow run shows where the time went.
phase() { echo "== $* ($((SECONDS / 60)) min $((SECONDS % 60)) s in)"; }
# A one-off build gains nothing from the incremental cache, which would double the disk it
# takes (several GiB); a user who rebuilds often can set CARGO_INCREMENTAL=1. Set before the
# set-up, whose build of the Python binding the test build then reuses (the setting is part of
# what cargo compares).
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
bash scripts/setup.sh
# Interop tests check our files with Python packages from the virtual environment.
export OCM_PYTHON="$PWD/.venv/bin/python3"

# Free disk is printed so that a link that dies for lack of space can be told from a bug.
echo "== free disk: $(df -h --output=avail . | tail -1 | tr -d ' ') available"

# The set-up's build of the Python binding is reused by the test build only where cargo gives
# the shared crates the same features in both (host/rl/py/Cargo.toml pins them); a drift costs
# minutes of compile, not correctness, so it is reported and the run goes on.
features() { cargo tree "$@" --prefix none -f '{p}|{f}' 2>/dev/null | sed 's/ (\*)$//' | LC_ALL=C sort -u; }
drift=$(LC_ALL=C join -t'|' <(features -p ocm-rl-py -e normal,build) <(features --workspace -e normal,build,dev) |
    awk -F'|' '$2 != $3 { print $1 }' | tr '\n' ' ')
if [ -n "$drift" ]; then
    echo "== warning: the Python binding's build gives these crates other features than the workspace's (pin them in host/rl/py/Cargo.toml): $drift"
fi

phase "cargo fmt --check"
cargo fmt --all -- --check

phase "cargo clippy"
cargo clippy -q --workspace --all-targets -- -D warnings

if [ -x firmware/boards/build.sh ]; then
    phase "firmware cross-builds"
    bash firmware/boards/build.sh
fi

phase "cargo test"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
cargo test --workspace 2>&1 | tee "$log"
phase "done"
echo "== build size: $(du -sh target 2>/dev/null | cut -f1), free disk: $(df -h --output=avail . | tail -1 | tr -d ' ')"
# One closing line with the totals over every test binary.
awk '/^test result:/ { for (i = 1; i <= NF; i++) { if ($(i+1) ~ /^passed/) p += $i; if ($(i+1) ~ /^failed/) f += $i } }
     END { printf "tests: %d passed, %d failed\n", p, f }' "$log"
