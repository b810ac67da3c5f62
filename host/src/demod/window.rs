//! Reading a window of frames: region of interest, code-value conversion, per-band means.
//!
//! Frames are kept in their native 8/16-bit form (a 128-frame 720p 8-bit window is 118 MB);
//! the spatial mean of every row band (frames in parallel) is computed once the window is
//! read, because the waveform fit ([`super::fit`]) needs it before the per-pixel pass. On
//! frames above [`MEAN_PIXELS`] it is taken over every k-th row: the fit only needs the mean to
//! fix the shared timing, and 65 536 pixels already average the noise down by 256×, while
//! reading every row would cost a second full pass over memory (measured: 6–12 ms of a
//! 128-frame 720p window, against 2 ms sampled).

use super::config::{Linearize, Roi};
use super::error::DemodError;
use crate::capture::{FrameFormat, FrameSource, Samples};
use rayon::prelude::*;

/// Pixels per frame above which the band means sample rows (see [`read_window`]).
pub const MEAN_PIXELS: usize = 1 << 16;

/// Maps code values to fractions of full scale (optionally linearised).
#[derive(Debug, Clone)]
pub enum CodeMap {
    /// fraction = (code − black) · scale: applied after accumulation, the hot loop sums codes.
    Linear {
        /// Black level code.
        black: f32,
        /// 1 / (white − black).
        scale: f32,
    },
    /// A lookup table over every code value.
    Table(Vec<f32>),
}

impl CodeMap {
    /// Builds the map for a stream format and linearisation.
    pub fn new(format: &FrameFormat, linearize: Linearize) -> Result<Self, DemodError> {
        let (black, white) = (format.black_level, format.white_level);
        if !black.is_finite() || !white.is_finite() || white <= black {
            return Err(DemodError::InvalidConfig(format!(
                "frame format has black level {black} and white level {white}"
            )));
        }
        let scale = 1.0 / (white - black);
        let curve: fn(f32, f32) -> f32 = match linearize {
            Linearize::None => return Ok(Self::Linear { black, scale }),
            Linearize::Srgb => |v, _| {
                if v <= 0.04045 {
                    v / 12.92
                } else {
                    ((v + 0.055) / 1.055).powf(2.4)
                }
            },
            Linearize::Gamma(g) => {
                if !g.is_finite() || g <= 0.0 {
                    return Err(DemodError::InvalidConfig(format!(
                        "gamma {g} is not positive"
                    )));
                }
                |v, g| v.powf(g)
            }
        };
        let gamma = match linearize {
            Linearize::Gamma(g) => g,
            _ => 1.0,
        };
        let codes = 1usize << format.bit_depth.min(16);
        Ok(Self::Table(
            (0..codes)
                .map(|c| {
                    let v = ((c as f32 - black) * scale).clamp(0.0, 1.0);
                    curve(v, gamma)
                })
                .collect(),
        ))
    }

    /// Factor from accumulated values to fractions of full scale.
    pub fn scale(&self) -> f32 {
        match self {
            Self::Linear { scale, .. } => *scale,
            Self::Table(_) => 1.0,
        }
    }

    /// The value the hot loop accumulates for a code.
    #[inline]
    pub fn value(&self, code: u16) -> f32 {
        match self {
            Self::Linear { .. } => f32::from(code),
            Self::Table(t) => t.get(usize::from(code)).copied().unwrap_or(1.0),
        }
    }

    /// Converts an accumulated mean value to a fraction of full scale.
    pub fn mean_fraction(&self, mean_value: f64) -> f64 {
        match self {
            Self::Linear { black, scale } => (mean_value - f64::from(*black)) * f64::from(*scale),
            Self::Table(_) => mean_value,
        }
    }
}

/// Frames of one decoding window plus their per-band spatial means.
#[derive(Debug, Default)]
pub struct Window {
    /// Cropped frames in native form.
    pub frames: Vec<Samples>,
    /// `band_means[b][j]`: mean fraction of full scale of band b in frame j.
    pub band_means: Vec<Vec<f64>>,
    /// `mean[j]`: mean fraction of full scale of the whole region in frame j.
    pub mean: Vec<f64>,
}

/// Geometry of the decoded region.
#[derive(Debug, Clone, Copy)]
pub struct Region {
    /// Region in source pixels.
    pub roi: Roi,
    /// Row bands.
    pub bands: usize,
}

