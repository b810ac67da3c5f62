//! Pixel binning: every k×k block of camera pixels becomes one pixel of a k-times smaller
//! frame, as a camera's on-sensor binning does.
//!
//! The demodulation is linear in the code values (docs/maths/demodulation.md#the-matched-filter:
//! each LED image is a projection of the
//! pixel's time series on its carrier), so demodulating the sum of a block's samples gives the
//! sum of the block's LED images: binning before the decode costs the LED images nothing but
//! resolution, while the decode, the photometric stereo and the integration each see k² times
//! fewer pixels and the shot noise of a binned pixel falls by k relative to its signal. The
//! binned pixel's ray is the one through the block's centre ([`crate::rig::Camera::binned`]).
//!
//! A block's samples are summed when the sum fits in 16 bits (black and white levels scale by
//! k², the bit depth grows by ⌈log₂ k²⌉: 8-bit 2×2 blocks give 10-bit samples); otherwise they
//! are averaged with rounding at the stream's own depth and levels. A block with any saturated
//! sample (at or above the last code that rounds to white, as the decoder (`meb-pipeline`) classifies
//! pixels) is saturated as a whole: its sum would look unsaturated but is not linear in the
//! light. Rows and columns that do not fill a whole block at the bottom and right are dropped.
//! Binning code values is exact only for linear codes: a linearising decoder must refuse binned
//! streams (the video pipeline does).

use super::{CaptureError, FrameFormat, FrameSource, Samples};

/// How a block's samples combine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Combine {
    /// The block's sum (it fits in 16 bits).
    Sum,
    /// The block's mean, rounded (the sum would not fit).
    Mean,
}

/// The geometry and code arithmetic of binning one stream by a factor.
#[derive(Debug, Clone, PartialEq)]
pub struct Binning {
    factor: usize,
    combine: Combine,
    /// The source's format.
    source: FrameFormat,
    /// The binned frames' format.
    binned: FrameFormat,
    /// Source codes at or above this are saturated.
    saturated_from: u32,
    /// The code a saturated block gets.
    saturated_code: u32,
}

impl Binning {
    /// Binning of frames of `source` format into `factor`×`factor` blocks; refused when the
    /// factor is 0 or larger than the frame, or the format's levels are not usable.
    pub fn new(source: &FrameFormat, factor: usize) -> Result<Self, CaptureError> {
        if factor == 0 || factor > source.width || factor > source.height {
            return Err(CaptureError::Other(format!(
                "cannot bin {}x{} frames by {factor}: the factor must be between 1 and the \
                 frame's smaller side",
                source.width, source.height
            )));
        }
        let usable = source.black_level.is_finite()
            && source.white_level.is_finite()
            && source.black_level < source.white_level
            && (1..=16).contains(&source.bit_depth);
        if !usable {
            return Err(CaptureError::Other(format!(
                "cannot bin a stream of {} bits with black level {} and white level {}",
                source.bit_depth, source.black_level, source.white_level
            )));
        }
        let block = (factor * factor) as u32;
        let extra_bits = block.next_power_of_two().trailing_zeros() as u8;
        let max_code = (1u32 << source.bit_depth) - 1;
        let combine = if source.bit_depth + extra_bits <= 16 {
            Combine::Sum
        } else {
            Combine::Mean
        };
        let mut binned = FrameFormat {
            width: source.width / factor,
            height: source.height / factor,
            ..source.clone()
        };
        if combine == Combine::Sum {
            let k2 = block as f32;
            binned.bit_depth += extra_bits;
            binned.black_level *= k2;
            binned.white_level *= k2;
        }
        let saturated_from = source.saturated_from();
        let saturated_code = match combine {
            Combine::Sum => max_code * block,
            Combine::Mean => max_code,
        };
        Ok(Self {
            factor,
            combine,
            source: source.clone(),
            binned,
            saturated_from,
            saturated_code,
        })
    }

    /// The binned frames' format.
    pub fn format(&self) -> &FrameFormat {
        &self.binned
    }

