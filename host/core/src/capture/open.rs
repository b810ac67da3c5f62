//! Choosing a frame reader for a path: directory of frames, multi-page TIFF, y4m, raw, a
//! video container through FFmpeg, or `-` for a y4m or raw stream on standard input.

use super::ffmpeg::FfmpegSource;
use super::images::{ImageSequence, TiffStack};
use super::raw::{RawLayout, RawSource};
use super::y4m::Y4mSource;
use super::{CaptureError, FrameSource};
use std::path::Path;

/// How to open an input.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OpenOptions {
    /// Capture frame rate (overrides a container's; image sequences and raw files need it
    /// only for reporting the chip rate in Hz).
    pub fps: Option<f64>,
    /// Read the file as headerless raw frames with this layout.
    pub raw: Option<RawLayout>,
}

/// Opens `path` with the reader its kind calls for; `-` is standard input (a y4m stream, or
/// raw frames with `options.raw`).
pub fn open(path: &Path, options: &OpenOptions) -> Result<Box<dyn FrameSource>, CaptureError> {
    if super::stdin::is_stdin(path) {
        return super::stdin::open_stdin(options.raw, options.fps);
    }
    if !path.exists() {
        return Err(CaptureError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        });
    }
    let fps = options.fps.unwrap_or(0.0);
    if let Some(layout) = options.raw {
        return Ok(Box::new(RawSource::open(path, layout, fps)?));
    }
    if path.is_dir() {
        return Ok(Box::new(ImageSequence::open(path, fps)?));
    }
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    match extension.as_str() {
        "y4m" => Ok(Box::new(Y4mSource::open(path, options.fps)?)),
        "tif" | "tiff" => Ok(Box::new(TiffStack::open(path, fps)?)),
        "raw" | "bin" => Err(CaptureError::Other(format!(
            "{}: raw frames need their layout (width, height and bits per sample)",
            path.display()
        ))),
        _ => Ok(Box::new(FfmpegSource::open(path, options.fps)?)),
    }
}
