#!/usr/bin/env bash
# Every test of the project: formatting, lints, host tests of all crates
# (unit, property, real-data and end-to-end), and the firmware cross-builds.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

echo "== cargo fmt --check"
cargo fmt --all -- --check

echo "== cargo clippy"
cargo clippy -q --workspace --all-targets -- -D warnings

echo "== cargo test"
cargo test --workspace

if [ -x firmware/boards/build.sh ]; then
    echo "== firmware cross-builds"
    bash firmware/boards/build.sh
fi
