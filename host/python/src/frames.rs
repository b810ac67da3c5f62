//! A frame source over a numpy array of frames (N×H×W, uint8 or uint16, C order), read where
//! it lies: each frame is copied once into the decoder's reused frame storage, as a file
//! source reads each frame from disk.

use meb_core::capture::{
    CaptureError, Frame, FrameFormat, FrameSource, Samples, next_frame_from_storage,
};

/// The code values of a frame stack, borrowed.
#[derive(Debug, Clone, Copy)]
pub enum Codes<'a> {
    /// 8-bit codes.
    U8(&'a [u8]),
    /// 10- to 16-bit codes.
    U16(&'a [u16]),
}

/// Yields the frames of a borrowed frame stack.
#[derive(Debug)]
pub struct ArraySource<'a> {
    codes: Codes<'a>,
    format: FrameFormat,
    count: usize,
    next: usize,
}

impl<'a> ArraySource<'a> {
    /// A source over `count` frames of `format`'s size stored one after the other in `codes`.
    pub fn new(codes: Codes<'a>, format: FrameFormat, count: usize) -> Self {
        Self {
            codes,
            format,
            count,
            next: 0,
        }
    }
}

impl FrameSource for ArraySource<'_> {
    fn format(&self) -> &FrameFormat {
        &self.format
    }

    fn next_frame(&mut self) -> Result<Option<Frame>, CaptureError> {
        next_frame_from_storage(self)
    }

    fn frame_count_hint(&self) -> Option<usize> {
        Some(self.count - self.next)
    }

    fn read_frame_into(&mut self, samples: &mut Samples) -> Result<Option<usize>, CaptureError> {
        if self.next >= self.count {
            return Ok(None);
        }
        let pixels = self.format.pixels();
        let range = self.next * pixels..(self.next + 1) * pixels;
        match self.codes {
            Codes::U8(codes) => {
                if let Samples::U8(plane) = samples {
                    plane.clear();
                    plane.extend_from_slice(&codes[range]);
                } else {
                    *samples = Samples::U8(codes[range].to_vec());
                }
            }
            Codes::U16(codes) => {
                if let Samples::U16(plane) = samples {
                    plane.clear();
                    plane.extend_from_slice(&codes[range]);
                } else {
                    *samples = Samples::U16(codes[range].to_vec());
                }
            }
        }
        self.next += 1;
        Ok(Some(self.next - 1))
    }
}
