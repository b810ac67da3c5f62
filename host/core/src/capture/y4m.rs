//! YUV4MPEG2 (`.y4m`) reader: the luma plane of every frame, 8-bit or high bit depth
//! (`Cmono16`, `C420p10`, … stored little-endian in two bytes), from a file or any byte stream
//! (standard input, [`super::stdin`]). A stream ending inside a frame is an error that names
//! the frame and how many of its bytes arrived, not a short stream; the frames before it have
//! been delivered. FFmpeg's `XCOLORRANGE=LIMITED` marks limited ("tv") range: black
//! 16·2^(b−8), white 235·2^(b−8), as for video containers.

use super::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use std::io::{BufRead, BufReader, Read, Seek};
use std::path::{Path, PathBuf};

/// Longest header or frame-marker line read, bytes.
const MAX_LINE: u64 = 4096;
/// Read buffer of a file, bytes: smaller than a luma plane, so that the plane is read straight
/// into the frame's storage past it (only the marker line and the plane's first bytes are
/// copied through it).
const FILE_BUFFER: usize = 64 << 10;

/// Passes over `count` bytes (a frame's chroma planes) and returns how many there were (fewer
/// only at the end of the stream).
type SkipBytes<R> = fn(&mut R, usize) -> std::io::Result<usize>;

/// A y4m stream read one frame at a time from `R` (a file unless said otherwise).
pub struct Y4mSource<R = BufReader<std::fs::File>> {
    format: FrameFormat,
    path: PathBuf,
    reader: R,
    /// Bytes of chroma after the luma plane of each frame.
    chroma_bytes: usize,
    index: usize,
    /// The last frame-marker line (storage reused).
    line: Vec<u8>,
    /// Bytes of the last 16-bit luma plane (storage reused).
    scratch: Vec<u8>,
    /// How the chroma planes are passed over: a seek in a file, read and dropped in a stream.
    skip: SkipBytes<R>,
}

impl Y4mSource {
    /// Opens a y4m file; `fps` overrides the header's rate. The chroma planes of a regular
    /// file are seeked over, never read (a named pipe's are read and dropped).
    pub fn open(path: &Path, fps: Option<f64>) -> Result<Self, CaptureError> {
        let file = std::fs::File::open(path).map_err(|source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let regular = file.metadata().is_ok_and(|m| m.is_file());
        let mut source = Self::from_reader(BufReader::with_capacity(FILE_BUFFER, file), path, fps)?;
        if regular {
            source.skip = seek_over;
        }
        Ok(source)
    }
}

/// Seeks over `count` bytes of a file, up to its end.
fn seek_over(reader: &mut BufReader<std::fs::File>, count: usize) -> std::io::Result<usize> {
    let position = reader.stream_position()?;
    let len = reader.get_ref().metadata()?.len();
    let n = u64::try_from(count)
        .unwrap_or(u64::MAX)
        .min(len.saturating_sub(position));
    // n ≤ the file's length, far below i64::MAX.
    reader.seek_relative(n as i64)?;
    Ok(n as usize)
}

/// Reads and drops `count` bytes of a stream straight out of the reader's buffer (no copy).
fn consume_over<R: BufRead>(reader: &mut R, count: usize) -> std::io::Result<usize> {
    let mut skipped = 0;
    while skipped < count {
        let available = match reader.fill_buf() {
            Ok(buf) => buf.len(),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available == 0 {
            break;
        }
        let n = available.min(count - skipped);
        reader.consume(n);
        skipped += n;
    }
    Ok(skipped)
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
            line: Vec::new(),
            scratch: Vec::new(),
            skip: consume_over::<R>,
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
        super::next_frame_from_storage(self)
    }

    fn read_frame_into(&mut self, samples: &mut Samples) -> Result<Option<usize>, CaptureError> {
        let mut line = std::mem::take(&mut self.line);
        line.clear();
        let marker = (&mut self.reader)
            .take(MAX_LINE)
            .read_until(b'\n', &mut line)
            .map_err(|source| CaptureError::Io {
                path: self.path.clone(),
                source,
            });
        let marker_len = line.len();
        let complete = line.ends_with(b"\n");
        let is_frame = line.starts_with(b"FRAME");
        let partial_marker = b"FRAME".iter().zip(&line).all(|(a, b)| a == b);
        self.line = line;
        if marker? == 0 {
            return Ok(None);
        }
        if !complete && partial_marker {
            return Err(self.truncated(marker_len));
        }
        if !is_frame {
            return Err(CaptureError::Format {
                path: self.path.clone(),
                reason: format!("frame {}: missing FRAME marker", self.index),
            });
        }
        // The luma plane goes straight into the caller's storage (read_plane grows it only
        // as data arrives, so a bad header's size cannot allocate more than the stream holds).
        let pixels = self.format.pixels();
        let luma_bytes = Samples::bytes_per_sample(self.format.bit_depth) * pixels;
        let got = super::read_plane(
            &mut self.reader,
            samples,
            &mut self.scratch,
            pixels,
            self.format.bit_depth,
            &self.path,
        );
        match got {
            Ok(got) if got == luma_bytes => {}
            Ok(got) => return Err(self.truncated(marker_len + got)),
            Err(_) => return Err(self.truncated(marker_len)),
        }
        let skipped = (self.skip)(&mut self.reader, self.chroma_bytes).map_err(|source| {
            CaptureError::Io {
                path: self.path.clone(),
                source,
            }
        })?;
        if skipped != self.chroma_bytes {
            return Err(self.truncated(marker_len + luma_bytes + skipped));
        }
        let index = self.index;
        self.index += 1;
        Ok(Some(index))
    }
}
