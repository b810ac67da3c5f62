//! A cold window started from its own reconstruction at half the resolution, itself started
//! the same way: a pyramid down to [`COARSE_MIN_PIXELS`].
//!
//! A cold reconstruction runs four near-field passes on the full frame; the first, from light
//! vectors at z = 0, with the widest offset search. At 1280×720 that is ≈ 0.45 s, a tenth of a
//! 2000-frame `meb video` run for its first window alone. The same window binned 2×2 (each
//! block's LED levels averaged, [`bin_decoded`]) is reconstructed on the binned camera
//! ([`meb_core::rig::Rig::binned`]: every binned pixel keeps the ray of its block's centre) at a
//! quarter of the cost, and its depth, spread back over the blocks and two pixels beyond the
//! rim ([`spread`]), starts the full-resolution window as a previous window's would
//! ([`super::WarmStart`]). The binned window is reconstructed by the same rule: a frame of at
//! least [`COARSE_MIN_PIXELS`] starts from its own binned reconstruction, a smaller one runs its
//! cold passes until they settle (`ColdPasses::UntilSettled`). So a 1280×720 window starts from
//! 320×180, whose cold passes cost a sixteenth of the full frame's, through one warm pass at
//! 640×360; its first window's binned stages went from ≈ 150–230 ms (three cold passes at
//! 640×360) to ≈ 70–110 ms. A result that strays from its start is redone cold at its own
//! resolution, so a coarse start never gives a result the warm checks would have refused. A
//! window whose previous window's warm start strayed is redone this way too.

use super::inputs::Source;
use super::{ReconstructConfig, StageTiming, WarmStart};
use crate::demod::Decoded;
use crate::photometric::highlights::looks_glossy;
use meb_core::rig::Rig;
use meb_core::types::LedImages;
use ndarray::Array2;
use rayon::prelude::*;

/// Binning factor of the coarse reconstruction.
pub const COARSE_BIN: usize = 2;

/// Fewest camera pixels for which a coarse start is used: 640×360 (the binned frame is then at
/// least 320×180; smaller frames, the pyramid's last level among them, are reconstructed cold,
/// which costs little there).
pub const COARSE_MIN_PIXELS: usize = 640 * 360;

/// Pixels the spread depth reaches beyond the coarse depth's rim: a block's object pixels next
/// to a background block, which the binned decode did not see as object.
const RIM_PX: usize = 2;

/// The warm start of a cold window of `inputs` (module docs): its reconstruction binned by
/// [`COARSE_BIN`] (coarse-started in turn when the binned frame is large enough) spread over
/// the frame, its stages added to `timings` (each level's labelled "binned" once more);
/// `None` below [`COARSE_MIN_PIXELS`], for inputs other than a decoded capture of the rig's
/// frame, or when the binned window cannot be reconstructed.
pub(super) fn start(
    inputs: &Source,
    rig: &Rig,
    config: &ReconstructConfig,
    timings: &mut Vec<StageTiming>,
) -> Option<WarmStart> {
    let frame = (rig.camera.height, rig.camera.width);
    let Source::Decoded(decoded) = inputs else {
        return None;
    };
    if frame.0 * frame.1 < COARSE_MIN_PIXELS || decoded.noise.dim() != frame {
        return None;
    }
    let binned = bin_decoded(decoded, COARSE_BIN);
    let binned_rig = rig.binned(COARSE_BIN);
    let coarse = super::reconstruct_inputs(
        &Source::Decoded(&binned),
        &binned_rig,
        None,
        config,
        None,
        super::ColdPasses::UntilSettled,
    )
    .ok()?
    .into_frame(&binned_rig.camera.projection());
    timings.extend(coarse.timings.into_iter().map(|mut t| {
        t.stage = format!("{}, binned", t.stage);
        t
    }));
    Some(WarmStart {
        depth_mm: spread(&coarse.integration.depth.depth_mm, COARSE_BIN, frame),
        glossy: looks_glossy(&coarse.photometric),
    })
}

/// One binned row: LED levels (LED-major), σ, saturated and under-exposed flags.
type BinnedRow = (Vec<f32>, Vec<f32>, Vec<bool>, Vec<bool>);

