//! YUV4MPEG2 (`.y4m`) reader: the luma plane of every frame, 8-bit or high bit depth
//! (`Cmono16`, `C420p10`, … stored little-endian in two bytes). A file ending inside a frame is
//! an error, not a short stream. FFmpeg's `XCOLORRANGE=LIMITED` marks limited ("tv") range:
//! black 16·2^(b−8), white 235·2^(b−8), as for video containers.

use super::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

/// A y4m stream read one frame at a time.
pub struct Y4mSource {
    format: FrameFormat,
    path: PathBuf,
    reader: BufReader<std::fs::File>,
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
        let mut reader = BufReader::new(file);
        let mut header = String::new();
        reader
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

impl FrameSource for Y4mSource {
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
        let n = self.reader.read_until(b'\n', &mut line).map_err(io)?;
        if n == 0 {
            return Ok(None);
        }
        if !line.starts_with(b"FRAME") {
            return Err(CaptureError::Format {
                path,
                reason: format!("frame {}: missing FRAME marker", self.index),
            });
        }
        let truncated = |index| CaptureError::Format {
            path: self.path.clone(),
            reason: format!("file is truncated inside frame {index}"),
        };
        let pixels = self.format.pixels();
        let sample_bytes = Samples::bytes_per_sample(self.format.bit_depth);
        // Read up to one luma plane, growing the buffer as data arrives, so a bad header's
        // size cannot allocate more than the file holds.
        let mut bytes = Vec::new();
        (&mut self.reader)
            .take((sample_bytes * pixels) as u64)
            .read_to_end(&mut bytes)
            .map_err(|_| truncated(self.index))?;
        if bytes.len() != sample_bytes * pixels {
            return Err(truncated(self.index));
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
            return Err(truncated(self.index));
        }
        let frame = Frame {
            index: self.index,
            samples,
        };
        self.index += 1;
        Ok(Some(frame))
    }
}
