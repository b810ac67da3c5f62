//! Image-sequence sources: a directory of PNG/TIFF frames sorted by name, and a multi-page TIFF.
//!
//! Names sort naturally: runs of digits compare as numbers, so `frame10.png` follows
//! `frame9.png` whether or not the numbers are zero-padded.
//!
//! Colour frames are converted to luma (Rec. 709 weights, as the `image` crate does); 16-bit
//! files stay 16-bit (reading them as 8-bit would throw away the precision PS needs).

use super::{CaptureError, Frame, FrameFormat, FrameSource, Samples};
use image::{DynamicImage, ImageReader};
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Whether a file name looks like a still frame this reader understands.
pub fn is_frame_file(path: &Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Some("png" | "tif" | "tiff")
    )
}

/// Decodes one still image into native greyscale samples and its bit depth.
fn load_still(path: &Path) -> Result<Still, CaptureError> {
    let image = ImageReader::open(path)
        .map_err(|source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .decode()
        .map_err(|e| CaptureError::Decode {
            path: path.to_path_buf(),
            source: Box::new(e),
        })?;
    Ok(grey(image))
}

/// Greyscale samples of a decoded image (8 or 16 bits kept).
fn grey(image: DynamicImage) -> Still {
    let (w, h) = (image.width() as usize, image.height() as usize);
    match image {
        DynamicImage::ImageLuma8(im) => (w, h, 8, Samples::U8(im.into_raw())),
        DynamicImage::ImageLuma16(im) => (w, h, 16, Samples::U16(im.into_raw())),
        im if im.color().bytes_per_pixel() / im.color().channel_count().max(1) >= 2 => {
            (w, h, 16, Samples::U16(im.to_luma16().into_raw()))
        }
        im => (w, h, 8, Samples::U8(im.to_luma8().into_raw())),
    }
}

/// Frames decoded ahead of the reader: [`ImageSequence`] decodes this many files at once,
/// in parallel (PNG decoding is single-threaded per file; a 720p frame takes ~3 ms).
const DECODE_AHEAD: usize = 8;

/// A decoded still: width, height, bit depth and samples.
type Still = (usize, usize, u8, Samples);

/// A directory of still frames, read in name order; files are decoded \[`DECODE_AHEAD`\] at a
/// time in parallel, so memory holds at most that many frames beyond the caller's.
#[derive(Debug)]
pub struct ImageSequence {
    format: FrameFormat,
    files: Vec<PathBuf>,
    next: usize,
    first: Option<Samples>,
    ahead: std::collections::VecDeque<Result<Still, CaptureError>>,
}

impl ImageSequence {
    /// Opens `dir`; every PNG/TIFF in it is a frame. `fps` is the capture rate.
    pub fn open(dir: &Path, fps: f64) -> Result<Self, CaptureError> {
        let io = |source| CaptureError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_frame_file(p))
            .collect();
        files = largest_numbered_group(files);
        files.sort_by(|a, b| natural_order(&file_name(a), &file_name(b)).then_with(|| a.cmp(b)));
        let Some(first_path) = files.first() else {
            return Err(CaptureError::Format {
                path: dir.to_path_buf(),
                reason: "no PNG or TIFF frames in this directory".into(),
            });
        };
        let (width, height, bits, samples) = load_still(first_path)?;
        Ok(Self {
            format: FrameFormat::full_range(width, height, bits, fps),
            files,
            next: 0,
            first: Some(samples),
            ahead: Default::default(),
        })
    }

    /// The decoded still at `index` (the next one to deliver), decoding the following
    /// [`DECODE_AHEAD`] files in parallel when none is waiting.
    fn decoded(&mut self, index: usize) -> Result<Still, CaptureError> {
        if self.ahead.is_empty() {
            use rayon::prelude::*;
            let end = (index + DECODE_AHEAD).min(self.files.len());
            let batch: Vec<Result<Still, CaptureError>> = self.files[index..end]
                .par_iter()
                .map(|path| load_still(path))
                .collect();
            self.ahead.extend(batch);
        }
        self.ahead.pop_front().unwrap_or_else(|| {
            Err(CaptureError::Other(format!(
                "frame {index} was not decoded ahead"
            )))
        })
    }
}

