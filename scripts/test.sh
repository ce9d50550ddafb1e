#!/usr/bin/env bash
# Every test of the project: formatting, lints, the firmware cross-builds
# (flash/RAM budget and the QEMU instruction-count bench), and the host tests
# of all crates (unit, property, real-data and end-to-end, QEMU included), run by
# cargo-nextest where it is installed and by cargo test where not.
set -euo pipefail
cd "$(dirname "$0")/.."
# Each phase's heading says when it started, so that a slow run shows where the time went.
phase() { echo "== $* ($((SECONDS / 60)) min $((SECONDS % 60)) s in)"; }
# A one-off build gains nothing from the incremental cache, which would double the disk it
# takes (several GiB); a user who rebuilds often can set CARGO_INCREMENTAL=1. Set before any
# build, since the setting is part of what cargo compares when the Python binding's build
# reuses the workspace's.
export CARGO_INCREMENTAL="${CARGO_INCREMENTAL:-0}"
bash scripts/setup.sh --no-binding
# Interop tests check our files with Python packages from the virtual environment.
export OCM_PYTHON="$PWD/.venv/bin/python3"

# Free disk is printed so that a link that dies for lack of space can be told from a bug.
echo "== free disk: $(df -h --output=avail . | tail -1 | tr -d ' ') available"

phase "cargo fmt --check"
cargo fmt --all -- --check

# The whole workspace is compiled in one cargo run before anything else builds: cargo then
# keeps both cores busy to the end (98 % on a fresh clone). Building the Python binding first
# compiled the heavy dependencies alone, with one core idle behind long units such as
# burn-flex, and the set-up and test build together took 22 minutes against 14.
phase "test build"
cargo test -q --workspace --no-run

# The binding's build then compiles only its own crate, where cargo gives the shared crates the
# same features in both builds (host/rl/py/Cargo.toml pins them); a drift costs minutes of
# compile, not correctness, so it is reported and the run goes on.
phase "Python binding"
features() { cargo tree "$@" --prefix none -f '{p}|{f}' 2>/dev/null | sed 's/ (\*)$//' | LC_ALL=C sort -u; }
drift=$(LC_ALL=C join -t'|' <(features -p ocm-rl-py -e normal,build) <(features --workspace -e normal,build,dev) |
    awk -F'|' '$2 != $3 { print $1 }' | tr '\n' ' ')
if [ -n "$drift" ]; then
    echo "== warning: the Python binding's build gives these crates other features than the workspace's (pin them in host/rl/py/Cargo.toml): $drift"
fi
bash scripts/setup.sh

phase "cargo clippy"
cargo clippy -q --workspace --all-targets -- -D warnings

if [ -x firmware/boards/build.sh ]; then
    phase "firmware cross-builds"
    bash firmware/boards/build.sh
fi

phase "tests"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
if cargo nextest --version >/dev/null 2>&1; then
    # cargo-nextest (where the machine has it) runs the tests of every binary from one pool of
    # two: cargo test runs the binaries one after another, and a binary's last long test left
    # a core idle (9.2 against 12.2 minutes on 2 cores, 1.95 against 1.68 cores busy). It runs
    # no doctests, which cargo test then does.
    cargo nextest run --workspace --no-fail-fast 2>&1 | tee "$log"
    cargo test --workspace --doc 2>&1 | tee -a "$log"
else
    cargo test --workspace --no-fail-fast 2>&1 | tee "$log"
fi
phase "done"
echo "== build size: $(du -sh target 2>/dev/null | cut -f1), free disk: $(df -h --output=avail . | tail -1 | tr -d ' ')"
# One closing line with the totals over every test binary (cargo test's "test result:" lines,
# nextest's "Summary" line).
awk '/^test result:|^ *Summary \[/ { for (i = 1; i <= NF; i++) { if ($(i+1) ~ /^passed/) p += $i; if ($(i+1) ~ /^failed/) f += $i } }
     END { printf "tests: %d passed, %d failed\n", p, f }' "$log"
