//! The per-pixel matched filter: least squares of every pixel against the fitted waveforms.
//!
//! One pass over the window's frames accumulates, per pixel, the K projections Q·r and |r|²
//! ([`super::basis`]). Rows run in parallel with rayon. Inside a row, tiles of [`TILE`] pixels
//! visit the frames [`GROUP`] at a time: a tile's K+1 sums are loaded into registers once per
//! group, and each sample costs one load and conversion plus K+1 multiply-adds. Each tile's
//! least-squares solution, noise variance, saturation/under-exposure flags and report sums are
//! then written straight into the output planes. The kernel is monomorphised on K, the sample
//! type and the code map, and built twice: for the baseline target and, chosen at run time, for
//! AVX2 + FMA (8-lane vectors, fused multiply-adds).
//!
//! Measured with the criterion `decode` bench (720p 8-bit, 4 LEDs, 128 frames, whole decode)
//! on the 2-core CI machine: 223 ms when 8-pixel tiles visited all frames at once (scalar
//! maxima, baseline target); 50.5 ms with AVX2, vectorised maxima and groups of 4 frames;
//! 46.4 ms with 16-pixel tiles.

use super::basis::TemplateBasis;
use super::stats::PixelStats;
use super::window::{CodeMap, Region};
use meb_core::capture::Samples;
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Pixels accumulated together in registers.
const TILE: usize = 16;
/// Frames added to a tile per visit.
const GROUP: usize = 4;

/// Per-pixel results of one window.
#[derive(Debug, Clone)]
pub struct WindowAmplitudes {
    /// `leds[i][p]`: A_i of pixel p (fraction of full scale).
    pub leds: Vec<Vec<f32>>,
    /// Per-frame noise variance σ² of pixel p (fraction² of full scale).
    pub noise_variance: Vec<f32>,
    /// Pixel p reached the white level in some frame of the window.
    pub saturated: Vec<bool>,
    /// Pixel p's brightest frame of the window stayed below the under-exposure level.
    pub underexposed: Vec<bool>,
    /// Report statistics of this window, when gathered while writing.
    pub stats: Option<PixelStats>,
}

pub use meb_core::capture::CodeLimits;

/// A sample type the kernel reads.
trait Code: Copy + Send + Sync + Ord + Default {
    /// The code value.
    fn code(self) -> u16;
}

impl Code for u8 {
    #[inline(always)]
    fn code(self) -> u16 {
        u16::from(self)
    }
}

impl Code for u16 {
    #[inline(always)]
    fn code(self) -> u16 {
        self
    }
}

/// Shared inputs of one window's kernel.
struct Plan<'a> {
    region: Region,
    limits: CodeLimits,
    bases: &'a [TemplateBasis],
    scale: f64,
    dof: f64,
}

/// Runs the matched filter over a window: `bases[b]` is the template basis of row band b.
pub fn matched_filter(
    frames: &[Samples],
    region: Region,
    bases: &[TemplateBasis],
    map: &CodeMap,
    limits: CodeLimits,
) -> WindowAmplitudes {
    let k = bases.first().map_or(1, |b| b.columns);
    let plan = Plan {
        region,
        limits,
        bases,
        scale: f64::from(map.scale()),
        dof: frames.len().saturating_sub(k).max(1) as f64,
    };
    let u8_frames: Option<Vec<&[u8]>> = frames
        .iter()
        .map(|f| match f {
            Samples::U8(v) => Some(v.as_slice()),
            Samples::U16(_) => None,
        })
        .collect();
    if let Some(data) = u8_frames {
        return match map {
            CodeMap::Linear { .. } => dispatch(&plan, &data, |c: u8| f32::from(c)),
            CodeMap::Table(t) => dispatch(&plan, &data, |c: u8| {
                t.get(usize::from(c)).copied().unwrap_or(1.0)
            }),
        };
    }
    // 16-bit (or mixed) frames: read everything as 16-bit codes.
    let widened: Vec<std::borrow::Cow<'_, [u16]>> = frames
        .iter()
        .map(|f| match f {
            Samples::U16(v) => std::borrow::Cow::Borrowed(v.as_slice()),
            Samples::U8(v) => std::borrow::Cow::Owned(v.iter().map(|&c| u16::from(c)).collect()),
        })
        .collect();
    let data: Vec<&[u16]> = widened.iter().map(|c| c.as_ref()).collect();
    match map {
        CodeMap::Linear { .. } => dispatch(&plan, &data, |c: u16| f32::from(c)),
        CodeMap::Table(t) => dispatch(&plan, &data, |c: u16| {
            t.get(usize::from(c)).copied().unwrap_or(1.0)
        }),
    }
}

