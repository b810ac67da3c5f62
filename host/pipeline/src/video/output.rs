//! A video run's output folder: per-3-D-frame arrays, the depth and shaded videos, and
//! `video.json`.
//!
//! Per window k: `depth_kkkkk.npy` (H×W mm, NaN off the surface) and, when asked,
//! `normals_kkkkk.npy` (H×W×3) and `albedo_kkkkk.npy`; windows without a reconstruction get
//! no arrays and a blank picture in the videos, so the videos keep the 3-D frame rate.
//! The videos are MP4 through FFmpeg, or animated PNGs when FFmpeg is not installed
//! ([`super::encode`]); `video.json`'s `outputs` names the container and, for the fallback,
//! why. `video.json` holds the settings, the summary, the mean stage timings and one record per
//! window ([`FrameRecord`]): which frames it used, what became of it and why, its motion,
//! decoder and reconstruction figures, accuracy against the truth and timing. Records are
//! appended to a hidden file as they come (memory does not grow with the clip) and copied
//! into `video.json` at the end.
//!
//! The folder is the caller's [`OutputFolder`](meb_core::io::OutputFolder): written
//! in a temporary place and put in place whole. Each array is synced to disk as it is written
//! (on the writer's thread, [`super::writer`]), so the folder's final sync, which the run
//! waits for, has only `video.json` and the videos left.

use super::encode::{VideoContainer, VideoEncoder};
use super::render::{PictureSize, blank_picture, depth_range, pictures};
use super::{FrameRecord, FrameStatus, FrameTiming, VideoError, VideoFrame, VideoSummary};
use meb_core::io::{FilesError, write_npy_synced};
use ndarray::{Array2, Array3};
use serde::{Deserialize, Serialize};
use std::io::{BufRead, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Name of the hidden file the records go to while the video runs.
const RECORDS: &str = ".video-frames.jsonl";

/// What to write besides depth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputOptions {
    /// Write `normals_kkkkk.npy`.
    pub normals: bool,
    /// Write `albedo_kkkkk.npy`.
    pub albedo: bool,
    /// Largest width of the video pictures, pixels (0 = the camera's).
    pub video_width: usize,
    /// Depth range of the colour video, mm; default from the first 3-D frame.
    pub depth_range: Option<(f32, f32)>,
    /// Video container.
    pub container: VideoContainer,
    /// Display rate of the videos, 3-D frames per second.
    pub display_fps: f64,
}

impl Default for OutputOptions {
    fn default() -> Self {
        Self {
            normals: false,
            albedo: false,
            video_width: 640,
            depth_range: None,
            container: VideoContainer::Auto,
            display_fps: 25.0,
        }
    }
}

/// The files a finished run wrote, relative to its folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WrittenVideo {
    /// The colour-mapped depth video.
    pub depth_video: Option<String>,
    /// The shaded-render video.
    pub shaded_video: Option<String>,
    /// Depth range of the colour video, mm.
    pub depth_range_mm: Option<(f32, f32)>,
    /// 3-D frames with arrays.
    pub frames_written: usize,
    /// Container of both videos: `"mp4"` (FFmpeg) or `"apng"` (animated PNG).
    pub video_container: String,
    /// Why the videos are APNG when MP4 was asked for (FFmpeg missing); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video_fallback: Option<String>,
}

/// Mean time per window of each stage, ms.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanTiming {
    /// Windows averaged.
    pub windows: usize,
    /// The mean of every stage (the reconstruction's own stages are left out).
    #[serde(flatten)]
    pub mean: FrameTiming,
}

impl MeanTiming {
    fn add(&mut self, record: &FrameRecord) {
        let t = &record.timing;
        let n = self.windows as f64;
        let m = &mut self.mean;
        for (mean, x) in [
            (&mut m.read_ms, t.read_ms),
            (&mut m.wait_ms, t.wait_ms),
            (&mut m.decode_ms, t.decode_ms),
            (&mut m.motion_ms, t.motion_ms),
            (&mut m.reconstruct_ms, t.reconstruct_ms),
            (&mut m.compare_ms, t.compare_ms),
            (&mut m.write_ms, t.write_ms),
        ] {
            *mean = (*mean * n + x) / (n + 1.0);
        }
        self.windows += 1;
    }
}

