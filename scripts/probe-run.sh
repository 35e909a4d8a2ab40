#!/usr/bin/env bash
# The boards' cargo runner (`cargo run --release` in boards/pico or boards/pico2): flashes the
# image through a debug probe with probe-rs and prints its defmt log, or says in one line what
# is missing. Building the image needs neither.
set -euo pipefail
if ! command -v probe-rs >/dev/null; then
  echo "probe-rs is not installed: it flashes a board through a debug probe (https://probe.rs); \`cargo build --release\` builds the image without it" >&2
  exit 127
fi
exec probe-rs run "$@"
