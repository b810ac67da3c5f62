//! `meb video` end to end on simulated moving scenes: the thesis' turning ellipsoid (Ch. 5)
//! scored frame by frame, sliding windows, standard input, motion detection on an object that
//! moves and then stops, and bad input (a clip shorter than a window, a stream cut mid-frame).
//!
//! The rig is the thesis' dynamic rig (1000 fps, out-of-plane LEDs, 43° field of view at
//! 420 mm) with its camera at 160×90 pixels instead of 1280×720 to keep the tests quick.

use meb_core::capture::{OpenOptions, open};
use meb_core::rig::Rig;
use meb_pipeline::demod::{DecodeConfig, decode};
use meb_pipeline::reconstruct::{
    ReconstructConfig, ReconstructError, Reconstruction, Request, Source, Start, WarmStart,
    bin_decoded, reconstruct, reconstruct_extent,
};
use meb_pipeline::video::truth::TruthFolder;
use meb_pipeline::video::{FrameStatus, TimingSource, VideoConfig, WindowSchedule, process};
use ndarray::{Array2, Array3};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common;
use crate::video_run::{Spin, ellipsoid_clip};
use common::{dynamic_rig, meb, run_ok, simulate_y4m};

/// The thesis' dynamic rig at 160×90 pixels.
fn small_dynamic_rig(dir: &Path) -> String {
    dynamic_rig(dir, 160, 90)
}

fn s(path: &Path) -> String {
    path.display().to_string()
}

/// Simulates `frames` of the 100×60×60 mm ellipsoid turning at `rpm` about `axis` as a y4m
/// clip with the true depth every 20 frames and LED phases 3, 7, 11, 5 chips; returns the
/// capture folder.
fn ellipsoid(dir: &Path, rig: &str, name: &str, frames: usize, rpm: f64, axis: &str) -> PathBuf {
    ellipsoid_with(dir, rig, name, frames, rpm, axis, &["--phases", "3,7,11,5"])
}

/// [`ellipsoid`] with other simulator options.
fn ellipsoid_with(
    dir: &Path,
    rig: &str,
    name: &str,
    frames: usize,
    rpm: f64,
    axis: &str,
    options: &[&str],
) -> PathBuf {
    ellipsoid_clip(dir, rig, name, frames, Spin(rpm, axis), Some(20), options)
}

fn video_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("video.json")).unwrap()).unwrap()
}

fn frames(json: &serde_json::Value) -> &Vec<serde_json::Value> {
    json["frames"].as_array().unwrap()
}

fn depth(dir: &Path, k: usize) -> Array2<f32> {
    ndarray_npy::read_npy(dir.join(format!("depth_{k:05}.npy"))).unwrap()
}

