#!/usr/bin/env bash
# Runs a firmware ELF in QEMU and decodes its defmt log:
#
#   scripts/qemu-run.sh [--machine mps2-an386|mps2-an505] ELF
#
# mps2-an386 runs a Cortex-M4F (thumbv7em-none-eabihf), mps2-an505 a Cortex-M33
# (thumbv8m.main-none-eabihf). Without --machine the ELF's architecture decides (readelf -A:
# Tag_CPU_arch v7E-M or v8-M.mainline); the cargo runners and `cargo xtask` name it.
# -icount makes the emulated clock follow the instruction count: runs are reproducible.
# The exit status is the firmware's (semihosting exit), 124 on a hang, 127 when a tool is
# missing (said in one line with the command that installs it), 2 on a wrong argument.
set -euo pipefail
usage() {
  echo "usage: qemu-run.sh [--machine mps2-an386|mps2-an505] ELF" >&2
  exit 2
}
machine=""
if [ "${1:-}" = --machine ]; then
  [ $# -ge 2 ] || usage
  machine="$2"
  shift 2
fi
[ $# -eq 1 ] || usage
elf="$1"

if [ -z "$machine" ]; then
  readelf=$(command -v arm-none-eabi-readelf || command -v readelf || true)
  if [ -z "$readelf" ]; then
    echo "qemu-run.sh: no readelf to tell the ELF's core; name the machine: qemu-run.sh --machine mps2-an386|mps2-an505 $elf" >&2
    exit 127
  fi
  arch=$("$readelf" -A "$elf" | sed -n 's/^ *Tag_CPU_arch: *//p' | head -n 1)
  case "$arch" in
    v7E-M) machine=mps2-an386 ;;
    v8-M.mainline) machine=mps2-an505 ;;
    *)
      echo "qemu-run.sh: $elf is built for '${arch:-no known architecture}', which neither machine runs; name one with --machine" >&2
      exit 2
      ;;
  esac
fi
case "$machine" in
  mps2-an386) cpu=cortex-m4 ;;
  mps2-an505) cpu=cortex-m33 ;;
  *)
    echo "qemu-run.sh: unknown machine '$machine' (mps2-an386 or mps2-an505)" >&2
    exit 2
    ;;
esac

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

timeout "${QEMU_TIMEOUT:-300}" qemu-system-arm -machine "$machine" -cpu "$cpu" \
  -display none -monitor none -serial none \
  -semihosting-config enable=on,target=native \
  -icount shift=5,align=off,sleep=off \
  -kernel "$elf" | defmt-print -e "$elf"