/// Picks the kernel for the model size K.
fn dispatch<T: Code>(
    plan: &Plan<'_>,
    frames: &[&[T]],
    value: impl Fn(T) -> f32 + Sync + Copy,
) -> WindowAmplitudes {
    let k = plan.bases.first().map_or(1, |b| b.columns);
    match k {
        1 => run::<1, T>(plan, frames, value),
        2 => run::<2, T>(plan, frames, value),
        3 => run::<3, T>(plan, frames, value),
        4 => run::<4, T>(plan, frames, value),
        5 => run::<5, T>(plan, frames, value),
        6 => run::<6, T>(plan, frames, value),
        7 => run::<7, T>(plan, frames, value),
        8 => run::<8, T>(plan, frames, value),
        _ => run::<9, T>(plan, frames, value),
    }
}

/// One row's output slices, not yet written: the row's kernel writes every pixel of each
/// (the planes are allocated without being zeroed first, [`OutputPlanes`]).
struct RowOutput<'a> {
    leds: Vec<&'a mut [MaybeUninit<f32>]>,
    noise_variance: &'a mut [MaybeUninit<f32>],
    saturated: &'a mut [MaybeUninit<bool>],
    underexposed: &'a mut [MaybeUninit<bool>],
    /// The row's report statistics.
    stats: PixelStats,
}

impl RowOutput<'_> {
    /// Writes 0 (no signal, no noise, neither saturated nor under-exposed) to every pixel of
    /// the row from column `from` on, in every plane.
    fn clear_from(&mut self, from: usize) {
        let clear = |row: &mut [MaybeUninit<f32>]| {
            row.iter_mut().skip(from).for_each(|v| {
                v.write(0.0);
            })
        };
        self.leds.iter_mut().for_each(|row| clear(row));
        clear(self.noise_variance);
        for flags in [&mut *self.saturated, &mut *self.underexposed] {
            flags.iter_mut().skip(from).for_each(|v| {
                v.write(false);
            });
        }
    }
}

/// The output planes of a window: allocated without zeroing (a `vec![0.0; n]` of memory the
/// allocator kept for reuse is a serial memset of ≈ 20 MB at 1280×720, 1–2 ms of a window
/// on the calling thread) and handed out row by row; every pixel of every plane is then
/// written once by its row's kernel.
struct OutputPlanes {
    leds: Vec<Vec<f32>>,
    noise_variance: Vec<f32>,
    saturated: Vec<bool>,
    underexposed: Vec<bool>,
    pixels: usize,
}

impl OutputPlanes {
    /// Room for `images` LED planes of `pixels` pixels and the three per-pixel maps.
    fn with_room(images: usize, pixels: usize) -> Self {
        Self {
            leds: (0..images).map(|_| Vec::with_capacity(pixels)).collect(),
            noise_variance: Vec::with_capacity(pixels),
            saturated: Vec::with_capacity(pixels),
            underexposed: Vec::with_capacity(pixels),
            pixels,
        }
    }

