//! Helpers shared by the CLI test files: running the `meb` binary and small test rigs.
#![allow(dead_code)] // each test binary uses a different subset

use std::path::Path;
use std::process::{Command, Output};

/// Runs the `meb` binary built for these tests.
pub fn meb(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(args)
        .output()
        .expect("meb runs")
}

/// The standard output of a command that must have succeeded (its stderr in the failure).
pub fn stdout_of(output: &Output) -> String {
    succeeded(output, "meb")
}

/// Runs `meb args`, which must succeed, and returns its standard output.
pub fn run_ok(args: &[&str]) -> String {
    succeeded(&meb(args), &format!("meb {args:?}"))
}

/// The standard output of `output`, which must be a success (`what` and its stderr in the
/// failure).
fn succeeded(output: &Output, what: &str) -> String {
    assert!(
        output.status.success(),
        "{what} failed: {}",
        stderr_of(output)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The standard error of a run, as text.
pub fn stderr_of(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// A path as a command-line argument.
pub fn arg(path: &Path) -> &str {
    path.to_str().expect("test paths are UTF-8")
}

/// Runs `meb args`, which must fail with one line `error: …`, and returns that line.
pub fn run_err(args: &[&str]) -> String {
    let out = meb(args);
    assert!(!out.status.success(), "meb {args:?} should fail");
    let stderr = stderr_of(&out).trim().to_string();
    assert_eq!(
        stderr.lines().count(),
        1,
        "meb {args:?}: expected a one-line message, got {stderr:?}"
    );
    assert!(stderr.starts_with("error: "), "{stderr}");
    stderr
}

/// Runs `meb args`, which must fail with a message containing `expect` and leave no `out`;
/// returns the message.
pub fn refused(args: &[&str], out: &Path, expect: &str) -> String {
    let text = run_err(args);
    assert!(text.contains(expect), "meb {args:?}: {text}");
    assert!(!out.exists(), "meb {args:?} left {}", out.display());
    text
}

/// Simulates `frames` frames of `scene` (`meb simulate` scene arguments) under the rig preset
/// `rig` with its camera at `size` (`WxH`) into the y4m capture folder `out` (capture.y4m,
/// rig.toml, depth.npy).
pub fn simulate_y4m(out: &Path, rig: &str, size: &str, frames: usize, scene: &[&str]) {
    let frames = frames.to_string();
    let mut args = vec![
        "simulate",
        "--rig",
        rig,
        "--camera-size",
        size,
        "--frames",
        &frames,
        "--format",
        "y4m",
        "--out",
        arg(out),
    ];
    args.extend_from_slice(scene);
    run_ok(&args);
}

/// The thesis' out-of-plane LED positions (docs/formats/rig.md#presets), mm.
pub const OUT_OF_PLANE_LEDS: [[f64; 3]; 4] = [
    [-270.0, 420.0, 100.0],
    [-140.0, 420.0, 350.0],
    [140.0, 420.0, 350.0],
    [270.0, 420.0, 100.0],
];

/// A rig TOML: a 960 fps camera at 420 mm with the given size and pixel pitch, and `leds`.
pub fn rig_toml(width: usize, height: usize, pitch_mm: f64, leds: &[[f64; 3]]) -> String {
    let mut toml = format!(
        "[camera]\nwidth = {width}\nheight = {height}\nfps = 960.0\ndistance_mm = 420.0\n\
         pixel_pitch_mm = {pitch_mm:?}\n"
    );
    for [x, y, z] in leds {
        toml.push_str(&format!("[[led]]\nposition_mm = [{x:?}, {y:?}, {z:?}]\n"));
    }
    toml
}

/// Writes the thesis' dynamic rig (1000 fps, out-of-plane LEDs, 43° field of view at 420 mm)
/// with a `width` × `height` camera into `dir`; returns its path.
pub fn dynamic_rig(dir: &Path, width: usize, height: usize) -> String {
    let mut toml = format!(
        "[camera]\nwidth = {width}\nheight = {height}\nfps = 1000.0\ndistance_mm = 420.0\n\
         fov_deg = 43.0\n"
    );
    for [x, y, z] in OUT_OF_PLANE_LEDS {
        toml.push_str(&format!("[[led]]\nposition_mm = [{x:?}, {y:?}, {z:?}]\n"));
    }
    let path = dir.join(format!("dynamic-{width}x{height}.toml"));
    std::fs::write(&path, toml).expect("the rig file is written");
    path.display().to_string()
}

/// Whether FFmpeg (`ffmpeg` and `ffprobe`) can run. Without it, a test that needs it must
/// return early and say so; under `CI=true` a missing FFmpeg fails the test instead, because
/// CI installs it (`scripts/setup.sh`) and a quiet skip there would hide a broken setup.
pub fn ffmpeg_available() -> bool {
    let ok = |tool: &str| {
        Command::new(tool)
            .arg("-version")
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if ok("ffmpeg") && ok("ffprobe") {
        return true;
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "ffmpeg/ffprobe are not installed but CI=true: scripts/setup.sh must install FFmpeg"
    );
    eprintln!("SKIPPED: ffmpeg/ffprobe not installed (apt-get install ffmpeg); FFmpeg untested");
    false
}

/// The vertices of a PLY file, read with `ply-rs-bw` (float x, y, z).
pub fn ply_points(path: &Path) -> Vec<[f32; 3]> {
    let file = std::fs::File::open(path).expect("PLY opens");
    let parser = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut std::io::BufReader::new(file))
        .expect("PLY parses");
    let float = |e: &ply_rs_bw::ply::DefaultElement, k: &str| match e.get(k) {
        Some(ply_rs_bw::ply::Property::Float(v)) => *v,
        other => panic!("vertex {k} is {other:?}"),
    };
    ply.payload["vertex"]
        .iter()
        .map(|v| [float(v, "x"), float(v, "y"), float(v, "z")])
        .collect()
}

/// Least-squares gain of each decoded LED image against the capture's truth at `time`
/// (seconds), over the pixels the decoder kept (neither saturated nor underexposed) that the
/// LED lights (above a tenth of its brightest truth pixel).
pub fn gains_against_truth(
    decoded: &meb_pipeline::demod::Decoded,
    capture: &meb_sim::capture::SimulatedCapture,
    time: f64,
) -> Vec<f64> {
    let truth = capture.truth_at(time).led_true;
    decoded
        .leds
        .images
        .iter()
        .zip(&truth.images)
        .map(|(image, truth)| {
            let top = truth.iter().copied().fold(0.0f32, f32::max);
            let (mut dt, mut tt) = (0.0, 0.0);
            for (((d, t), s), u) in image
                .iter()
                .zip(truth)
                .zip(&decoded.saturated)
                .zip(&decoded.underexposed)
            {
                if !s && !u && *t > 0.1 * top {
                    dt += f64::from(*d) * f64::from(*t);
                    tt += f64::from(*t) * f64::from(*t);
                }
            }
            dt / tt
        })
        .collect()
}

/// Names in `dir`, sorted.
pub fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// Least-squares gains of the four decoded LED images in the decode folder `decoded` against
/// the simulator's truth in the capture folder `capture`, over the pixels lit above 10 % of each
/// LED's brightest that the decoder did not flag as saturated or underexposed.
pub fn folder_gains(decoded: &Path, capture: &Path) -> Vec<f64> {
    let flagged = |name: &str| -> Option<ndarray::Array2<bool>> {
        ndarray_npy::read_npy(decoded.join(name)).ok()
    };
    let (saturated, underexposed) = (flagged("saturated.npy"), flagged("underexposed.npy"));
    let kept = |p: (usize, usize)| {
        ![&saturated, &underexposed]
            .iter()
            .any(|f| f.as_ref().is_some_and(|f| f[p]))
    };
    (1..=4)
        .map(|i| {
            let image: ndarray::Array2<f32> =
                ndarray_npy::read_npy(decoded.join(format!("led{i}.npy"))).unwrap();
            let truth: ndarray::Array2<f32> =
                ndarray_npy::read_npy(capture.join(format!("led{i}_true.npy"))).unwrap();
            let top = truth.iter().copied().fold(0.0f32, f32::max);
            let (mut dt, mut tt) = (0.0f64, 0.0f64);
            for ((p, d), t) in image.indexed_iter().zip(&truth) {
                if *t > 0.1 * top && kept(p) {
                    dt += f64::from(*d) * f64::from(*t);
                    tt += f64::from(*t) * f64::from(*t);
                }
            }
            dt / tt
        })
        .collect()
}

/// The decode report (`decode.json`) of the decode folder `decoded`.
pub fn decode_report(decoded: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(decoded.join("decode.json")).unwrap()).unwrap()
}
