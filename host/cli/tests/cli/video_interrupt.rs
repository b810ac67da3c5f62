//! `meb video` and interrupts, with real processes and real signals: the first SIGINT of a live
//! stream (standard input) ends the stream and the folder is written and committed as at a
//! natural end; a second one discards everything; an interrupt of a file input discards the
//! run as for every command.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

use crate::common;
use common::{dynamic_rig, names, run_ok};

/// How long any wait on `meb` may take (debug builds on a busy machine are slow).
const PATIENCE: Duration = Duration::from_secs(240);

/// The line `meb video` prints when an interrupt ends a live stream.
const ENDED: &str = "interrupted: the stream ends here";

fn s(path: &Path) -> String {
    path.display().to_string()
}

/// Temporary output folders (`.NAME.meb-partial-…`) in `dir`.
pub(crate) fn temporaries(dir: &Path) -> Vec<PathBuf> {
    names(dir)
        .into_iter()
        .filter(|n| n.contains(".meb-partial-"))
        .map(|n| dir.join(n))
        .collect()
}

pub(crate) fn video_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("video.json")).unwrap()).unwrap()
}

/// A simulated y4m clip of the turning ellipsoid (as in `video_cli`) on the thesis' dynamic
/// rig at 160×90: the rig's path and the clip split into its header and frames.
pub(crate) struct Clip {
    pub(crate) rig: String,
    pub(crate) header: Vec<u8>,
    pub(crate) frames: Vec<Vec<u8>>,
}

impl Clip {
    pub(crate) fn simulate(dir: &Path, frames: usize) -> Self {
        let rig = dynamic_rig(dir, 160, 90);
        let out = dir.join("clip");
        let count = frames.to_string();
        run_ok(&[
            "simulate",
            "--rig",
            &rig,
            "--scene",
            "ellipsoid",
            "--axes-mm",
            "100,60,60",
            "--rpm",
            "7.5",
            "--spin-axis",
            "0,1,0",
            "--frames",
            &count,
            "--format",
            "y4m",
            "--phases",
            "3,7,11,5",
            "--out",
            &s(&out),
        ]);
        let bytes = std::fs::read(out.join("capture.y4m")).unwrap();
        let header = bytes.iter().position(|&c| c == b'\n').unwrap() + 1;
        let size = (bytes.len() - header) / frames;
        assert_eq!(header + size * frames, bytes.len(), "frames of one size");
        Self {
            rig,
            header: bytes[..header].to_vec(),
            frames: bytes[header..].chunks(size).map(<[u8]>::to_vec).collect(),
        }
    }

    /// The header and the first `n` frames (cycling through the clip past its end).
    pub(crate) fn stream(&self, n: usize) -> Vec<u8> {
        let mut bytes = self.header.clone();
        for k in 0..n {
            bytes.extend_from_slice(&self.frames[k % self.frames.len()]);
        }
        bytes
    }
}

/// A running `meb video`: its stderr lines arrive on `lines`; for standard input, a feeder
/// thread writes the stream and keeps the pipe open until `close` is dropped.
struct Run {
    child: Child,
    lines: Receiver<String>,
    stderr: Vec<String>,
    close: Option<Sender<()>>,
}

impl Run {
    /// `meb video INPUT --rig RIG --out OUT`, with `stream` written to its standard input
    /// (INPUT `-`) when given.
    fn start(input: &str, rig: &str, out: &Path, stream: Option<Vec<u8>>) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_meb"))
            .args(["video", input, "--rig", rig, "--out", &s(out)])
            .stdin(if stream.is_some() {
                Stdio::piped()
            } else {
                Stdio::null()
            })
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (line_sender, lines) = channel();
        let stderr = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if line_sender.send(line).is_err() {
                    break;
                }
            }
        });
        let close = stream.map(|bytes| {
            let mut stdin = child.stdin.take().unwrap();
            let (close, closed) = channel::<()>();
            std::thread::spawn(move || {
                // meb may end before reading everything (then the write fails): fine.
                let _ = stdin.write_all(&bytes).and_then(|()| stdin.flush());
                let _ = closed.recv();
            });
            close
        });
        Self {
            child,
            lines,
            stderr: Vec::new(),
            close,
        }
    }

    /// Collects the stderr lines that have arrived.
    fn read_stderr(&mut self) {
        self.stderr.extend(self.lines.try_iter());
    }

    /// Waits until `ready` holds, while `meb` runs.
    fn wait_until(&mut self, what: &str, mut ready: impl FnMut(&mut Self) -> bool) {
        let start = Instant::now();
        while !ready(self) {
            self.read_stderr();
            assert!(
                self.child.try_wait().unwrap().is_none(),
                "meb ended before {what}: {:?}",
                self.stderr
            );
            assert!(start.elapsed() < PATIENCE, "no {what}: {:?}", self.stderr);
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits until the temporary folder beside `out` holds `file`.
    fn wait_for_file(&mut self, out: &Path, file: &str) {
        let parent = out.parent().unwrap();
        self.wait_until(file, |_| {
            temporaries(parent).iter().any(|t| t.join(file).exists())
        });
    }

    /// Waits for a stderr line containing `text`.
    fn wait_for_line(&mut self, text: &str) {
        let start = Instant::now();
        loop {
            if self.stderr.iter().any(|l| l.contains(text)) {
                return;
            }
            match self.lines.recv_timeout(Duration::from_millis(100)) {
                Ok(line) => self.stderr.push(line),
                Err(_) => assert!(
                    start.elapsed() < PATIENCE && self.child.try_wait().unwrap().is_none(),
                    "no line {text:?}: {:?}",
                    self.stderr
                ),
            }
        }
    }

    fn interrupt(&self) {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
    }

    /// Waits for `meb` to end (the pipe still open), then closes the pipe; its status and
    /// all of its stderr.
    fn finish(mut self) -> (ExitStatus, String) {
        let start = Instant::now();
        let status = loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                break status;
            }
            assert!(start.elapsed() < PATIENCE, "meb did not end");
            std::thread::sleep(Duration::from_millis(20));
        };
        drop(self.close.take());
        // The reader thread sees the end of stderr once meb has exited.
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(10)) {
            self.stderr.push(line);
        }
        (status, self.stderr.join("\n"))
    }
}

impl Drop for Run {
    /// A test that fails while `meb` runs does not leave it behind.
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_first_interrupt_of_a_live_stream_ends_it_and_writes_the_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 180);
    let out = tmp.path().join("live");
    // 180 frames: four whole 40-frame windows and half of a fifth; the pipe stays open.
    let mut run = Run::start("-", &clip.rig, &out, Some(clip.stream(180)));
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
fn a_second_interrupt_while_finishing_discards_the_live_output() {
    let tmp = tempfile::tempdir().unwrap();
    let clip = Clip::simulate(tmp.path(), 180);
    let out = tmp.path().join("live");
    let mut run = Run::start("-", &clip.rig, &out, Some(clip.stream(180)));
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
    let mut run = Run::start(&s(&file), &clip.rig, &out, None);
    run.wait_for_file(&out, "depth_00000.npy");
    run.interrupt();
    let (status, stderr) = run.finish();
    assert!(!status.success(), "{status:?}: {stderr}");
    assert_eq!(status.signal(), Some(Signal::SIGINT as i32), "{stderr}");
    assert!(!stderr.contains(ENDED), "{stderr}");
    assert!(!out.exists(), "nothing is left at {}", out.display());
    assert_eq!(temporaries(tmp.path()), Vec::<PathBuf>::new());
}