/// One window's record and arrays, as [`VideoOutput::add_arrays`] writes them.
#[derive(Debug)]
pub struct FrameArrays<'a> {
    /// The window's record.
    pub record: FrameRecord,
    /// Depth, mm (a reconstructed window).
    pub depth: Option<&'a Array2<f32>>,
    /// Normals (H×W×3), written when the options ask for them.
    pub normals: Option<&'a Array3<f32>>,
    /// Albedo, written when the options ask for it.
    pub albedo: Option<&'a Array2<f32>>,
}

/// Writes `array` as `.npy` at `path` and waits until it is on disk (past the page cache:
/// [`meb_core::io::direct`]).
fn write_synced<D: ndarray::Dimension>(
    path: &Path,
    array: &ndarray::Array<f32, D>,
) -> Result<(), VideoError> {
    Ok(write_npy_synced(path, array)?)
}

/// Writes a run's outputs into `dir` as windows arrive (module docs).
pub struct VideoOutput {
    dir: PathBuf,
    options: OutputOptions,
    size: PictureSize,
    pitch_mm: f64,
    range: Option<(f32, f32)>,
    /// The depth video and the shaded one, written together.
    videos: VideoEncoder,
    records: BufWriter<std::fs::File>,
    timing: MeanTiming,
    accuracy: Vec<f64>,
    written: usize,
}

impl VideoOutput {
    /// Starts the outputs of a camera of `width` × `height` pixels at `pitch_mm` in `dir`.
    pub fn create(
        dir: &Path,
        width: usize,
        height: usize,
        pitch_mm: f64,
        options: OutputOptions,
    ) -> Result<Self, VideoError> {
        let size = PictureSize::fit(width, height, options.video_width);
        let (w, h) = (size.width as u32, size.height as u32);
        let videos = VideoEncoder::create(
            &[dir.join("depth"), dir.join("shaded")],
            w,
            h,
            options.display_fps,
            options.container,
        )?;
        let path = dir.join(RECORDS);
        let records = std::fs::File::create(&path).map_err(|e| FilesError::write(&path, e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            range: options.depth_range,
            options,
            size,
            pitch_mm,
            videos,
            records: BufWriter::new(records),
            timing: MeanTiming::default(),
            accuracy: Vec::new(),
            written: 0,
        })
    }

    /// Writes one window's arrays, pictures and record.
    pub fn add(&mut self, frame: &VideoFrame) -> Result<(), VideoError> {
        let reconstruction = frame
            .reconstruction
            .filter(|_| frame.record.status == FrameStatus::Reconstructed);
        let normals = reconstruction
            .filter(|_| self.options.normals)
            .map(|r| r.normals());
        let albedo = reconstruction
            .filter(|_| self.options.albedo)
            .map(|r| r.albedo());
        self.add_arrays(FrameArrays {
            record: frame.record.clone(),
            depth: reconstruction.map(|r| r.depth_mm()),
            normals: normals.as_deref(),
            albedo: albedo.as_deref(),
        })
    }

    /// Writes one window's arrays (those of a reconstructed window; `None` for the others),
    /// pictures and record. Each array is on disk (`fsync`) when this returns, so the folder's
    /// final sync has little left to do.
    pub fn add_arrays(&mut self, frame: FrameArrays<'_>) -> Result<(), VideoError> {
        let started = Instant::now();
        let mut record = frame.record;
        let k = record.index;
        match frame.depth {
            Some(depth) => {
                write_synced(&self.dir.join(format!("depth_{k:05}.npy")), depth)?;
                if let Some(normals) = frame.normals.filter(|_| self.options.normals) {
                    write_synced(&self.dir.join(format!("normals_{k:05}.npy")), normals)?;
                }
                if let Some(albedo) = frame.albedo.filter(|_| self.options.albedo) {
                    write_synced(&self.dir.join(format!("albedo_{k:05}.npy")), albedo)?;
                }
                if self.range.is_none() {
                    self.range = depth_range(depth);
                }
                let (lo, hi) = self.range.unwrap_or((0.0, 1.0));
                let drawn = pictures(depth, self.size, self.pitch_mm, lo, hi);
                self.videos.push(&[&drawn.depth, &drawn.shaded])?;
                self.written += 1;
            }
            None => {
                let blank = blank_picture(self.size);
                self.videos.push(&[&blank, &blank])?;
            }
        }
        record.timing.write_ms = started.elapsed().as_secs_f64() * 1e3;
        if let Some(rmse) = record.accuracy.as_ref().and_then(|a| a.rmse_mm) {
            self.accuracy.push(rmse);
        }
        self.timing.add(&record);
        let path = self.dir.join(RECORDS);
        let line = serde_json::to_string(&record).map_err(|e| FilesError::Encode {
            path: path.clone(),
            source: Box::new(e),
        })?;
        writeln!(self.records, "{line}").map_err(|e| FilesError::write(&path, e))?;
        Ok(())
    }

