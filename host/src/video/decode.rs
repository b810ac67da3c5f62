//! Decoding one window of frames already in memory with the demodulator
//! ([`crate::demod::decode`]), as one decoding window.

use crate::capture::memory::MemorySource;
use crate::capture::{Frame, FrameFormat, Samples};
use crate::demod::{DecodeConfig, Decoded, DemodError, decode};

/// Decodes `frames` (all of `format`'s size) as a single window with `config`; the frame
/// range settings of `config` (`start`, `frames`) are ignored.
pub fn decode_frames(
    frames: &[Samples],
    format: &FrameFormat,
    config: &DecodeConfig,
) -> Result<Decoded, DemodError> {
    let frame_bytes = format.pixels() * Samples::bytes_per_sample(format.bit_depth);
    let config = DecodeConfig {
        start: 0,
        frames: None,
        window_bytes: config
            .window_bytes
            .max(frame_bytes.saturating_mul(frames.len())),
        ..config.clone()
    };
    let frames = frames
        .iter()
        .enumerate()
        .map(|(index, samples)| Frame {
            index,
            samples: samples.clone(),
        })
        .collect();
    let mut source = MemorySource::new(format.clone(), frames)?;
    decode(&mut source, &config, &mut |_, _| {})
}
