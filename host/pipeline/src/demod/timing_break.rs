//! A frame the camera dropped or repeated inside a window, found from the data.
//!
//! A camera that drops frame k writes camera frame j + 1 as frame j for every j ≥ k; one that
//! repeats a frame writes camera frame j − 1 as frame j for j ≥ k. Either way every carrier's
//! phase jumps by the same ρ chips (ρ the chips per frame) at frame k, which no single timing
//! (ρ, e, Δ_i) explains: the window's fit is refused. The break is found with the timing of a
//! part of the window it does not touch: each half of the window is fitted on its own, and
//! its model, extended over the whole window with the frame times
//!
//! ```text
//! t_j = j + s·[j ≥ k]   (s = +1 dropped, −1 repeated; the first half's model)
//! t_j = j − s·[j < k]   (the second half's model)
//! ```
//!
//! gives for every (k, s) the energy of the pixel sample its templates leave unexplained,
//! R(k, s) = tr G − tr(QᵀGQ), Q an orthonormal basis of the constant and the templates and G
//! the Gram matrix of the centred sample (per row band when a rolling shutter was fitted).
//!
//! In a window one timing decoded plausibly, a break counts only when the best (k, s) leaves
//! little more than noise, R ≤ [`EXPLAINED_NOISE`]·(F − 1 − N)·σ²_G, and at least
//! [`BREAK_SIGNIFICANCE`]·σ²_G less than that timing (a likelihood-ratio test, the break's
//! position being its one extra parameter). A break a few frames from an end is absorbed by a
//! whole-window timing with its rate ratio and exposure off: a drop 3 frames from the start of
//! a 128-frame window left 4.3 σ²_G more with that timing than with the break, and its gains
//! were up to 8.5 % off.
//!
//! A refused window has no timing to compete with: there the break must leave at most
//! 1/[`GAIN_OVER_UNBROKEN`] of what the same half's model leaves without a break. A misfit of
//! another cause (a wrong exposure or LED count, an unmodelled nuisance) is explained by no
//! single jump of all carriers at once, so it fails this test. The noise test does not apply
//! there: an object that turns leaves more than noise with any timing (a drop in a 64-frame
//! window of a turning ellipsoid: 3.5–5× the noise energy with the break, 8–210× without), and
//! the pieces the break cuts the window into must then decode plausibly on their own.

use super::DemodError;
use super::fit::TimingModel;
use super::waveform::ReceivedWaveform;
use meb_core::capture::clock::TimestampGap;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// In a window one timing decoded, the best break leaves at most this multiple of the noise
/// energy unexplained …
pub const EXPLAINED_NOISE: f64 = 1.5;
/// … and, in a window one timing decoded, this many noise variances σ²_G less than that
/// timing. Over the break-free windows of the decode sweep, the room tests and the simulated
/// decodes the best break left at most 0.06 σ²_G less; drops 3–109 frames into 128-frame
/// windows of 320×180 captures left 4.3–290 σ²_G less. A break can leave as little as 1 σ²_G
/// less: on 640×360 captures with weak LEDs (0.01–0.02 of full scale under a background of
/// 0.15), a frame dropped or repeated in the middle of 128 frames was matched by one timing
/// with a near-instant exposure and a rate ratio of 1.013, whose sampling instants cross a
/// chip boundary of every carrier at the same frame (1.06 and 1.08 σ²_G more than the break;
/// decoded with that timing, LED 2 came out 5 % low).
pub const BREAK_SIGNIFICANCE: f64 = 0.5;
/// In a refused window, the best break leaves at most 1/this of what the same model leaves
/// without a break (the halves' noise counts an LED a wrong count leaves out, so a noise test
/// would not tell that misfit from a break).
pub const GAIN_OVER_UNBROKEN: f64 = 4.0;

/// What the camera did at a break.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BreakKind {
    /// A camera frame is missing: every later frame is one frame period later.
    Dropped,
    /// A frame is written twice: every later frame is one frame period earlier.
    Repeated,
}

/// A break in the frame timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TimingBreak {
    /// First frame after the break (for a repeated frame: the copy), counted from the
    /// window's first frame.
    pub frame: usize,
    /// What happened.
    pub kind: BreakKind,
}

impl TimingBreak {
    /// The phase step s of every later frame, in frame periods.
    fn step(self) -> i64 {
        match self.kind {
            BreakKind::Dropped => 1,
            BreakKind::Repeated => -1,
        }
    }

    /// The break in words.
    pub fn describe(&self) -> String {
        match self.kind {
            BreakKind::Dropped => format!("a frame dropped before frame {}", self.frame),
            BreakKind::Repeated => format!("frame {} repeating the one before", self.frame),
        }
    }
}

/// One row band of the window's pixel sample: its Gram matrix and its central region row.
pub struct Band {
    /// Gram matrix of the band's centred values (F × F).
    pub gram: DMatrix<f64>,
    /// Region row at the band's centre.
    pub row: f64,
}

/// A half of the window and the timing fitted to it.
pub struct HalfFit<'a> {
    /// The fitted model, frame 0 being the half's first frame.
    pub model: &'a TimingModel,
    /// The half's first frame in the window.
    pub start: usize,
    /// Whether the half lies before the break (its model is right for frames before it).
    pub before: bool,
}

