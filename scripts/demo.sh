#!/usr/bin/env bash
# The main job, end to end on the embedded default: build the default OCM
# LUT from the energy model, check it against the f64 model, and write the
# plots and CSV tables. Output goes to ./out (or $1).
set -euo pipefail
cd "$(dirname "$0")/.."
# The demo needs no Python binding (only the tests do).
bash scripts/setup.sh --no-binding
out="${1:-out}"
mkdir -p "$out"
cargo build --release -q -p ocm-cli
ocm=target/release/ocm
"$ocm" lut build --out "$out/ocm_default.lut"
"$ocm" lut check "$out/ocm_default.lut"
"$ocm" lut check "$out/ocm_default.lut" --json > "$out/lut_check.json"
"$ocm" lut plot "$out/ocm_default.lut" --out "$out/plots"
"$ocm" lut export "$out/ocm_default.lut" --out "$out/tables"
"$ocm" track --out "$out/track"
echo "demo: results in $out/"
