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
//!
//! A single part's offset is its distance from the camera, which the shape does not need: when
//! its misfit is not clearly lower than 20 mm nearer and farther either (LEDs in the camera's
//! plane: a Ø48 mm sphere at 320×180, t 0.6 / 0.6), the depth is kept but reported as
//! unmeasured ([`AbsoluteDepth`]), so that no one takes `depth.npy`'s distances for
//! measurements.

use super::offset::{Unplaced, WhyUnplaced};
use crate::demod::quality::Verdict;
use crate::integrate::Integration;
use meb_core::types::ConfidenceCounts;

/// Least share of the reconstructed pixels that must be measured by three or more LEDs. On a
/// sweep of simulated still captures (640×360, three thesis rigs, spheres, ellipsoids, blobby
/// shapes and cubes at several poses) every reconstruction within a few mm of the truth had a
/// share of 0.77 or more (spheres 0.78, ellipsoids 0.77–0.98, blobby shapes 0.83–0.98); the
/// two-LED cubes that were 8–13 mm off had 0.04–0.08, and the turning corner-on cube's
/// windows 0.27–0.39. The windows of the turning ellipsoid (1280×720, thesis-dynamic, 0.4–1.6
/// mm) go down to 0.688. A floor of 0.5 is too low: the corner-on cube captured without
/// clipping (`meb simulate --auto-exposure`, out-of-plane and dynamic rigs, 320×180 and
/// 1280×720), one face measured and the other lit by two LEDs and tilted by the integrator's
/// guess, has a share of 0.505–0.507 at 5.1–11 mm depth RMSE.
pub const MIN_MEASURED_SHARE: f64 = 0.6;

/// What the check found: the verdict and the figures behind it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Support {
    /// Share of the reconstructed pixels measured by three or more LEDs.
    pub measured_share: f64,
    /// Whether the depth's distance from the camera was measured.
    pub absolute_depth: AbsoluteDepth,
    /// Plausible, or what looks wrong and what to try.
    pub verdict: Verdict,
}

/// Whether a reconstruction's distance from the camera rests on the lighting (module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum AbsoluteDepth {
    /// Every part's offset was scanned for, and its near-field misfit is clearly higher
    /// 20 mm nearer and farther.
    Measured,
    /// One part whose misfit is not clearly higher `within_mm` nearer or farther: its shape is
    /// measured, its distance from the camera is the misfit's shallow minimum.
    Unmeasured {
        /// The distance tested, mm.
        within_mm: f64,
    },
    /// Not judged: distant lights (no offset is searched), or offsets carried from a warm
    /// start (a video's earlier window), or a part too small to search.
    #[default]
    Unjudged,
}

impl AbsoluteDepth {
    /// One line for reports: what is known of the depth's distance from the camera.
    pub fn describe(&self) -> String {
        match self {
            Self::Measured => "measured by the near-field lighting".into(),
            Self::Unmeasured { within_mm } => format!(
                "not measured: the lighting misfit is not clearly worse {within_mm:.0} mm \
                 nearer or farther, so the shape is measured but its distance from the camera \
                 is not (place it with a range camera, --tof, or take depths as relative)"
            ),
            Self::Unjudged => "not judged (distant lights, or carried from a warm start)".into(),
        }
    }
}

/// Judges the support of `integration`'s depth, whose offset search left the parts
/// `unplaced` and judged every part's placement by a scan when `scanned` (module docs).
pub(super) fn judge(integration: &Integration, unplaced: &[Unplaced], scanned: bool) -> Support {
    let measured_share = ConfidenceCounts::of(&integration.confidence).measured_share();
    // A single part that is only flat keeps its depth: its distance is what is unmeasured.
    let single_flat = match unplaced {
        [u] if integration.parts == 1 => match u.why {
            WhyUnplaced::Flat { within_mm } => Some(within_mm),
            WhyUnplaced::AtEdge { .. } => None,
        },
        _ => None,
    };
    let absolute_depth = match single_flat {
        Some(within_mm) => AbsoluteDepth::Unmeasured { within_mm },
        None if scanned && unplaced.is_empty() => AbsoluteDepth::Measured,
        None => AbsoluteDepth::Unjudged,
    };
    let unplaced = if single_flat.is_some() { &[] } else { unplaced };
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
        absolute_depth,
        verdict: Verdict::from_findings(problems, advice),
    }
}

#[cfg(test)]
mod tests {
    use super::super::Reconstruction;
    use super::super::tests::still_sphere;
    use super::*;
    use meb_core::types::Confidence;

    /// The still sphere's cold reconstruction (a Ø60 mm sphere, thesis-dynamic rig at 320×180).
    fn sphere() -> Reconstruction {
        still_sphere().cold
    }

    #[test]
    fn a_sphere_rests_on_its_measurements() {
        let r = sphere();
        assert!(r.support.verdict.is_plausible(), "{:?}", r.support);
        assert!(r.support.measured_share >= MIN_MEASURED_SHARE);
        assert_eq!(r.support, judge(&r.integration, &[], true));
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
        let support = judge(&r.integration, &[], true);
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
        let support = judge(&r.integration, &unplaced, true);
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
        assert_eq!(support.absolute_depth, AbsoluteDepth::Unjudged);
    }

    #[test]
    fn a_single_part_without_a_measured_distance_is_kept_and_reported() {
        let r = sphere();
        assert_eq!(r.integration.parts, 1);
        assert_eq!(r.support.absolute_depth, AbsoluteDepth::Measured);
        let flat = [Unplaced {
            part: 0,
            pixels: 9000,
            why: WhyUnplaced::Flat { within_mm: 20.0 },
        }];
        let support = judge(&r.integration, &flat, true);
        assert!(support.verdict.is_plausible(), "{support:?}");
        assert_eq!(
            support.absolute_depth,
            AbsoluteDepth::Unmeasured { within_mm: 20.0 }
        );
        assert!(support.absolute_depth.describe().contains("not measured"));
        // Without a scan (a warm start) nothing is claimed; at the range's edge it is refused.
        assert_eq!(
            judge(&r.integration, &[], false).absolute_depth,
            AbsoluteDepth::Unjudged
        );
        let at_edge = [Unplaced {
            why: WhyUnplaced::AtEdge { reach_mm: 60.0 },
            ..flat[0]
        }];
        assert!(!judge(&r.integration, &at_edge, true).verdict.is_plausible());
    }
}
