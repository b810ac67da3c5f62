//! `meb video` and interrupts, with real processes and real signals: the first SIGINT of a live
//! stream (standard input or a named pipe) ends the stream and the folder is written and committed as at a
//! natural end; a second one discards everything; an interrupt of a file input discards the
//! run as for every command.

use nix::sys::signal::Signal;
use std::os::unix::process::ExitStatusExt;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use crate::common::names;
use crate::video_run::{Clip, Feed, VideoRun, s, temporaries, video_json};

/// The line `meb video` prints when an interrupt ends a live stream.
const ENDED: &str = "interrupted: the stream ends here";

/// `meb video INPUT --rig RIG --out OUT`.
fn video(input: &str, rig: &str, out: &std::path::Path) -> Vec<String> {
    ["video", input, "--rig", rig, "--out", &s(out)]
        .map(String::from)
        .to_vec()
}

#[test]
fn the_first_interrupt_of_a_live_stream_ends_it_and_writes_the_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 180);
    let out = tmp.path().join("live");
    // 180 frames: four whole 40-frame windows and half of a fifth; the pipe stays open.
    let mut run = VideoRun::start(&video("-", &clip.rig, &out), Feed::Stream(clip.stream(180)));
    // Once the fourth window is written, meb has read every frame and its reader is blocked
    // reading standard input, where nothing more comes: the interrupt must still end it.
    run.wait_for_file(&out, "depth_00003.npy");
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(status.success(), "{status:?}: {stderr}");
    assert_eq!(
        stderr.lines().filter(|l| l.contains(ENDED)).count(),
        1,
        "{stderr}"
    );
    assert!(!stderr.contains("error"), "{stderr}");
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
    let json = video_json(&out);
    assert_eq!(json["summary"]["end"], "interrupted", "{json}");
    assert_eq!(
        json["summary"]["windows"], 4,
        "the fifth, half read, is dropped"
    );
    assert_eq!(json["summary"]["camera_frames"], 180);
    assert_eq!(json["frames"].as_array().unwrap().len(), 4);

    // The same frames ended naturally (the pipe closed) give the same folder.
    let natural = tmp.path().join("natural");
    let stream = tmp.path().join("stream.y4m");
    std::fs::write(&stream, clip.stream(180)).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["video", "-", "--rig", &clip.rig, "--out", &s(&natural)])
        .stdin(Stdio::from(std::fs::File::open(&stream).unwrap()))
        .output()
        .unwrap();
    assert!(output.status.success(), "{output:?}");
    assert_eq!(video_json(&natural)["summary"]["end"], "complete");
    assert_eq!(names(&out), names(&natural));
    assert!(names(&out).contains(&"video.json".to_string()));
    for k in 0..4 {
        let file = format!("depth_{k:05}.npy");
        assert_eq!(
            std::fs::read(out.join(&file)).unwrap(),
            std::fs::read(natural.join(&file)).unwrap(),
            "{file}"
        );
    }
}

#[test]
fn a_named_pipe_is_a_live_stream_that_the_first_interrupt_ends() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 180);
    let fifo = tmp.path().join("camera.y4m");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let out = tmp.path().join("live");
    let feed = Feed::Fifo(fifo.clone(), clip.stream(180));
    let mut run = VideoRun::start(&video(&s(&fifo), &clip.rig, &out), feed);
    run.wait_for_file(&out, "depth_00003.npy");
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(status.success(), "{status:?}: {stderr}");
    assert!(stderr.contains(ENDED), "{stderr}");
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
    let json = video_json(&out);
    assert_eq!(json["summary"]["end"], "interrupted", "{json}");
    assert_eq!(json["summary"]["windows"], 4, "{json}");
}

#[test]
fn a_second_interrupt_while_finishing_discards_the_live_output() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 180);
    let out = tmp.path().join("live");
    let mut run = VideoRun::start(&video("-", &clip.rig, &out), Feed::Stream(clip.stream(180)));
    run.wait_for_file(&out, "depth_00000.npy");
    run.interrupt();
    // The second interrupt comes as soon as meb says the stream has ended: it is then still
    // finishing the windows read and writing the videos.
    run.wait_for_line(ENDED);
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(!status.success(), "{status:?}: {stderr}");
    assert_eq!(status.signal(), Some(Signal::SIGINT as i32), "{stderr}");
    assert!(!out.exists(), "nothing is left at {}", out.display());
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
}

#[test]
fn an_interrupt_of_a_file_input_discards_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 160);
    // A regular file of 30 windows, long enough to be mid-run when the signal comes.
    let file = tmp.path().join("long.y4m");
    std::fs::write(&file, clip.stream(1200)).unwrap();
    let out = tmp.path().join("video");
    let mut run = VideoRun::start(&video(&s(&file), &clip.rig, &out), Feed::Nothing);
    run.wait_for_file(&out, "depth_00000.npy");
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(!status.success(), "{status:?}: {stderr}");
    assert_eq!(status.signal(), Some(Signal::SIGINT as i32), "{stderr}");
    assert!(!stderr.contains(ENDED), "{stderr}");
    assert!(!out.exists(), "nothing is left at {}", out.display());
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
}
