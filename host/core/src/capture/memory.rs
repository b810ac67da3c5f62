//! An in-memory frame source: frames already decoded or rendered (tests, benchmarks, the
//! simulator's output).

use super::{CaptureError, Frame, FrameFormat, FrameSource};
use std::collections::VecDeque;

/// Yields frames held in memory, moving each out as it is read.
#[derive(Debug, Clone)]
pub struct MemorySource {
    format: FrameFormat,
    frames: VecDeque<Frame>,
}

impl MemorySource {
    /// A source over `frames`, which must all match `format`'s size.
    pub fn new(format: FrameFormat, frames: Vec<Frame>) -> Result<Self, CaptureError> {
        for frame in &frames {
            if frame.samples.len() != format.pixels() {
                return Err(CaptureError::Other(format!(
                    "frame {} has {} samples, expected {}x{}",
                    frame.index,
                    frame.samples.len(),
                    format.width,
                    format.height
                )));
            }
        }
        Ok(Self {
            format,
            frames: frames.into(),
        })
    }
}

impl FrameSource for MemorySource {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        Ok(self.frames.pop_front())
    }

    fn frame_count_hint(&self) -> Option<usize> {
        Some(self.frames.len())
    }
}
