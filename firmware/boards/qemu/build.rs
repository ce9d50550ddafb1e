//! Puts memory.x where the linker finds it, and writes the bring-up LUT
//! image that the instruction-count bench embeds.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR is set by cargo"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is readable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    let mut img = vec![0u8; 64 * 1024];
    let n = ocm_firmware::bringup::write_image(&ocm_shared::params::OcmParams::TABLE_3_1, &mut img)
        .expect("the bring-up model encodes");
    fs::write(out.join("bringup_lut.bin"), &img[..n]).expect("OUT_DIR is writable");
}
