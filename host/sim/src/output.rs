//! Writing a simulated capture to disk: frames (PNG sequence, y4m, or MP4 through the
//! `ffmpeg` program) and the ground truth (`depth.npy`, `normals.npy`, `mask.png`,
//! `albedo.npy`, `led<i>_true.npy`, `rig.toml`, `truth.json`; for moving scenes optionally the
//! depth every K frames, `truth/depth_FFFFF.npy`).
//!
//! Everything is written into a folder the caller replaces atomically (an
//! [`OutputFolder`](meb_core::io::OutputFolder)), so a failed or interrupted run never
//! leaves a half-written result under the requested name. Frames are rendered and written one
//! at a time (bounded memory). 10- and 12-bit samples are stored in 16-bit containers scaled to
//! full range (code · 65535 / (2^b − 1)); MP4 is lossless H.264 (`-qp 0`) in `gray` (8-bit) or
//! `gray10le`.

use super::SimulateError;
use super::capture::{GroundTruth, SimulatedCapture, TruthInfo};
use image::{ImageBuffer, Luma};
use meb_core::capture::{Frame, FrameFormat, FrameSource, Samples};
use meb_core::io::{FilesError, write_mask, write_npy};
use meb_core::rig::Rig;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

/// Container of the rendered frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum VideoFormat {
    /// `frame_00000.png` … (8- or 16-bit greyscale).
    Png,
    /// `capture.y4m`, `mono` or `mono16`.
    Y4m,
    /// `capture.mp4`, lossless H.264 through `ffmpeg`.
    Mp4,
}

fn write_err(path: &Path, e: std::io::Error) -> SimulateError {
    FilesError::write(path, e).into()
}

fn encode_err(path: &Path, e: impl std::error::Error + Send + Sync + 'static) -> SimulateError {
    FilesError::Encode {
        path: path.to_path_buf(),
        source: Box::new(e),
    }
    .into()
}

/// Sample values as stored: 8-bit as is, deeper captures scaled to 16-bit full range.
fn stored_u16(format: &FrameFormat, samples: &Samples) -> Vec<u16> {
    let max = (1u32 << format.bit_depth) - 1;
    match samples {
        Samples::U8(v) => v.iter().map(|&c| u16::from(c)).collect(),
        Samples::U16(v) if format.bit_depth == 16 => v.clone(),
        Samples::U16(v) => v
            .iter()
            .map(|&c| ((u32::from(c) * 65535 + max / 2) / max) as u16)
            .collect(),
    }
}

/// Writes frames one by one.
enum FrameWriter {
    Png {
        dir: PathBuf,
    },
    Y4m {
        path: PathBuf,
        file: std::io::BufWriter<std::fs::File>,
    },
    Mp4 {
        child: Child,
    },
}

impl FrameWriter {
    fn open(dir: &Path, video: VideoFormat, format: &FrameFormat) -> Result<Self, SimulateError> {
        match video {
            VideoFormat::Png => Ok(Self::Png {
                dir: dir.to_path_buf(),
            }),
            VideoFormat::Y4m => {
                let path = dir.join("capture.y4m");
                let file = std::fs::File::create(&path).map_err(|e| write_err(&path, e))?;
                let mut file = std::io::BufWriter::new(file);
                let (num, den) = rate_fraction(format.fps);
                let colour = if format.bit_depth == 8 {
                    "mono"
                } else {
                    "mono16"
                };
                writeln!(
                    file,
                    "YUV4MPEG2 W{} H{} F{num}:{den} Ip A1:1 C{colour}",
                    format.width, format.height
                )
                .map_err(|e| write_err(&path, e))?;
                Ok(Self::Y4m { path, file })
            }
            VideoFormat::Mp4 => {
                let path = dir.join("capture.mp4");
                let (input, output) = if format.bit_depth == 8 {
                    ("gray", "gray")
                } else {
                    ("gray16le", "gray10le")
                };
                let child = Command::new("ffmpeg")
                    .args(["-hide_banner", "-loglevel", "error", "-y"])
                    .args(["-f", "rawvideo", "-pix_fmt", input])
                    .args(["-s", &format!("{}x{}", format.width, format.height)])
                    .args(["-framerate", &format.fps.to_string(), "-i", "-"])
                    .args(["-c:v", "libx264", "-qp", "0", "-pix_fmt", output])
                    .args(["-color_range", "pc"])
                    .arg(&path)
                    .stdin(Stdio::piped())
                    .stdout(Stdio::null())
                    .stderr(Stdio::piped())
                    .spawn()
                    .map_err(|source| SimulateError::FfmpegIo {
                        what: "start",
                        source,
                    })?;
                Ok(Self::Mp4 { child })
            }
        }
    }

    fn write(&mut self, format: &FrameFormat, frame: &Frame) -> Result<(), SimulateError> {
        let (w, h) = (format.width as u32, format.height as u32);
        match self {
            Self::Png { dir } => {
                let path = dir.join(format!("frame_{:05}.png", frame.index));
                match &frame.samples {
                    Samples::U8(v) => {
                        let img = ImageBuffer::<Luma<u8>, _>::from_raw(w, h, v.clone())
                            .ok_or_else(|| frame_size_err(&path))?;
                        img.save(&path).map_err(|e| encode_err(&path, e))
                    }
                    samples => {
                        let img = ImageBuffer::<Luma<u16>, _>::from_raw(
                            w,
                            h,
                            stored_u16(format, samples),
                        )
                        .ok_or_else(|| frame_size_err(&path))?;
                        img.save(&path).map_err(|e| encode_err(&path, e))
                    }
                }
            }
            Self::Y4m { path, file } => {
                file.write_all(b"FRAME\n").map_err(|e| write_err(path, e))?;
                write_raw(file, format, &frame.samples).map_err(|e| write_err(path, e))
            }
            Self::Mp4 { child } => {
                let stdin = child
                    .stdin
                    .as_mut()
                    .ok_or_else(|| SimulateError::Ffmpeg("no stdin pipe".into()))?;
                write_raw(stdin, format, &frame.samples).map_err(|source| SimulateError::FfmpegIo {
                    what: "feed frames to",
                    source,
                })
            }
        }
    }