impl FrameSource for ImageSequence {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        let index = self.next;
        let Some(path) = self.files.get(index) else {
            return Ok(None);
        };
        self.next += 1;
        let path = path.clone();
        let samples = match self.first.take() {
            Some(s) => s,
            None => {
                let (w, h, bits, samples) = self.decoded(index)?;
                check_frame(index, w, h, &self.format)?;
                if bits != self.format.bit_depth {
                    return Err(CaptureError::Format {
                        path,
                        reason: format!(
                            "{bits}-bit frame in a {}-bit sequence",
                            self.format.bit_depth
                        ),
                    });
                }
                samples
            }
        };
        Ok(Some(Frame { index, samples }))
    }

    fn frame_count_hint(&self) -> Option<usize> {
        Some(self.files.len() - self.next)
    }
}

/// Keeps the largest group of files whose names differ only in their digits (`frame_00012.png`),
/// so stray stills in the directory (a `mask.png`) are not taken for frames.
fn largest_numbered_group(files: Vec<PathBuf>) -> Vec<PathBuf> {
    let pattern = |p: &PathBuf| -> String {
        p.file_name()
            .map(|n| {
                n.to_string_lossy()
                    .replace(|c: char| c.is_ascii_digit(), "")
            })
            .unwrap_or_default()
    };
    let mut groups: std::collections::BTreeMap<String, Vec<PathBuf>> = Default::default();
    for file in files {
        groups.entry(pattern(&file)).or_default().push(file);
    }
    groups
        .into_values()
        .max_by_key(Vec::len)
        .unwrap_or_default()
}

/// The file name of `path` (empty when it has none).
fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Natural order of two names: digit runs compare by numeric value, the rest character by
/// character.
fn natural_order(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (mut a, mut b) = (a, b);
    loop {
        let (Some(ca), Some(cb)) = (a.chars().next(), b.chars().next()) else {
            return a.len().cmp(&b.len());
        };
        if ca.is_ascii_digit() && cb.is_ascii_digit() {
            let split = |s: &str| s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
            let (na, ra) = a.split_at(split(a));
            let (nb, rb) = b.split_at(split(b));
            let (ta, tb) = (na.trim_start_matches('0'), nb.trim_start_matches('0'));
            let order = ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb));
            if order != Ordering::Equal {
                return order;
            }
            (a, b) = (ra, rb);
        } else {
            if ca != cb {
                return ca.cmp(&cb);
            }
            (a, b) = (&a[ca.len_utf8()..], &b[cb.len_utf8()..]);
        }
    }
}

/// Checks a frame's size against the stream.
pub(crate) fn check_frame(
    index: usize,
    width: usize,
    height: usize,
    format: &FrameFormat,
) -> Result<(), CaptureError> {
    if width != format.width || height != format.height {
        return Err(CaptureError::SizeMismatch {
            index,
            got_width: width,
            got_height: height,
            width: format.width,
            height: format.height,
        });
    }
    Ok(())
}

/// A multi-page TIFF, one page per frame.
pub struct TiffStack {
    format: FrameFormat,
    path: PathBuf,
    decoder: tiff::decoder::Decoder<BufReader<std::fs::File>>,
    index: usize,
    done: bool,
}

