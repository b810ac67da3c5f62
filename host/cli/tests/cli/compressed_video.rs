//! Captures that went through a lossy codec: `meb decode` of an MP4 (H.264 or HEVC, encoded
//! by FFmpeg from the simulator's PNG frames) names the compression when the LEDs' swing is
//! too weak for it, never advises more LEDs for a codec's extra component, records the codec
//! in decode.json, and decodes a capture with a strong enough swing within 1.5 % of the
//! truth (relative to the gains' mean: compression may scale all LEDs alike).
//!
//! The capture: 320×180 at 960 fps, a Ø60 mm sphere on a ground plane, read noise 1 %, a
//! steady background of 0.15 of full scale, the brightest LED peaking at `peak` on the sphere.

use crate::common::{
    self, OUT_OF_PLANE_LEDS, arg, ffmpeg_available, folder_gains, meb, rig_toml, stderr_of,
};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Simulates the capture as PNG frames into `dir/name`; returns the folder.
fn capture(dir: &Path, name: &str, peak: f64) -> PathBuf {
    let rig = dir.join("rig.toml");
    std::fs::write(&rig, rig_toml(320, 180, 0.5, &OUT_OF_PLANE_LEDS)).unwrap();
    let peak = peak.to_string();
    let base = [
        "simulate",
        "--rig",
        arg(&rig),
        "--scene",
        "sphere",
        "--size-mm",
        "60",
        "--ground-mm",
        "-30",
        "--peak",
        &peak,
        "--exposure",
        "0.6",
        "--noise",
        "0.01",
        "--seed",
        "7",
    ];
    // The background's level follows from the LEDs' irradiance of a dark capture.
    let dark = dir.join(format!("{name}-dark"));
    let mut args = base.to_vec();
    args.extend(["--frames", "8", "--out", arg(&dark)]);
    common::run_ok(&args);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dark.join("truth.json")).unwrap()).unwrap();
    let signal = truth["signal_irradiance"].as_f64().unwrap();
    let snr = format!("--snr-db={}", 10.0 * (signal / 0.15).log10());
    let out = dir.join(name);
    let mut args = base.to_vec();
    args.extend(["--frames", "128", &snr, "--out", arg(&out)]);
    common::run_ok(&args);
    out
}

/// Encodes the PNG frames of `capture` with `codec` (`libx264`, `libx265`, `ffv1`) at `crf`
/// (ignored for FFV1) into `dir/name`.
fn encode(capture: &Path, codec: &str, crf: u32, dir: &Path, name: &str) -> PathBuf {
    let out = dir.join(name);
    let crf = crf.to_string();
    let mut args = vec!["-loglevel", "error", "-y", "-framerate", "960", "-i"];
    let pattern = capture.join("frame_%05d.png");
    args.push(arg(&pattern));
    args.extend(["-c:v", codec]);
    if codec == "ffv1" {
        args.extend(["-pix_fmt", "gray"]);
    } else {
        args.extend(["-crf", &crf, "-pix_fmt", "yuv420p"]);
        if codec == "libx265" {
            args.extend(["-x265-params", "log-level=error"]);
        }
    }
    args.push(arg(&out));
    let status = Command::new("ffmpeg").args(&args).status().unwrap();
    assert!(status.success(), "ffmpeg {args:?}");
    out
}

/// The `compression` entry of a decode folder's decode.json.
fn compression(decoded: &Path) -> serde_json::Value {
    common::decode_report(decoded)["compression"].clone()
}

#[test]
fn a_weak_modulation_in_a_lossy_video_is_refused_naming_the_compression() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let weak = capture(tmp.path(), "weak", 0.08);
    // Uncompressed and losslessly compressed, the same frames decode.
    let lossless = encode(&weak, "ffv1", 0, tmp.path(), "weak-ffv1.mkv");
    for (input, name) in [(&weak, "png"), (&lossless, "ffv1")] {
        let out = tmp.path().join(format!("dec-{name}"));
        common::run_ok(&["decode", arg(input), "--out", arg(&out)]);
        assert!(compression(&out).is_null(), "{name}: {}", compression(&out));
    }
    // HEVC CRF 28 was decoded with gains 3 % off and exit 0; H.264 CRF 35 was refused with
    // "use --leds 5".
    for (codec, crf, name) in [("libx265", 28, "hevc"), ("libx264", 35, "h264")] {
        let video = encode(&weak, codec, crf, tmp.path(), &format!("weak-{name}.mp4"));
        let out = tmp.path().join(format!("dec-{name}"));
        let run = meb(&["decode", arg(&video), "--out", arg(&out)]);
        let text = stderr_of(&run);
        assert!(!run.status.success(), "{name} CRF {crf} was decoded");
        assert!(
            text.contains(&format!("the video is {name}"))
                || text.contains(&format!("it is {name}")),
            "{name} CRF {crf}: {text}"
        );
        assert!(text.contains("compression"), "{name} CRF {crf}: {text}");
        assert!(!text.contains("use --leds"), "{name} CRF {crf}: {text}");
        assert!(!out.exists(), "{name} CRF {crf} left {}", out.display());
    }
}

#[test]
fn a_strong_modulation_in_a_lossy_video_is_decoded_and_the_codec_recorded() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let strong = capture(tmp.path(), "strong", 0.32);
    let video = encode(&strong, "libx265", 23, tmp.path(), "strong-hevc.mp4");
    let out = tmp.path().join("dec");
    common::run_ok(&["decode", arg(&video), "--out", arg(&out)]);
    let found = compression(&out);
    assert_eq!(found["codec"], "hevc", "{found}");
    let bpp = found["bits_per_pixel"].as_f64().unwrap();
    assert!(bpp > 0.0 && bpp < 1.0, "{found}");
    let gains = folder_gains(&out, &strong);
    let mean = gains.iter().sum::<f64>() / gains.len() as f64;
    eprintln!("HEVC CRF 23: gains {gains:.4?}");
    for (i, g) in gains.iter().enumerate() {
        assert!(
            (g / mean - 1.0).abs() < 0.015,
            "LED {}: gain {g:.4} vs mean {mean:.4} ({gains:.4?})",
            i + 1
        );
    }
}
