//! Decoding around the object: the focus region of a window.
//!
//! The turning ellipsoid fills about a tenth of a 1280×720 frame, yet the matched filter, the
//! motion test and the cut of the reconstruction's inputs visit every pixel of it. Once the
//! timing carry has settled ([`super::carry`]), a window is decoded only inside the box of the
//! previous window's lit pixels grown by [`FOCUS_MARGIN_PX`] (the decoder's region of interest,
//! [`crate::demod::DecodeConfig::roi`]) and reconstructed there
//! ([`crate::reconstruct::Request::region`]). A pixel is lit when its brightest LED image
//! stands [`MaskConfig::snr_threshold`] level-noise σ above zero, specks smaller than
//! [`MaskConfig::min_component_pixels`] left out: the brightness test of the automatic object
//! mask ([`crate::photometric`]), so the lit pixels hold the object the reconstruction finds.
//!
//! The object may move beyond its region: a window whose lit pixels reach an edge of the
//! region that is not an edge of the frame, or whose region holds no lit pixel at all (the
//! object jumped away), is decoded again whole ([`LitBox::reaches_edge`]). A region's decode
//! equals the whole frame's there: the decoder's pixel sample lies on the frame's rows
//! (the demodulator's module `sample`) and the motion test's on the frame's pixels, so the timing fit and
//! the motion score are the whole frame's.
//! An object that appears elsewhere is found by the whole-frame decode of every
//! `full_frame_every`-th window. A lit box that keeps most of the frame (a lit background) is
//! not worth a region, and every window is then decoded whole.
//!
//! The carry judges a carried timing by the median per-pixel σ of the decode, which depends on
//! the pixels decoded (an object's σ is not the dark background's): a region's decode is judged
//! against the median σ of the last whole-frame decode inside that region
//! ([`FocusRegion::reference_noise`]).

use crate::demod::{Decoded, Roi};
use crate::photometric::MaskConfig;
use crate::regions::{bounding_box, remove_small};
use ndarray::Array2;
use rayon::prelude::*;

/// Pixels added on every side of the lit box: what the object's silhouette may move from one
/// window to the next (as the warm reconstruction's [`crate::reconstruct::ROI_MARGIN_PX`]).
pub const FOCUS_MARGIN_PX: usize = crate::reconstruct::ROI_MARGIN_PX;

/// A region keeping more than this share of the frame's pixels is not worth it.
const WORTHWHILE_SHARE: f64 = 0.6;

/// Image rows per parallel task of the lit test.
const ROWS_PER_TASK: usize = 16;

/// Where a window is decoded, and what its carried timing is judged against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FocusRegion {
    /// The region, in frame pixels.
    pub roi: Roi,
    /// Median per-pixel σ inside the region of the last whole-frame decode, fraction of full
    /// scale.
    pub reference_noise: f64,
}

/// The lit pixels of a decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LitBox {
    /// Their bounding box in frame pixels (`None`: nothing is lit).
    pub bounds: Option<Roi>,
    /// Whether they reach an edge of the decoded region that is not an edge of the frame.
    pub reaches_edge: bool,
}

/// The lit pixels of `decoded`, decoded over `region` of a `frame` (width, height) (the whole
/// frame for `None`), with the mask settings `config` (module docs).
pub fn lit_box(
    decoded: &Decoded,
    region: Option<Roi>,
    frame: (usize, usize),
    config: &MaskConfig,
) -> LitBox {
    let lit = lit_pixels(decoded, config);
    let region = region.unwrap_or(Roi {
        x: 0,
        y: 0,
        width: frame.0,
        height: frame.1,
    });
    let none = LitBox {
        bounds: None,
        reaches_edge: false,
    };
    // Specks are removed inside the box of every lit pixel, which holds them all.
    let Some((outer_rows, outer_cols)) = bounding_box(&lit) else {
        return none;
    };
    let mut inner = lit
        .slice(ndarray::s![outer_rows.clone(), outer_cols.clone()])
        .to_owned();
    remove_small(&mut inner, config.min_component_pixels);
    let Some((rows, cols)) = bounding_box(&inner) else {
        return none;
    };
    let rows = rows.start + outer_rows.start..rows.end + outer_rows.start;
    let cols = cols.start + outer_cols.start..cols.end + outer_cols.start;
    let (height, width) = lit.dim();
    let reaches_edge = (rows.start == 0 && region.y > 0)
        || (cols.start == 0 && region.x > 0)
        || (rows.end == height && region.y + height < frame.1)
        || (cols.end == width && region.x + width < frame.0);
    LitBox {
        bounds: Some(Roi {
            x: region.x + cols.start,
            y: region.y + rows.start,
            width: cols.len(),
            height: rows.len(),
        }),
        reaches_edge,
    }
}

