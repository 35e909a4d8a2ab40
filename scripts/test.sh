#!/usr/bin/env bash
# Every check CI runs. Installs what a clean machine lacks first, so it works on a fresh clone.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }

# Every build here is a first build: incremental state would only take disk (gigabytes of it).
export CARGO_INCREMENTAL=0
# The live view's page test (host-sim/tests/view.rs) skips without chromium, except here: the
# tools step installs it, and a missing one fails the host tests.
export PSMPA_REQUIRE_CHROMIUM=1

step "tools: MCU targets, clippy, rustfmt, QEMU, ARM binutils, valgrind, chromium, defmt-print, flip-link, the bench's rp2040js (only what is missing)"
bash scripts/install-tools.sh all

step "format"
cargo fmt --all --check

step "clippy (warnings are errors)"
cargo clippy --workspace --all-targets -- -D warnings

# Before anything writes files: a clean tree packages.
step "the library crates package and build as published (psmpa-model, -macros, -core, -testkit, -drivers)"
# Cargo keeps a dry run's unpacked crates by version and never unpacks the same version again:
# a version packaged earlier from other sources would be built instead of this one.
rm -rf "${CARGO_HOME:-$HOME/.cargo}"/registry/src/-*/psmpa-*
cargo publish --workspace --dry-run

step "host tests"
cargo test --workspace

step "psmpa-core's defmt text: fact names reach the log as names (defmt's host encoder)"
cargo test -p psmpa-core --features defmt,defmt/unstable-test --lib text::tests

step "psmpa-core with the log facade (feature log)"
cargo build -p psmpa-core --features log

step "docs (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps

step "psmpa-core (and psmpa-model beneath it) builds for microcontrollers"
for target in thumbv7em-none-eabihf thumbv6m-none-eabi riscv32imac-unknown-none-elf; do
  cargo build -p psmpa-core --target "$target" --release
  cargo build -p psmpa-core --target "$target" --release --features defmt
done

step "the simulated world builds without std (the firmware runs it)"
cargo build -p psmpa-sim --no-default-features --target thumbv7em-none-eabihf --release

step "the dock example builds for a microcontroller"
cargo build -p psmpa-dock --target thumbv7em-none-eabihf --release

step "the drivers and the Fetch Tea robot build for microcontrollers (Cortex-M4F; Cortex-M33 as on the RP2350)"
for target in thumbv7em-none-eabihf thumbv8m.main-none-eabihf; do
  cargo build -p psmpa-drivers -p psmpa-fetch-tea --target "$target" --release
  cargo build -p psmpa-drivers -p psmpa-fetch-tea --target "$target" --release --features defmt
done

step "the boards (Pico 2, Pico): formatted, clippy-clean and built as their READMEs say (cargo build --release in boards/pico2, boards/pico)"
(cd boards && cargo fmt --all --check)
for board in pico2 pico; do
  (cd "boards/$board" && cargo clippy --release -- -D warnings && cargo build --release)
done

step "a crate outside the workspace, at its own tick rate, compiles its mission in (include_mission!) for the host and a microcontroller and tests it with psmpa-testkit"
cargo test --locked --manifest-path examples/outside/Cargo.toml --target-dir target/outside
cargo build --locked --manifest-path examples/outside/Cargo.toml --target-dir target/outside --target thumbv7em-none-eabihf

step "a robot on a compiled mission builds no JSON loader for its MCU: no serde, serde-json-core or ryu in the Pico's or the outside crate's target graph"
for dir in boards/pico examples/outside; do
  target=$([ "$dir" = boards/pico ] && echo thumbv6m-none-eabi || echo thumbv7em-none-eabihf)
  if (cd "$dir" && cargo tree --locked -e normal,no-proc-macro --target "$target") | grep -E ' (serde|serde-json-core|ryu) v'; then
    echo "$dir builds a JSON loader for $target: psmpa-core's feature loader is on" >&2
    exit 1
  fi
done

step "a mission whose period a slow tick rate cannot represent fails the build, naming the sensor, the period and the rate (tests/slow-tick: 10 Hz)"
# Its trybuild cases resolve their mission beside the target directory: an absolute one.
CARGO_TARGET_DIR="$PWD/target/outside" cargo test --locked --manifest-path tests/slow-tick/Cargo.toml

