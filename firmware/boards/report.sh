#!/usr/bin/env bash
# Builds the board binaries and prints their flash and RAM use against the
# budget (128 KiB flash, 32 KiB RAM); with qemu-system-arm present, also runs
# the instruction-count bench of the control tick.
#
#   firmware/boards/report.sh            # sizes + bench
#   firmware/boards/report.sh --no-bench # sizes only
#
# Needs the thumbv7em-none-eabihf target and llvm-size (or arm-none-eabi-size).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
target_dir="${OCM_BOARDS_TARGET_DIR:-$here/../../target-boards}"
flash_budget=$((128 * 1024))
ram_budget=$((32 * 1024))

size_tool=""
for t in llvm-size arm-none-eabi-size rust-size; do
  if command -v "$t" >/dev/null 2>&1; then size_tool="$t"; break; fi
done
if [ -z "$size_tool" ]; then
  echo "no size tool found (install llvm or binutils-arm-none-eabi)" >&2
  exit 1
fi

report() { # name elf
  # Berkeley format: text data bss. Flash holds text + data, RAM data + bss
  # (the stack takes the rest of RAM at run time).
  read -r text data bss _ < <("$size_tool" "$2" | awk 'NR == 2 { print $1, $2, $3 }')
  local flash=$((text + data)) ram=$((data + bss))
  awk -v n="$1" -v f="$flash" -v r="$ram" -v fb="$flash_budget" -v rb="$ram_budget" 'BEGIN {
    printf "%-22s flash %6d B (%5.1f%% of 128 KiB)   RAM %6d B static (%5.1f%% of 32 KiB, %d B left for the stack)\n",
      n, f, 100 * f / fb, r, 100 * r / rb, rb - r }'

}

for board in qemu stm32f4; do
  (cd "$here/$board" && CARGO_TARGET_DIR="$target_dir" cargo build --release --quiet)
done
rel="$target_dir/thumbv7em-none-eabihf/release"
report "qemu (mps2-an386)" "$rel/ocm-qemu"
report "stm32f4 (STM32F411)" "$rel/ocm-stm32f4"

if [ "${1:-}" != "--no-bench" ]; then
  if command -v qemu-system-arm >/dev/null 2>&1; then
    echo "bench on the default physics LUT (QEMU -icount shift=0: 1 instruction = 1 ns of virtual time):"
    # The bench exits non-zero when its setup fails, a tick faults or the
    # worst tick exceeds 10 000 instructions.
    if ! timeout 300 qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -display none -monitor none \
      -semihosting-config enable=on,target=native -icount shift=0 \
      -kernel "$rel/ocm-qemu-bench"; then
      echo "bench FAILED: setup error, faults, or a tick over 10 000 instructions (see above)" >&2
      exit 1
    fi
  elif [ "${OCM_REQUIRE_DATA:-}" = 1 ]; then
    echo "bench: qemu-system-arm not found and OCM_REQUIRE_DATA=1 (run scripts/setup.sh)" >&2
    exit 1
  else
    echo "bench skipped: qemu-system-arm not found"
  fi
fi
