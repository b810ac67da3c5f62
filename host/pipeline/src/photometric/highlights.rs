//! Highlights: LED readings a Lambertian surface cannot give, found with the redundancy of a
//! fourth LED and left out of the fit.
//!
//! A glossy surface (plastic, glaze, paint, skin) adds to the diffuse reading of LED i a
//! specular lobe that peaks where the normal n bisects the directions to the LED l̂_i and to the
//! camera v, i.e. where n lies along the half vector h_i = (l̂_i + v)/|l̂_i + v|. With four or
//! more LEDs lighting a pixel the Lambertian fit has a spare reading, so such a pixel fails the
//! solver's χ² consistency test ([`super::solve`], step 3). The solver then predicts each lit
//! LED from the others: a highlight reads above its prediction, and the others' normal lies
//! near its half vector (within [`super::PhotometricConfig::highlight_max_deg`]; a GGX lobe of
//! roughness 0.4 and weight 0.3 adds less than 3 % of the diffuse level beyond 30°). Of those,
//! the LED whose half vector lies nearest the others' normal is rejected and the pixel solved again from
//! the rest, and tested again while four or more remain; a pixel with no such LED loses the LED
//! that reads most below its prediction instead (a partial shadow). This is four-source
//! photometric stereo with highlight and shadow rejection (S. Barsky and M. Petrou, "The
//! 4-Source Photometric Stereo Technique for Three-Dimensional Surfaces in the Presence of
//! Highlights and Shadows", IEEE Trans. Pattern Analysis and Machine Intelligence 25(10),
//! 2003), which tells highlight from shadow by colour; here the sign of the deviation and the
//! mirror geometry do.
//!
//! Saturated samples never enter a fit: the decoder flags a pixel that clips in any frame and
//! the reconstruction reads it as unusable (NaN), so it joins the filled holes. A pixel lit by
//! three LEDs has no spare reading and cannot be tested.
//!
//! [`HighlightShares`] counts the result; a surface where most solved pixels needed a
//! rejection ([`MOSTLY_NON_LAMBERTIAN_SHARE`]) is mostly non-Lambertian, and its normals rest
//! on three LEDs each with nothing left to check them.

use super::{Lights, PhotometricResult};
use crate::demod::quality::Verdict;
use nalgebra::Vector3;
use ndarray::Array2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Relative model error of the test for a highlight's tail ([`super::solve`], step 3; only on a
/// surface known to be glossy, [`super::PhotometricConfig::reject_highlight_tails`]): a pixel
/// that the consistency test's model error lets pass but that fails against its noise and
/// this much of each reading loses a highlight, though never a shadow.
pub const HIGHLIGHT_MODEL_ERROR: f64 = 0.01;

/// Share of the solved pixels with a rejected highlight above which a surface is called mostly
/// non-Lambertian. A Ø48 mm sphere under the thesis' out-of-plane LEDs, exposed for the object,
/// has 11.6 % of its solved pixels with a highlight under a 10 % GGX coat of roughness 0.25,
/// 13.5 % under a 30 % one and 19 % at roughness 0.4; a matte one 0.1 %.
pub const MOSTLY_NON_LAMBERTIAN_SHARE: f64 = 0.5;

/// How many solved pixels had LEDs rejected as highlights.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HighlightShares {
    /// Pixels solved from three or more LEDs.
    pub solved_pixels: usize,
    /// Solved pixels with at least one LED rejected as a highlight.
    pub pixels_with_highlight: usize,
    /// `pixels_with_highlight / solved_pixels` (0 without solved pixels).
    pub share: f64,
    /// Per LED (LED 1 first): solved pixels where it was rejected.
    pub per_led: Vec<usize>,
}