/// The break that best explains `bands` (module docs) with the models of the window's
/// halves, if one counts; `single` is the timing one fit decoded the whole window with
/// (frame 0 its first; `None` when the window was refused), `noise` σ²_G of the whole
/// sample, `frames` the window's length.
pub fn find(
    bands: &[Band],
    halves: &[HalfFit<'_>],
    single: Option<&TimingModel>,
    waves: &[ReceivedWaveform],
    frames: usize,
    noise: f64,
) -> Option<TimingBreak> {
    let leds = waves.len();
    let f = frames;
    if f < 8 || bands.is_empty() || halves.is_empty() {
        return None;
    }
    let trace: f64 = bands.iter().map(|b| b.gram.trace()).sum();
    let mut best: Option<(f64, f64, TimingBreak)> = None;
    for half in halves {
        // Templates over frames −1 … F (index + 1), on the window's clock.
        let columns: Vec<Vec<Vec<f64>>> = bands
            .iter()
            .map(|band| {
                let mut model = half.model.clone();
                let shift = model.timing.rate_ratio * (half.start as f64 + 1.0);
                model.shifts.iter_mut().for_each(|s| *s -= shift);
                model.columns(waves, band.row, f + 2)
            })
            .collect();
        let residual = |at: &dyn Fn(usize) -> usize| -> f64 {
            let explained: f64 = bands
                .iter()
                .zip(&columns)
                .map(|(band, cols)| {
                    let design = DMatrix::from_fn(f, leds + 1, |j, c| cols[c][at(j)]);
                    let q = design.qr().q();
                    (q.transpose() * &band.gram * &q).trace()
                })
                .sum();
            trace - explained
        };
        let unbroken = residual(&|j| j + 1);
        for kind in [BreakKind::Dropped, BreakKind::Repeated] {
            for k in 1..f {
                let candidate = TimingBreak { frame: k, kind };
                let s = candidate.step();
                let at = |j: usize| -> usize {
                    let t = j as i64 + 1;
                    let t = match (half.before, j >= k) {
                        (true, true) => t + s,
                        (false, false) => t - s,
                        _ => t,
                    };
                    t.clamp(0, f as i64 + 1) as usize
                };
                let r = residual(&at);
                if best.as_ref().is_none_or(|(b, _, _)| r < *b) {
                    best = Some((r, unbroken, candidate));
                }
            }
        }
    }
    let (r, unbroken, found) = best?;
    let expected = (f.saturating_sub(1 + leds)).max(1) as f64 * noise;
    // What the whole window's timing leaves (its templates over frames 0 … F − 1).
    let whole = single.filter(|m| m.shifts.len() == leds).map(|model| {
        bands
            .iter()
            .map(|band| {
                let cols = model.columns(waves, band.row, f);
                let design = DMatrix::from_fn(f, leds + 1, |j, c| cols[c][j]);
                let q = design.qr().q();
                band.gram.trace() - (q.transpose() * &band.gram * &q).trace()
            })
            .sum::<f64>()
    });
    match whole {
        Some(w) => r <= EXPLAINED_NOISE * expected && w - r >= BREAK_SIGNIFICANCE * noise,
        None => r * GAIN_OVER_UNBROKEN <= unbroken,
    }
    .then_some(found)
}

/// `error` with the frames the container's timestamps show missing (`gaps`, non-empty) named
/// as its likely cause: a refused window holding such a gap could not be re-aligned.
pub fn explain_gaps(error: DemodError, gaps: &[TimestampGap]) -> DemodError {
    let named = gaps
        .iter()
        .map(|g| format!("{} before frame {}", g.missing, g.frame))
        .collect::<Vec<_>>()
        .join(", ");
    let problem = format!(
        "the container's timestamps show frames missing ({named}): the camera dropped them, \
         and every carrier's phase jumps there"
    );
    let advice = "decode a range of at least two carrier periods clear of the gap (--start, \
                  --frames), or record again with the camera's frame rate fixed (no dropped \
                  frames; on a phone, a shorter clip or a lower resolution)";
    match error {
        DemodError::LedCountMismatch {
            requested,
            detected,
        } if detected > requested => DemodError::Implausible {
            problems: format!(
                "{problem}; {requested} LEDs requested and the video shows {detected} \
                 modulated components, as a break leaves"
            ),
            advice: advice.into(),
        },
        DemodError::Implausible {
            problems,
            advice: a,
        } => DemodError::Implausible {
            problems: format!("{problem}; {problems}"),
            advice: format!("{advice}; {a}"),
        },
        other => other,
    }
}

/// The window's frames re-aligned at `found`: a repeated frame left out (one contiguous
/// piece), or the two pieces either side of a dropped one.
pub fn pieces(found: TimingBreak, frames: usize) -> Vec<std::ops::Range<usize>> {
    match found.kind {
        BreakKind::Repeated => vec![0..found.frame, found.frame + 1..frames],
        BreakKind::Dropped => vec![0..found.frame, found.frame..frames],
    }
}
