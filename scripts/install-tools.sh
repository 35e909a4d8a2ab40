#!/usr/bin/env bash
# Installs the tools a clean machine lacks, and only those that are missing:
#
#   bash scripts/install-tools.sh board      # build the boards' images (boards/pico2, boards/pico)
#   bash scripts/install-tools.sh bench      # and play them on the emulated Pico (cargo xtask hil)
#   bash scripts/install-tools.sh firmware   # build the firmware and run it in QEMU
#   bash scripts/install-tools.sh            # everything scripts/test.sh (CI) runs
#
# board: the thumbv8m.main-none-eabihf and thumbv6m-none-eabi targets (rustup) and flip-link
# (cargo install), what `cargo build --release` in boards/pico2 and boards/pico needs.
# bench: also Node.js (apt, if the machine has none) and the harness's rp2040js, pinned by
# xtask/hil/package-lock.json (`npm ci`), what `cargo xtask hil` needs.
#
# firmware: the thumbv7em-none-eabihf and thumbv8m.main-none-eabihf targets (rustup; QEMU's
# mps2-an386 and mps2-an505; the Pico 2 board), qemu-system-arm (apt), defmt-print and flip-link (cargo install,
# about 4 minutes on 2 cores).
# all: all of these, the riscv32imac-unknown-none-elf target, clippy and rustfmt,
# binutils-arm-none-eabi (objdump for `cargo xtask stack`), valgrind (callgrind) and Debian's
# chromium (headless, for the live view's page test, host-sim/tests/view.rs).
#
# apt installs without recommended packages: qemu-system-arm then pulls 25 packages (80 MB
# installed) instead of 165 (870 MB). On Debian 12 it comes with qemu-system-common 7.2,
# which a qemu-utils from bookworm-backports (10.x, `Breaks: qemu-system-common (<< 8.0)`)
# cannot sit beside: apt removes that qemu-utils. Nothing here uses qemu-utils.
set -euo pipefail

what="${1:-all}"
case "$what" in
  board | bench | firmware | all) ;;
  *)
    echo "usage: bash scripts/install-tools.sh [board|bench|firmware|all]" >&2
    exit 2
    ;;
esac

targets=(thumbv8m.main-none-eabihf thumbv6m-none-eabi)
components=()
packages=()
if [ "$what" = firmware ] || [ "$what" = all ]; then
  targets+=(thumbv7em-none-eabihf)
  packages+=(qemu-system-arm:qemu-system-arm)
fi
if [ "$what" = bench ] || [ "$what" = all ]; then
  packages+=(node:nodejs npm:npm)
fi
if [ "$what" = all ]; then
  targets+=(riscv32imac-unknown-none-elf)
  components+=(clippy rustfmt)
  packages+=(arm-none-eabi-objdump:binutils-arm-none-eabi valgrind:valgrind chromium:chromium)
fi

installed_targets=$(rustup target list --installed)
for target in "${targets[@]}"; do
  grep -qx "$target" <<<"$installed_targets" || rustup target add "$target"
done
if ((${#components[@]})); then
  installed_components=$(rustup component list --installed)
  for component in "${components[@]}"; do
    grep -q "^$component" <<<"$installed_components" || rustup component add "$component"
  done
fi

# Each entry is command:package; the package is installed when the command is missing.
missing=()
for entry in "${packages[@]}"; do
  command -v "${entry%%:*}" >/dev/null || missing+=("${entry#*:}")
done
if ((${#missing[@]})); then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo=sudo
  $sudo apt-get update -q
  $sudo env DEBIAN_FRONTEND=noninteractive \
    apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

if [ "$what" = firmware ] || [ "$what" = all ]; then
  command -v defmt-print >/dev/null || cargo install defmt-print --locked
fi
command -v flip-link >/dev/null || cargo install flip-link --locked

# The bench's harness: rp2040js at the version its lock file pins, installed again only when
# the lock file changed since (npm ci writes node_modules/.package-lock.json).
if [ "$what" = bench ] || [ "$what" = all ]; then
  hil="$(dirname "$0")/../xtask/hil"
  if ! cmp -s "$hil/package-lock.json" "$hil/node_modules/.psmpa-lock" 2>/dev/null; then
    npm ci --prefix "$hil" --no-audit --no-fund
    cp "$hil/package-lock.json" "$hil/node_modules/.psmpa-lock"
  fi
fi
