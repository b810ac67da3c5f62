//! A video container's timestamps: `meb decode` of an MP4 whose timestamps show a frame the
//! camera dropped records the gap beside the break it finds in the data, and an MP4 whose
//! timestamps put a frame half a period late (a variable frame rate) is refused naming it,
//! unless the frame rate is given.
//!
//! The capture: 320×180 at 960 fps, a Ø60 mm sphere on a ground plane, read noise 1 %, frame
//! 60 dropped by the camera, encoded losslessly (H.264, QP 0) with a 1/96000 s time base.

use crate::common::{
    self, OUT_OF_PLANE_LEDS, arg, decode_report, ffmpeg_available, folder_gains, meb, rig_toml,
    stderr_of,
};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Simulates the capture as PNG frames into `dir/frames`; returns the folder.
fn capture(dir: &Path) -> PathBuf {
    let rig = dir.join("rig.toml");
    std::fs::write(&rig, rig_toml(320, 180, 0.5, &OUT_OF_PLANE_LEDS)).unwrap();
    let out = dir.join("frames");
    common::run_ok(&[
        "simulate",
        "--rig",
        arg(&rig),
        "--scene",
        "sphere",
        "--size-mm",
        "60",
        "--ground-mm",
        "-30",
        "--exposure",
        "0.6",
        "--noise",
        "0.01",
        "--seed",
        "10",
        "--drop-frame",
        "60",
        "--out",
        arg(&out),
    ]);
    out
}

/// Encodes the PNG frames of `capture` into `dir/name` with frame j stamped at
/// `stamp` (an FFmpeg expression in frame periods of N, the frame number).
fn encode(capture: &Path, stamp: &str, dir: &Path, name: &str) -> PathBuf {
    let out = dir.join(name);
    let pattern = capture.join("frame_%05d.png");
    let filter = format!("settb=1/96000,setpts=({stamp})*100");
    let status = Command::new("ffmpeg")
        .args(["-loglevel", "error", "-y", "-framerate", "960", "-i"])
        .arg(&pattern)
        .args(["-vf", &filter, "-fps_mode", "passthrough"])
        .args([
            "-enc_time_base",
            "1/96000",
            "-video_track_timescale",
            "96000",
        ])
        .args(["-c:v", "libx264", "-qp", "0", "-pix_fmt", "gray"])
        .args(["-color_range", "pc"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg for {name}");
    out
}

#[test]
fn a_gap_in_the_timestamps_is_recorded_and_a_variable_frame_rate_refused() {
    if !ffmpeg_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let frames = capture(tmp.path());

    // The camera dropped frame 60, and the container's stamps show it.
    let gap = encode(&frames, "N+gte(N\\,60)", tmp.path(), "gap.mp4");
    let out = tmp.path().join("gap");
    common::run_ok(&["decode", arg(&gap), "--leds", "4", "--out", arg(&out)]);
    let room = decode_report(&out)["room"].clone();
    assert_eq!(
        room["container_gaps"],
        serde_json::json!([{ "frame": 60, "missing": 1 }]),
        "{room}"
    );
    assert_eq!(
        room["timing_breaks"],
        serde_json::json!([{ "frame": 60, "kind": "dropped" }]),
        "{room}"
    );
    let gains = folder_gains(&out, &frames);
    assert!(
        gains.iter().all(|g| (g - 1.0).abs() < 0.01),
        "gains {gains:?}"
    );

    // Frame 60 stamped 1.5 periods after frame 59: no constant clock explains the stamps.
    let jitter = encode(&frames, "N+0.5*gte(N\\,60)", tmp.path(), "jitter.mp4");
    let refused = tmp.path().join("refused");
    let output = meb(&[
        "decode",
        arg(&jitter),
        "--leds",
        "4",
        "--out",
        arg(&refused),
    ]);
    let text = stderr_of(&output);
    assert!(!output.status.success(), "{text}");
    assert!(text.contains("variable frame rate"), "{text}");
    assert!(text.contains("frame 60 comes 1.50 frame periods"), "{text}");
    assert!(text.contains("--fps"), "{text}");
    assert!(
        !refused.exists(),
        "nothing is written for a refused capture"
    );

    // Given the rate, the user vouches for the clock: the frames decode, the drop found from
    // the data alone.
    let given = tmp.path().join("given");
    let rate = ["--fps", "960", "--out", arg(&given)];
    let args = [&["decode", arg(&jitter), "--leds", "4"][..], &rate[..]].concat();
    common::run_ok(&args);
    let room = decode_report(&given)["room"].clone();
    assert_eq!(room["container_gaps"], serde_json::json!([]), "{room}");
    assert_eq!(
        room["timing_breaks"],
        serde_json::json!([{ "frame": 60, "kind": "dropped" }]),
        "{room}"
    );
}
