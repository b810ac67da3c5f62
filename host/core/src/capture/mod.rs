//! Frame sources: the camera side of the pipeline.
//!
//! Every source (image sequences, y4m, raw files, video containers through FFmpeg, and the
//! simulator) yields greyscale [`Frame`]s in the camera's native code values together with a
//! [`FrameFormat`] that says how code values map to light: `(code - black) / (white - black)` is
//! the fraction of full scale. Limited-range ("tv") video has black 16 and white 235 at 8 bits.

use thiserror::Error;

/// Lossy compression of a stored capture, as its container states it: the codec's
/// quantisation removes part of the camera's noise and can bend a modulation of a few code
/// values, so the decoder's noise estimate no longer bounds its error.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossyCompression {
    /// Codec name as FFmpeg reports it (`h264`, `hevc`, `vp9`, `av1`, `mjpeg`, …).
    pub codec: String,
    /// Coded bits per pixel and frame (the stream's bit rate over width·height·fps), when the
    /// container states a bit rate.
    pub bits_per_pixel: Option<f64>,
}

impl LossyCompression {
    /// The compression in words, e.g. "h264 at 0.0046 bits per pixel".
    pub fn describe(&self) -> String {
        match self.bits_per_pixel {
            Some(bpp) => format!("{} at {bpp:.2e} bits per pixel", self.codec),
            None => format!("{} (lossy)", self.codec),
        }
    }
}

/// Geometry, depth and timing of a frame stream.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameFormat {
    /// Frame width in pixels.
    pub width: usize,
    /// Frame height in pixels.
    pub height: usize,
    /// Bits per sample (8, 10, 12 or 16).
    pub bit_depth: u8,
    /// Code value of zero light.
    pub black_level: f32,
    /// Code value of full scale.
    pub white_level: f32,
    /// Capture frame rate in frames per second.
    pub fps: f64,
}

impl FrameFormat {
    /// Full-range format: black 0, white 2^bits − 1.
    pub fn full_range(width: usize, height: usize, bit_depth: u8, fps: f64) -> Self {
        Self {
            width,
            height,
            bit_depth,
            black_level: 0.0,
            white_level: ((1u32 << bit_depth) - 1) as f32,
            fps,
        }
    }

    /// The first saturated code: the last code that rounds to white, ⌈white − ½⌉ (u32::MAX
    /// when white is beyond the code range).
    pub fn saturated_from(&self) -> u32 {
        let white = (f64::from(self.white_level) - 0.5).ceil().max(0.0);
        white.min(f64::from(u32::MAX)) as u32
    }

    /// Converts a code value to a fraction of full scale.
    pub fn to_fraction(&self, code: f32) -> f32 {
        (code - self.black_level) / (self.white_level - self.black_level)
    }

    /// Number of pixels in one frame.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}

/// Native sample storage of one frame, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// 8-bit samples.
    U8(Vec<u8>),
    /// 10/12/16-bit samples (low bits used).
    U16(Vec<u16>),
}

impl Samples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        match self {
            Self::U8(v) => v.len(),
            Self::U16(v) => v.len(),
        }
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes one sample takes in a little-endian stream of `bit_depth`-bit samples: 1 up to
    /// 8 bits, else 2.
    pub fn bytes_per_sample(bit_depth: u8) -> usize {
        if bit_depth > 8 { 2 } else { 1 }
    }

    /// Samples from a little-endian byte stream of `bit_depth`-bit samples (y4m, raw files,
    /// FFmpeg's `gray`/`gray16le` output): bytes as they are up to 8 bits, byte pairs above
    /// (a trailing odd byte is ignored).
    pub fn from_le_bytes(bytes: Vec<u8>, bit_depth: u8) -> Self {
        if Self::bytes_per_sample(bit_depth) == 1 {
            Self::U8(bytes)
        } else {
            Self::U16(
                bytes
                    .chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]]))
                    .collect(),
            )
        }
    }

    /// Sample `i` as a code value.
    pub fn code(&self, i: usize) -> f32 {
        match self {
            Self::U8(v) => f32::from(v[i]),
            Self::U16(v) => f32::from(v[i]),
        }
    }
}

