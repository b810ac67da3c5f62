//! Puts the workspace's top-level `memory.x` on the linker search path (cortex-m-rt's
//! `link.x` includes it) and relinks when it changes.

use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let workspace_root = manifest_dir
        .parent()
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest_dir.clone());
    println!("cargo:rustc-link-search={}", workspace_root.display());
    println!(
        "cargo:rerun-if-changed={}",
        workspace_root.join("memory.x").display()
    );
    println!("cargo:rerun-if-changed=build.rs");
}