    /// Every plane's unwritten pixels as rows of `width`.
    fn rows(&mut self, width: usize) -> Vec<RowOutput<'_>> {
        let (pixels, images) = (self.pixels, self.leds.len());
        let mut led_rows: Vec<_> = self
            .leds
            .iter_mut()
            .map(|p| p.spare_capacity_mut()[..pixels].chunks_mut(width))
            .collect();
        self.noise_variance.spare_capacity_mut()[..pixels]
            .chunks_mut(width)
            .zip(self.saturated.spare_capacity_mut()[..pixels].chunks_mut(width))
            .zip(self.underexposed.spare_capacity_mut()[..pixels].chunks_mut(width))
            .map(|((noise_variance, saturated), underexposed)| RowOutput {
                leds: led_rows.iter_mut().filter_map(Iterator::next).collect(),
                noise_variance,
                saturated,
                underexposed,
                stats: PixelStats::new(images),
            })
            .collect()
    }

    /// The planes, once every row from [`Self::rows`] was written whole.
    ///
    /// # Safety
    ///
    /// Every element of every row [`Self::rows`] handed out must have been written.
    unsafe fn written(mut self) -> (Vec<Vec<f32>>, Vec<f32>, Vec<bool>, Vec<bool>) {
        let pixels = self.pixels;
        // SAFETY: the capacity is `pixels` (`with_room`) and the caller wrote every element of
        // the first `pixels` (the rows cover them).
        unsafe {
            for plane in &mut self.leds {
                plane.set_len(pixels);
            }
            self.noise_variance.set_len(pixels);
            self.saturated.set_len(pixels);
            self.underexposed.set_len(pixels);
        }
        (
            self.leds,
            self.noise_variance,
            self.saturated,
            self.underexposed,
        )
    }
}

/// The kernel for K model columns: every row in parallel, written straight into the images.
fn run<const K: usize, T: Code>(
    plan: &Plan<'_>,
    frames: &[&[T]],
    value: impl Fn(T) -> f32 + Sync + Copy,
) -> WindowAmplitudes {
    let width = plan.region.roi.width;
    let height = plan.region.roi.height;
    let pixels = width * height;
    // Q column per frame, one [f32; K] per frame and band.
    let weights: Vec<Vec<[f32; K]>> = plan
        .bases
        .iter()
        .map(|basis| {
            (0..frames.len())
                .map(|j| {
                    let mut w = [0.0f32; K];
                    for (c, q) in basis.rows.iter().enumerate().take(K) {
                        w[c] = q.get(j).copied().unwrap_or(0.0) as f32;
                    }
                    w
                })
                .collect()
        })
        .collect();
    let solvers: Vec<[[f32; K]; K]> = plan
        .bases
        .iter()
        .map(|basis| {
            std::array::from_fn(|row| {
                std::array::from_fn(|col| {
                    (basis.r_inverse.get(row * K + col).copied().unwrap_or(0.0) * plan.scale) as f32
                })
            })
        })
        .collect();
    let noise_factor = (plan.scale * plan.scale / plan.dof) as f32;
    let mut planes = OutputPlanes::with_room(K - 1, pixels);
    let simd = simd_available();
    let stats = planes
        .rows(width)
        .into_par_iter()
        .enumerate()
        .map_init(Vec::new, |tiles, (row, mut out)| {
            let band = plan.region.band_of(row);
            let samples: Vec<&[T]> = frames
                .iter()
                .map(|f| f.get(row * width..(row + 1) * width).unwrap_or(&[]))
                .collect();
            let job = RowJob {
                solver: &solvers[band],
                noise_factor,
                limits: plan.limits,
                weights: &weights[band],
                samples: &samples,
                width,
            };
            let written = run_row::<K, T, _>(simd, &job, value, &mut out, tiles);
            // Every pixel is written (the tiles cover the row); should one not be, it reads 0.
            out.clear_from(written);
            out.stats
        })
        // Merged in row order: the sums do not depend on how the pool split the work.
        .collect::<Vec<_>>()
        .into_iter()
        .fold(PixelStats::new(K - 1), |a, b| a.merge(&b));
    // SAFETY: every row's kernel wrote its first `written` pixels and `clear_from` the rest.
    let (leds, noise_variance, saturated, underexposed) = unsafe { planes.written() };
    WindowAmplitudes {
        leds,
        noise_variance,
        saturated,
        underexposed,
        stats: Some(stats),
    }
}

