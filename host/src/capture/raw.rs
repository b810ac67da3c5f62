//! Headerless raw frames: width × height samples per frame, 8-bit or 16-bit little-endian.

use super::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// Layout of a raw file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RawLayout {
    /// Frame width.
    pub width: usize,
    /// Frame height.
    pub height: usize,
    /// Bits per sample: 8 (one byte) or 9..=16 (two bytes, little-endian).
    pub bit_depth: u8,
}

impl std::fmt::Display for RawLayout {
    /// "1280x720, 8-bit", the `WxHxBITS` layout in words.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}, {}-bit", self.width, self.height, self.bit_depth)
    }
}

/// A raw frame file read one frame at a time.
pub struct RawSource {
    format: FrameFormat,
    path: PathBuf,
    reader: BufReader<std::fs::File>,
    frames: usize,
    index: usize,
}

impl RawSource {
    /// Opens `path` with the given layout; the file size must be a whole number of frames.
    pub fn open(path: &Path, layout: RawLayout, fps: f64) -> Result<Self, CaptureError> {
        let io = |source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        };
        if layout.width == 0 || layout.height == 0 {
            return Err(CaptureError::Other(format!(
                "raw layout {layout}: width and height must be at least 1"
            )));
        }
        if !(1..=16).contains(&layout.bit_depth) {
            return Err(CaptureError::Other(format!(
                "raw layout {layout}: bits per sample must be 1 to 16"
            )));
        }
        let file = std::fs::File::open(path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len() as usize;
        let frame_bytes = layout
            .width
            .checked_mul(layout.height)
            .and_then(|p| p.checked_mul(Samples::bytes_per_sample(layout.bit_depth)))
            .ok_or_else(|| {
                CaptureError::Other(format!(
                    "raw layout {layout}: a frame is too large to address"
                ))
            })?;
        if !size.is_multiple_of(frame_bytes) {
            return Err(CaptureError::Format {
                path: path.to_path_buf(),
                reason: format!(
                    "size {size} bytes is not a whole number of {}x{} frames ({frame_bytes} bytes): truncated or wrong size",
                    layout.width, layout.height
                ),
            });
        }
        Ok(Self {
            format: FrameFormat::full_range(layout.width, layout.height, layout.bit_depth, fps),
            path: path.to_path_buf(),
            reader: BufReader::new(file),
            frames: size / frame_bytes,
            index: 0,
        })
    }
}

impl FrameSource for RawSource {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        if self.index >= self.frames {
            return Ok(None);
        }
        let pixels = self.format.pixels();
        let io = |source| CaptureError::Io {
            path: self.path.clone(),
            source,
        };
        let mut bytes = vec![0u8; Samples::bytes_per_sample(self.format.bit_depth) * pixels];
        self.reader.read_exact(&mut bytes).map_err(io)?;
        let samples = Samples::from_le_bytes(bytes, self.format.bit_depth);
        let frame = Frame {
            index: self.index,
            samples,
        };
        self.index += 1;
        Ok(Some(frame))
    }

    fn frame_count_hint(&self) -> Option<usize> {
        Some(self.frames - self.index)
    }
}
