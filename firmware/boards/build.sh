#!/usr/bin/env bash
# Cross-builds the board binaries for thumbv7em-none-eabihf, prints their
# flash and RAM use against the budget (128 KiB / 32 KiB; memory.x makes the
# link fail beyond it) and, where qemu-system-arm exists, runs the control-tick
# instruction-count bench. scripts/test.sh runs this in CI.
set -euo pipefail
exec bash "$(dirname "$0")/report.sh" "$@"