/// Inputs of one row.
struct RowJob<'a, const K: usize, T> {
    /// R⁻¹ of the row's band, times the code-to-fraction scale.
    solver: &'a [[f32; K]; K],
    /// From residual energy to per-frame variance in fraction²: scale² / (F − K).
    noise_factor: f32,
    /// Saturation and under-exposure limits.
    limits: CodeLimits,
    weights: &'a [[f32; K]],
    samples: &'a [&'a [T]],
    width: usize,
}

/// Whether the CPU runs the AVX2 + FMA build of the row kernel.
fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Runs one row with the widest kernel the CPU supports; returns how many of the row's first
/// pixels it wrote.
fn run_row<const K: usize, T: Code, V: Fn(T) -> f32 + Copy>(
    simd: bool,
    job: &RowJob<'_, K, T>,
    value: V,
    out: &mut RowOutput<'_>,
    tiles: &mut Vec<TileSums<K, T>>,
) -> usize {
    #[cfg(target_arch = "x86_64")]
    if simd {
        // SAFETY: `simd_available` checked that this CPU has AVX2 and FMA.
        return unsafe { row_avx2::<K, T, V>(job, value, out, tiles) };
    }
    let _ = simd;
    row_kernel::<K, false, T, V>(job, value, out, tiles)
}

/// The row kernel compiled for AVX2 + FMA (8-lane f32 vectors, fused multiply-adds).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn row_avx2<const K: usize, T: Code, V: Fn(T) -> f32 + Copy>(
    job: &RowJob<'_, K, T>,
    value: V,
    out: &mut RowOutput<'_>,
    tiles: &mut Vec<TileSums<K, T>>,
) -> usize {
    row_kernel::<K, true, T, V>(job, value, out, tiles)
}

/// The row's tiles of [`TILE`] pixels stream over the frames [`GROUP`] at a time: each
/// group reads a few contiguous runs of the row (prefetcher-friendly), while every tile's
/// running sums are loaded into registers once per group. Then every tile is solved.
#[inline(always)]
fn row_kernel<const K: usize, const FMA: bool, T: Code, V: Fn(T) -> f32 + Copy>(
    job: &RowJob<'_, K, T>,
    value: V,
    out: &mut RowOutput<'_>,
    tiles: &mut Vec<TileSums<K, T>>,
) -> usize {
    let count = job.width.div_ceil(TILE);
    tiles.clear();
    tiles.resize(count, TileSums::default());
    let mut groups = job
        .samples
        .chunks_exact(GROUP)
        .zip(job.weights.chunks_exact(GROUP));
    for (rows, weights) in groups.by_ref() {
        add_frames::<K, GROUP, FMA, T, V>(tiles, rows, weights, job.width, value);
    }
    let rest = job.samples.len() - job.samples.len() % GROUP;
    for (row, weight) in job.samples[rest..]
        .chunks(1)
        .zip(job.weights[rest..].chunks(1))
    {
        add_frames::<K, 1, FMA, T, V>(tiles, row, weight, job.width, value);
    }
    let mut lanes = LaneStats::<K>::default();
    let mut written = 0;
    for (t, sums) in tiles.iter().enumerate() {
        let x = t * TILE;
        if x != written {
            break;
        }
        written += solve::<K, T>(job, sums, x, TILE.min(job.width - x), out, &mut lanes);
    }
    lanes.fold_into(&mut out.stats);
    written
}

