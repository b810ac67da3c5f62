//! YUV4MPEG2 (`.y4m`) reader: the luma plane of every frame, 8-bit or high bit depth
//! (`Cmono16`, `C420p10`, … stored little-endian in two bytes), from a file or any byte stream
//! (standard input, [`super::stdin`]). A stream ending inside a frame is an error that names
//! the frame and how many of its bytes arrived, not a short stream; the frames before it have
//! been delivered. FFmpeg's `XCOLORRANGE=LIMITED` marks limited ("tv") range: black
//! 16·2^(b−8), white 235·2^(b−8), as for video containers.

use super::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// Longest header or frame-marker line read, bytes.
const MAX_LINE: u64 = 4096;

/// A y4m stream read one frame at a time from `R` (a file unless said otherwise).
pub struct Y4mSource<R = BufReader<std::fs::File>> {
    format: FrameFormat,
    path: PathBuf,
    reader: R,
    /// Bytes of chroma after the luma plane of each frame.
    chroma_bytes: usize,
    index: usize,
}

impl Y4mSource {
    /// Opens a y4m file; `fps` overrides the header's rate.
    pub fn open(path: &Path, fps: Option<f64>) -> Result<Self, CaptureError> {
        let file = std::fs::File::open(path).map_err(|source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_reader(BufReader::with_capacity(1 << 20, file), path, fps)
    }
}

impl<R: BufRead> Y4mSource<R> {
    /// Reads a y4m stream from `reader`, named `path` in errors; `fps` overrides the header's
    /// rate.
    pub fn from_reader(mut reader: R, path: &Path, fps: Option<f64>) -> Result<Self, CaptureError> {
        let mut header = String::new();
        // A header is a short text line: a stream that is no y4m cannot make this read grow.
        (&mut reader)
            .take(MAX_LINE)
            .read_line(&mut header)
            .map_err(|source| CaptureError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        let bad = |reason: String| CaptureError::Format {
            path: path.to_path_buf(),
            reason,
        };
        let mut words = header.split_ascii_whitespace();
        if words.next() != Some("YUV4MPEG2") {
            return Err(bad("not a YUV4MPEG2 file".into()));
        }
        let (mut width, mut height, mut rate, mut colour) = (0usize, 0usize, 0.0f64, "420jpeg");
        let mut limited_range = false;
        for word in words {
            let (tag, value) = word.split_at(1);
            match tag {
                "W" => {
                    width = value
                        .parse()
                        .map_err(|_| bad(format!("bad width {value}")))?
                }
                "H" => {
                    height = value
                        .parse()
                        .map_err(|_| bad(format!("bad height {value}")))?
                }
                "F" => {
                    let (num, den) = value.split_once(':').unwrap_or((value, "1"));
                    let num: f64 = num.parse().map_err(|_| bad(format!("bad rate {value}")))?;
                    let den: f64 = den.parse().map_err(|_| bad(format!("bad rate {value}")))?;
                    rate = if den > 0.0 { num / den } else { 0.0 };
                }
                "C" => colour = value,
                "X" if value == "COLORRANGE=LIMITED" => limited_range = true,
                _ => {}
            }
        }
        if width == 0 || height == 0 {
            return Err(bad("missing frame size".into()));
        }
        let bits: u8 = colour
            .split_once('p')
            .and_then(|(_, b)| b.parse().ok())
            .or_else(|| colour.strip_prefix("mono").and_then(|b| b.parse().ok()))
            .unwrap_or(8);
        if !(8..=16).contains(&bits) {
            return Err(bad(format!("unsupported bit depth {bits} (C{colour})")));
        }
        let pixels = width
            .checked_mul(height)
            .filter(|p| p.checked_mul(6).is_some())
            .ok_or_else(|| bad(format!("frame size {width}x{height} is too large")))?;
        let chroma_pixels = if colour.starts_with("mono") {
            0
        } else if colour.starts_with("444") {
            2 * pixels
        } else if colour.starts_with("422") {
            2 * (width.div_ceil(2) * height)
        } else {
            2 * (width.div_ceil(2) * height.div_ceil(2))
        };
        let sample_bytes = if bits > 8 { 2 } else { 1 };
        let mut format = FrameFormat::full_range(width, height, bits, fps.unwrap_or(rate));
        if limited_range {
            let scale = f32::from(1u16 << (bits - 8));
            format.black_level = 16.0 * scale;
            format.white_level = 235.0 * scale;
        }
        Ok(Self {
            format,
            path: path.to_path_buf(),
            reader,
            chroma_bytes: chroma_pixels * sample_bytes,
            index: 0,
        })
    }
}

impl<R> Y4mSource<R> {
    /// The error for a stream that ends after `got` bytes of the current frame (marker
    /// line included): it names the frame and says the ones before it are whole.
    fn truncated(&self, got: usize) -> CaptureError {
        let index = self.index;
        let pixels = self.format.pixels();
        let frame_bytes = "FRAME\n".len()
            + Samples::bytes_per_sample(self.format.bit_depth) * pixels
            + self.chroma_bytes;
        CaptureError::Format {
            path: self.path.clone(),
            reason: format!(
                "stream is truncated inside frame {index}: {got} of its {frame_bytes} bytes \
                 arrived (the {index} frames before it are whole)"
            ),
        }
    }
}

impl<R: BufRead + Send> FrameSource for Y4mSource<R> {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        let path = self.path.clone();
        let io = |source| CaptureError::Io {
            path: path.clone(),
            source,
        };
        let mut line = Vec::new();
        let n = (&mut self.reader)
            .take(MAX_LINE)
            .read_until(b'\n', &mut line)
            .map_err(io)?;
        if n == 0 {
            return Ok(None);
        }
        if !line.ends_with(b"\n") && b"FRAME".iter().zip(&line).all(|(a, b)| a == b) {
            return Err(self.truncated(line.len()));
        }
        if !line.starts_with(b"FRAME") {
            return Err(CaptureError::Format {
                path,
                reason: format!("frame {}: missing FRAME marker", self.index),
            });
        }
        let pixels = self.format.pixels();
        let sample_bytes = Samples::bytes_per_sample(self.format.bit_depth);
        // Read up to one luma plane into a buffer reserved for at most 64 MiB and grown as
        // data arrives beyond that, so a bad header's size cannot allocate more than the
        // stream holds.
        let luma_bytes = sample_bytes * pixels;
        let mut bytes = Vec::with_capacity(luma_bytes.min(1 << 26));
        let luma = (&mut self.reader)
            .take(luma_bytes as u64)
            .read_to_end(&mut bytes);
        if luma.is_err() || bytes.len() != luma_bytes {
            return Err(self.truncated(line.len() + bytes.len()));
        }
        let samples = Samples::from_le_bytes(bytes, self.format.bit_depth);
        let skipped = std::io::copy(
            &mut (&mut self.reader).take(self.chroma_bytes as u64),
            &mut std::io::sink(),
        )
        .map_err(|source| CaptureError::Io {
            path: self.path.clone(),
            source,
        })?;
        if skipped != self.chroma_bytes as u64 {
            return Err(self.truncated(line.len() + luma_bytes + skipped as usize));
        }
        let frame = Frame {
            index: self.index,
            samples,
        };
        self.index += 1;
        Ok(Some(frame))
    }
}