/// `decoded` binned by `k`: each k×k block's LED levels and σ averaged over its usable pixels
/// (neither saturated nor under-exposed; σ of the mean, √Σσ² / n), saturated when one of its
/// pixels is, under-exposed when none is usable otherwise. Rows and columns that do not fill a
/// block are dropped, as the binned camera drops them.
pub fn bin_decoded(decoded: &Decoded, k: usize) -> Decoded {
    let k = k.max(1);
    let (rows, cols) = decoded.noise.dim();
    let (out_rows, out_cols) = (rows / k, cols / k);
    let leds = decoded.leds.images.len();
    // Binned rows in parallel: LED levels (LED-major), σ, saturated, under-exposed.
    let binned_rows: Vec<BinnedRow> = (0..out_rows)
        .into_par_iter()
        .map(|r| {
            let mut levels = vec![0.0f32; leds * out_cols];
            let mut noise = vec![f32::NAN; out_cols];
            let mut saturated = vec![false; out_cols];
            let mut underexposed = vec![true; out_cols];
            for c in 0..out_cols {
                let level = |i: usize| i * out_cols + c;
                let block =
                    (r * k..(r + 1) * k).flat_map(|y| (c * k..(c + 1) * k).map(move |x| (y, x)));
                let (mut n, mut variance) = (0usize, 0.0f32);
                let mut any_saturated = false;
                for p in block {
                    any_saturated |= decoded.saturated[p];
                    if decoded.underexposed[p] {
                        continue;
                    }
                    n += 1;
                    variance += decoded.noise[p].powi(2);
                    for (i, image) in decoded.leds.images.iter().enumerate() {
                        levels[level(i)] += image[p];
                    }
                }
                if any_saturated || n == 0 {
                    (0..leds).for_each(|i| levels[level(i)] = f32::NAN);
                    saturated[c] = any_saturated;
                    underexposed[c] = !any_saturated;
                    continue;
                }
                underexposed[c] = false;
                (0..leds).for_each(|i| levels[level(i)] /= n as f32);
                noise[c] = variance.sqrt() / n as f32;
            }
            (levels, noise, saturated, underexposed)
        })
        .collect();
    let mut images = vec![Array2::from_elem((out_rows, out_cols), f32::NAN); leds];
    let mut noise = Array2::from_elem((out_rows, out_cols), f32::NAN);
    let mut saturated = Array2::from_elem((out_rows, out_cols), false);
    let mut underexposed = Array2::from_elem((out_rows, out_cols), true);
    for (r, (levels, sigma, sat, under)) in binned_rows.into_iter().enumerate() {
        for (i, image) in images.iter_mut().enumerate() {
            image.row_mut(r).assign(&ndarray::ArrayView1::from(
                &levels[i * out_cols..(i + 1) * out_cols],
            ));
        }
        noise.row_mut(r).assign(&ndarray::Array1::from(sigma));
        saturated.row_mut(r).assign(&ndarray::Array1::from(sat));
        underexposed
            .row_mut(r)
            .assign(&ndarray::Array1::from(under));
    }
    let mut report = decoded.report.clone();
    report.width = out_cols;
    report.height = out_rows;
    Decoded {
        leds: LedImages { images },
        noise,
        saturated,
        underexposed,
        report,
    }
}

/// The binned depth `coarse` on the full frame of `frame` (rows, columns): each block's depth
/// on its k×k pixels, then carried [`RIM_PX`] pixels past the rim (each unknown pixel takes the
/// nearest known one's depth along its row or column, one pixel per step).
fn spread(coarse: &Array2<f32>, k: usize, frame: (usize, usize)) -> Array2<f32> {
    let (rows, cols) = coarse.dim();
    let mut depth = Array2::from_shape_fn(frame, |(r, c)| {
        let (br, bc) = (r / k, c / k);
        if br < rows && bc < cols {
            coarse[(br, bc)]
        } else {
            f32::NAN
        }
    });
    for _ in 0..RIM_PX {
        let known = depth.clone();
        for ((r, c), z) in depth.indexed_iter_mut() {
            if z.is_finite() {
                continue;
            }
            let neighbours = [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ];
            if let Some(&v) = neighbours
                .iter()
                .filter_map(|&p| known.get(p))
                .find(|v| v.is_finite())
            {
                *z = v;
            }
        }
    }
    depth
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::fixture::decoded;

    #[test]
    fn blocks_average_their_usable_pixels() {
        let levels = Array2::from_shape_fn((4, 6), |(r, c)| (r * 6 + c) as f32);
        let mut d = decoded(levels, Array2::from_elem((4, 6), 0.3));
        d.underexposed[(0, 0)] = true;
        d.saturated[(2, 4)] = true;
        d.underexposed.slice_mut(ndarray::s![2..4, 0..2]).fill(true);
        let b = bin_decoded(&d, 2);
        assert_eq!(b.noise.dim(), (2, 3));
        assert_eq!((b.report.width, b.report.height), (3, 2));
        // Block (0, 0) without its under-exposed pixel 0: (1 + 6 + 7) / 3.
        assert_eq!(b.leds.images[0][(0, 0)], 14.0 / 3.0);
        assert!((b.noise[(0, 0)] - 0.3 * 3f32.sqrt() / 3.0).abs() < 1e-6);
        // Block (0, 1): pixels 2, 3, 8, 9.
        assert_eq!(b.leds.images[0][(0, 1)], 5.5);
        assert_eq!(b.leds.images[1][(0, 1)], 2.75, "LED 2 is at half");
        assert!((b.noise[(0, 1)] - 0.15).abs() < 1e-6);
        // A saturated pixel makes its block saturated; no usable pixel, under-exposed.
        assert!(b.saturated[(1, 2)] && !b.underexposed[(1, 2)]);
        assert!(b.underexposed[(1, 0)] && b.leds.images[0][(1, 0)].is_nan());
    }

    #[test]
    fn the_coarse_depth_covers_its_blocks_and_the_rim() {
        let mut coarse = Array2::from_elem((4, 5), f32::NAN);
        coarse[(1, 2)] = 10.0;
        coarse[(2, 2)] = 20.0;
        let depth = spread(&coarse, 2, (9, 10));
        assert_eq!(depth[(2, 4)], 10.0);
        assert_eq!(depth[(3, 5)], 10.0);
        assert_eq!(depth[(5, 5)], 20.0);
        // Two pixels past the rim, not three.
        assert_eq!(depth[(2, 2)], 10.0);
        assert!(depth[(2, 1)].is_nan());
        assert_eq!(depth[(7, 4)], 20.0);
        assert!(
            depth[(8, 4)].is_nan(),
            "the row the binned camera dropped, three away"
        );
        let known = depth.iter().filter(|z| z.is_finite()).count();
        assert!(known > 16 && known < 60, "{known}");
    }
}
