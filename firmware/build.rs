//! Links the firmware with the memory map of the machine its target runs on, tells the code
//! which machine that is, and embeds its data:
//!
//! * `thumbv8m.main-none-eabihf` (Cortex-M33): QEMU's mps2-an505, `memory-an505.x` and the cfg
//!   `board_an505`; any other target: mps2-an386 (Cortex-M4F) and `memory-an386.x`. The code
//!   reads the board's addresses, interrupts and clock from `src/board.rs`, one set of
//!   constants per machine. cortex-m-rt's `link.x` includes `memory.x`, which the linker
//!   finds in its working directory, the workspace root (before any search path): the
//!   top-level `memory.x` includes `psmpa-machine.x`, the chosen map, copied here to
//!   `OUT_DIR`. (flip-link follows the include and moves the stack in the copy.)
//! * every `scenarios/*.json`, validated here by the host's parser and embedded in its
//!   canonical form (integers only), which the firmware reads with serde-json-core at boot;
//! * each scenario's mission hash under each architecture, for its recordings' headers
//!   (`psmpa_sim::robot::mission_hash`, which `psmpa-sim replay` checks).

use std::{env, fs, path::Path, path::PathBuf};

use psmpa_sim::robot::{Arch, mission_hash};
use psmpa_sim::scenario::Scenario;

fn write(path: &Path, bytes: &[u8]) {
    if let Err(e) = fs::write(path, bytes) {
        panic!("cannot write {}: {e}", path.display());
    }
}

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default());
    let root = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default()).join("..");

    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rustc-check-cfg=cfg(board_an505)");
    let an505 = target.starts_with("thumbv8m.main");
    if an505 {
        println!("cargo:rustc-cfg=board_an505");
    }
    // cortex-m-rt's link.x includes the top-level `memory.x`, which includes the machine's
    // map under this name.
    let memory = root.join(if an505 {
        "firmware/memory-an505.x"
    } else {
        "firmware/memory-an386.x"
    });
    println!("cargo:rerun-if-changed={}", root.join("memory.x").display());
    if let Err(e) = fs::copy(&memory, out.join("psmpa-machine.x")) {
        panic!("cannot copy {}: {e}", memory.display());
    }
    // No device interrupts are used: the vector table ends after 16 default entries
    // (src/main.rs); cortex-m-rt's "device" feature wants a device.x, which has nothing to add.
    write(&out.join("device.x"), b"");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    if target.starts_with("thumb") {
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }

    let dir = root.join("scenarios");
    let mut names: Vec<String> = fs::read_dir(&dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".json"))
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    let mut list = String::from(
        "/// The embedded scenarios: (file name, canonical JSON, the mission hash of a recording of it\n/// under each of `Arch::ALL`).\npub static SCENARIOS: &[(&str, &[u8], [u64; 2])] = &[\n",
    );
    for name in &names {
        let path = dir.join(name);
        println!("cargo:rerun-if-changed={}", path.display());
        let json =
            fs::read(&path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
        let scenario = Scenario::parse(&json).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut canonical = vec![0u8; 16 * 1024];
        let len = scenario.to_canonical(&mut canonical).unwrap_or_else(|e| {
            panic!(
                "{}: no canonical form for the firmware: {e}",
                path.display()
            )
        });
        canonical.truncate(len);
        let file = out.join(format!("canonical-{name}"));
        write(&file, &canonical);
        let hashes = Arch::ALL.map(|arch| mission_hash(&canonical, arch));
        list.push_str(&format!(
            "    ({name:?}, include_bytes!({:?}), {hashes:?}),\n",
            file.display().to_string()
        ));
    }
    list.push_str("];\n");
    write(&out.join("scenarios.rs"), list.as_bytes());
    println!("cargo:rerun-if-changed={}", dir.display());
}
