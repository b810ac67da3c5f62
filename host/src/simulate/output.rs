//! Writing a simulated capture to disk: frames (PNG sequence, y4m, or MP4 through the
//! `ffmpeg` program) and the ground truth (`depth.npy`, `normals.npy`, `mask.png`,
//! `albedo.npy`, `led<i>_true.npy`, `rig.toml`, `truth.json`).
//!
//! Everything is written into a hidden temporary directory next to the destination and renamed
//! into place only when complete, so a failed or interrupted run never leaves a half-written
//! result under the requested name. Frames are rendered and written one at a time (bounded
//! memory). 10- and 12-bit samples are stored in 16-bit containers scaled to full range
//! (code · 65535 / (2^b − 1)); MP4 is lossless H.264 (`-qp 0`) in `gray` (8-bit) or `gray10le`.

use super::SimulateError;
use super::capture::{GroundTruth, SimulatedCapture, TruthInfo};
use crate::capture::{Frame, FrameFormat, FrameSource, Samples};
use crate::rig::Rig;
use image::{ImageBuffer, Luma};
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

fn write_err(path: &Path, e: impl std::fmt::Display) -> SimulateError {
    SimulateError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    }
}

/// A temporary output directory that becomes `target` on [`Self::commit`] and is deleted if
/// dropped before that.
#[derive(Debug)]
pub struct StagingDir {
    target: PathBuf,
    temp: PathBuf,
    force: bool,
    committed: bool,
}

impl StagingDir {
    /// Prepares a staging directory for `target`; refuses a non-empty `target` unless `force`.
    pub fn create(target: &Path, force: bool) -> Result<Self, SimulateError> {
        if target.exists() && !force {
            let empty = std::fs::read_dir(target)
                .map(|mut d| d.next().is_none())
                .unwrap_or(false);
            if !empty {
                return Err(SimulateError::OutputExists(target.to_path_buf()));
            }
        }
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "out".into());
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| write_err(&parent, e))?;
        let temp = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if temp.exists() {
            std::fs::remove_dir_all(&temp).map_err(|e| write_err(&temp, e))?;
        }
        std::fs::create_dir(&temp).map_err(|e| write_err(&temp, e))?;
        Ok(Self {
            target: target.to_path_buf(),
            temp,
            force,
            committed: false,
        })
    }

    /// Where to write meanwhile.
    pub fn path(&self) -> &Path {
        &self.temp
    }

    /// Moves the finished directory to its final name.
    pub fn commit(mut self) -> Result<PathBuf, SimulateError> {
        if self.target.exists() {
            if self.target.is_dir() {
                let removal = if self.force {
                    std::fs::remove_dir_all(&self.target)
                } else {
                    std::fs::remove_dir(&self.target)
                };
                removal.map_err(|e| write_err(&self.target, e))?;
            } else {
                return Err(SimulateError::OutputExists(self.target.clone()));
            }
        }
        std::fs::rename(&self.temp, &self.target).map_err(|e| write_err(&self.target, e))?;
        self.committed = true;
        Ok(self.target.clone())
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.temp);
        }
    }
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
                    .map_err(|e| SimulateError::Ffmpeg(e.to_string()))?;
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
                            .ok_or_else(|| write_err(&path, "frame size mismatch"))?;
                        img.save(&path).map_err(|e| write_err(&path, e))
                    }
                    samples => {
                        let img = ImageBuffer::<Luma<u16>, _>::from_raw(
                            w,
                            h,
                            stored_u16(format, samples),
                        )
                        .ok_or_else(|| write_err(&path, "frame size mismatch"))?;
                        img.save(&path).map_err(|e| write_err(&path, e))
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
                write_raw(stdin, format, &frame.samples)
                    .map_err(|e| SimulateError::Ffmpeg(format!("writing frames failed: {e}")))
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
                    .map_err(|e| SimulateError::Ffmpeg(e.to_string()))?;
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
    let npy = |name: &str, result: Result<(), ndarray_npy::WriteNpyError>| {
        result.map_err(|e| write_err(&dir.join(name), e))
    };
    npy(
        "depth.npy",
        ndarray_npy::write_npy(dir.join("depth.npy"), &truth.depth_mm),
    )?;
    npy(
        "normals.npy",
        ndarray_npy::write_npy(dir.join("normals.npy"), &truth.normals),
    )?;
    npy(
        "albedo.npy",
        ndarray_npy::write_npy(dir.join("albedo.npy"), &truth.albedo),
    )?;
    for (i, image) in truth.led_true.images.iter().enumerate() {
        let name = format!("led{}_true.npy", i + 1);
        npy(&name, ndarray_npy::write_npy(dir.join(&name), image))?;
    }
    write_mask(&dir.join("mask.png"), &truth.mask)?;
    let rig_path = dir.join("rig.toml");
    std::fs::write(&rig_path, rig.to_toml_string()).map_err(|e| write_err(&rig_path, e))
}

/// Writes a boolean mask as an 8-bit PNG (255 inside).
pub fn write_mask(path: &Path, mask: &ndarray::Array2<bool>) -> Result<(), SimulateError> {
    let (h, w) = mask.dim();
    let pixels: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    let img = ImageBuffer::<Luma<u8>, _>::from_raw(w as u32, h as u32, pixels)
        .ok_or_else(|| write_err(path, "mask size mismatch"))?;
    img.save(path).map_err(|e| write_err(path, e))
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
    /// Replace an existing non-empty output directory.
    pub force: bool,
    /// Scene description stored in `truth.json`.
    pub scene: serde_json::Value,
}

/// Renders every frame of `capture` and writes frames plus ground truth to `out`
/// atomically; `progress(done, total)` is called after each frame. Returns the final path.
pub fn write_capture(
    capture: &mut SimulatedCapture,
    out: &Path,
    options: &OutputOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PathBuf, SimulateError> {
    let staging = StagingDir::create(out, options.force)?;
    let dir = staging.path().to_path_buf();
    let format = capture.format().clone();
    let total = capture.info().frames;
    let mut writer = FrameWriter::open(&dir, options.video, &format)?;
    let mut done = 0;
    while let Some(frame) = capture.next_frame().map_err(|e| write_err(&dir, e))? {
        writer.write(&format, &frame)?;
        done += 1;
        progress(done, total);
    }
    writer.finish()?;
    let t = capture.frame_time(options.truth_frame);
    let truth = capture.truth_at(t);
    write_truth(&dir, &truth, capture.rig())?;
    let stored_white_level = if format.bit_depth == 8 { 255 } else { 65535 };
    let file = TruthFile {
        info: capture.info(),
        truth_time_s: t,
        video: options.video,
        stored_white_level,
        scene: &options.scene,
    };
    let json_path = dir.join("truth.json");
    let text = serde_json::to_string_pretty(&file).map_err(|e| write_err(&json_path, e))?;
    std::fs::write(&json_path, text).map_err(|e| write_err(&json_path, e))?;
    staging.commit()
}
