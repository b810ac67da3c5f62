//! Brings three.js (pinned in `viewer/package.json` + `viewer/package-lock.json`, from the npm
//! registry) to the build: `report.html` inlines it for its interactive 3-D view of the surface,
//! so the page stays one self-contained file that works offline.
//!
//! When `viewer/node_modules` lacks it (a fresh checkout), this runs `npm ci` in `viewer/`;
//! without npm the build stops with a message saying how to install it.

use std::path::Path;
use std::process::Command;

/// The single-file ES module build of three.js (r170 still ships one without imports).
const THREE: &str = "node_modules/three/build/three.module.min.js";

fn main() {
    let viewer = Path::new(env!("CARGO_MANIFEST_DIR")).join("viewer");
    let three = viewer.join(THREE);
    println!("cargo:rerun-if-changed=viewer/package.json");
    println!("cargo:rerun-if-changed=viewer/package-lock.json");
    println!("cargo:rerun-if-changed=viewer/{THREE}");
    if !three.is_file() {
        let status = Command::new("npm")
            .args(["ci", "--ignore-scripts", "--no-audit", "--no-fund"])
            .current_dir(&viewer)
            .status();
        match status {
            Ok(s) if s.success() => {}
            Ok(s) => fail(&format!(
                "`npm ci` in {} failed ({s}); is the npm registry reachable?",
                viewer.display()
            )),
            Err(e) => fail(&format!(
                "cannot run npm ({e}). meb's report inlines three.js from the npm registry: \
                 install Node.js and npm (`bash scripts/setup.sh`, or `apt-get install npm`), \
                 or run `npm ci` in {}",
                viewer.display()
            )),
        }
    }
    let out = Path::new(&std::env::var("OUT_DIR").unwrap_or_else(|_| fail("OUT_DIR is not set")))
        .join("three.module.min.js");
    if let Err(e) = std::fs::copy(&three, &out) {
        fail(&format!(
            "cannot copy {} to {}: {e}",
            three.display(),
            out.display()
        ));
    }
}

/// Stops the build with `message`.
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}
