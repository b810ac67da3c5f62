//! A `meb video` run in a real process for the tests of live streams (`video_interrupt`,
//! `video_live`): a simulated y4m clip, a feeder thread that writes it to standard input (at
//! once or paced a window at a time) and keeps the pipe open, the stderr lines as they come,
//! real signals, and the temporary folders the run leaves.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

use crate::common::{dynamic_rig, names, run_ok};

/// How long any wait on `meb` may take (debug builds on a busy machine are slow).
pub(crate) const PATIENCE: Duration = Duration::from_secs(240);

pub(crate) fn s(path: &Path) -> String {
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
        let phases = ["--phases", "3,7,11,5"];
        let out = ellipsoid_clip(dir, &rig, "clip", frames, Spin(7.5, "0,1,0"), None, &phases);
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

/// How the simulated ellipsoid of the video tests turns: revolutions per minute about an axis
/// given as `x,y,z`.
pub(crate) struct Spin<'a>(pub(crate) f64, pub(crate) &'a str);

/// Simulates `frames` frames of the 100×60×60 mm ellipsoid turning as `spin` under `rig`, as a
/// y4m clip with the true depth every `truth_every` frames (if given) and more simulator
/// `options`;
/// returns the capture folder `dir/name`.
pub(crate) fn ellipsoid_clip(
    dir: &Path,
    rig: &str,
    name: &str,
    frames: usize,
    Spin(rpm, axis): Spin<'_>,
    truth_every: Option<usize>,
    options: &[&str],
) -> PathBuf {
    let out = dir.join(name);
    let (rpm, frames, out_arg) = (rpm.to_string(), frames.to_string(), s(&out));
    let every = truth_every.map(|k| k.to_string());
    let mut args = vec![
        "simulate",
        "--rig",
        rig,
        "--scene",
        "ellipsoid",
        "--axes-mm",
        "100,60,60",
        "--rpm",
        &rpm,
        "--spin-axis",
        axis,
        "--frames",
        &frames,
        "--format",
        "y4m",
        "--out",
        &out_arg,
    ];
    if let Some(every) = &every {
        args.extend(["--truth-every", every]);
    }
    args.extend(options);
    run_ok(&args);
    out
}

/// What a `meb video` run reads on its standard input.
pub(crate) enum Feed {
    /// Nothing: the input is a file.
    Nothing,
    /// These bytes, written at once.
    Stream(Vec<u8>),
    /// These bytes, written at once into the named pipe (FIFO) `meb` reads, which stays open
    /// like standard input.
    Fifo(PathBuf, Vec<u8>),
    /// The clip's header, then `windows` windows of `window` frames each (cycling through the
    /// clip), one window every `pace`.
    Paced {
        clip: Clip,
        windows: usize,
        window: usize,
        pace: Duration,
    },
}

impl Feed {
    /// Writes the feed to `stdin` (or its FIFO) and returns the writer to keep the pipe open;
    /// stops at the first failed write (meb may end before reading everything: fine).
    fn write(self, mut stdin: impl Write + Send + 'static) -> Box<dyn Write + Send> {
        let fed = match self {
            Feed::Nothing => Ok(()),
            Feed::Stream(bytes) => stdin.write_all(&bytes),
            Feed::Fifo(path, bytes) => {
                // Opening blocks until meb opens the pipe for reading.
                let mut fifo = std::fs::OpenOptions::new().write(true).open(path).unwrap();
                let _ = fifo.write_all(&bytes).and_then(|()| fifo.flush());
                return Box::new(fifo);
            }
            Feed::Paced {
                clip,
                windows,
                window,
                pace,
            } => (|| {
                stdin.write_all(&clip.header)?;
                for k in 0..windows * window {
                    if k % window == 0 && k > 0 {
                        std::thread::sleep(pace);
                    }
                    stdin.write_all(&clip.frames[k % clip.frames.len()])?;
                }
                Ok(())
            })(),
        };
        let _ = fed.and_then(|()| stdin.flush());
        Box::new(stdin)
    }
}

/// A running `meb video`: its stderr lines arrive on `lines`; with a feed, a feeder thread
/// writes it and keeps the pipe open until `close` is dropped.
pub(crate) struct VideoRun {
    child: Child,
    lines: Receiver<String>,
    pub(crate) stderr: Vec<String>,
    close: Option<Sender<()>>,
}

impl VideoRun {
    /// `meb ARGS…` (a `meb video` command line), reading `feed` on standard input.
    pub(crate) fn start(args: &[String], feed: Feed) -> Self {
        let piped = matches!(feed, Feed::Stream(_) | Feed::Paced { .. });
        let mut child = Command::new(env!("CARGO_BIN_EXE_meb"))
            .args(args)
            .stdin(if piped { Stdio::piped() } else { Stdio::null() })
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
        let stdin = child.stdin.take();
        let close = (!matches!(feed, Feed::Nothing)).then(|| {
            let (close, closed) = channel::<()>();
            std::thread::spawn(move || {
                let open = match stdin {
                    Some(stdin) => feed.write(stdin),
                    None => feed.write(std::io::sink()),
                };
                let _ = closed.recv();
                drop(open);
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
    pub(crate) fn wait_until(&mut self, what: &str, mut ready: impl FnMut(&mut Self) -> bool) {
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
    pub(crate) fn wait_for_file(&mut self, out: &Path, file: &str) {
        let parent = out.parent().unwrap();
        self.wait_until(file, |_| {
            temporaries(parent).iter().any(|t| t.join(file).exists())
        });
    }

    /// Waits for a stderr line containing `text`, while `meb` runs; the first such line.
    pub(crate) fn wait_for_line(&mut self, text: &str) -> String {
        let start = Instant::now();
        loop {
            if let Some(line) = self.stderr.iter().find(|l| l.contains(text)) {
                return line.clone();
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

    pub(crate) fn interrupt(&self) {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
    }

    /// Waits for `meb` to end (the pipe still open), then closes the pipe; its status and
    /// all of its stderr.
    pub(crate) fn finish(mut self) -> (ExitStatus, String) {
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

impl Drop for VideoRun {
    /// A test that fails while `meb` runs does not leave it behind.
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
