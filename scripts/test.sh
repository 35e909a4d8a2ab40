#!/usr/bin/env bash
# Every check CI runs. Installs what a clean machine lacks first, so it works on a fresh clone.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }

step "toolchain: MCU targets and components"
installed_targets=$(rustup target list --installed)
for target in thumbv7em-none-eabihf thumbv6m-none-eabi riscv32imac-unknown-none-elf; do
  grep -qx "$target" <<<"$installed_targets" || rustup target add "$target"
done
installed_components=$(rustup component list --installed)
for component in clippy rustfmt; do
  grep -q "^$component" <<<"$installed_components" || rustup component add "$component"
done

step "format"
cargo fmt --all --check

step "clippy (warnings are errors)"
cargo clippy --workspace --all-targets -- -D warnings

step "host tests"
cargo test --workspace

step "docs (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps

step "psmpa-core builds for microcontrollers"
for target in thumbv7em-none-eabihf thumbv6m-none-eabi riscv32imac-unknown-none-elf; do
  cargo build -p psmpa-core --target "$target" --release
  cargo build -p psmpa-core --target "$target" --release --features defmt
done

step "the simulated world builds without std (the firmware runs it)"
cargo build -p psmpa-sim --no-default-features --target thumbv7em-none-eabihf --release

step "psmpa-core uses no allocator"
# `extern crate std/alloc` is allowed only right under `#[cfg(test)]`.
awk 'FNR == 1 { prev = "" }
     /extern crate (alloc|std)/ && prev !~ /cfg\(test\)/ { print FILENAME ":" FNR ": " $0; bad = 1 }
     { prev = $0 }
     END { exit bad }' core/src/*.rs || { echo "core must not use alloc or std outside tests" >&2; exit 1; }

printf '\nall checks passed\n'