/// A row's report sums kept per lane, so that adding a tile vectorises (the pixel-by-pixel
/// f64 additions were a quarter of the row kernel's time on 32 frames); folded into
/// [`PixelStats`] once per row.
struct LaneStats<const K: usize> {
    saturated: [u32; TILE],
    underexposed: [u32; TILE],
    valid: [u32; TILE],
    noise_power: [f64; TILE],
    /// `level_sums[i]`: LED i's on-levels (row K − 1 stays zero).
    level_sums: [[f64; TILE]; K],
}

impl<const K: usize> Default for LaneStats<K> {
    fn default() -> Self {
        Self {
            saturated: [0; TILE],
            underexposed: [0; TILE],
            valid: [0; TILE],
            noise_power: [0.0; TILE],
            level_sums: [[0.0; TILE]; K],
        }
    }
}

impl<const K: usize> LaneStats<K> {
    /// Adds a whole tile, as [`PixelStats::add`] does pixel by pixel (the masks are classified
    /// again from the maxima so that the loop stays in vector registers).
    #[allow(clippy::needless_range_loop)] // indexed lanes vectorise
    #[inline(always)]
    fn add<T: Code>(
        &mut self,
        limits: CodeLimits,
        max_code: &[T; TILE],
        noise: &[f32; TILE],
        levels: &[[f32; TILE]; K],
    ) {
        // All ones where the pixel is valid: the sums take `value & keep` (a bitwise select
        // that vectorises where a branch on a stored flag did not).
        let mut keep = [0u32; TILE];
        for l in 0..TILE {
            let (saturated, underexposed) = limits.classify(max_code[l].code());
            let valid = !saturated & !underexposed;
            keep[l] = 0u32.wrapping_sub(u32::from(valid));
            self.saturated[l] += u32::from(saturated);
            self.underexposed[l] += u32::from(underexposed);
            self.valid[l] += u32::from(valid);
        }
        let kept = |value: f32, keep: u32| f64::from(f32::from_bits(value.to_bits() & keep));
        for l in 0..TILE {
            self.noise_power[l] += kept(noise[l], keep[l]);
        }
        for (sums, level) in self.level_sums.iter_mut().zip(levels) {
            for l in 0..TILE {
                sums[l] += kept(level[l], keep[l]);
            }
        }
    }

    /// Adds the lanes to the row's statistics.
    fn fold_into(&self, stats: &mut PixelStats) {
        let count = |lanes: &[u32; TILE]| lanes.iter().map(|&n| n as usize).sum::<usize>();
        stats.saturated_pixels += count(&self.saturated);
        stats.underexposed_pixels += count(&self.underexposed);
        stats.valid_pixels += count(&self.valid);
        stats.noise_power += self.noise_power.iter().sum::<f64>();
        for (sum, lanes) in stats.level_sums.iter_mut().zip(&self.level_sums) {
            *sum += lanes.iter().sum::<f64>();
        }
    }
}

/// Running sums of one tile: projections, squares and maximum code per pixel (kept in the
/// sample type so that the maximum vectorises).
#[derive(Clone, Copy)]
struct TileSums<const K: usize, T> {
    projections: [[f32; TILE]; K],
    squares: [f32; TILE],
    max_code: [T; TILE],
}

impl<const K: usize, T: Code> Default for TileSums<K, T> {
    fn default() -> Self {
        Self {
            projections: [[0.0; TILE]; K],
            squares: [0.0; TILE],
            max_code: [T::default(); TILE],
        }
    }
}

impl<const K: usize, T: Code> TileSums<K, T> {
    /// Adds one frame's values `v` with its basis weights `w`.
    #[allow(clippy::needless_range_loop)] // indexed lanes vectorise
    #[inline(always)]
    fn add<const FMA: bool>(&mut self, w: &[f32; K], v: &[f32; TILE]) {
        for c in 0..K {
            for l in 0..TILE {
                self.projections[c][l] = multiply_add::<FMA>(w[c], v[l], self.projections[c][l]);
            }
        }
        for l in 0..TILE {
            self.squares[l] = multiply_add::<FMA>(v[l], v[l], self.squares[l]);
        }
    }
}