impl HighlightShares {
    /// The counts of a photometric result.
    pub fn of(result: &PhotometricResult) -> Self {
        let leds = result.noise_gains.len();
        let mut per_led = vec![0usize; leds];
        let (mut solved_pixels, mut pixels_with_highlight) = (0usize, 0usize);
        for (&solved, &bits) in result.field.mask.iter().zip(&result.highlights) {
            if !solved {
                continue;
            }
            solved_pixels += 1;
            if bits != 0 {
                pixels_with_highlight += 1;
                for (i, n) in per_led.iter_mut().enumerate().take(16) {
                    *n += usize::from(bits & (1 << i) != 0);
                }
            }
        }
        let share = if solved_pixels > 0 {
            pixels_with_highlight as f64 / solved_pixels as f64
        } else {
            0.0
        };
        Self {
            solved_pixels,
            pixels_with_highlight,
            share,
            per_led,
        }
    }

    /// `verdict` with [`Self::problem`] added to its findings, if there is one.
    pub fn judge(&self, verdict: Verdict) -> Verdict {
        match self.problem() {
            Some((problem, advice)) => {
                let mut problems = verdict.problems;
                let mut all_advice = verdict.advice;
                problems.push(problem);
                all_advice.push(advice);
                Verdict::from_findings(problems, all_advice)
            }
            None => verdict,
        }
    }

    /// What looks wrong when the surface is mostly non-Lambertian (module docs), with what
    /// to try.
    pub fn problem(&self) -> Option<(String, String)> {
        (self.share > MOSTLY_NON_LAMBERTIAN_SHARE).then(|| {
            (
                format!(
                    "the surface is mostly non-Lambertian: {:.0} % of its solved pixels read a \
                     highlight from some LED (more than {:.0} %), so their normals rest on the \
                     remaining three LEDs with nothing to check them",
                    100.0 * self.share,
                    100.0 * MOSTLY_NON_LAMBERTIAN_SHARE
                ),
                "dull the surface (a matte spray or cross-polarised LEDs and camera), or add \
                 LEDs so that more of them see each point away from its mirror direction"
                    .to_string(),
            )
        })
    }
}

/// Share of the solved pixels with a rejected highlight from which a surface counts as glossy
/// ([`looks_glossy`]): a matte sphere has at most 0.1 % (noise), a Ø48 mm sphere under a 10 %
/// GGX coat of roughness 0.25 about 12 %.
pub const GLOSSY_SHARE: f64 = 0.005;

/// Whether `result`'s surface is glossy: at least [`GLOSSY_SHARE`] of its solved pixels had a
/// highlight rejected.
pub fn looks_glossy(result: &PhotometricResult) -> bool {
    HighlightShares::of(result).share >= GLOSSY_SHARE
}