fn run_err(args: &[&str]) -> String {
    let out = meb(args);
    assert!(!out.status.success(), "meb {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// `meb video CAPTURE --rig RIG --out OUT OPTIONS…`.
fn video_args(capture: &Path, rig: &str, out: &Path, options: &[&str]) -> Vec<String> {
    let fixed = ["video", &s(capture), "--rig", rig, "--out", &s(out)];
    fixed.iter().chain(options).map(|a| a.to_string()).collect()
}

/// Runs `meb video` ([`video_args`]), which must succeed; its standard output.
fn video_ok(capture: &Path, rig: &str, out: &Path, options: &[&str]) -> String {
    let args = video_args(capture, rig, out, options);
    run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

/// Runs `meb video` ([`video_args`]), which must fail; its standard error.
fn video_err(capture: &Path, rig: &str, out: &Path, options: &[&str]) -> String {
    let args = video_args(capture, rig, out, options);
    run_err(&args.iter().map(String::as_str).collect::<Vec<_>>())
}

#[test]
fn the_turning_ellipsoid_is_scored_frame_by_frame_within_the_thesis_accuracy() {
    let tmp = tempfile::tempdir().unwrap();
    // 320×180 with the simulator's seed-0 phases (where an earlier per-window timing fit went
    // astray in window 1: rate ratio 0.984, 38 mm RMSE).
    let rig = dynamic_rig(tmp.path(), 320, 180);
    let clip = ellipsoid_with(tmp.path(), &rig, "ellipsoid", 200, 7.5, "0,1,0", &[]);
    let out = tmp.path().join("video");
    let truth = s(&clip);
    let options = ["--window", "40", "--drop", "4", "--ground-truth", &truth];
    let options = [&options[..], &["--save", "normals,albedo"]].concat();
    let stdout = video_ok(&clip.join("capture.y4m"), &rig, &out, &options);
    assert!(
        stdout.contains("5 3-D frames from 200 camera frames"),
        "{stdout}"
    );
    let json = video_json(&out);
    assert_eq!(json["schema"], "meb-video v1");
    assert_eq!(json["summary"]["reconstructed"], 5, "{:#}", json["frames"]);
    assert_eq!(json["settings"]["rate_3d_fps"], 25.0);
    let records = frames(&json);
    assert_eq!(records.len(), 5);
    for (k, record) in records.iter().enumerate() {
        assert_eq!(record["status"], "reconstructed", "{record}");
        // The turning surface leaves modulation unexplained by the still-scene model; the
        // motion measured from frames one code period apart explains it (never --force).
        let verdict = record["verdict"].as_str().unwrap();
        assert!(verdict == "plausible" || verdict == "motion", "{record}");
        if verdict == "motion" {
            assert_eq!(record["motion"]["moving"], true, "{record}");
            assert_eq!(
                record["decode"]["verdict"]["status"], "implausible",
                "{record}"
            );
            assert!(
                record["motion"]["period_ratio"].as_f64().unwrap() > 1.5,
                "{record}"
            );
        }
        assert_eq!(record["decoded"][0], 40 * k + 4);
        assert_eq!(record["decoded"][1], 40 * k + 36);
        let accuracy = &record["accuracy"];
        // Compared with the truth at the window's middle (frame 40k + 20).
        assert_eq!(accuracy["truth_frame"], (40 * k + 20) as f64);
        let rmse = accuracy["rmse_mm"].as_f64().unwrap();
        // Thesis Ch. 5: 4.8–11 mm per 3-D frame.
        assert!(rmse < 4.8, "3-D frame {k}: RMSE {rmse} mm");
        // The LEDs sit above the object: its lower part sees fewer than three of them.
        let fraction = accuracy["reconstructed_fraction"].as_f64().unwrap();
        assert!(fraction > 0.35, "3-D frame {k}: {fraction} of the surface");
        assert!(record["timing"]["reconstruct_ms"].as_f64().unwrap() > 0.0);
        assert!(record["decode"]["led_snr_db"].as_array().unwrap().len() == 4);
        let depth_k = depth(&out, k);
        assert_eq!(depth_k.dim(), (180, 320));
        let normals: Array3<f32> =
            ndarray_npy::read_npy(out.join(format!("normals_{k:05}.npy"))).unwrap();
        assert_eq!(normals.dim(), (180, 320, 3));
        let albedo: Array2<f32> =
            ndarray_npy::read_npy(out.join(format!("albedo_{k:05}.npy"))).unwrap();
        assert_eq!(albedo.dim(), (180, 320));
        // Windows decoded around the object (from the 4th) keep their normals and albedo in
        // the region and paste them into the frame: measured pixels are reconstructed ones,
        // unit normals facing the camera, most of the surface.
        let (mut measured, mut without_depth) = (0, 0);
        for ((r, c), z) in depth_k.indexed_iter() {
            let n = [0, 1, 2].map(|j| normals[(r, c, j)]);
            if !n[0].is_finite() {
                assert!(
                    !albedo[(r, c)].is_finite(),
                    "3-D frame {k}: albedo at {r},{c}"
                );
                continue;
            }
            measured += 1;
            without_depth += usize::from(!z.is_finite());
            let norm = n.iter().map(|v| v * v).sum::<f32>().sqrt();
            assert!((norm - 1.0).abs() < 1e-3, "3-D frame {k}: {n:?} at {r},{c}");
            assert!(albedo[(r, c)] > 0.0, "3-D frame {k}: albedo at {r},{c}");
        }
        let reconstructed = depth_k.iter().filter(|z| z.is_finite()).count();
        assert!(
            measured * 2 > reconstructed && without_depth * 100 <= measured,
            "3-D frame {k}: {measured} normals ({without_depth} without depth) for \
             {reconstructed} depths"
        );
    }
    assert_eq!(
        records
            .iter()
            .filter(|r| !r["decode_region"].is_null())
            .count(),
        2,
        "windows 4 and 5 are decoded around the object"
    );
    assert_eq!(json["accuracy"]["frames"], 5);
    // Windows after the first start from the previous window's depth; the same clip with every
    // window reconstructed cold is no more accurate (per 3-D frame, within 0.2 mm).
    // `meb video` of the clip into folder `name` with `options`, scored against the truth.
    let scored = |name: &str, options: &[&str]| {
        let out = tmp.path().join(name);
        let truth = s(&clip);
        let options = [&["--ground-truth", &truth][..], options].concat();
        video_ok(&clip.join("capture.y4m"), &rig, &out, &options);
        let json = video_json(&out);
        (out, json)
    };
    let (_, cold_json) = scored("cold", &["--cold-start"]);
    for (k, (warm, cold)) in records.iter().zip(frames(&cold_json)).enumerate() {
        // The first window has nothing to start from; a later one is warm-started, or redone
        // cold when its offset left the warm start's bracket (it does in one window of five:
        // the offset the misfit picks jitters by millimetres from window to window).
        let start = &warm["reconstruction"]["start"];
        match (k, start["kind"].as_str().unwrap()) {
            (0, "cold") | (1.., "warm") => {}
            (1.., "redone") => assert!(start["reason"].as_str().unwrap().contains("mm")),
            _ => panic!("3-D frame {k} started {start}"),
        }
        assert_eq!(cold["reconstruction"]["start"]["kind"], "cold", "{cold}");
        let rmse = |r: &serde_json::Value| r["accuracy"]["rmse_mm"].as_f64().unwrap();
        eprintln!(
            "3-D frame {k}: RMSE warm {:.3} mm, cold {:.3} mm; reconstruction {:.0} ms vs {:.0} ms",
            rmse(warm),
            rmse(cold),
            warm["timing"]["reconstruct_ms"].as_f64().unwrap(),
            cold["timing"]["reconstruct_ms"].as_f64().unwrap()
        );
        assert!(
            rmse(warm) <= rmse(cold) + 0.2,
            "3-D frame {k}: warm {} mm vs cold {} mm",
            rmse(warm),
            rmse(cold)
        );
    }
    // Binned 2×2 before decoding: 160×90 3-D frames scored against the truth's block means.
    // At a quarter of the pixels the ellipsoid spans ~35×25 of them, so the shape is coarser
    // (0.80–2.18 mm per 3-D frame measured, against 0.40–0.51 mm at full resolution) but still
    // within the thesis' 4.8–11 mm. (At 1280×720 binned to 640×360 the binned frames are the
    // more accurate: `host/pipeline/benches/NOTES.md`.)
    let (binned, binned_json) = scored("binned", &["--bin", "2"]);
    assert_eq!(binned_json["settings"]["bin"], 2);
    assert_eq!(binned_json["summary"]["reconstructed"], 5);
    let mut binned_rmse = Vec::new();
    for (k, record) in frames(&binned_json).iter().enumerate() {
        assert_eq!(depth(&binned, k).dim(), (90, 160));
        let accuracy = &record["accuracy"];
        assert_eq!(accuracy["truth_frame"], (40 * k + 20) as f64);
        let rmse = accuracy["rmse_mm"].as_f64().unwrap();
        assert!(rmse < 4.8, "binned 3-D frame {k}: RMSE {rmse} mm");
        assert!(accuracy["reconstructed_fraction"].as_f64().unwrap() > 0.35);
        binned_rmse.push(rmse);
    }
    eprintln!("binned 2x2: RMSE {binned_rmse:.3?} mm");
    let mean = binned_rmse.iter().sum::<f64>() / binned_rmse.len() as f64;
    assert!(mean < 2.0, "binned RMSE {binned_rmse:?} mm");
    // Binning sums code values: a linearising decode is refused, not approximated.
    let options = ["--bin", "2", "--linearize", "srgb"];
    let err = video_err(
        &clip.join("capture.y4m"),
        &rig,
        &tmp.path().join("binned-srgb"),
        &options,
    );
    assert!(err.contains("linear codes"), "{err}");
    assert!(!tmp.path().join("binned-srgb").exists());
    let videos = json["outputs"].clone();
    for key in ["depth_video", "shaded_video"] {
        let name = videos[key].as_str().unwrap();
        assert!(name.ends_with(".mp4") || name.ends_with(".png"), "{name}");
        assert!(std::fs::metadata(out.join(name)).unwrap().len() > 0);
    }
    if common::ffmpeg_available() {
        // FFmpeg is installed: the videos are MP4s of five 3-D frames at 25 fps.
        let probe = Command::new("ffprobe")
            .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
            .args([
                "-show_entries",
                "stream=nb_read_frames,width,height,r_frame_rate",
            ])
            .args(["-of", "csv=p=0"])
            .arg(out.join("depth.mp4"))
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&probe.stdout);
        assert_eq!(text.trim(), "320,180,25/1,5", "{text}");
    }

    // Sliding windows every 8 frames: window 5 covers the same frames as window 1 above and
    // gives the same depth (timing fitted per window and every window reconstructed cold in
    // both runs, so they are comparable).
    let sliding = tmp.path().join("sliding");
    let clip_path = clip.join("capture.y4m");
    for (dir, hop) in [(&sliding, "8"), (&tmp.path().join("thesis-free"), "40")] {
        let options = ["--hop", hop, "--fit-every-window", "--cold-start", "--apng"];
        video_ok(&clip_path, &rig, dir, &options);
    }
    let json = video_json(&sliding);
    assert_eq!(frames(&json).len(), (200 - 40) / 8 + 1);
    assert_eq!(frames(&json)[5]["frames"][0], 40);
    let a = depth(&sliding, 5);
    let b = depth(&tmp.path().join("thesis-free"), 1);
    assert!(
        a.iter()
            .zip(&b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x - y).abs() < 1e-4),
        "sliding window 5 differs from thesis window 1"
    );
    assert!(
        sliding.join("depth.png").exists(),
        "--apng writes depth.png"
    );
}

/// A rolling shutter's line delay belongs to the camera, like the exposure and the rate: once
/// the timing carry has settled, every carried window is decoded with the best free fit's line
/// delay instead of fitting it again (each window fitted its own before), and its 3-D frame
/// stays within the thesis' accuracy.
#[test]
fn a_rolling_shutters_line_delay_is_carried_from_window_to_window() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = small_dynamic_rig(tmp.path());
    // 10 µs per row at 1000 fps: 0.01 frame periods per row, a 0.9-chip ramp over 90 rows.
    let options = ["--phases", "3,7,11,5", "--line-time-us", "10"];
    let clip = ellipsoid_with(tmp.path(), &rig, "rolling", 280, 7.5, "0,1,0", &options);
    let out = tmp.path().join("video");
    let truth = s(&clip);
    video_ok(
        &clip.join("capture.y4m"),
        &rig,
        &out,
        &["--ground-truth", &truth],
    );
    let json = video_json(&out);
    let records = frames(&json);
    assert_eq!(records.len(), 7);
    let delay = |r: &serde_json::Value| r["decode"]["line_delay_frames"].as_f64().unwrap();
    for record in records {
        assert_eq!(record["status"], "reconstructed", "{record:#}");
        let rmse = record["accuracy"]["rmse_mm"].as_f64().unwrap();
        assert!(rmse < 4.8, "{record:#}");
        // The free fit trades some of the line delay against the exposure on this small
        // object (0.0081–0.0082 frame periods per row with an exposure of 0.81–0.82 instead
        // of 1.0).
        assert!((delay(record) - 0.01).abs() < 0.0025, "{record:#}");
    }
    let carried: Vec<f64> = records[3..]
        .iter()
        .filter(|r| r["timing_source"] == "carried")
        .map(delay)
        .collect();
    assert!(carried.len() >= 3, "{records:#?}");
    assert!(
        carried.iter().all(|&d| d == carried[0]),
        "carried windows refitted the line delay: {carried:?}"
    );
}