    fn finish(self) -> Result<(), SimulateError> {
        match self {
            Self::Png { .. } => Ok(()),
            Self::Y4m { path, mut file } => file.flush().map_err(|e| write_err(&path, e)),
            Self::Mp4 { mut child } => {
                drop(child.stdin.take());
                let out = child
                    .wait_with_output()
                    .map_err(|source| SimulateError::FfmpegIo {
                        what: "wait for",
                        source,
                    })?;
                if out.status.success() {
                    Ok(())
                } else {
                    Err(SimulateError::Ffmpeg(format!(
                        "ffmpeg failed: {}",
                        String::from_utf8_lossy(&out.stderr).trim()
                    )))
                }
            }
        }
    }
}

/// Raw little-endian samples (16-bit containers for deeper captures).
fn write_raw(out: &mut dyn Write, format: &FrameFormat, samples: &Samples) -> std::io::Result<()> {
    match samples {
        Samples::U8(v) => out.write_all(v),
        other => {
            let bytes: Vec<u8> = stored_u16(format, other)
                .iter()
                .flat_map(|c| c.to_le_bytes())
                .collect();
            out.write_all(&bytes)
        }
    }
}

/// The frame rate as a y4m fraction (exact for integer and 1/1000-resolution rates).
fn rate_fraction(fps: f64) -> (u64, u64) {
    if (fps - fps.round()).abs() < 1e-9 {
        (fps.round() as u64, 1)
    } else {
        ((fps * 1000.0).round() as u64, 1000)
    }
}

/// Writes the ground-truth files into `dir`.
pub fn write_truth(dir: &Path, truth: &GroundTruth, rig: &Rig) -> Result<(), SimulateError> {
    write_npy(&dir.join("depth.npy"), &truth.depth_mm)?;
    write_npy(&dir.join("normals.npy"), &truth.normals)?;
    write_npy(&dir.join("albedo.npy"), &truth.albedo)?;
    for (i, image) in truth.led_true.images.iter().enumerate() {
        write_npy(&dir.join(format!("led{}_true.npy", i + 1)), image)?;
    }
    write_mask(&dir.join("mask.png"), &truth.mask)?;
    let rig_path = dir.join("rig.toml");
    std::fs::write(&rig_path, rig.to_toml_string()).map_err(|e| write_err(&rig_path, e))
}

/// The error of a frame whose samples do not fill its size.
fn frame_size_err(path: &Path) -> SimulateError {
    encode_err(path, std::io::Error::other("frame size mismatch"))
}

/// Contents of `truth.json`.
#[derive(Debug, Serialize)]
struct TruthFile<'a> {
    #[serde(flatten)]
    info: &'a TruthInfo,
    /// Camera time the ground-truth files describe.
    truth_time_s: f64,
    /// How the frames were stored.
    video: VideoFormat,
    /// Code value of full scale in the stored files.
    stored_white_level: u32,
    /// Free-form description of the scene (from the caller).
    scene: &'a serde_json::Value,
}

/// Options of [`write_capture`].
#[derive(Debug, Clone)]
pub struct OutputOptions {
    /// Frame container.
    pub video: VideoFormat,
    /// Frame whose start time the ground truth describes.
    pub truth_frame: usize,
    /// Scene description stored in `truth.json`.
    pub scene: serde_json::Value,
    /// Also write the true depth at the start of every K-th frame as
    /// `truth/depth_FFFFF.npy` (F = frame), for scoring a moving scene frame by frame.
    pub truth_every: Option<usize>,
}

/// Renders every frame of `capture` and writes frames plus ground truth into the existing
/// folder `dir`; `progress(done, total)` is called after each frame.
pub fn write_capture(
    capture: &mut SimulatedCapture,
    dir: &Path,
    options: &OutputOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SimulateError> {
    let format = capture.format().clone();
    let total = capture.info().frames;
    let mut writer = FrameWriter::open(dir, options.video, &format)?;
    let every = options.truth_every.filter(|&k| k > 0);
    if every.is_some() {
        let truth_dir = dir.join("truth");
        std::fs::create_dir_all(&truth_dir).map_err(|e| write_err(&truth_dir, e))?;
    }
    let mut done = 0;
    while let Some(frame) = capture.next_frame()? {
        writer.write(&format, &frame)?;
        if every.is_some_and(|k| frame.index.is_multiple_of(k)) {
            let truth = capture.truth_at(capture.frame_time(frame.index));
            let path = dir.join(format!("truth/depth_{:05}.npy", frame.index));
            write_npy(&path, &truth.depth_mm)?;
        }
        done += 1;
        progress(done, total);
    }
    writer.finish()?;
    let t = capture.frame_time(options.truth_frame);
    let truth = capture.truth_at(t);
    write_truth(dir, &truth, capture.rig())?;
    let stored_white_level = if format.bit_depth == 8 { 255 } else { 65535 };
    let file = TruthFile {
        info: capture.info(),
        truth_time_s: t,
        video: options.video,
        stored_white_level,
        scene: &options.scene,
    };
    let json_path = dir.join("truth.json");
    let text = serde_json::to_string_pretty(&file).map_err(|e| encode_err(&json_path, e))?;
    std::fs::write(&json_path, text).map_err(|e| write_err(&json_path, e))
}