/// One greyscale frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Index of this frame in its source (after any `--start` offset).
    pub index: usize,
    /// The samples, `format.width * format.height` of them.
    pub samples: Samples,
}

/// Errors reading frames.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CaptureError {
    /// An I/O error on a named file.
    #[error("cannot read {path}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file whose content is not what its format promises.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An image file the codec cannot decode.
    #[error("{path}: cannot decode the image")]
    Decode {
        /// The file.
        path: std::path::PathBuf,
        /// The codec's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A frame whose size differs from the stream's.
    #[error("frame {index} is {got_width}x{got_height}, expected {width}x{height}")]
    SizeMismatch {
        /// Frame index.
        index: usize,
        /// Size of the offending frame.
        got_width: usize,
        /// Size of the offending frame.
        got_height: usize,
        /// Size of the stream.
        width: usize,
        /// Size of the stream.
        height: usize,
    },
    /// A container whose timestamps put frames no whole number of frame periods apart: a
    /// variable frame rate, which the decoder's frame clock cannot model.
    #[error(
        "{path}: the container's timestamps show a variable frame rate: frame {frame} comes \
         {periods:.2} frame periods (of {period_ms:.3} ms) after the one before, and the \
         carriers can only be decoded from frames taken at a constant rate; record at a fixed \
         frame rate (on a phone: a slow-motion mode without speed ramps), or give --fps if the \
         frames were taken at a constant rate and only their timestamps are irregular"
    )]
    IrregularFrameTimes {
        /// The file.
        path: std::path::PathBuf,
        /// The frame after the first irregular interval.
        frame: usize,
        /// That interval in frame periods.
        periods: f64,
        /// The median frame period, milliseconds.
        period_ms: f64,
    },
    /// Anything else that makes the source unusable.
    #[error("{0}")]
    Other(String),
}

/// Reads from `reader` until `buf` is full or the stream ends, and returns the bytes read
/// (fewer than `buf.len()` only at the end of the stream); `path` names the stream in errors.
pub(crate) fn read_up_to(
    reader: &mut impl std::io::Read,
    buf: &mut [u8],
    path: &std::path::Path,
) -> Result<usize, CaptureError> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(source) => {
                return Err(CaptureError::Io {
                    path: path.to_path_buf(),
                    source,
                });
            }
        }
    }
    Ok(filled)
}

/// A stream of frames (`Send`, so a reader thread can run ahead of the consumer).
pub trait FrameSource: Send {
    /// The stream's format.
    fn format(&self) -> &FrameFormat;
    /// The next frame, or `None` at the end of the stream.
    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError>;
    /// Number of frames not yet read, when the source knows it.
    fn frame_count_hint(&self) -> Option<usize> {
        None
    }
    /// The lossy compression the frames went through, when the source knows it (`None` for
    /// uncompressed and losslessly compressed sources).
    fn lossy_compression(&self) -> Option<LossyCompression> {
        None
    }
    /// Frame periods the container's timestamps show missing ([`clock`]); empty when the
    /// source has no timestamps or they show none.
    fn timestamp_gaps(&self) -> Vec<clock::TimestampGap> {
        Vec::new()
    }
    /// Reads the next frame into `samples`, reusing its storage where the source can (a y4m
    /// or raw stream reads the luma plane straight into it), and returns the frame's index, or
    /// `None` at the end of the stream (`samples` is then unchanged).
    fn read_frame_into(&mut self, samples: &mut Samples) -> Result<Option<usize>, CaptureError> {
        Ok(self.next_frame()?.map(|frame| {
            *samples = frame.samples;
            frame.index
        }))
    }
}