/// Pixels whose brightest LED image stands `snr_threshold` level-noise σ above zero.
fn lit_pixels(decoded: &Decoded, config: &MaskConfig) -> Array2<bool> {
    let (rows, cols) = decoded.noise.dim();
    let factor = crate::reconstruct::level_noise_factor(decoded);
    let mut lit = Array2::from_elem((rows, cols), false);
    let Some(flat) = lit.as_slice_mut() else {
        unreachable!("a new array is in standard layout")
    };
    let threshold = config.snr_threshold * factor;
    flat.par_chunks_mut(cols.max(1))
        .enumerate()
        .with_min_len(ROWS_PER_TASK)
        .for_each_init(Vec::new, |brightest, (r, row)| {
            brightest.resize(row.len(), 0.0);
            decoded.leds.brightest_in_row(r, brightest);
            // NaN σ or levels fail the comparison: not lit.
            for ((lit, &b), &noise) in row
                .iter_mut()
                .zip(brightest.iter())
                .zip(&decoded.noise.row(r))
            {
                *lit = b >= threshold * noise;
            }
        });
    lit
}

/// `lit` grown by `margin` pixels on every side and clipped to a `frame` (width, height);
/// `None` when it would keep more than [`WORTHWHILE_SHARE`] of the frame.
fn grown(lit: Roi, margin: usize, frame: (usize, usize)) -> Option<Roi> {
    let x = lit.x.saturating_sub(margin);
    let y = lit.y.saturating_sub(margin);
    let right = (lit.x + lit.width + margin).min(frame.0);
    let bottom = (lit.y + lit.height + margin).min(frame.1);
    let region = Roi {
        x,
        y,
        width: right.saturating_sub(x),
        height: bottom.saturating_sub(y),
    };
    let share = (region.width * region.height) as f64 / (frame.0 * frame.1).max(1) as f64;
    (region.width > 0 && region.height > 0 && share <= WORTHWHILE_SHARE).then_some(region)
}

/// Where the windows of a video are decoded (module docs).
#[derive(Debug, Clone)]
pub struct Focus {
    /// Every this many windows one is decoded whole (1: every window).
    full_frame_every: usize,
    /// The frame (width, height).
    frame: (usize, usize),
    /// The region for the next window.
    next: Option<FocusRegion>,
}

impl Focus {
    /// A focus for frames of `frame` (width, height) that decodes every `full_frame_every`-th
    /// window whole (0 or 1: every window).
    pub fn new(full_frame_every: usize, frame: (usize, usize)) -> Self {
        Self {
            full_frame_every: full_frame_every.max(1),
            frame,
            next: None,
        }
    }

    /// The region to decode window `k` in; `None` for the whole frame.
    pub fn region(&self, k: usize) -> Option<FocusRegion> {
        self.next
            .filter(|_| !k.is_multiple_of(self.full_frame_every))
    }

    /// Learns the next window's region from the chosen decode of a window, `lit` its lit
    /// pixels, decoded over `region` (`None`: the whole frame); a failed window (`None`)
    /// leaves the next one to be decoded whole.
    pub fn learn(&mut self, decoded: Option<(&Decoded, LitBox)>, region: Option<FocusRegion>) {
        let Some((decoded, lit)) = decoded else {
            self.next = None;
            return;
        };
        let Some(roi) = lit
            .bounds
            .and_then(|b| grown(b, FOCUS_MARGIN_PX, self.frame))
        else {
            self.next = None;
            return;
        };
        let reference_noise = match region {
            // A region's decode keeps the reference of the whole-frame decode it came from.
            Some(previous) => previous.reference_noise,
            None => match median_inside(decoded, roi) {
                Some(median) => median,
                None => {
                    self.next = None;
                    return;
                }
            },
        };
        self.next = Some(FocusRegion {
            roi,
            reference_noise,
        });
    }
}