/// On a glossy surface ([`GLOSSY_SHARE`]), the solved pixels whose normal lies within
/// `max_deg` of some LED's half vector under `lights` (an LED's lobe); `None` on a matte one.
/// A lobe's tail reads above the Lambertian model by less than the noise, yet always above,
/// so the measures that sum or rank residuals over the surface — the depth offset search's
/// misfit, the rig check — leave these pixels out: on a Ø48 mm sphere with a 30 % coat the
/// offset misfit was flat within ±60 mm with them and the sphere was placed 37 mm too near.
pub fn glossy_lobes(
    result: &PhotometricResult,
    lights: &Lights,
    max_deg: f32,
) -> Option<Array2<bool>> {
    if !looks_glossy(result) {
        return None;
    }
    let cos_max = f64::from(max_deg).to_radians().cos();
    let normals = &result.field.normals;
    let mask = &result.field.mask;
    let (rows, cols) = mask.dim();
    let flags: Vec<bool> = (0..rows * cols)
        .into_par_iter()
        .map_init(
            || vec![Vector3::zeros(); lights.count()],
            |l, k| {
                let (r, c) = (k / cols, k % cols);
                if !mask[(r, c)] {
                    return false;
                }
                let n = Vector3::new(
                    f64::from(normals[(r, c, 0)]),
                    f64::from(normals[(r, c, 1)]),
                    f64::from(normals[(r, c, 2)]),
                );
                lights.at(r, c, l);
                let v = lights.view_at(r, c);
                l.iter().any(|li| {
                    (li.normalize() + v)
                        .try_normalize(0.0)
                        .is_some_and(|h| n.dot(&h) >= cos_max)
                })
            },
        )
        .collect();
    let lobes = Array2::from_shape_vec((rows, cols), flags).ok()?;
    Some(lobes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::types::NormalField;
    use ndarray::{Array2, Array3};

    /// A 10×10 result, every pixel solved, with `marked` of them carrying a highlight of LED 2.
    fn result(marked: usize) -> PhotometricResult {
        let mut highlights = Array2::zeros((10, 10));
        for (k, h) in highlights.iter_mut().enumerate() {
            if k < marked {
                *h = 0b10;
            }
        }
        PhotometricResult {
            field: NormalField {
                normals: Array3::zeros((10, 10, 3)),
                albedo: Array2::ones((10, 10)),
                mask: Array2::from_elem((10, 10), true),
            },
            lit_count: Array2::from_elem((10, 10), 4),
            highlights,
            object_mask: Array2::from_elem((10, 10), true),
            planes: Vec::new(),
            fill: Array2::from_elem((10, 10), false),
            noise_gains: vec![1.0; 4],
        }
    }

    #[test]
    fn shares_count_the_rejected_leds() {
        let shares = HighlightShares::of(&result(30));
        assert_eq!(shares.solved_pixels, 100);
        assert_eq!(shares.pixels_with_highlight, 30);
        assert_eq!(shares.per_led, vec![0, 30, 0, 0]);
        assert!((shares.share - 0.3).abs() < 1e-12);
        assert!(shares.problem().is_none());
    }

    /// On a glossy surface the pixels whose normal lies within the angle of an LED's half
    /// vector are marked as in its lobe (distant lights, camera along z); on a matte one
    /// (fewer than 0.5 % of the pixels with a highlight) nothing is marked.
    #[test]
    fn lobes_are_marked_on_glossy_surfaces_only() {
        let l = Vector3::new(0.6, 0.0, 0.8);
        let lights = Lights::Distant(vec![l, Vector3::new(-0.6, 0.0, 0.8)]);
        let half = (l + Vector3::z()).normalize();
        let mut glossy = result(10);
        for r in 0..10 {
            // Row r: the normal tilted r·10° from LED 1's half vector, away from LED 2's.
            let n = nalgebra::Rotation3::new(Vector3::y() * (r as f64 * 10f64.to_radians())) * half;
            for c in 0..10 {
                for j in 0..3 {
                    glossy.field.normals[(r, c, j)] = n[j] as f32;
                }
            }
        }
        glossy.field.mask[(0, 9)] = false;
        let lobes = glossy_lobes(&glossy, &lights, 25.0).expect("a glossy surface");
        for r in 0..10 {
            for c in 0..10 {
                let expected = r <= 2 && (r, c) != (0, 9);
                assert_eq!(lobes[(r, c)], expected, "pixel ({r}, {c})");
            }
        }
        assert!(glossy_lobes(&result(0), &lights, 25.0).is_none());
    }

    /// A surface with highlights in most of its pixels is called mostly non-Lambertian and the
    /// verdict refuses it; one with a few is left alone.
    #[test]
    fn a_mostly_non_lambertian_surface_is_refused() {
        let plausible = Verdict::from_findings(Vec::new(), Vec::new());
        assert!(
            HighlightShares::of(&result(50))
                .judge(plausible.clone())
                .is_plausible()
        );
        let verdict = HighlightShares::of(&result(51)).judge(plausible);
        assert!(!verdict.is_plausible());
        assert!(
            verdict.problems[0].contains("mostly non-Lambertian"),
            "{verdict:?}"
        );
        assert!(!verdict.advice.is_empty());
    }
}