/// A new [`Frame`] from [`FrameSource::read_frame_into`]: `next_frame` for sources whose
/// reading goes into caller storage.
pub fn next_frame_from_storage<S: FrameSource + ?Sized>(
    source: &mut S,
) -> Result<Option<Frame>, CaptureError> {
    let mut samples = Samples::U8(Vec::new());
    Ok(source
        .read_frame_into(&mut samples)?
        .map(|index| Frame { index, samples }))
}

/// Fills `samples` with one plane of `count` little-endian `bit_depth`-bit samples from
/// `reader`, reusing the storage of `samples` and of `scratch` (the bytes of a 16-bit plane),
/// and returns how many bytes arrived: fewer than a plane only at the end of the stream. A
/// plane larger than the storage already held is grown as data arrives, so a bad header's size
/// cannot allocate more than the stream holds.
pub(crate) fn read_plane(
    reader: &mut impl std::io::Read,
    samples: &mut Samples,
    scratch: &mut Vec<u8>,
    count: usize,
    bit_depth: u8,
    path: &std::path::Path,
) -> Result<usize, CaptureError> {
    let bytes = Samples::bytes_per_sample(bit_depth) * count;
    if bit_depth <= 8 {
        if !matches!(samples, Samples::U8(_)) {
            *samples = Samples::U8(Vec::new());
        }
        let Samples::U8(plane) = samples else {
            unreachable!("set to 8-bit samples above")
        };
        fill(reader, plane, bytes, path)
    } else {
        let got = fill(reader, scratch, bytes, path)?;
        if got == bytes {
            if !matches!(samples, Samples::U16(_)) {
                *samples = Samples::U16(Vec::new());
            }
            let Samples::U16(plane) = samples else {
                unreachable!("set to 16-bit samples above")
            };
            plane.clear();
            plane.extend(
                scratch
                    .chunks_exact(2)
                    .map(|b| u16::from_le_bytes([b[0], b[1]])),
            );
        }
        Ok(got)
    }
}

/// Reads `len` bytes into `buf` (its storage reused; grown as data arrives when it is
/// smaller); returns the bytes that arrived.
fn fill(
    reader: &mut impl std::io::Read,
    buf: &mut Vec<u8>,
    len: usize,
    path: &std::path::Path,
) -> Result<usize, CaptureError> {
    if buf.capacity() >= len {
        buf.resize(len, 0);
        let got = read_up_to(reader, buf, path)?;
        buf.truncate(got);
        return Ok(got);
    }
    buf.clear();
    std::io::Read::read_to_end(&mut std::io::Read::take(reader, len as u64), buf).map_err(
        |source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        },
    )
}

pub mod binning;
pub mod clock;
pub mod ffmpeg;
pub mod images;
pub mod memory;
pub mod open;
pub mod raw;
pub mod stdin;
pub mod y4m;

pub use open::{OpenOptions, open};

/// Code-value limits that classify a pixel by its brightest frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CodeLimits {
    /// Codes at or above this are saturated.
    pub white: u32,
    /// A pixel whose largest code is below this is under-exposed.
    pub dark: u32,
}

impl CodeLimits {
    /// Limits for a stream: saturated from `white_level − ½` (the last code that rounds to
    /// white), under-exposed below `black + below·(white − black)`.
    pub fn new(format: &FrameFormat, underexposed_below: f32) -> Self {
        let black = f64::from(format.black_level);
        let dark = (black
            + f64::from(underexposed_below) * (f64::from(format.white_level) - black))
            .ceil()
            .max(0.0);
        Self {
            white: format.saturated_from(),
            dark: dark.min(f64::from(u32::MAX)) as u32,
        }
    }

    /// (saturated, under-exposed) for a pixel whose largest code is `max_code`.
    #[inline(always)]
    pub fn classify(&self, max_code: u16) -> (bool, bool) {
        let code = u32::from(max_code);
        (code >= self.white, code < self.dark)
    }
}
