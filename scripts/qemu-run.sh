#!/usr/bin/env bash
# Runs a firmware ELF in QEMU (mps2-an386, Cortex-M4F) and decodes its defmt log.
# -icount makes the emulated clock follow the instruction count: runs are reproducible.
# The exit status is the firmware's (semihosting exit), 124 on a hang, 127 when a tool is
# missing (said in one line with the command that installs it).
set -euo pipefail
elf="$1"

# Checked before QEMU starts, so that a missing tool is one line, not a broken pipe.
install_firmware_tools="bash $(dirname "$0")/install-tools.sh firmware"
missing=()
command -v qemu-system-arm >/dev/null || missing+=(qemu-system-arm)
command -v defmt-print >/dev/null || missing+=(defmt-print)
case "${missing[*]}" in
  "") ;;
  defmt-print)
    echo "qemu-run.sh: defmt-print is not installed; install it with: cargo install defmt-print --locked" >&2
    exit 127
    ;;
  qemu-system-arm)
    echo "qemu-run.sh: qemu-system-arm is not installed; install it with: $install_firmware_tools" >&2
    exit 127
    ;;
  *)
    echo "qemu-run.sh: qemu-system-arm and defmt-print are not installed; install them with: $install_firmware_tools" >&2
    exit 127
    ;;
esac

timeout "${QEMU_TIMEOUT:-300}" qemu-system-arm -machine mps2-an386 -cpu cortex-m4 \
  -display none -monitor none -serial none \
  -semihosting-config enable=on,target=native \
  -icount shift=5,align=off,sleep=off \
  -kernel "$elf" | defmt-print -e "$elf"