#[test]
fn a_window_from_the_stream_equals_a_fresh_decode_of_its_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let rig_path = small_dynamic_rig(tmp.path());
    let clip = ellipsoid(tmp.path(), &rig_path, "clip", 120, 7.5, "0,1,0");
    let capture = clip.join("capture.y4m");
    let rig = Rig::load(&rig_path).unwrap();
    let mut config = VideoConfig::thesis(4);
    config.schedule = WindowSchedule::new(40, 4, 12, 32).unwrap();
    config.carry_timing = false;
    let source = open(&capture, &OpenOptions::default()).unwrap();
    let mut windows = Vec::new();
    let summary = process(source, &rig, &config, None, &mut |frame| {
        let decoded = frame.decoded.expect("decoded");
        windows.push((frame.record.decoded, decoded.leds.images.clone()));
        Ok(())
    })
    .unwrap();
    assert_eq!(summary.windows, (120 - 40) / 12 + 1);
    assert_eq!(windows.len(), summary.windows);
    for (range, images) in windows.iter().step_by(3) {
        let mut source = open(&capture, &OpenOptions::default()).unwrap();
        let fresh = decode(
            source.as_mut(),
            &DecodeConfig {
                start: range.0,
                frames: Some(range.1 - range.0),
                ..config.decode.clone()
            },
            &mut |_, _| {},
        )
        .unwrap();
        for (a, b) in images.iter().zip(&fresh.leds.images) {
            let worst = a
                .iter()
                .zip(b)
                .filter(|(x, y)| x.is_finite() || y.is_finite())
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst < 1e-6,
                "window {range:?}: LED images differ by {worst}"
            );
        }
    }
}

/// What a video run gave for one window: its record and, when decoded, its LED images and
/// depth.
struct Window {
    record: meb_pipeline::video::FrameRecord,
    images: Vec<Array2<f32>>,
    depth: Option<Array2<f32>>,
}

/// Runs the video pipeline over `capture` with `config` and keeps every window.
fn windows_of(capture: &Path, rig: &Rig, config: &VideoConfig) -> Vec<Window> {
    let source = open(capture, &OpenOptions::default()).unwrap();
    let mut windows = Vec::new();
    process(source, rig, config, None, &mut |frame| {
        windows.push(Window {
            record: frame.record.clone(),
            images: frame
                .decoded
                .map(|d| d.leds.images.clone())
                .unwrap_or_default(),
            depth: frame.reconstruction.map(|r| r.depth_mm().clone()),
        });
        Ok(())
    })
    .unwrap();
    windows
}

