//! `meb video` on a machine without FFmpeg: the depth and shaded-render videos are written as
//! animated PNGs (one picture per 3-D frame) instead of MP4, and `video.json` says so and why.
//!
//! The binary runs with a `PATH` that holds no programs at all, so FFmpeg cannot be found
//! whether or not this machine has it; the input is a y4m clip, which `meb` reads itself.

use std::path::Path;
use std::process::Command;

use crate::common;
use common::{dynamic_rig, run_ok, stderr_of};

/// Frames in an APNG and the size of its pictures.
fn apng_frames(path: &Path) -> (u32, (u32, u32)) {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let reader = png::Decoder::new(file).read_info().unwrap();
    let info = reader.info();
    let control = info
        .animation_control
        .unwrap_or_else(|| panic!("{} is not animated", path.display()));
    (control.num_frames, (info.width, info.height))
}

#[test]
fn without_ffmpeg_the_videos_are_animated_pngs_and_video_json_says_why() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = dynamic_rig(tmp.path(), 160, 90);
    let clip = tmp.path().join("clip");
    let clip_arg = clip.display().to_string();
    run_ok(&[
        "simulate",
        "--rig",
        &rig,
        "--scene",
        "ellipsoid",
        "--axes-mm",
        "100,60,60",
        "--rpm",
        "0",
        "--frames",
        "120",
        "--format",
        "y4m",
        "--phases",
        "3,7,11,5",
        "--out",
        &clip_arg,
    ]);
    let no_programs = tmp.path().join("empty-bin");
    std::fs::create_dir(&no_programs).unwrap();
    let out = tmp.path().join("video");
    let output = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["video", &format!("{clip_arg}/capture.y4m"), "--rig", &rig])
        .arg("--out")
        .arg(&out)
        .env("PATH", &no_programs)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "meb video without ffmpeg failed: {}",
        stderr_of(&output)
    );
    let stderr = stderr_of(&output);
    assert!(stderr.contains("ffmpeg was not found"), "{stderr}");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("video.json")).unwrap()).unwrap();
    let outputs = &json["outputs"];
    assert_eq!(outputs["video_container"], "apng", "{outputs}");
    assert!(
        outputs["video_fallback"]
            .as_str()
            .is_some_and(|r| r.contains("ffmpeg")),
        "{outputs}"
    );
    assert_eq!(outputs["depth_video"], "depth.png", "{outputs}");
    assert_eq!(outputs["shaded_video"], "shaded.png", "{outputs}");
    let windows = json["frames"].as_array().unwrap().len();
    assert_eq!(windows, 3, "120 frames in windows of 40");
    assert_eq!(json["summary"]["reconstructed"], 3, "{:#}", json["frames"]);
    for name in ["depth.png", "shaded.png"] {
        let (frames, size) = apng_frames(&out.join(name));
        assert_eq!(
            frames as usize, windows,
            "{name}: one picture per 3-D frame"
        );
        assert_eq!(size, (160, 90), "{name}");
    }
    let names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n.ends_with(".mp4") || n.ends_with("-frames")),
        "no MP4 and no leftover picture folders: {names:?}"
    );
}
