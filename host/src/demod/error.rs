//! Errors of the demodulator.

use crate::capture::CaptureError;
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
    /// The capture carries a different number of modulated LEDs than requested.
    #[error(
        "--leds {requested} requested but the video shows {detected} modulated LED(s) \
         (use --leds {detected} or --leds auto)"
    )]
    LedCountMismatch {
        /// Requested LEDs.
        requested: usize,
        /// LEDs seen in the video.
        detected: usize,
    },
    /// No LED modulation at all in the capture.
    #[error("no MEB-FDMA modulation found in the video (is the luminaire on and the rate right?)")]
    NoModulation,
    /// A setting is out of range.
    #[error("invalid decode setting: {0}")]
    InvalidConfig(String),
    /// Every pixel is saturated or under-exposed.
    #[error("every pixel of the region is {0}: nothing to decode")]
    NothingToDecode(&'static str),
}
