//! Whether a reconstruction's depth rests on what the LEDs measured (a result is right or
//! refused).
//!
//! Photometric stereo measures a pixel's normal where three or more LEDs light it. Two LEDs
//! only bound the normal to a circle, on which the integrator chooses by integrability; a
//! filled pixel has no measurement at all. Where such pixels make up most of the surface, its
//! shape is the integrator's guess: a flat face lit by two LEDs fits every tilt about its
//! circle equally well (the turning 60 mm cube seen corner-on, 640×360: windows reported as
//! reconstructed at 8–42 mm depth RMSE). So at least [`MIN_MEASURED_SHARE`] of the
//! reconstructed pixels must be measured ([`Confidence::Measured`]).
//!
//! The depth of each separately integrated part is placed by the near-field misfit
//! ([`super::offset`]); a part whose misfit kept falling to the edge of the searched range was
//! not placed at all (an in-plane capture of a sphere before a cube 70 mm behind it: the cube
//! left at the −70 mm edge, 20 mm from its depth), and the result is refused too. So is one of
//! several parts whose misfit at its minimum is not clearly lower than 20 mm nearer and farther
//! (the same capture decoded along its exposure valley: the cube placed 26 mm off, inside the
//! range): the parts' depths relative to each other rest on nothing else.

use super::offset::{Unplaced, WhyUnplaced};
use crate::demod::quality::Verdict;
use crate::integrate::Integration;
use crate::types::ConfidenceCounts;

/// Least share of the reconstructed pixels that must be measured by three or more LEDs. On a
/// sweep of simulated still captures (640×360, three thesis rigs, spheres, ellipsoids, blobby
/// shapes and cubes at several poses) every reconstruction within a few mm of the truth had a
/// share of 0.77 or more (spheres 0.78, ellipsoids 0.77–0.98, blobby shapes 0.83–0.98); the
/// two-LED cubes that were 8–13 mm off had 0.04–0.08, and the turning corner-on cube's
/// windows 0.27–0.39.
pub const MIN_MEASURED_SHARE: f64 = 0.5;

/// What the check found: the verdict and the figure behind it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Support {
    /// Share of the reconstructed pixels measured by three or more LEDs.
    pub measured_share: f64,
    /// Plausible, or what looks wrong and what to try.
    pub verdict: Verdict,
}

/// Judges the support of `integration`'s depth, whose offset search left the parts
/// `unplaced` (module docs).
pub(super) fn judge(integration: &Integration, unplaced: &[Unplaced]) -> Support {
    let measured_share = ConfidenceCounts::of(&integration.confidence).measured_share();
    let mut problems = Vec::new();
    let mut advice = Vec::new();
    if measured_share < MIN_MEASURED_SHARE {
        problems.push(format!(
            "only {:.0} % of the reconstructed surface is lit by three or more LEDs (at least \
             {:.0} % needed): the rest is lit by two LEDs or filled, whose tilt the integrator \
             guesses",
            100.0 * measured_share,
            100.0 * MIN_MEASURED_SHARE
        ));
        advice.push(
            "turn the object or move the LEDs so that three or more light most of it".to_string(),
        );
    }
    for u in unplaced {
        let why = match u.why {
            WhyUnplaced::AtEdge { reach_mm } => format!(
                "its lighting misfit kept falling to the edge of the ±{reach_mm:.0} mm search"
            ),
            WhyUnplaced::Flat { within_mm } => format!(
                "its lighting misfit is not clearly worse {within_mm:.0} mm nearer or farther, \
                 so its depth relative to the other parts is not measured"
            ),
        };
        problems.push(format!(
            "part {} ({} pixels) could not be placed in depth: {why}",
            u.part, u.pixels
        ));
    }
    if !unplaced.is_empty() {
        advice.push(
            "reconstruct each object alone (--mask), or place the objects with a range camera \
             (--tof)"
                .to_string(),
        );
    }
    Support {
        measured_share,
        verdict: Verdict::from_findings(problems, advice),
    }
}

#[cfg(test)]
mod tests {
    use super::super::Reconstruction;
    use super::super::tests::still_sphere;
    use super::*;
    use crate::types::Confidence;

    /// The still sphere's cold reconstruction (a Ø60 mm sphere, thesis-dynamic rig at 320×180).
    fn sphere() -> Reconstruction {
        still_sphere().cold
    }

    #[test]
    fn a_sphere_rests_on_its_measurements() {
        let r = sphere();
        assert!(r.support.verdict.is_plausible(), "{:?}", r.support);
        assert!(r.support.measured_share >= MIN_MEASURED_SHARE);
        assert_eq!(r.support, judge(&r.integration, &[]));
    }

    #[test]
    fn a_surface_mostly_lit_by_two_leds_is_refused() {
        // The sphere with three in five of its measured pixels taken as two-LED ones (a
        // decoded capture of the corner-on cube: `meb reconstruct` and `meb video` end to end,
        // tests/).
        let mut r = sphere();
        let mut n = 0;
        for k in r.integration.confidence.iter_mut() {
            if *k == Confidence::Measured {
                if n % 5 < 3 {
                    *k = Confidence::TwoLeds;
                }
                n += 1;
            }
        }
        let support = judge(&r.integration, &[]);
        assert!(support.measured_share < MIN_MEASURED_SHARE, "{support:?}");
        assert!((support.measured_share - r.support.measured_share * 0.4).abs() < 0.01);
        assert!(!support.verdict.is_plausible());
        assert!(support.verdict.problems[0].contains("three or more LEDs"));
        assert!(!support.verdict.advice.is_empty());
    }

    #[test]
    fn a_part_its_offset_search_could_not_place_is_refused() {
        let r = sphere();
        let unplaced = [
            Unplaced {
                part: 1,
                pixels: 1260,
                why: WhyUnplaced::AtEdge { reach_mm: 70.0 },
            },
            Unplaced {
                part: 2,
                pixels: 856,
                why: WhyUnplaced::Flat { within_mm: 20.0 },
            },
        ];
        let support = judge(&r.integration, &unplaced);
        assert!(!support.verdict.is_plausible());
        assert_eq!(support.measured_share, r.support.measured_share);
        let problems = &support.verdict.problems;
        assert!(
            problems[0].contains("part 1 (1260 pixels) could not be placed")
                && problems[0].contains("edge of the ±70 mm search"),
            "{support:?}"
        );
        assert!(
            problems[1].contains("part 2 (856 pixels) could not be placed")
                && problems[1].contains("20 mm nearer or farther"),
            "{support:?}"
        );
        assert!(support.verdict.advice[0].contains("--mask"));
    }
}