/// The ellipsoid at 320×180 (the object about a third of the frame wide) for 200 frames, then
/// 40 mm to the side for 80 more: once the timing carry has settled (three windows) the windows
/// are decoded around the object, the window after the jump (the object reaches out of its
/// region) whole, and the next one around the object's new place. A window decoded around the
/// object holds the whole frame's decode there, and its depth is the one of a run that decodes
/// every window whole; a region that cuts through the object is refused.
#[test]
fn windows_are_decoded_around_the_object_and_whole_when_it_jumps() {
    let tmp = tempfile::tempdir().unwrap();
    let rig_path = dynamic_rig(tmp.path(), 320, 180);
    let first = ellipsoid(tmp.path(), &rig_path, "first", 200, 7.5, "0,1,0");
    let moved = ellipsoid_with(
        tmp.path(),
        &rig_path,
        "moved",
        80,
        7.5,
        "0,1,0",
        &["--phases", "3,7,11,5", "--position-mm", "40,0,0"],
    );
    // The second clip's frames after the first's: one y4m stream of 280 frames.
    let mut clip = std::fs::read(first.join("capture.y4m")).unwrap();
    let second = std::fs::read(moved.join("capture.y4m")).unwrap();
    let header = second.iter().position(|&b| b == b'\n').unwrap();
    clip.extend_from_slice(&second[header + 1..]);
    let capture = tmp.path().join("jump.y4m");
    std::fs::write(&capture, clip).unwrap();
    let rig = Rig::load(&rig_path).unwrap();
    let config = VideoConfig::thesis(4);
    let focused = windows_of(&capture, &rig, &config);
    let whole = windows_of(
        &capture,
        &rig,
        &VideoConfig {
            full_frame_every: 1,
            ..config.clone()
        },
    );
    assert_eq!(focused.len(), 7);
    let regions: Vec<_> = focused.iter().map(|w| w.record.decode_region).collect();
    assert!(regions[..3].iter().all(Option::is_none), "{regions:?}");
    assert!(regions[3].is_some() && regions[4].is_some(), "{regions:?}");
    assert!(
        regions[5].is_none() && focused[5].record.widened,
        "{regions:?}"
    );
    let (before, after) = (
        regions[4].unwrap(),
        regions[6].expect("a region after the jump"),
    );
    assert!(
        after.x >= before.x + 30,
        "the region did not follow the object: {before:?} then {after:?}"
    );
    assert!(whole.iter().all(|w| w.record.decode_region.is_none()));
    // A region's decode is judged against the whole frame's σ there: the carried timing holds.
    for w in &focused[3..] {
        assert_eq!(
            w.record.timing_source,
            TimingSource::Carried,
            "window {}",
            w.record.index
        );
    }
    for (f, w) in focused.iter().zip(&whole) {
        let index = f.record.index;
        assert_eq!(
            f.record.status,
            FrameStatus::Reconstructed,
            "window {index}"
        );
        // The same depth as decoding the whole frame, to a few µm.
        let (a, b) = (f.depth.as_ref().unwrap(), w.depth.as_ref().unwrap());
        let (rms, shared) = depth_difference(a, b);
        assert!(
            rms < 0.05 && shared > 0.99,
            "window {index}: {rms} mm RMS from the whole-frame run, {shared} shared"
        );
        let Some(region) = f.record.decode_region else {
            continue;
        };
        // The region's LED images are the whole frame's decode (same timing) cut to it, to
        // within a twentieth of the level noise (the shifts are fitted again, from rows
        // counted from the region's top instead of the frame's).
        let quality = f.record.decode.as_ref().unwrap();
        let mut source = open(&capture, &OpenOptions::default()).unwrap();
        let fresh = decode(
            source.as_mut(),
            &DecodeConfig {
                start: f.record.decoded.0,
                frames: Some(f.record.decoded.1 - f.record.decoded.0),
                rate_ratio: Some(quality.rate_ratio),
                exposure: Some(quality.exposure),
                ..config.decode.clone()
            },
            &mut |_, _| {},
        )
        .unwrap();
        let noise = meb_core::stats::median(fresh.noise.iter().copied()).unwrap();
        let level_noise = noise * (2.0 / fresh.report.frames_used as f32).sqrt();
        for (inner, full) in f.images.iter().zip(&fresh.leds.images) {
            let cut = full.slice(ndarray::s![
                region.y..region.y + region.height,
                region.x..region.x + region.width
            ]);
            assert_eq!(inner.dim(), cut.dim());
            let worst = inner
                .iter()
                .zip(cut)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst < 0.05 * level_noise,
                "window {index}: LED images differ by {worst} (level noise {level_noise})"
            );
        }
    }
    // A region that cuts through the object (the right half of the frame): its depth is
    // refused, never pasted into a frame as if the object ended there.
    let half = meb_pipeline::demod::Roi {
        x: 160,
        y: 0,
        width: 160,
        height: 180,
    };
    let mut source = open(&capture, &OpenOptions::default()).unwrap();
    let decoded_half = decode(
        source.as_mut(),
        &DecodeConfig {
            start: 4,
            frames: Some(32),
            roi: Some(half),
            ..config.decode.clone()
        },
        &mut |_, _| {},
    )
    .unwrap();
    let refused = reconstruct_extent(
        Source::Decoded(&decoded_half),
        &rig,
        &config.reconstruct,
        Request {
            region: Some(half),
            ..Request::default()
        },
    );
    assert!(
        matches!(refused, Err(ReconstructError::Region(_))),
        "{:?}",
        refused.map(|r| r.into_frame(&rig.camera.projection()).start)
    );
}

/// RMS difference (mm) of two depth maps where both are finite, and the share of `a`'s finite
/// pixels that `b` has too.
fn depth_difference(a: &Array2<f32>, b: &Array2<f32>) -> (f64, f64) {
    let (mut sum, mut both, mut in_a) = (0.0, 0usize, 0usize);
    for (x, y) in a.iter().zip(b) {
        if x.is_finite() {
            in_a += 1;
            if y.is_finite() {
                sum += f64::from(x - y).powi(2);
                both += 1;
            }
        }
    }
    (
        (sum / both.max(1) as f64).sqrt(),
        both as f64 / in_a.max(1) as f64,
    )
}