/// The median σ of a whole-frame decode inside `roi` over the pixels its report's median
/// counts (neither saturated nor under-exposed).
fn median_inside(decoded: &Decoded, roi: Roi) -> Option<f64> {
    let (rows, cols) = decoded.noise.dim();
    if roi.y + roi.height > rows || roi.x + roi.width > cols {
        return None;
    }
    let area = ndarray::s![roi.y..roi.y + roi.height, roi.x..roi.x + roi.width];
    let valid = ndarray::Zip::from(decoded.noise.slice(area))
        .and(decoded.saturated.slice(area))
        .and(decoded.underexposed.slice(area))
        .fold(Vec::new(), |mut valid, &sigma, &saturated, &under| {
            if !saturated && !under {
                valid.push(sigma);
            }
            valid
        });
    meb_core::stats::quantile(valid, 0.5).map(f64::from)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::fixture::decoded;

    const FRAME: (usize, usize) = (200, 120);
    /// A region of [`FRAME`] away from its edges.
    const REGION: Roi = Roi {
        x: 30,
        y: 20,
        width: 100,
        height: 80,
    };

    /// The lit box of a bright block at `rows`, `cols` of the frame decoded over `region`.
    fn lit_in(region: Roi, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> LitBox {
        let decoded = block(Some(region), rows, cols);
        lit_box(&decoded, Some(region), FRAME, &MaskConfig::default())
    }

    /// A decode over `region` (the whole frame for `None`) of a bright block at `rows`, `cols`
    /// of the frame, with σ 0.001 outside and 0.002 on the block.
    fn block(
        region: Option<Roi>,
        rows: std::ops::Range<usize>,
        cols: std::ops::Range<usize>,
    ) -> Decoded {
        let r = region.unwrap_or(Roi {
            x: 0,
            y: 0,
            width: FRAME.0,
            height: FRAME.1,
        });
        let inside =
            |(y, x): (usize, usize)| rows.contains(&(y + r.y)) && cols.contains(&(x + r.x));
        let levels =
            Array2::from_shape_fn(
                (r.height, r.width),
                |p| {
                    if inside(p) { 0.5 } else { 0.0005 }
                },
            );
        let noise =
            Array2::from_shape_fn(
                (r.height, r.width),
                |p| {
                    if inside(p) { 0.002 } else { 0.001 }
                },
            );
        decoded(levels, noise)
    }

    #[test]
    fn the_lit_box_is_the_object_without_specks_in_frame_pixels() {
        let mut d = block(None, 40..70, 50..110);
        // A lit speck far from the object is not part of it.
        d.leds.images[0][(5, 5)] = 0.5;
        let lit = lit_box(&d, None, FRAME, &MaskConfig::default());
        let expected = Roi {
            x: 50,
            y: 40,
            width: 60,
            height: 30,
        };
        assert_eq!(lit.bounds, Some(expected));
        assert!(!lit.reaches_edge);
        // The same object decoded in a region around it: the same box, in frame pixels.
        assert_eq!(lit_in(REGION, 40..70, 50..110), lit);
        // Nothing lit: no box.
        let dark = block(None, 0..0, 0..0);
        assert_eq!(
            lit_box(&dark, None, FRAME, &MaskConfig::default()).bounds,
            None
        );
    }

    #[test]
    fn an_object_reaching_an_inner_edge_of_its_region_may_go_on_beyond_it() {
        for (rows, cols) in [(40..70, 20..60), (10..40, 50..90), (40..70, 100..140)] {
            let lit = lit_in(REGION, rows.clone(), cols.clone());
            assert!(lit.reaches_edge, "{rows:?} {cols:?}");
        }
        // At an edge of the region that is the frame's edge, it cannot go on.
        let corner = Roi {
            x: 0,
            y: 0,
            width: 100,
            height: 80,
        };
        let lit = lit_in(corner, 0..30, 0..40);
        assert!(!lit.reaches_edge);
        assert_eq!(lit.bounds.map(|b| (b.x, b.y)), Some((0, 0)));
    }

    #[test]
    fn regions_follow_the_object_and_whole_frames_come_back() {
        let config = MaskConfig::default();
        let mut focus = Focus::new(4, FRAME);
        assert_eq!(focus.region(1), None, "nothing learnt yet");
        let whole = block(None, 40..70, 50..110);
        focus.learn(Some((&whole, lit_box(&whole, None, FRAME, &config))), None);
        let region = focus.region(1).expect("a region around the object");
        assert_eq!(
            region.roi,
            Roi {
                x: 50 - FOCUS_MARGIN_PX,
                y: 40 - FOCUS_MARGIN_PX,
                width: 60 + 2 * FOCUS_MARGIN_PX,
                height: 30 + 2 * FOCUS_MARGIN_PX,
            }
        );
        // The reference is the whole decode's median σ inside the region: mostly background.
        assert_eq!(region.reference_noise, f64::from(0.001f32));
        assert_eq!(focus.region(4), None, "every 4th window is decoded whole");
        assert_eq!(focus.region(5), Some(region));
        // The object moves right: the region follows and keeps its reference.
        let moved = block(Some(region.roi), 40..70, 60..120);
        let lit = lit_box(&moved, Some(region.roi), FRAME, &config);
        focus.learn(Some((&moved, lit)), Some(region));
        let next = focus.region(5).expect("a region");
        assert_eq!(next.roi.x, 60 - FOCUS_MARGIN_PX);
        assert_eq!(next.reference_noise, region.reference_noise);
        // A failed window, or an object that fills the frame, leaves the next one whole.
        focus.learn(None, Some(next));
        assert_eq!(focus.region(5), None);
        let large = block(None, 5..115, 5..195);
        focus.learn(Some((&large, lit_box(&large, None, FRAME, &config))), None);
        assert_eq!(focus.region(5), None);
        // Every window whole.
        let mut always = Focus::new(1, FRAME);
        always.learn(Some((&whole, lit_box(&whole, None, FRAME, &config))), None);
        assert_eq!(always.region(3), None);
    }
}