    /// What to write besides depth.
    pub fn options(&self) -> &OutputOptions {
        &self.options
    }

    /// Mean stage timings so far.
    pub fn timing(&self) -> &MeanTiming {
        &self.timing
    }

    /// Closes the videos and writes `video.json` with `settings` (any JSON object: input,
    /// rig, schedule …) and `summary`.
    pub fn finish(
        mut self,
        settings: serde_json::Value,
        summary: &VideoSummary,
    ) -> Result<WrittenVideo, VideoError> {
        let records_path = self.dir.join(RECORDS);
        self.records
            .flush()
            .map_err(|e| FilesError::write(&records_path, e))?;
        let name = |p: Option<PathBuf>| {
            p.and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        };
        let video_container = self.videos.container().to_string();
        let video_fallback = self.videos.fallback().map(str::to_string);
        let mut videos = self.videos.finish()?.into_iter();
        let written = WrittenVideo {
            video_container,
            video_fallback,
            depth_video: name(videos.next().flatten()),
            shaded_video: name(videos.next().flatten()),
            depth_range_mm: self.range,
            frames_written: self.written,
        };
        let accuracy = accuracy_summary(&mut self.accuracy);
        let head = serde_json::json!({
            "schema": "meb-video v1",
            "settings": settings,
            "summary": summary,
            "outputs": written,
            "mean_timing_ms": self.timing,
            "accuracy": accuracy,
        });
        let path = self.dir.join("video.json");
        let encode = |e: serde_json::Error| FilesError::Encode {
            path: path.clone(),
            source: Box::new(e),
        };
        let mut text = serde_json::to_string_pretty(&head).map_err(encode)?;
        // Append the records as the "frames" array, one line each, streaming from the file.
        text.truncate(text.trim_end().trim_end_matches('}').trim_end().len());
        let file = std::fs::File::create(&path).map_err(|e| FilesError::write(&path, e))?;
        let mut out = BufWriter::new(file);
        let write = |out: &mut BufWriter<std::fs::File>, s: &str| {
            out.write_all(s.as_bytes())
                .map_err(|e| FilesError::write(&path, e))
        };
        write(&mut out, &text)?;
        write(&mut out, ",\n  \"frames\": [")?;
        let records =
            std::fs::File::open(&records_path).map_err(|e| FilesError::read(&records_path, e))?;
        for (i, line) in std::io::BufReader::new(records).lines().enumerate() {
            let line = line.map_err(|e| FilesError::read(&records_path, e))?;
            write(&mut out, if i == 0 { "\n    " } else { ",\n    " })?;
            write(&mut out, &line)?;
        }
        write(&mut out, "\n  ]\n}\n")?;
        out.flush().map_err(|e| FilesError::write(&path, e))?;
        drop(out);
        std::fs::remove_file(&records_path).map_err(|e| FilesError::write(&records_path, e))?;
        Ok(written)
    }
}

/// Median, minimum and maximum of the per-frame depth RMSE, mm (`null` without truth).
fn accuracy_summary(rmse: &mut [f64]) -> serde_json::Value {
    if rmse.is_empty() {
        return serde_json::Value::Null;
    }
    rmse.sort_by(f64::total_cmp);
    serde_json::json!({
        "frames": rmse.len(),
        "rmse_mm_min": rmse[0],
        "rmse_mm_median": rmse[rmse.len() / 2],
        "rmse_mm_max": rmse[rmse.len() - 1],
    })
}