    /// Bins one source frame (`width·height` samples, row-major) into `out`, reusing its
    /// storage; `index` names the frame in errors.
    pub fn bin(
        &self,
        frame: &Samples,
        index: usize,
        out: &mut Samples,
    ) -> Result<(), CaptureError> {
        let (width, height) = (self.source.width, self.source.height);
        if frame.len() != width * height {
            return Err(CaptureError::SizeMismatch {
                index,
                got_width: frame.len() / height.max(1),
                got_height: height,
                width,
                height,
            });
        }
        let mut codes = match std::mem::replace(out, Samples::U8(Vec::new())) {
            Samples::U16(v) => v,
            Samples::U8(_) => Vec::new(),
        };
        codes.resize(self.binned.width * self.binned.height, 0);
        match frame {
            Samples::U8(v) => self.bin_codes(v, &mut codes),
            Samples::U16(v) => self.bin_codes(v, &mut codes),
        }
        *out = if self.binned.bit_depth <= 8 {
            // A mean keeps the source's depth: 8-bit streams binned by more than 16 stay 8-bit.
            Samples::U8(codes.iter().map(|&c| c as u8).collect())
        } else {
            Samples::U16(codes)
        };
        Ok(())
    }

    /// Sums (or averages) each block of `codes` into `out` (one entry per binned pixel): by
    /// rows for the common factors (the block's columns a fixed-size array the compiler
    /// unrolls), block by block otherwise.
    fn bin_codes<C: Copy + Ord + Into<u32>>(&self, codes: &[C], out: &mut [u16]) {
        match self.factor {
            2 => self.bin_rows::<C, 2>(codes, out),
            3 => self.bin_rows::<C, 3>(codes, out),
            4 => self.bin_rows::<C, 4>(codes, out),
            _ => self.bin_blocks(codes, out),
        }
    }

    /// The code of a block from its sum and its brightest sample.
    #[inline(always)]
    fn block_code(&self, sum: u64, brightest: u32) -> u16 {
        let code = if brightest >= self.saturated_from {
            self.saturated_code
        } else {
            let block = (self.factor * self.factor) as u64;
            match self.combine {
                // Fits: the bit depth grew by enough for the sum (`Binning::new`).
                Combine::Sum => sum as u32,
                Combine::Mean => ((sum + block / 2) / block) as u32,
            }
        };
        code as u16
    }

    /// [`Self::bin_codes`] for a factor `K` known at compile time: each output row first adds
    /// its `K` source rows column by column (a loop the compiler vectorises), then sums the
    /// columns of each block. Saturation is rare, so the brightest sample of each block is
    /// looked for only when a source row's brightest sample saturates.
    fn bin_rows<C: Copy + Ord + Into<u32>, const K: usize>(&self, codes: &[C], out: &mut [u16]) {
        let (width, binned_width) = (self.source.width, self.binned.width);
        let used = binned_width * K;
        let mut columns = vec![0u32; used];
        let mut brightest = vec![0u32; binned_width];
        for (row, out_row) in out.chunks_exact_mut(binned_width).enumerate() {
            let rows = (row * K..row * K + K).map(|r| &codes[r * width..r * width + used]);
            columns.fill(0);
            let mut saturated = false;
            for source_row in rows.clone() {
                for (column, &c) in columns.iter_mut().zip(source_row) {
                    *column += c.into();
                }
                // The maximum in the samples' own width (16 or 8 lanes per instruction).
                let row_max = source_row.iter().copied().max().map_or(0, Into::into);
                saturated |= row_max >= self.saturated_from;
            }
            if saturated {
                brightest.fill(0);
                for source_row in rows {
                    let (blocks, _) = source_row.as_chunks::<K>();
                    for (bright, block) in brightest.iter_mut().zip(blocks) {
                        *bright = block.iter().map(|&c| c.into()).fold(*bright, u32::max);
                    }
                }
            }
            let (blocks, _) = columns.as_chunks::<K>();
            for (col, (o, block)) in out_row.iter_mut().zip(blocks).enumerate() {
                let bright = if saturated { brightest[col] } else { 0 };
                *o = self.block_code(u64::from(block.iter().sum::<u32>()), bright);
            }
        }
    }

