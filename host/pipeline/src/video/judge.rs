//! Whether a window's implausible decode is the object's motion or a wrong fit.
//!
//! The decoder's verdict ([`crate::demod::quality`]) refuses a decode that leaves part of an
//! LED's modulation unexplained: U_i, the energy left in LED i's carrier subspace after the
//! fit, above what noise leaves there, counted in noise directions. A wrong timing fit (rate
//! ratio, exposure, shifts, rolling shutter) leaves U_i there — but so does an object that
//! moves during the window, whose brightness ramps and steps have energy at the carriers'
//! low harmonics too. [`super::motion`] measures the motion's own energy E in the same units,
//! and from frames one code period apart, where no LED model enters. So a window is put down
//! to motion when
//!
//! - the verdict's only problems are unexplained modulation (no LED without signal, no gain
//!   uncertain beyond its limit, no timing parameter at the edge of its search),
//! - the object moved ([`super::MotionEstimate::moving`]), and
//! - every LED's unexplained energy U_i fits within the motion's energy E.
//!
//! A still window whose fit leaves modulation unexplained is a wrong fit and is refused, and
//! so is a moving one whose unexplained energy exceeds what its motion holds. A wrong fit
//! smaller than the motion in the same window cannot be told from it this way; the window is
//! then recorded as moving (and the motion policy decides), which is also what the motion
//! itself does to the decode.

use super::motion::MotionEstimate;
use crate::demod::Decoded;
use serde::{Deserialize, Serialize};

/// What a window's decode verdict comes to in a video.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WindowVerdict {
    /// The decoder found the decode plausible.
    Plausible,
    /// Implausible, and the window's motion explains what the fit left over.
    Motion,
    /// Implausible, and motion does not explain it: refused.
    Refused,
    /// Implausible, not explained by motion, kept on request (`--force`).
    Forced,
}

impl WindowVerdict {
    /// Whether the window may be reconstructed.
    pub fn is_usable(self) -> bool {
        self != Self::Refused
    }
}

/// Judges a decode with its motion (module docs); `force` keeps what would be refused.
pub fn judge(decoded: &Decoded, motion: Option<&MotionEstimate>, force: bool) -> WindowVerdict {
    if decoded.report.verdict.is_plausible() {
        return WindowVerdict::Plausible;
    }
    let refused = if force {
        WindowVerdict::Forced
    } else {
        WindowVerdict::Refused
    };
    let Some(motion) = motion.filter(|m| m.moving) else {
        return refused;
    };
    let unexplained: Vec<f64> = decoded
        .report
        .per_led
        .iter()
        .map(|led| &led.quality)
        .filter(|q| q.leaves_modulation_unexplained())
        .map(|q| q.unexplained)
        .collect();
    let only_unexplained =
        !unexplained.is_empty() && unexplained.len() == decoded.report.verdict.problems.len();
    if only_unexplained && unexplained.iter().all(|&u| u <= motion.energy) {
        WindowVerdict::Motion
    } else {
        refused
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::quality::{MAX_UNEXPLAINED, Verdict};
    use crate::demod::{LedQuality, LedReport};
    use meb_core::types::LedImages;
    use ndarray::Array2;

    /// A decode whose LEDs leave `unexplained` noise directions (fraction 1 %) unexplained,
    /// with the verdict the decoder gives that and `extra` problems.
    fn decode(unexplained: &[f64], extra: &[&str]) -> Decoded {
        let per_led: Vec<LedReport> = unexplained
            .iter()
            .enumerate()
            .map(|(i, &u)| LedReport {
                led: i + 1,
                phase_chips: 0.0,
                mean_level: 0.3,
                snr_db: 40.0,
                quality: LedQuality {
                    signal_to_noise: 100.0,
                    unexplained: u,
                    unexplained_fraction: 0.01,
                    gain_uncertainty: 0.001,
                    changing_share: 0.0,
                },
            })
            .collect();
        let mut problems: Vec<String> = per_led
            .iter()
            .filter(|l| l.quality.unexplained > MAX_UNEXPLAINED)
            .map(|l| format!("LED {} unexplained", l.led))
            .collect();
        problems.extend(extra.iter().map(|p| p.to_string()));
        let dim = (4, 4);
        let mut decoded = crate::demod::fixture::decoded(Array2::zeros(dim), Array2::zeros(dim));
        decoded.leds = LedImages {
            images: vec![Array2::zeros(dim); unexplained.len()],
        };
        decoded.report.leds = unexplained.len();
        decoded.report.per_led = per_led;
        decoded.report.verdict = Verdict::from_findings(problems, vec![]);
        decoded
    }

    fn motion(moving: bool, energy: f64) -> MotionEstimate {
        MotionEstimate {
            score: 0.0,
            moving,
            lit_pixels: 1000,
            moving_pixels: 0,
            period_ratio: Some(1.0 + energy),
            energy,
        }
    }

    #[test]
    fn a_plausible_decode_stays_plausible() {
        let d = decode(&[1.0, 2.0, 0.5], &[]);
        assert_eq!(judge(&d, None, false), WindowVerdict::Plausible);
    }

    #[test]
    fn motion_explains_unexplained_modulation_within_its_energy() {
        let d = decode(&[6.0, 2.0, 4.0], &[]);
        assert_eq!(
            judge(&d, Some(&motion(true, 20.0)), false),
            WindowVerdict::Motion
        );
        // More left unexplained than the motion holds: a wrong fit.
        assert_eq!(
            judge(&d, Some(&motion(true, 5.0)), false),
            WindowVerdict::Refused
        );
        assert_eq!(
            judge(&d, Some(&motion(true, 5.0)), true),
            WindowVerdict::Forced
        );
    }

    #[test]
    fn a_still_window_with_modulation_unexplained_is_refused() {
        let d = decode(&[6.0, 2.0, 4.0], &[]);
        assert_eq!(
            judge(&d, Some(&motion(false, 20.0)), false),
            WindowVerdict::Refused
        );
        assert_eq!(judge(&d, None, false), WindowVerdict::Refused);
        assert!(!WindowVerdict::Refused.is_usable());
        assert!(WindowVerdict::Forced.is_usable());
    }

    #[test]
    fn other_problems_are_never_put_down_to_motion() {
        let d = decode(
            &[6.0, 2.0, 4.0],
            &["the rate ratio sits at the edge of the searched range"],
        );
        assert_eq!(
            judge(&d, Some(&motion(true, 1e6)), false),
            WindowVerdict::Refused
        );
    }
}