/// `acc + a·b`, fused when the kernel is built for FMA.
#[inline(always)]
fn multiply_add<const FMA: bool>(a: f32, b: f32, acc: f32) -> f32 {
    if FMA { a.mul_add(b, acc) } else { acc + a * b }
}

/// Adds `G` frames (`rows[f]`, weights `weights[f]`) to every tile of the row: whole tiles
/// through fixed-size chunks (unrolled over the frames, no per-sample bounds checks), then the
/// partial tile at the row's end.
#[allow(clippy::needless_range_loop)] // indexed lanes keep the tile in registers
#[inline(always)]
fn add_frames<const K: usize, const G: usize, const FMA: bool, T: Code, V: Fn(T) -> f32>(
    tiles: &mut [TileSums<K, T>],
    rows: &[&[T]],
    weights: &[[f32; K]],
    width: usize,
    value: V,
) {
    let (Ok(rows), Ok(weights)) = (
        <&[&[T]; G]>::try_from(rows),
        <&[[f32; K]; G]>::try_from(weights),
    ) else {
        return;
    };
    let whole = (width / TILE).min(tiles.len());
    let chunks: [&[[T; TILE]]; G] = std::array::from_fn(|f| rows[f].as_chunks::<TILE>().0);
    let fast = chunks.iter().all(|c| c.len() >= whole);
    if fast {
        for (t, tile) in tiles[..whole].iter_mut().enumerate() {
            let mut sums = *tile;
            for f in 0..G {
                let samples = chunks[f][t];
                let mut v = [0.0f32; TILE];
                for l in 0..TILE {
                    v[l] = value(samples[l]);
                    sums.max_code[l] = sums.max_code[l].max(samples[l]);
                }
                sums.add::<FMA>(&weights[f], &v);
            }
            *tile = sums;
        }
    }
    // The partial tile at the row's end (every tile if a row were short) sample by sample.
    let start = if fast { whole } else { 0 };
    for (t, tile) in tiles.iter_mut().enumerate().skip(start) {
        let x = t * TILE;
        for f in 0..G {
            let mut v = [0.0f32; TILE];
            for l in 0..TILE.min(width.saturating_sub(x)) {
                if let Some(&c) = rows[f].get(x + l) {
                    v[l] = value(c);
                    tile.max_code[l] = tile.max_code[l].max(c);
                }
            }
            tile.add::<FMA>(&weights[f], &v);
        }
    }
}

/// Solves the tile's least-squares systems, all lanes at once in f32, and writes the
/// coefficients, noise variances and maxima of the `len` pixels from `x`; returns how many
/// pixels it wrote (`len`, or 0 if they lie beyond the row).
#[allow(clippy::needless_range_loop)] // indexed lanes vectorise
#[inline(always)]
fn solve<const K: usize, T: Code>(
    job: &RowJob<'_, K, T>,
    sums: &TileSums<K, T>,
    x: usize,
    len: usize,
    out: &mut RowOutput<'_>,
    lanes: &mut LaneStats<K>,
) -> usize {
    // Every plane must hold the pixels: a pixel reported written must be written in all.
    let end = x + len;
    if out.noise_variance.len() < end
        || out.saturated.len() < end
        || out.underexposed.len() < end
        || out.leds.iter().any(|row| row.len() < end)
    {
        return 0;
    }
    let mut explained = [0.0f32; TILE];
    for c in 0..K {
        for l in 0..TILE {
            explained[l] += sums.projections[c][l] * sums.projections[c][l];
        }
    }
    let mut noise = [0.0f32; TILE];
    for l in 0..TILE {
        noise[l] = (sums.squares[l] - explained[l]).max(0.0) * job.noise_factor;
    }
    let mut saturated = [false; TILE];
    let mut underexposed = [false; TILE];
    for l in 0..TILE {
        (saturated[l], underexposed[l]) = job.limits.classify(sums.max_code[l].code());
    }
    let mut coefficients = [[0.0f32; TILE]; K];
    for (i, image) in out.leds.iter_mut().enumerate() {
        // Coefficient i + 1 (column 0 is the background): row i + 1 of R⁻¹ times Q·r.
        let coefficient = &mut coefficients[i];
        if let Some(row) = job.solver.get(i + 1) {
            for c in i + 1..K {
                for l in 0..TILE {
                    coefficient[l] += row[c] * sums.projections[c][l];
                }
            }
        }
        write_lanes(image, x, len, coefficient);
    }
    if len == TILE {
        lanes.add(job.limits, &sums.max_code, &noise, &coefficients);
    } else {
        for l in 0..len {
            out.stats.add(saturated[l], underexposed[l], noise[l], |i| {
                coefficients[i][l]
            });
        }
    }
    write_lanes(out.noise_variance, x, len, &noise);
    write_lanes(out.saturated, x, len, &saturated);
    write_lanes(out.underexposed, x, len, &underexposed);
    len
}