    /// [`Self::bin_codes`] for any factor, block by block.
    fn bin_blocks<C: Copy + Into<u32>>(&self, codes: &[C], out: &mut [u16]) {
        let (k, width) = (self.factor, self.source.width);
        for (row, out_row) in out.chunks_exact_mut(self.binned.width).enumerate() {
            for (col, o) in out_row.iter_mut().enumerate() {
                let (mut sum, mut brightest) = (0u64, 0u32);
                for r in row * k..row * k + k {
                    let start = r * width + col * k;
                    for &c in &codes[start..start + k] {
                        let c: u32 = c.into();
                        sum += u64::from(c);
                        brightest = brightest.max(c);
                    }
                }
                *o = self.block_code(sum, brightest);
            }
        }
    }
}

/// A [`FrameSource`] that bins every frame of another ([`Binning`]).
pub struct BinnedSource {
    inner: Box<dyn FrameSource>,
    binning: Binning,
    /// The last source frame, its storage reused.
    full: Samples,
}

impl BinnedSource {
    /// Bins the frames of `inner` by `factor` (see [`Binning::new`] for what is refused).
    pub fn new(inner: Box<dyn FrameSource>, factor: usize) -> Result<Self, CaptureError> {
        let binning = Binning::new(inner.format(), factor)?;
        Ok(Self {
            inner,
            binning,
            full: Samples::U8(Vec::new()),
        })
    }
}

impl FrameSource for BinnedSource {
    fn format(&self) -> &FrameFormat {
        self.binning.format()
    }

    fn next_frame(&mut self) -> Result<Option<super::Frame>, CaptureError> {
        super::next_frame_from_storage(self)
    }

    fn frame_count_hint(&self) -> Option<usize> {
        self.inner.frame_count_hint()
    }

    fn lossy_compression(&self) -> Option<super::LossyCompression> {
        self.inner.lossy_compression()
    }

    fn timestamp_gaps(&self) -> Vec<super::clock::TimestampGap> {
        self.inner.timestamp_gaps()
    }