impl Region {
    /// Band of a region row.
    pub fn band_of(&self, row: usize) -> usize {
        (row * self.bands / self.roi.height.max(1)).min(self.bands - 1)
    }
}

/// Reads up to `count` frames; returns fewer only at the end of the stream.
pub fn read_window(
    source: &mut dyn FrameSource,
    format: &FrameFormat,
    region: Region,
    map: &CodeMap,
    count: usize,
    mut on_frame: impl FnMut(),
) -> Result<Window, DemodError> {
    let mut window = Window {
        frames: Vec::with_capacity(count),
        band_means: vec![Vec::with_capacity(count); region.bands],
        mean: Vec::with_capacity(count),
    };
    let roi = region.roi;
    while window.frames.len() < count {
        let Some(frame) = source.next_frame()? else {
            break;
        };
        if frame.samples.len() != format.pixels() {
            return Err(crate::capture::CaptureError::Other(format!(
                "frame {} has {} samples, expected {}x{}",
                frame.index,
                frame.samples.len(),
                format.width,
                format.height
            ))
            .into());
        }
        window.frames.push(crop(frame.samples, format.width, roi));
        on_frame();
    }
    // The fit needs the band means only to fix the timing, so large frames are sampled every
    // `stride`-th row (at least [`MEAN_PIXELS`] pixels, and every band's first row).
    let stride = (roi.width * roi.height / MEAN_PIXELS).max(1);
    let sampled =
        |row: usize| row.is_multiple_of(stride) || region.band_of(row) != region.band_of(row - 1);
    let rows: Vec<usize> = (0..roi.height).filter(|&row| sampled(row)).collect();
    let mut band_pixels = vec![0usize; region.bands];
    for &row in &rows {
        band_pixels[region.band_of(row)] += roi.width;
    }
    // Every frame's band sums, frames in parallel.
    let sums: Vec<Vec<f64>> = window
        .frames
        .par_iter()
        .map(|frame| {
            let mut band_sums = vec![0.0f64; region.bands];
            for &row in &rows {
                let range = row * roi.width..(row + 1) * roi.width;
                band_sums[region.band_of(row)] += row_sum(frame, range, map);
            }
            band_sums
        })
        .collect();
    let sampled_pixels: usize = band_pixels.iter().sum();
    for band_sums in &sums {
        for (band, means) in window.band_means.iter_mut().enumerate() {
            means.push(map.mean_fraction(band_sums[band] / band_pixels[band].max(1) as f64));
        }
        let total: f64 = band_sums.iter().sum();
        window
            .mean
            .push(map.mean_fraction(total / sampled_pixels.max(1) as f64));
    }
    Ok(window)
}

/// Sum of the accumulation values of one row: exact integer sums of the codes for a linear
/// map (no per-sample conversion), table look-ups otherwise.
fn row_sum(samples: &Samples, range: std::ops::Range<usize>, map: &CodeMap) -> f64 {
    match (samples, map) {
        (Samples::U8(v), CodeMap::Linear { .. }) => v[range]
            .chunks(1 << 16)
            .map(|chunk| u64::from(chunk.iter().map(|&c| u32::from(c)).sum::<u32>()))
            .sum::<u64>() as f64,
        (Samples::U16(v), CodeMap::Linear { .. }) => {
            v[range].iter().map(|&c| u64::from(c)).sum::<u64>() as f64
        }
        (Samples::U8(v), CodeMap::Table(t)) => v[range]
            .iter()
            .map(|&c| f64::from(t.get(usize::from(c)).copied().unwrap_or(1.0)))
            .sum(),
        (Samples::U16(v), CodeMap::Table(t)) => v[range]
            .iter()
            .map(|&c| f64::from(t.get(usize::from(c)).copied().unwrap_or(1.0)))
            .sum(),
    }
}

/// Cuts the region of interest out of a full frame (no copy when it is the whole frame).
fn crop(samples: Samples, width: usize, roi: Roi) -> Samples {
    if roi.x == 0 && roi.width == width && roi.y == 0 && roi.height * width == samples.len() {
        return samples;
    }
    let rows = roi.y..roi.y + roi.height;
    match samples {
        Samples::U8(v) => Samples::U8(
            rows.flat_map(|r| v[r * width + roi.x..r * width + roi.x + roi.width].to_vec())
                .collect(),
        ),
        Samples::U16(v) => Samples::U16(
            rows.flat_map(|r| v[r * width + roi.x..r * width + roi.x + roi.width].to_vec())
                .collect(),
        ),
    }
}
