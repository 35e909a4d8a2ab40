//! Links a board with its own `memory.x` (the chip's flash and RAM), shared by the boards'
//! crates (`build = "../build.rs"`). The RP2040 also needs embassy-rp's `link-rp.x`, which
//! places the second-stage bootloader in the first 256 bytes of flash.

use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default());
    if let Err(e) = fs::copy("memory.x", out.join("memory.x")) {
        panic!("cannot copy memory.x: {e}");
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if env::var("TARGET").is_ok_and(|t| t.starts_with("thumbv6m")) {
        println!("cargo:rustc-link-arg-bins=-Tlink-rp.x");
        // The Pico's image runs from SRAM: it starts at the copy in flash (memory.x), which
        // is where a debugger's `load` or a UF2 converter must start it, not at `Reset`.
        println!("cargo:rustc-link-arg-bins=--entry=psmpa_boot");
    }
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