    fn read_frame_into(&mut self, samples: &mut Samples) -> Result<Option<usize>, CaptureError> {
        let Some(index) = self.inner.read_frame_into(&mut self.full)? else {
            return Ok(None);
        };
        self.binning.bin(&self.full, index, samples)?;
        Ok(Some(index))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::Frame;
    use crate::capture::memory::MemorySource;

    fn format(width: usize, height: usize, bit_depth: u8) -> FrameFormat {
        FrameFormat::full_range(width, height, bit_depth, 960.0)
    }

    /// 8-bit 2×2 blocks are summed into 10-bit codes with scaled levels; a partial last row
    /// and column are dropped; a block with one saturated sample is saturated.
    #[test]
    fn blocks_are_summed_and_saturation_spreads_to_the_block() {
        let binning = Binning::new(&format(5, 3, 8), 2).expect("valid binning");
        let f = binning.format();
        assert_eq!((f.width, f.height, f.bit_depth), (2, 1, 10));
        assert_eq!((f.black_level, f.white_level), (0.0, 1020.0));
        #[rustfmt::skip]
        let codes = vec![
            1, 2, 3, 254, 9,
            4, 5, 6, 255, 9,
            7, 7, 7, 7, 7,
        ];
        let mut out = Samples::U8(Vec::new());
        binning
            .bin(&Samples::U8(codes), 0, &mut out)
            .expect("right size");
        assert_eq!(out, Samples::U16(vec![12, 1020]));
        let limits = crate::capture::CodeLimits::new(f, 0.0);
        assert!(limits.classify(1020).0 && !limits.classify(4 * 254).0);
    }

    /// Codes that would overflow 16 bits are averaged at the stream's depth; limited-range
    /// levels stay usable, and an unsaturated block never reaches the binned white.
    #[test]
    fn wide_codes_are_averaged_and_limited_range_keeps_its_levels() {
        let binning = Binning::new(&format(2, 2, 16), 2).expect("valid binning");
        assert_eq!(binning.format().bit_depth, 16);
        let mut out = Samples::U8(Vec::new());
        binning
            .bin(&Samples::U16(vec![1000, 1001, 1002, 1002]), 0, &mut out)
            .expect("right size");
        assert_eq!(out, Samples::U16(vec![1001]));

        let mut tv = format(2, 2, 8);
        (tv.black_level, tv.white_level) = (16.0, 235.0);
        let binning = Binning::new(&tv, 2).expect("valid binning");
        let limits = crate::capture::CodeLimits::new(binning.format(), 0.0);
        binning
            .bin(&Samples::U8(vec![234, 234, 234, 234]), 0, &mut out)
            .expect("right size");
        let Samples::U16(v) = &out else {
            panic!("binned 8-bit codes are 16-bit samples")
        };
        assert!(!limits.classify(v[0]).0, "{v:?} is not saturated");
        binning
            .bin(&Samples::U8(vec![16, 16, 16, 235]), 0, &mut out)
            .expect("right size");
        let Samples::U16(v) = &out else {
            panic!("binned 8-bit codes are 16-bit samples")
        };
        assert!(limits.classify(v[0]).0, "{v:?} is saturated");
    }

    /// The row kernels of factors 2–4 give what the block-by-block loop gives, on 8- and
    /// 16-bit codes with saturated samples, in both summing and averaging modes.
    #[test]
    fn row_kernels_equal_the_block_loop() {
        let (width, height) = (37, 26);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for bits in [8u8, 12, 16] {
            let top = (1u64 << bits) - 1;
            // Every 97th sample saturated.
            let codes: Vec<u16> = (0..width * height)
                .map(|i| if i % 97 == 0 { top } else { next() % (top + 1) } as u16)
                .collect();
            for k in 2..=4 {
                let binning = Binning::new(&format(width, height, bits), k).expect("valid");
                let n = binning.format().width * binning.format().height;
                let (mut rows, mut blocks) = (vec![0u16; n], vec![0u16; n]);
                if bits == 8 {
                    let narrow: Vec<u8> = codes.iter().map(|&c| c as u8).collect();
                    binning.bin_codes(&narrow, &mut rows);
                    binning.bin_blocks(&narrow, &mut blocks);
                } else {
                    binning.bin_codes(&codes, &mut rows);
                    binning.bin_blocks(&codes, &mut blocks);
                }
                assert_eq!(rows, blocks, "{bits} bits, factor {k}");
                assert!(
                    rows.contains(&(binning.saturated_code as u16)),
                    "{bits}, {k}"
                );
            }
        }
    }

    #[test]
    fn impossible_factors_and_wrong_frames_are_refused() {
        for factor in [0, 4] {
            assert!(Binning::new(&format(5, 3, 8), factor).is_err(), "{factor}");
        }
        let binning = Binning::new(&format(4, 4, 8), 2).expect("valid binning");
        let mut out = Samples::U8(Vec::new());
        let err = binning
            .bin(&Samples::U8(vec![0; 12]), 7, &mut out)
            .expect_err("a short frame");
        assert!(err.to_string().contains("frame 7"), "{err}");
    }

    /// The source adapter bins every frame, keeps indices and the length hint, and ends
    /// where its source ends.
    #[test]
    fn a_binned_source_bins_every_frame() {
        let frames = (0..3u8)
            .map(|i| Frame {
                index: usize::from(i),
                samples: Samples::U8((0..16).map(|p| p + i).collect()),
            })
            .collect();
        let source = MemorySource::new(format(4, 4, 8), frames).expect("whole frames");
        let mut binned = BinnedSource::new(Box::new(source), 2).expect("valid binning");
        assert_eq!(binned.frame_count_hint(), Some(3));
        let mut seen = Vec::new();
        while let Some(frame) = binned.next_frame().expect("frames are whole") {
            let Samples::U16(v) = frame.samples else {
                panic!("binned 8-bit frames are 16-bit")
            };
            let i = frame.index as u16;
            // Block (0, 0) holds codes 0, 1, 4, 5 plus 4·i.
            assert_eq!(v[0], 10 + 4 * i);
            assert_eq!(v.len(), 4);
            seen.push(frame.index);
        }
        assert_eq!(seen, vec![0, 1, 2]);
    }
}
