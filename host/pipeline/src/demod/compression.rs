//! Lossy compression of the video, named as the cause it usually is.
//!
//! A codec such as H.264 or HEVC quantises each block's transform coefficients: it removes
//! most of the camera's temporal noise and bends or erases a modulation of a few code values.
//! The decoder's noise estimate then measures the codec, not the camera, and the gains'
//! standard errors no longer bound their error; the artefacts that move with the picture can
//! also show up as an extra modulated component. A container that states a lossy codec
//! ([`LossyCompression`], from `ffprobe`) is therefore checked here:
//!
//! * an LED count mismatch in a lossy video names the compression first, and advises a larger
//!   LED count only for a luminaire that really plays that many;
//! * a decode whose weakest LED swings by fewer than [`MIN_LOSSY_SWING_CODES`] code values
//!   between its on and off chips is implausible. Measured on 640×360 captures of 128 frames
//!   of a sphere (read noise 1 %, background 0.15 of full scale), against the decode of the
//!   same frames uncompressed: with the weakest LED at 2.5 codes, H.264 CRF 18 and HEVC CRF
//!   18–28 moved gains by 1–4 %; at 5 codes, H.264 and HEVC CRF 23–28 by 1.1–4.8 %; at 9.4
//!   codes, CRF 23 by at most 0.5 % and CRF 28 by at most 1.9 % (1 % relative to the gains'
//!   mean). The decode's own standard errors said 0.1–0.4 % throughout: the codec had removed
//!   two thirds of the noise.

use super::error::DemodError;
use super::quality::VerdictStatus;
use super::report::DecodeReport;
use meb_core::capture::{FrameFormat, LossyCompression};

/// Smallest on–off swing, in code values of the video, of the weakest LED that a lossy codec
/// leaves within the decoder's error budget (module docs).
pub const MIN_LOSSY_SWING_CODES: f64 = 8.0;

/// The weakest LED's mean on–off swing in code values of `format`.
pub fn weakest_swing_codes(report: &DecodeReport, format: &FrameFormat) -> Option<f64> {
    let scale = f64::from(format.white_level - format.black_level);
    report
        .per_led
        .iter()
        .map(|led| led.mean_level * scale)
        .reduce(f64::min)
}

/// Adds the compression's problem to a plausible decode's verdict when its weakest LED swings
/// by too few code values, and records the compression in the report.
pub fn check(report: &mut DecodeReport, format: &FrameFormat, compression: &LossyCompression) {
    report.compression = Some(compression.clone());
    let Some(swing) = weakest_swing_codes(report, format) else {
        return;
    };
    if swing >= MIN_LOSSY_SWING_CODES {
        return;
    }
    let (led, _) = report
        .per_led
        .iter()
        .enumerate()
        .map(|(i, led)| (i + 1, led.mean_level))
        .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    let verdict = &mut report.verdict;
    verdict.status = VerdictStatus::Implausible;
    verdict.problems.push(format!(
        "the video is {}: lossy compression bends a modulation this weak (LED {led} swings \
             by {swing:.1} code values, fewer than {MIN_LOSSY_SWING_CODES}), so the gains can be \
             several percent off while the noise the decoder sees is the codec's, not the \
             camera's",
        compression.describe()
    ));
    verdict.advice.push(advice());
}

/// What to try against compression.
fn advice() -> String {
    "record with less compression (a higher bit rate or quality setting, or a lossless codec \
     such as FFV1), or a larger LED swing: brighter LEDs, a darker room, a longer exposure or \
     higher gain with nothing clipping"
        .into()
}

/// The error a lossy video's LED count mismatch is reported as: the compression named first.
pub fn explain(error: DemodError, compression: &LossyCompression) -> DemodError {
    match error {
        DemodError::LedCountMismatch {
            requested,
            detected,
        } if detected > requested => DemodError::Implausible {
            problems: format!(
                "{requested} LEDs requested and the video shows {detected} modulated \
                 components; it is {}, whose artefacts move with the picture and are the usual \
                 cause of an extra component",
                compression.describe()
            ),
            advice: format!(
                "{}; only if the luminaire really plays {detected} LEDs, decode {detected}",
                advice()
            ),
        },
        other => other,
    }
}
