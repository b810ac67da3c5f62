//! `meb decode --start S` skips S frames exactly once, for every reader: PNG and TIFF frame
//! folders, a multi-page TIFF, y4m, raw and MP4 through FFmpeg. Each capture has 42 frames of
//! two LEDs (n = 8), so `--start 10` leaves 32 frames, all of which a correct decoder uses; a
//! start counted twice would leave 22 and decode only 16. Starting at or past the end is a
//! clear error.

use meb_core::capture::Samples;
use meb_core::rig::Rig;
use meb_sim::capture::{SimConfig, SimulatedCapture};
use meb_sim::scene::{Scene, SceneObject};
use std::path::{Path, PathBuf};

use crate::common;
use common::{OUT_OF_PLANE_LEDS, meb, rig_toml};

const WIDTH: usize = 32;
const HEIGHT: usize = 24;
const FRAMES: usize = 42;

/// The rig file of the test captures.
fn rig_file(dir: &Path) -> PathBuf {
    let path = dir.join("rig.toml");
    std::fs::write(&path, rig_toml(WIDTH, HEIGHT, 2.0, &OUT_OF_PLANE_LEDS[..2])).unwrap();
    path
}

/// The 8-bit frames of the test capture, rendered in-process.
fn frames(dir: &Path) -> Vec<Vec<u8>> {
    let rig = Rig::load(rig_file(dir).to_str().unwrap()).unwrap();
    let config = SimConfig {
        frames: FRAMES,
        seed: 4,
        ..SimConfig::default()
    };
    let capture =
        SimulatedCapture::new(rig, Scene::single(SceneObject::sphere(40.0)), config).unwrap();
    (0..FRAMES)
        .map(|j| match capture.render_frame(j).samples {
            Samples::U8(v) => v,
            Samples::U16(_) => panic!("8-bit capture expected"),
        })
        .collect()
}

/// `meb simulate` into `dir/name` in `format`; returns the output folder.
fn simulate(dir: &Path, name: &str, format: &str) -> PathBuf {
    let out = dir.join(name);
    let rig = rig_file(dir);
    let result = meb(&[
        "simulate",
        "--rig",
        rig.to_str().unwrap(),
        "--frames",
        &FRAMES.to_string(),
        "--format",
        format,
        "--seed",
        "4",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    out
}

/// Decodes `input` with `--start start` (plus `extra`); the report when it succeeded, else the
/// error text.
fn decode_from(input: &Path, start: usize, extra: &[&str]) -> Result<serde_json::Value, String> {
    let out = input.with_extension("decoded");
    let mut args = vec![
        "decode",
        input.to_str().unwrap(),
        "--leds",
        "2",
        "--no-led-check",
        "--force",
        "--out",
        out.to_str().unwrap(),
    ];
    let start = start.to_string();
    args.extend(["--start", start.as_str()]);
    args.extend(extra);
    let result = meb(&args);
    if !result.status.success() {
        return Err(String::from_utf8_lossy(&result.stderr).into_owned());
    }
    let text = std::fs::read_to_string(out.join("decode.json")).unwrap();
    Ok(serde_json::from_str(&text).unwrap())
}

/// The reader contract: start 10 → 32 frames decoded; start 42 and 50 → a clear error.
fn check_reader(input: &Path, extra: &[&str]) {
    let report = decode_from(input, 10, extra).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        report["frames_used"],
        32,
        "{}: --start 10 of {FRAMES} frames",
        input.display()
    );
    for start in [FRAMES, FRAMES + 8] {
        let error = decode_from(input, start, extra).unwrap_err();
        assert!(
            error.contains(&format!(
                "cannot start at frame {start}: the capture has only {FRAMES} frames"
            )),
            "{}: {error}",
            input.display()
        );
    }
}

#[test]
fn png_folder_start_is_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = simulate(tmp.path(), "png", "png");
    check_reader(&sim, &[]);
}

#[test]
fn y4m_start_is_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let sim = simulate(tmp.path(), "y4m", "y4m");
    check_reader(&sim.join("capture.y4m"), &[]);
}

#[test]
fn tiff_folder_start_is_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("tiffs");
    std::fs::create_dir(&dir).unwrap();
    for (j, frame) in frames(tmp.path()).into_iter().enumerate() {
        let image = image::GrayImage::from_raw(WIDTH as u32, HEIGHT as u32, frame).unwrap();
        image.save(dir.join(format!("frame_{j:05}.tif"))).unwrap();
    }
    check_reader(&dir, &[]);
}

#[test]
fn multi_page_tiff_start_is_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("stack.tif");
    let file = std::fs::File::create(&path).unwrap();
    let mut encoder = tiff::encoder::TiffEncoder::new(std::io::BufWriter::new(file)).unwrap();
    for frame in frames(tmp.path()) {
        encoder
            .write_image::<tiff::encoder::colortype::Gray8>(WIDTH as u32, HEIGHT as u32, &frame)
            .unwrap();
    }
    drop(encoder);
    check_reader(&path, &[]);
}

#[test]
fn raw_start_is_counted_once() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("capture.raw");
    std::fs::write(&path, frames(tmp.path()).concat()).unwrap();
    check_reader(
        &path,
        &["--raw", &format!("{WIDTH}x{HEIGHT}x8"), "--fps", "960"],
    );
}

#[test]
fn mp4_through_ffmpeg_start_is_counted_once() {
    let found = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        found,
        "ffmpeg is needed to read MP4 (scripts/setup.sh installs it, as `bash scripts/test.sh` does)"
    );
    let tmp = tempfile::tempdir().unwrap();
    let sim = simulate(tmp.path(), "mp4", "mp4");
    check_reader(&sim.join("capture.mp4"), &[]);
}
