//! Errors of the demodulator.

use meb_core::capture::CaptureError;
use thiserror::Error;

/// Why a capture cannot be decoded.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DemodError {
    /// Reading frames failed.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// Fewer frames than one carrier frame of n = 2^(N+1) chips.
    #[error("{got} frames available, decoding {leds} LEDs needs at least {need}")]
    TooFewFrames {
        /// Frames read.
        got: usize,
        /// Frames needed.
        need: usize,
        /// LED count.
        leds: usize,
    },
    /// The start frame lies at or beyond the end of the capture.
    #[error("cannot start at frame {start}: the capture has only {available} frames")]
    StartBeyondEnd {
        /// Frames to skip.
        start: usize,
        /// Frames the capture holds.
        available: usize,
    },
    /// The capture carries a different number of modulated LEDs than requested.
    #[error(
        "{requested} LEDs requested but the video shows {detected} modulated LED(s) \
         (decode {detected}, or let the decoder detect the count)"
    )]
    LedCountMismatch {
        /// Requested LEDs.
        requested: usize,
        /// LEDs seen in the video.
        detected: usize,
    },
    /// Fewer modulated LEDs than requested in the pixels that do not clip, and enough clipped
    /// pixels to hold the others: the count cannot be told, and decoding fewer would be wrong.
    #[error(
        "{requested} LEDs requested but the pixels that do not clip show {detected} modulated \
         LED(s), and {clipped_percent:.1} % of the pixels examined clip at full scale: the \
         others may light only those. Lower the camera's exposure or gain (or the LEDs' \
         brightness) until nothing clips, then capture again (a simulated capture: `meb \
         simulate --auto-exposure`)"
    )]
    LedsHiddenByClipping {
        /// Requested LEDs.
        requested: usize,
        /// LEDs seen in the pixels that do not clip.
        detected: usize,
        /// Share of the examined pixels that clip, percent.
        clipped_percent: f64,
    },
    /// No LED modulation at all in the capture.
    #[error(
        "no MEB-FDMA modulation found in the video (is the luminaire on, in view, and its \
         chip rate within the searched range of the frame rate?)"
    )]
    NoModulation,
    /// A setting is out of range.
    #[error("invalid decode setting: {0}")]
    InvalidConfig(String),
    /// Every pixel is saturated or under-exposed.
    #[error("every pixel of the region is {0}: nothing to decode")]
    NothingToDecode(&'static str),
    /// The decoded images would not be trustworthy.
    #[error("the decode looks implausible: {problems}; try: {advice}")]
    Implausible {
        /// What looks wrong.
        problems: String,
        /// What to try.
        advice: String,
    },
    /// A modulation depth outside (0, 1].
    #[error("modulation depth {value} is outside (0, 1]")]
    InvalidDepth {
        /// The depth given.
        value: f64,
    },
    /// An off fraction outside [0, 1).
    #[error("off-chip light fraction {value} is outside [0, 1) (1 would leave no modulation)")]
    InvalidOffFraction {
        /// The fraction given.
        value: f64,
    },
    /// Per-LED depths that do not match the LED count.
    #[error(
        "{given} modulation depths given for {leds} LEDs (give one for every LED or one per LED)"
    )]
    DepthCount {
        /// Values given.
        given: usize,
        /// LEDs decoded.
        leds: usize,
    },
    /// The largest low-risk depths need the chip rate, which the capture did not give.
    #[error(
        "the largest low-risk depths depend on the chip rate, and the decoded chip rate \
         {chip_rate_hz} Hz is not one a luminaire plays (give the camera's frame rate, or the \
         depths themselves)"
    )]
    DepthNeedsChipRate {
        /// The chip rate the decode found (frame rate × rate ratio).
        chip_rate_hz: f64,
    },
    /// An image could not be assembled from the decoded values.
    #[error("cannot assemble the decoded images")]
    Shape(#[from] ndarray::ShapeError),
}
