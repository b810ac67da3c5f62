//! Headerless raw frames: width × height samples per frame, 8-bit or 16-bit little-endian,
//! from a file (whose size must be a whole number of frames) or any byte stream (standard
//! input, [`super::stdin`]), where a stream ending inside a frame is an error that names the
//! frame and how many of its bytes arrived, after the whole frames before it were delivered.

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

/// Raw frames read one at a time from `R` (a file unless said otherwise).
pub struct RawSource<R = BufReader<std::fs::File>> {
    format: FrameFormat,
    path: PathBuf,
    reader: R,
    /// Frames in the file; `None` for a stream of unknown length.
    frames: Option<usize>,
    index: usize,
    /// Bytes of the last 16-bit frame (storage reused).
    scratch: Vec<u8>,
}

/// Bytes of one frame of `layout`, after checking the layout.
fn frame_bytes(layout: RawLayout) -> Result<usize, CaptureError> {
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
    layout
        .width
        .checked_mul(layout.height)
        .and_then(|p| p.checked_mul(Samples::bytes_per_sample(layout.bit_depth)))
        .ok_or_else(|| {
            CaptureError::Other(format!(
                "raw layout {layout}: a frame is too large to address"
            ))
        })
}

impl RawSource {
    /// Opens `path` with the given layout; the file size must be a whole number of frames.
    pub fn open(path: &Path, layout: RawLayout, fps: f64) -> Result<Self, CaptureError> {
        let io = |source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        };
        let frame_bytes = frame_bytes(layout)?;
        let file = std::fs::File::open(path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len() as usize;
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
            reader: BufReader::with_capacity(1 << 20, file),
            frames: Some(size / frame_bytes),
            index: 0,
            scratch: Vec::new(),
        })
    }
}

impl<R: Read> RawSource<R> {
    /// Reads raw frames of `layout` from a stream of unknown length, named `path` in errors.
    pub fn from_stream(
        reader: R,
        path: &Path,
        layout: RawLayout,
        fps: f64,
    ) -> Result<Self, CaptureError> {
        frame_bytes(layout)?;
        Ok(Self {
            format: FrameFormat::full_range(layout.width, layout.height, layout.bit_depth, fps),
            path: path.to_path_buf(),
            reader,
            frames: None,
            index: 0,
            scratch: Vec::new(),
        })
    }
}

impl<R: Read + Send> FrameSource for RawSource<R> {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        super::next_frame_from_storage(self)
    }

    fn read_frame_into(&mut self, samples: &mut Samples) -> Result<Option<usize>, CaptureError> {
        if self.frames.is_some_and(|frames| self.index >= frames) {
            return Ok(None);
        }
        let pixels = self.format.pixels();
        let bytes = Samples::bytes_per_sample(self.format.bit_depth) * pixels;
        let got = super::read_plane(
            &mut self.reader,
            samples,
            &mut self.scratch,
            pixels,
            self.format.bit_depth,
            &self.path,
        )?;
        if got == 0 && self.frames.is_none() {
            return Ok(None);
        }
        if got < bytes {
            let index = self.index;
            return Err(CaptureError::Format {
                path: self.path.clone(),
                reason: format!(
                    "stream is truncated inside frame {index}: {got} of its {bytes} bytes \
                     arrived (the {index} frames before it are whole)"
                ),
            });
        }
        let index = self.index;
        self.index += 1;
        Ok(Some(index))
    }

    fn frame_count_hint(&self) -> Option<usize> {
        self.frames.map(|frames| frames - self.index)
    }
}