/// The still ellipsoid's first thesis window on the thesis' dynamic rig at `width` × `height`:
/// the rig, the video settings, the window decoded, and the capture folder.
fn still_window(
    dir: &Path,
    width: usize,
    height: usize,
) -> (Rig, VideoConfig, meb_pipeline::demod::Decoded, PathBuf) {
    let rig_path = dynamic_rig(dir, width, height);
    let clip = ellipsoid_with(dir, &rig_path, "still", 40, 0.0, "0,1,0", &[]);
    let rig = Rig::load(&rig_path).unwrap();
    let config = VideoConfig::thesis(4);
    let mut source = open(&clip.join("capture.y4m"), &OpenOptions::default()).unwrap();
    let decoded = decode(
        source.as_mut(),
        &DecodeConfig {
            start: 4,
            frames: Some(32),
            ..config.decode.clone()
        },
        &mut |_, _| {},
    )
    .unwrap();
    (rig, config, decoded, clip)
}

#[test]
fn a_warm_started_window_equals_a_cold_one_on_a_still_object() {
    let tmp = tempfile::tempdir().unwrap();
    let (rig, config, decoded, _) = still_window(tmp.path(), 320, 180);
    let cold = reconstruct(
        Source::Decoded(&decoded),
        &rig,
        &config.reconstruct,
        Request::default(),
    )
    .unwrap();
    assert_eq!(cold.start, Start::Cold);
    let cold_depth = &cold.integration.depth.depth_mm;
    // The same window warm-started from its own cold result: one or two passes, and the depth
    // within 0.1 mm RMS of the cold one (the ellipsoid's accuracy is 0.5–1 mm).
    let warm = reconstruct(
        Source::Decoded(&decoded),
        &rig,
        &config.reconstruct,
        Request {
            warm: Some(&WarmStart::of(&cold)),
            ..Request::default()
        },
    )
    .unwrap();
    let Start::Warm { passes, moved_mm } = warm.start else {
        panic!("the warm start was not kept: {:?}", warm.start);
    };
    assert!(passes <= 2, "{passes} passes");
    let (rms, shared) = depth_difference(&warm.integration.depth.depth_mm, cold_depth);
    assert!(rms < 0.1, "warm vs cold: {rms} mm RMS");
    assert!(moved_mm < 0.1, "moved {moved_mm} mm (median)");
    assert!(shared > 0.99, "warm covers {shared} of the cold pixels");
    // The same window warm-started from its cold result with every depth `mm` larger.
    let started_off = |mm: f32| {
        let mut off = WarmStart::of(&cold);
        off.depth_mm.mapv_inplace(|z| z + mm);
        let result = reconstruct(
            Source::Decoded(&decoded),
            &rig,
            &config.reconstruct,
            Request {
                warm: Some(&off),
                ..Request::default()
            },
        )
        .unwrap();
        let (rms, shared) = depth_difference(&result.integration.depth.depth_mm, cold_depth);
        (result.start, rms, shared)
    };
    // 30 mm off is out of both brackets: the window is redone cold, as if there had been no
    // warm start.
    let (start, rms, shared) = started_off(30.0);
    assert!(matches!(start, Start::Redone { .. }), "{start:?}");
    assert!(rms < 1e-3 && shared == 1.0, "redone vs cold: {rms} mm");
    // 7 mm off, beyond the ±4 mm bracket but inside the wider ±12 mm one
    // (WARM_WIDE_BRACKET_MM), stays warm: no cold redo, and the part does not move away from
    // the cold depth (it keeps the carried offset or moves part of the way back to it).
    let (start, rms, shared) = started_off(7.0);
    assert!(
        matches!(start, Start::Warm { .. }),
        "a 7 mm warm start was not kept: {start:?}"
    );
    assert!(
        rms < 7.2 && shared > 0.99,
        "kept vs cold: {rms} mm RMS, {shared} shared"
    );
}

/// A decoded window reconstructed as `meb video` reconstructs its first window (coarse
/// start) and cold.
fn coarse_and_cold(
    rig: &Rig,
    config: &VideoConfig,
    decoded: &meb_pipeline::demod::Decoded,
) -> (Reconstruction, Reconstruction) {
    assert!(config.reconstruct.coarse_start, "meb video starts coarse");
    let cold_config = ReconstructConfig {
        coarse_start: false,
        ..config.reconstruct.clone()
    };
    let cold = reconstruct(
        Source::Decoded(decoded),
        rig,
        &cold_config,
        Request::default(),
    )
    .unwrap();
    assert_eq!(cold.start, Start::Cold);
    let coarse = reconstruct(
        Source::Decoded(decoded),
        rig,
        &config.reconstruct,
        Request::default(),
    )
    .unwrap();
    (coarse, cold)
}

/// Asserts that `coarse` kept its coarse start (two passes at most, moving under 1 mm from it)
/// and has the shape of the `cold` reconstruction of the same window (within 0.1 mm RMS once
/// the mean difference is removed, over 99 % of its pixels) at the same distance (the mean
/// difference within `max_offset_mm`: the depth offset search places the surface to a few
/// tenths of a millimetre), and is as close to the truth of `clip` (within 0.05 mm).
fn assert_coarse_like_cold(
    coarse: &Reconstruction,
    cold: &Reconstruction,
    clip: &Path,
    max_offset_mm: f64,
) {
    let Start::Coarse { passes, moved_mm } = coarse.start else {
        panic!("the coarse start was not kept: {:?}", coarse.start);
    };
    assert!(
        passes <= 2 && moved_mm < 1.0,
        "{passes} passes, moved {moved_mm} mm"
    );
    let (depth, cold_depth) = (
        &coarse.integration.depth.depth_mm,
        &cold.integration.depth.depth_mm,
    );
    let (_, shared) = depth_difference(depth, cold_depth);
    let against_cold = meb_core::metrics::compare_depth(depth, cold_depth, None).unwrap();
    assert!(
        against_cold.rmse_mm < 0.1 && against_cold.offset_mm.abs() < max_offset_mm && shared > 0.99,
        "coarse vs cold: {} mm RMS about a mean difference of {} mm, {shared} shared",
        against_cold.rmse_mm,
        against_cold.offset_mm
    );
    let truth: Array2<f32> = ndarray_npy::read_npy(clip.join("depth.npy")).unwrap();
    let error = |d: &Array2<f32>| {
        meb_core::metrics::compare_depth(d, &truth, None)
            .unwrap()
            .rmse_mm
    };
    let (coarse_error, cold_error) = (error(depth), error(cold_depth));
    assert!(
        coarse_error < cold_error + 0.05,
        "coarse start {coarse_error} mm against the truth, cold {cold_error} mm"
    );
}