/// Writes the first `len` lanes to `target[x..]`.
#[inline(always)]
fn write_lanes<U: Copy>(target: &mut [MaybeUninit<U>], x: usize, len: usize, lanes: &[U; TILE]) {
    if let Some(slot) = target.get_mut(x..x + len)
        && let Some(values) = lanes.get(..len)
    {
        for (slot, &value) in slot.iter_mut().zip(values) {
            slot.write(value);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::config::Roi;

    /// The report sums gathered lane by lane while writing equal those gathered pixel by pixel
    /// from the written images: counts exactly, sums to rounding (a row ends in a part tile,
    /// and some pixels saturate or stay dark).
    #[test]
    fn lane_statistics_equal_a_pass_over_the_images() {
        let (width, height, count) = (37, 5, 12);
        let mut state = 11u32;
        let frames: Vec<Samples> = (0..count)
            .map(|_| {
                Samples::U8(
                    (0..width * height)
                        .map(|p| {
                            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                            match p % 11 {
                                0 => 255,
                                1 => (state >> 30) as u8,
                                _ => 20 + (state >> 25) as u8,
                            }
                        })
                        .collect(),
                )
            })
            .collect();
        let columns: Vec<Vec<f64>> = vec![
            vec![1.0; count],
            (0..count).map(|j| (j as f64 * 0.9).sin()).collect(),
            (0..count).map(|j| (j as f64 * 0.4).cos()).collect(),
        ];
        let region = Region {
            roi: Roi {
                x: 0,
                y: 0,
                width,
                height,
            },
            bands: 1,
        };
        let map = CodeMap::Linear {
            black: 0.0,
            scale: 1.0 / 255.0,
        };
        let limits = CodeLimits {
            white: 250,
            dark: 5,
        };
        let got = matched_filter(
            &frames,
            region,
            &[TemplateBasis::new(&columns)],
            &map,
            limits,
        );
        let lanes = got.stats.clone().unwrap_or_else(|| PixelStats::new(0));
        let pixels = PixelStats::gather(
            &got.leds,
            &got.noise_variance,
            &got.saturated,
            &got.underexposed,
        );
        assert_eq!(lanes.saturated_pixels, pixels.saturated_pixels);
        assert_eq!(lanes.underexposed_pixels, pixels.underexposed_pixels);
        assert_eq!(lanes.valid_pixels, pixels.valid_pixels);
        assert!(pixels.saturated_pixels > 0 && pixels.underexposed_pixels > 0);
        assert!(pixels.valid_pixels > width * height / 2);
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1e-9);
        assert!(close(lanes.noise_power, pixels.noise_power));
        assert_eq!(lanes.level_sums.len(), 2);
        for (a, b) in lanes.level_sums.iter().zip(&pixels.level_sums) {
            assert!(close(*a, *b), "{a} vs {b}");
        }
    }
}
