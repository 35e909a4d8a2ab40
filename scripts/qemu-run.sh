#!/usr/bin/env bash
# Runs a firmware ELF in QEMU (mps2-an386, Cortex-M4F) and decodes its defmt log.
# -icount makes the emulated clock follow the instruction count: runs are reproducible.
# The exit status is the firmware's (semihosting exit), or 124 on a hang.
set -euo pipefail
elf="$1"
timeout "${QEMU_TIMEOUT:-300}" qemu-system-arm -machine mps2-an386 -cpu cortex-m4 \
  -display none -monitor none -serial none \
  -semihosting-config enable=on,target=native \
  -icount shift=5,align=off,sleep=off \
  -kernel "$elf" | defmt-print -e "$elf"