/// A cold window of the still ellipsoid at 640×360 started from its own reconstruction binned
/// 2×2 (what `meb video` does for its first window): the cold reconstruction's depth, to a
/// fraction of the accuracy, and as close to the truth; a warm start far off is redone the
/// same way. A frame below 640×360 is reconstructed cold.
#[test]
fn a_coarse_started_window_equals_a_cold_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (rig, config, decoded, clip) = still_window(tmp.path(), 640, 360);
    let (coarse, cold) = coarse_and_cold(&rig, &config, &decoded);
    assert_coarse_like_cold(&coarse, &cold, &clip, 0.1);
    assert!(
        coarse.timings.iter().any(|t| t.stage.ends_with(", binned"))
            && !coarse
                .timings
                .iter()
                .any(|t| t.stage.contains("binned, binned")),
        "one level below 640×360: {:?}",
        coarse.timings
    );
    let cold_depth = &cold.integration.depth.depth_mm;
    // Warm-started 30 mm off, out of both brackets: redone from the coarse start.
    let mut off = WarmStart::of(&cold);
    off.depth_mm.mapv_inplace(|z| z + 30.0);
    let redone = reconstruct(
        Source::Decoded(&decoded),
        &rig,
        &config.reconstruct,
        Request {
            warm: Some(&off),
            ..Request::default()
        },
    )
    .unwrap();
    assert!(
        matches!(&redone.start, Start::Redone { reason } if reason.contains("binned 2×2")),
        "{:?}",
        redone.start
    );
    let (rms, shared) = depth_difference(&redone.integration.depth.depth_mm, cold_depth);
    assert!(
        rms < 0.1 && shared > 0.99,
        "redone vs cold: {rms} mm RMS, {shared} shared"
    );
    // The same window binned, 320×180: below the coarse start's size, reconstructed cold.
    let small = reconstruct(
        Source::Decoded(&bin_decoded(&decoded, 2)),
        &rig.binned(2),
        &config.reconstruct,
        Request::default(),
    )
    .unwrap();
    assert_eq!(small.start, Start::Cold);
}

/// The first window of a 1280×720 video starts from a pyramid: the window binned 2×2 is itself
/// started from the window binned 4×4, whose cold passes cost a sixteenth of the full frame's.
/// The result has the cold reconstruction's shape and accuracy, as at one level.
#[test]
fn a_two_level_coarse_start_at_1280x720_equals_a_cold_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (rig, config, decoded, clip) = still_window(tmp.path(), 1280, 720);
    let (coarse, cold) = coarse_and_cold(&rig, &config, &decoded);
    // One level already placed this window's surface 0.27 mm from the cold one; two, 0.39 mm.
    assert_coarse_like_cold(&coarse, &cold, &clip, 0.5);
    let stages = |level: &str| {
        coarse
            .timings
            .iter()
            .filter(|t| t.stage.ends_with(level))
            .count()
    };
    // Cold passes at 320×180, then a warm pass at 640×360 (its stages end "warm (pass 1),
    // binned"), then the full frame.
    assert!(
        stages(", binned, binned") >= 3 && stages("warm (pass 1), binned") >= 2,
        "{:?}",
        coarse.timings
    );
}

#[test]
fn standard_input_gives_the_same_video_as_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = small_dynamic_rig(tmp.path());
    let clip = ellipsoid(tmp.path(), &rig, "clip", 80, 7.5, "0,1,0");
    let capture = clip.join("capture.y4m");
    let from_file = tmp.path().join("file");
    video_ok(&capture, &rig, &from_file, &[]);
    let from_stdin = tmp.path().join("stdin");
    let out = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["video", "-", "--rig", &rig, "--out", &s(&from_stdin)])
        .stdin(Stdio::from(std::fs::File::open(&capture).unwrap()))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for k in 0..2 {
        assert_eq!(
            depth(&from_file, k).mapv(f32::to_bits),
            depth(&from_stdin, k).mapv(f32::to_bits)
        );
    }
    assert_eq!(video_json(&from_stdin)["settings"]["input"], "-");
    // Raw frames on standard input need their layout; a PNG is refused in words.
    let out = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args([
            "video",
            "-",
            "--rig",
            &rig,
            "--out",
            &s(&tmp.path().join("png")),
        ])
        .stdin(Stdio::from(
            std::fs::File::open(clip.join("mask.png")).unwrap(),
        ))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not a y4m stream"), "{stderr}");
}

