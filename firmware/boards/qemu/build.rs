//! Puts memory.x where the linker finds it, and writes the default physics
//! LUT image (`ocm-lutgen`'s defaults, what `ocm lut build` writes and users
//! flash) that the instruction-count bench embeds.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is readable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    let img = ocm_firmware_support::physics::build_default_image()
        .unwrap_or_else(|e| panic!("the default LUT image does not build: {e}"));
    fs::write(out.join("default_lut.bin"), img).expect("OUT_DIR is writable");
}