impl TiffStack {
    /// Opens a (possibly multi-page) TIFF file.
    pub fn open(path: &Path, fps: f64) -> Result<Self, CaptureError> {
        let file = std::fs::File::open(path).map_err(|source| CaptureError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let tiff_error = |e: tiff::TiffError| CaptureError::Decode {
            path: path.to_path_buf(),
            source: Box::new(e),
        };
        let mut decoder = tiff::decoder::Decoder::new(BufReader::new(file)).map_err(tiff_error)?;
        let (w, h) = decoder.dimensions().map_err(tiff_error)?;
        let bits = match decoder.colortype().map_err(tiff_error)? {
            tiff::ColorType::Gray(b) | tiff::ColorType::RGB(b) | tiff::ColorType::RGBA(b) => b,
            other => {
                return Err(CaptureError::Format {
                    path: path.to_path_buf(),
                    reason: format!("unsupported TIFF colour type {other:?}"),
                });
            }
        };
        let bits = if bits > 8 { 16 } else { 8 };
        Ok(Self {
            format: FrameFormat::full_range(w as usize, h as usize, bits, fps),
            path: path.to_path_buf(),
            decoder,
            index: 0,
            done: false,
        })
    }
}

impl FrameSource for TiffStack {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        if self.done {
            return Ok(None);
        }
        let path = self.path.clone();
        let tiff_error = |e: tiff::TiffError| CaptureError::Decode {
            path: path.clone(),
            source: Box::new(e),
        };
        if self.index > 0 {
            if !self.decoder.more_images() {
                self.done = true;
                return Ok(None);
            }
            self.decoder.next_image().map_err(tiff_error)?;
        }
        let (w, h) = self.decoder.dimensions().map_err(tiff_error)?;
        check_frame(self.index, w as usize, h as usize, &self.format)?;
        let channels = match self.decoder.colortype().map_err(tiff_error)? {
            tiff::ColorType::Gray(_) => 1,
            tiff::ColorType::RGB(_) => 3,
            tiff::ColorType::RGBA(_) => 4,
            other => {
                return Err(CaptureError::Format {
                    path: path.clone(),
                    reason: format!("unsupported TIFF colour type {other:?}"),
                });
            }
        };
        let samples = match self.decoder.read_image().map_err(tiff_error)? {
            tiff::decoder::DecodingResult::U8(v) => Samples::U8(luma(&v, channels)),
            tiff::decoder::DecodingResult::U16(v) => Samples::U16(luma(&v, channels)),
            _ => {
                return Err(CaptureError::Format {
                    path,
                    reason: "TIFF sample type is not 8- or 16-bit unsigned".into(),
                });
            }
        };
        let frame = Frame {
            index: self.index,
            samples,
        };
        self.index += 1;
        Ok(Some(frame))
    }
}

/// Rec. 709 luma of interleaved samples (grey passes through).
fn luma<T: Copy + Into<f32> + FromLuma>(samples: &[T], channels: usize) -> Vec<T> {
    if channels == 1 {
        return samples.to_vec();
    }
    samples
        .chunks_exact(channels)
        .map(|px| {
            let y = 0.2126 * px[0].into() + 0.7152 * px[1].into() + 0.0722 * px[2].into();
            T::from_luma(y)
        })
        .collect()
}

/// Conversion back from a luma value.
trait FromLuma {
    /// Rounds and clamps `y` into the sample type.
    fn from_luma(y: f32) -> Self;
}

impl FromLuma for u8 {
    fn from_luma(y: f32) -> Self {
        y.round().clamp(0.0, 255.0) as u8
    }
}

impl FromLuma for u16 {
    fn from_luma(y: f32) -> Self {
        y.round().clamp(0.0, 65535.0) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::natural_order;
    use std::cmp::Ordering::{Equal, Greater, Less};

    #[test]
    fn digit_runs_compare_as_numbers() {
        assert_eq!(natural_order("frame9.png", "frame10.png"), Less);
        assert_eq!(natural_order("frame10.png", "frame9.png"), Greater);
        assert_eq!(natural_order("f_0009.png", "f_0010.png"), Less);
        assert_eq!(natural_order("frame007.png", "frame7.png"), Equal);
        assert_eq!(natural_order("a2b10.png", "a2b9.png"), Greater);
        assert_eq!(natural_order("frame1.png", "frame1.tif"), Less);
        assert_eq!(natural_order("frame", "frame1"), Less);
        assert_eq!(natural_order("é2", "é10"), Less);
    }
}