#[test]
fn motion_is_found_while_the_object_turns_and_not_once_it_stops() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = small_dynamic_rig(tmp.path());
    // 128 frames turning at 60 rpm in the image plane, then 128 frames still. The carriers'
    // code period is 32 frames, so the two clips join without a jump in the modulation.
    let turning = ellipsoid(tmp.path(), &rig, "moving", 128, 60.0, "0,0,1");
    let still = ellipsoid(tmp.path(), &rig, "still", 128, 0.0, "0,1,0");
    let a = std::fs::read(turning.join("capture.y4m")).unwrap();
    let b = std::fs::read(still.join("capture.y4m")).unwrap();
    let header = b.iter().position(|&c| c == b'\n').unwrap() + 1;
    let joined = tmp.path().join("moves-then-stops.y4m");
    std::fs::write(&joined, [&a[..], &b[header..]].concat()).unwrap();
    let out = tmp.path().join("marked");
    let with_motion = |out: &Path, policy: &str, more: &[&str]| {
        let options = ["--window", "32", "--drop", "0", "--motion", policy];
        video_ok(&joined, &rig, out, &[&options[..], more].concat())
    };
    with_motion(&out, "mark", &[]);
    let json = video_json(&out);
    let moving: Vec<bool> = frames(&json)
        .iter()
        .map(|f| {
            f["motion"]["moving"]
                .as_bool()
                .unwrap_or_else(|| panic!("{f:#}"))
        })
        .collect();
    assert_eq!(moving, [true, true, true, true, false, false, false, false]);
    assert_eq!(json["summary"]["moving"], 4);
    assert_eq!(json["summary"]["reconstructed"], 8);
    // The still windows decode plausibly; the turning ones are recorded as moving, with what
    // the verdict found put down to the motion (32-frame windows hold no frames one code
    // period apart: the residual outliers measure it).
    let verdicts: Vec<&str> = frames(&json)
        .iter()
        .map(|f| f["verdict"].as_str().unwrap())
        .collect();
    assert_eq!(verdicts[4..], ["plausible"; 4]);
    for f in &frames(&json)[..4] {
        assert!(f["reason"].as_str().unwrap().contains("moved"), "{f:#}");
        assert!(f["motion"]["period_ratio"].is_null(), "{f:#}");
    }

    // Skipping, scored against the joined clips' truth: a skipped window's truth is not
    // even read (no time spent comparing), a reconstructed one's is.
    let truth = tmp.path().join("joined-truth");
    std::fs::create_dir(&truth).unwrap();
    for (clip, first) in [(&turning, 0), (&still, 128)] {
        let files = TruthFolder::open(&clip.join("truth"), (90, 160)).unwrap();
        for (frame, path) in files.files() {
            std::fs::copy(path, truth.join(format!("depth_{:05}.npy", first + frame))).unwrap();
        }
    }
    let out = tmp.path().join("skipped");
    with_motion(&out, "skip", &["--ground-truth", &s(&truth)]);
    let json = video_json(&out);
    let status: Vec<&str> = frames(&json)
        .iter()
        .map(|f| f["status"].as_str().unwrap())
        .collect();
    assert_eq!(status[..4], ["skipped"; 4]);
    assert_eq!(status[4..], ["reconstructed"; 4]);
    for f in &frames(&json)[..4] {
        assert_eq!(f["timing"]["compare_ms"], 0.0, "{f:#}");
        assert!(f["accuracy"].is_null(), "{f:#}");
    }
    // A timing fitted while the object turned is provisional: once it is seen still in two
    // windows, the next window is fitted freely and carries the rest (the clips' chips run at
    // the frame rate; a turning window's fit carried on was up to 0.12 % off, and the last
    // window 2.6 mm off).
    for f in &frames(&json)[6..] {
        let rate = f["decode"]["rate_ratio"].as_f64().unwrap();
        assert!((rate - 1.0).abs() < 1e-4, "{f:#}");
    }
    for f in &frames(&json)[4..] {
        assert!(f["timing"]["compare_ms"].as_f64().unwrap() > 0.0, "{f:#}");
        assert!(f["accuracy"]["rmse_mm"].as_f64().unwrap() < 2.0, "{f:#}");
    }
    assert!(!out.join("depth_00000.npy").exists());
    assert!(out.join("depth_00004.npy").exists());
    assert_eq!(
        serde_json::to_value(FrameStatus::Skipped).unwrap(),
        "skipped"
    );

    // Placing: no window may be moved across the join (a sudden change of pose, whose decode
    // is implausible) and called still; the still windows stay where they were scheduled.
    let out = tmp.path().join("placed");
    with_motion(&out, "place", &[]);
    let json = video_json(&out);
    let records = frames(&json);
    let moving: Vec<bool> = records
        .iter()
        .map(|f| f["motion"]["moving"].as_bool().unwrap_or(true))
        .collect();
    assert_eq!(moving, [true, true, true, true, false, false, false, false]);
    for f in &records[4..] {
        assert_eq!(f["placed_by"], 0, "{f:#}");
    }
}

#[test]
fn a_wrong_fit_is_refused_moving_or_still_unless_forced() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = dynamic_rig(tmp.path(), 320, 180);
    let turning = ellipsoid_with(tmp.path(), &rig, "turning", 80, 7.5, "0,1,0", &[]);
    let still = ellipsoid_with(tmp.path(), &rig, "still", 40, 0.0, "0,1,0", &[]);
    // A rolling-shutter line time given for a global-shutter capture: the fit leaves more of
    // the LEDs' modulation unexplained (tens of noise levels) than the turning object's
    // motion holds (window 1: about 10).
    for (clip, windows) in [(&turning, 2), (&still, 1)] {
        let capture = clip.join("capture.y4m");
        let refused = tmp.path().join("refused");
        let wrong = ["--line-time-us", "5"];
        let stderr = video_err(&capture, &rig, &refused, &wrong);
        assert!(
            stderr.contains("implausible and the window's motion does not explain it"),
            "{stderr}"
        );
        assert!(stderr.contains("modulation unexplained"), "{stderr}");
        assert!(!refused.exists(), "no output for no 3-D frame");
        // --force keeps the windows, each recorded as forced.
        let forced = tmp.path().join("forced");
        video_ok(
            &capture,
            &rig,
            &forced,
            &[&wrong[..], &["--force"]].concat(),
        );
        let json = video_json(&forced);
        let records = frames(&json);
        assert_eq!(records.len(), windows);
        for record in records {
            assert_eq!(record["status"], "reconstructed", "{record}");
            assert_eq!(record["verdict"], "forced", "{record}");
            assert_eq!(
                record["decode"]["verdict"]["status"], "overridden",
                "{record}"
            );
            assert!(
                record["reason"].as_str().unwrap().contains("--force"),
                "{record}"
            );
        }
        if windows == 2 {
            // The object moved in window 1, and that was not enough to explain the fit.
            assert_eq!(records[1]["motion"]["moving"], true, "{:#}", records[1]);
        }
    }
}

/// The turning 75 mm cube seen corner-on (320×180): its windows decode right, but two of the
/// faces are lit by two LEDs only, so most of the depth would be the integrator's guess (the
/// 640×360 clip was reported as reconstructed at 8–42 mm RMSE). Every window is refused, so
/// nothing is written; `--force` keeps them with what the check found.
#[test]
fn windows_whose_depth_rests_on_two_led_guesses_are_refused_unless_forced() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("cube");
    let scene = ["--scene", "cube", "--corner", "--rpm", "7.5"];
    simulate_y4m(&clip, "thesis-dynamic", "320x180", 80, &scene);
    let rig = s(&clip.join("rig.toml"));
    let refused = tmp.path().join("refused");
    let stderr = video_err(&clip.join("capture.y4m"), &rig, &refused, &[]);
    assert!(
        stderr.contains("the reconstruction is implausible")
            && stderr.contains("lit by three or more LEDs"),
        "{stderr}"
    );
    assert!(!refused.exists(), "no output for no 3-D frame");
    let forced = tmp.path().join("forced");
    video_ok(&clip.join("capture.y4m"), &rig, &forced, &["--force"]);
    let json = video_json(&forced);
    let records = frames(&json);
    assert_eq!(records.len(), 2);
    for record in records {
        assert_eq!(record["status"], "reconstructed", "{record}");
        let share = record["reconstruction"]["measured_share"].as_f64().unwrap();
        assert!(
            share < meb_pipeline::reconstruct::MIN_MEASURED_SHARE,
            "{record}"
        );
        assert!(
            record["reason"]
                .as_str()
                .unwrap()
                .contains("kept on request"),
            "{record}"
        );
    }
}

