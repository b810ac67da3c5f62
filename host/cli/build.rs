//! Brings three.js (pinned in `viewer/package.json` + `viewer/package-lock.json`, from the npm
//! registry) to the build: `report.html` inlines it for its interactive 3-D view of the surface,
//! so the page stays one self-contained file that works offline.
//!
//! When `viewer/node_modules` lacks it (a fresh checkout), this runs `npm ci` in `viewer/`.
//! Without npm (or without the registry) the build still succeeds, with a warning: it leaves
//! the inlined copy empty and the report page then fetches the same pinned file from a CDN,
//! checked against its SHA-384 (`export::viewer`), so only the 3-D view needs the network.

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
        let problem = match status {
            Ok(s) if s.success() => None,
            Ok(s) => Some(format!(
                "`npm ci` in {} failed ({s}); is the npm registry reachable?",
                viewer.display()
            )),
            Err(e) => Some(format!("cannot run npm ({e})")),
        };
        if let Some(problem) = problem {
            println!(
                "cargo:warning={problem}: report.html will load three.js from a CDN instead of \
                 inlining it (install npm, e.g. `bash scripts/setup.sh`, for pages that work offline)"
            );
        }
    }
    let out = Path::new(&std::env::var("OUT_DIR").unwrap_or_else(|_| fail("OUT_DIR is not set")))
        .join("three.module.min.js");
    let copied = if three.is_file() {
        std::fs::copy(&three, &out).map(|_| ())
    } else {
        std::fs::write(&out, "")
    };
    if let Err(e) = copied {
        fail(&format!("cannot write {}: {e}", out.display()));
    }
}

/// Stops the build with `message`.
fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}
