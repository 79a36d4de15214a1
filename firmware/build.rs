//! Picks the linker memory map of the board being built and the linker scripts it needs.
//!
//! * `h743`: `memory.x` at the repository root (STM32H743 regions), `link.x` from
//!   cortex-m-rt, `defmt.x` for defmt;
//! * `qemu`: `qemu/memory.x` (mps2-an500), `link.x`.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let qemu = env::var_os("CARGO_FEATURE_QEMU").is_some();
    let h743 = env::var_os("CARGO_FEATURE_H743").is_some();
    if qemu && h743 {
        panic!("features `qemu` and `h743` are exclusive: build the emulated board with --no-default-features --features qemu");
    }
    let memory = if qemu {
        manifest.join("qemu/memory.x")
    } else {
        manifest.join("../memory.x")
    };
    fs::copy(&memory, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed=build.rs");

    let target = env::var("TARGET").unwrap_or_default();
    if target.starts_with("thumb") {
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        if h743 {
            println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
        }
    }
}