#[test]
fn a_clip_shorter_than_a_window_and_a_cut_stream_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = small_dynamic_rig(tmp.path());
    let clip = ellipsoid(tmp.path(), &rig, "clip", 150, 7.5, "0,1,0");
    let capture = clip.join("capture.y4m");
    let bytes = std::fs::read(&capture).unwrap();
    let header = bytes.iter().position(|&c| c == b'\n').unwrap() + 1;
    // Mono 8-bit y4m (or 4:2:0): the frame size follows from the file.
    let frame = (bytes.len() - header) / 150;

    // 30 frames: shorter than one 40-frame window.
    let short = tmp.path().join("short.y4m");
    std::fs::write(&short, &bytes[..header + 30 * frame]).unwrap();
    let stderr = video_err(&short, &rig, &tmp.path().join("short"), &[]);
    assert!(
        stderr.contains("ended after 30 frames, before its first window (frames 0..40)"),
        "{stderr}"
    );
    assert!(
        !tmp.path().join("short").exists(),
        "no output for no 3-D frame"
    );

    // Cut 100 bytes into frame 130: the three windows before it are kept, the error says
    // where the stream stopped, and the command fails.
    let cut = tmp.path().join("cut.y4m");
    std::fs::write(&cut, &bytes[..header + 130 * frame + 100]).unwrap();
    let out = tmp.path().join("cut");
    let stderr = video_err(&cut, &rig, &out, &[]);
    assert!(stderr.contains("truncated inside frame 130"), "{stderr}");
    assert!(stderr.contains("3 3-D frames before it"), "{stderr}");
    let json = video_json(&out);
    assert_eq!(json["summary"]["end"], "cut");
    assert_eq!(frames(&json).len(), 3);
    assert!(out.join("depth_00002.npy").exists());

    // A window too short for four LEDs is refused before any work.
    let stderr = video_err(&capture, &rig, &tmp.path().join("bad"), &["--window", "36"]);
    assert!(stderr.contains("28 frames are left to decode"), "{stderr}");
}

/// The first picture of a written video as RGB bytes: decoded by FFmpeg for an MP4, by the
/// `png` crate for an APNG.
fn first_picture(path: &Path) -> Vec<u8> {
    if path.extension().is_some_and(|e| e == "mp4") {
        let out = Command::new("ffmpeg")
            .args(["-v", "error", "-i"])
            .arg(path)
            .args(["-frames:v", "1", "-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        return out.stdout;
    }
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buffer = vec![0; reader.output_buffer_size().unwrap()];
    reader.next_frame(&mut buffer).unwrap();
    buffer
}

#[test]
fn videos_written_together_each_get_their_own_pictures() {
    use image::{Rgb, RgbImage};
    use meb_pipeline::video::encode::{VideoContainer, VideoEncoder};
    let tmp = tempfile::tempdir().unwrap();
    let stems = ["red", "green", "blue"].map(|n| tmp.path().join(n));
    let colours = [[200u8, 30, 30], [30, 200, 30], [30, 30, 200]];
    let mut videos = VideoEncoder::create(&stems, 64, 32, 25.0, VideoContainer::Auto).unwrap();
    if std::env::var("CI").as_deref() == Ok("true") {
        assert_eq!(videos.container(), "mp4", "CI installs FFmpeg");
    }
    let pictures = colours.map(|c| RgbImage::from_pixel(64, 32, Rgb(c)));
    for _ in 0..3 {
        videos
            .push(&[&pictures[0], &pictures[1], &pictures[2]])
            .unwrap();
    }
    // A step must give every video its picture, all of the videos' size.
    assert!(videos.push(&[&pictures[0]]).is_err());
    let small = RgbImage::new(8, 8);
    assert!(videos.push(&[&pictures[0], &small, &pictures[2]]).is_err());
    let paths = videos.finish().unwrap();
    assert_eq!(paths.len(), 3);
    for ((path, colour), stem) in paths.iter().zip(colours).zip(&stems) {
        let path = path.as_ref().expect("each video is written");
        assert_eq!(path.file_stem(), stem.file_name());
        let picture = first_picture(path);
        assert_eq!(picture.len(), 64 * 32 * 3, "{}", path.display());
        // H.264's 4:2:0 colour moves flat colours by a few levels at most.
        for (pixel, k) in picture.chunks(3).zip(0..) {
            for (got, want) in pixel.iter().zip(colour) {
                assert!(
                    got.abs_diff(want) <= 8,
                    "{} pixel {k}: {pixel:?}, expected {colour:?}",
                    path.display()
                );
            }
        }
    }
    let left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().collect();
    assert_eq!(left.len(), 3, "only the three videos are left");
}

#[test]
fn a_frame_dropped_or_repeated_while_the_object_turns_costs_no_window_of_two_periods() {
    // Windows of 80 frames (72 decoded) while the ellipsoid turns: the window holding the
    // break is re-aligned and decoded from the 32 frames on the far side of it. The turning
    // surface leaves more than noise unexplained, which kept such a break from counting and
    // the window was refused with "use --leds 5".
    let tmp = tempfile::tempdir().unwrap();
    let rig = dynamic_rig(tmp.path(), 320, 180);
    for (name, option, at, kind) in [
        ("dropped", "--drop-frame", "100", ("dropped", 16)),
        ("repeated", "--duplicate-frame", "120", ("repeated", 37)),
    ] {
        let clip = ellipsoid_with(tmp.path(), &rig, name, 160, 7.5, "0,1,0", &[option, at]);
        let out = tmp.path().join(format!("{name}-video"));
        let truth = s(&clip);
        let options = ["--window", "80", "--drop", "4", "--ground-truth", &truth];
        video_ok(&clip.join("capture.y4m"), &rig, &out, &options);
        let json = video_json(&out);
        let records = frames(&json);
        assert_eq!(records.len(), 2, "{name}: {:#}", json["frames"]);
        for record in records {
            assert_eq!(record["status"], "reconstructed", "{name}: {record}");
            let rmse = record["accuracy"]["rmse_mm"].as_f64().unwrap();
            assert!(rmse < 1.0, "{name}: RMSE {rmse} mm in {record}");
        }
        assert!(records[0]["decode"].get("room").is_none(), "{}", records[0]);
        let (kind, frame) = kind;
        assert_eq!(
            records[1]["decode"]["room"]["timing_breaks"],
            serde_json::json!([{ "frame": frame, "kind": kind }]),
            "{name}: {}",
            records[1]
        );
    }
}