step "the dock example, copied out of the checkout as docs/guide.md says (\"Start from the dock example\"), passes its tests there"
own=$(mktemp -d)
trap 'rm -rf "$own"' EXIT
ln -s "$PWD" "$own/psmpa"
sed -n '/<!-- own-robot:start -->/,/<!-- own-robot:end -->/p' docs/guide.md | sed '/^```/d;/^<!--/d' > "$own/steps.sh"
# Built beside the crate outside the workspace, whose crates it shares where features agree.
outside_target="$PWD/target/outside"
# `cargo doc --open` runs $BROWSER on the page: `true` opens nothing on a machine without one.
(cd "$own" && BROWSER=true CARGO_TARGET_DIR="$outside_target" bash -eu -o pipefail steps.sh)

# The measuring commands below write their figures into these pages (size from its snapshot,
# the QEMU timing, the bench, the stack and the static timing): they must come out as
# committed (deterministic emulators and analyses: a figure that moved was not measured by
# this tree).
figures=$(mktemp -d)
cp --parents README.md docs/firmware.md docs/experiment.md docs/benchmarks.md boards/README.md "$figures/"

step "firmware: clippy for both targets (mps2-an386's Cortex-M4F, mps2-an505's Cortex-M33)"
for target in thumbv7em-none-eabihf thumbv8m.main-none-eabihf; do
  cargo clippy -p psmpa-firmware --target "$target" --profile firmware -- -D warnings
done

step "firmware in QEMU on mps2-an386 and mps2-an505: every scenario, both architectures, equal to the host"
cargo xtask qemu

step "the check can fail: a deliberately broken scenario must be caught (mps2-an386)"
cargo xtask qemu --inject-fault --expect-failure

step "firmware size: flash, static RAM, stack high-water against budget and snapshot (the QEMU images and both boards)"
cargo xtask size

step "the bench: the Pico's firmware on an emulated RP2040 (rp2040js) against the project's world, every scenario and fault, judged from its pins and its flight recording against psmpa-sim and the committed cost budget, and every annotated loop's back edges counted"
cargo xtask hil

step "the bench can fail: images with planted bugs (a deaf sonar, a floating bumper, slow brakes, ...) must each fail it"
cargo xtask hil --mutants

step "firmware stack: static worst case from the binary, at least the high-water marks of QEMU and the bench"
cargo xtask stack

step "static timing: every job of the Pico's image bounded in cycles from its binary (every loop counted or annotated)"
cargo xtask wcet

step "the static timing's cycle table against rp2040js's count: functions of the image called on the emulated chip, each within its bound, exact where every path is taken"
cargo xtask wcet --emulated

step "the static timing can fail: a busy loop planted in the switches' driver raises the sensing bound, a busy wait planted in the safety stop is refused, a cheap load planted in its table fails --emulated"
cargo xtask wcet --mutants

step "timing: response-time analysis from QEMU step costs on both cores; every measured reaction within its bound"
cargo xtask timing

step "the analysis can fail: at 250 kHz the same jobs need more than the processor"
cargo xtask timing --clock-hz 250000 --expect-failure

step "the sensitivity study (psmpa-sim sensitivity, seeded): its figures on the pages"
cargo xtask experiment

step "instructions under callgrind (deterministic): psmpa's action step, the floor, every implementation's plan, where the step goes"
cargo xtask bench --instructions

step "the figures on the pages are the ones the commands measured (size, timing, bench, stack, static timing, the study, the instruction counts)"
for page in README.md docs/firmware.md docs/experiment.md docs/benchmarks.md boards/README.md; do
  diff -u "$figures/$page" "$page" || { echo "$page: the figures moved: commit what cargo xtask size, timing, hil, stack, wcet, experiment and bench --instructions wrote" >&2; exit 1; }
done
rm -rf "$figures"

step "psmpa-core and psmpa-model use no allocator"
# `extern crate std/alloc` is allowed only right under `#[cfg(test)]`, or under psmpa-model's
# host-only feature `std` (strict JSON and mission checks for tools; never on a robot).
awk 'FNR == 1 { prev = "" }
     /extern crate (alloc|std)/ && prev !~ /cfg\((test|all\(feature = "std", not\(test\)\))\)/ { print FILENAME ":" FNR ": " $0; bad = 1 }
     { prev = $0 }
     END { exit bad }' $(find core/src model/src -name '*.rs' | sort) || { echo "core and model must not use alloc or std outside tests" >&2; exit 1; }

printf '\nall checks passed\n'
