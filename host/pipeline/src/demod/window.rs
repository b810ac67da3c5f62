//! Reading a window of frames (region of interest) and the code-value conversion.
//!
//! Frames are kept in their native 8/16-bit form (a 128-frame 720p 8-bit window is 118 MB), so
//! the memory a decode needs is bounded by the window, not the clip.

use super::config::{Linearize, Roi};
use super::error::DemodError;
use meb_core::capture::{FrameFormat, FrameSource, Samples};

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

/// Frames of one decoding window.
#[derive(Debug, Default)]
pub struct Window {
    /// Cropped frames in native form.
    pub frames: Vec<Samples>,
}

/// Geometry of the decoded region and its row bands.
#[derive(Debug, Clone, Copy)]
pub struct Region {
    /// Region in source pixels.
    pub roi: Roi,
    /// Row bands with their own waveforms in the per-pixel fit (rolling shutter).
    pub bands: usize,
}

impl Region {
    /// Band of a region row.
    pub fn band_of(&self, row: usize) -> usize {
        (row * self.bands / self.roi.height.max(1)).min(self.bands.max(1) - 1)
    }

    /// Centre row of band `band`.
    pub fn band_centre(&self, band: usize) -> f64 {
        // Rows r with band_of(r) = b are ceil(b·H/B) ..= ceil((b+1)·H/B) − 1.
        let (h, b) = (self.roi.height, self.bands.max(1));
        let first = (band * h).div_ceil(b);
        let last = ((band + 1) * h).div_ceil(b).max(first + 1) - 1;
        0.5 * (first + last) as f64
    }
}

/// Reads up to `count` frames cropped to `roi`; returns fewer only at the end of the stream.
pub fn read_window(
    source: &mut dyn FrameSource,
    format: &FrameFormat,
    roi: Roi,
    count: usize,
    mut on_frame: impl FnMut(),
) -> Result<Window, DemodError> {
    let mut window = Window {
        frames: Vec::with_capacity(count),
    };
    while window.frames.len() < count {
        let Some(frame) = source.next_frame()? else {
            break;
        };
        if frame.samples.len() != format.pixels() {
            return Err(meb_core::capture::CaptureError::Other(format!(
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
    Ok(window)
}

/// Cuts the region of interest out of a full frame (no copy when it is the whole frame).
pub(super) fn crop(samples: Samples, width: usize, roi: Roi) -> Samples {
    if roi.x == 0 && roi.width == width && roi.y == 0 && roi.height * width == samples.len() {
        return samples;
    }
    cut(&samples, width, roi)
}

/// The region of interest of a full frame, row by row into one allocation.
pub(super) fn cut(samples: &Samples, width: usize, roi: Roi) -> Samples {
    fn rows<T: Copy>(v: &[T], width: usize, roi: Roi) -> Vec<T> {
        let mut out = Vec::with_capacity(roi.width * roi.height);
        for r in roi.y..roi.y + roi.height {
            out.extend_from_slice(&v[r * width + roi.x..r * width + roi.x + roi.width]);
        }
        out
    }
    match samples {
        Samples::U8(v) => Samples::U8(rows(v, width, roi)),
        Samples::U16(v) => Samples::U16(rows(v, width, roi)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cut_keeps_the_region_row_by_row_and_a_whole_frame_is_not_copied() {
        let (width, height) = (7, 5);
        let values: Vec<u16> = (0..(width * height) as u16).collect();
        let roi = Roi {
            x: 2,
            y: 1,
            width: 3,
            height: 2,
        };
        let expected: Vec<u16> = vec![9, 10, 11, 16, 17, 18];
        let Samples::U16(cut16) = cut(&Samples::U16(values.clone()), width, roi) else {
            panic!("16-bit samples stay 16-bit");
        };
        assert_eq!(cut16, expected);
        let bytes = Samples::U8(values.iter().map(|&v| v as u8).collect());
        let Samples::U8(cut8) = crop(bytes, width, roi) else {
            panic!("8-bit samples stay 8-bit");
        };
        assert_eq!(cut8, expected.iter().map(|&v| v as u8).collect::<Vec<_>>());
        let whole = Roi {
            x: 0,
            y: 0,
            width,
            height,
        };
        let frame = values.clone();
        let storage = frame.as_ptr();
        let Samples::U16(all) = crop(Samples::U16(frame), width, whole) else {
            panic!("16-bit samples stay 16-bit");
        };
        assert_eq!(all, values);
        assert_eq!(all.as_ptr(), storage, "the whole frame was copied");
    }
}
