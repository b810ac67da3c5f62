//! Decoding speed: 1280×720 8-bit, 4 LEDs, 32 and 128 frames (targets ≤ 15 ms and ≤ 50 ms on
//! 2 cores), against a straightforward per-pixel least-squares implementation.
//!
//! Measured on the 2-core CI machine (criterion medians, several runs on a shared VM whose
//! memory speed varies from run to run): 32 frames 12.3–14.8 ms (straightforward: 346–438 ms,
//! ~28× slower); 128 frames 30.6–58.9 ms, median of six runs 48.3 ms. Before the kernel and
//! fit rework: 88 ms and 223 ms. The 128-frame case includes the five-LED count check
//! (`check_led_count`).
//!
//! After the robustness work of issue #12 (global spectral seed, variable-projection fit,
//! quality verdict, rolling-shutter test) on a quiet machine: 32 frames 20.4 ms (19.4–21.8),
//! 128 frames 61.9 ms (59.6–64.0). Most of that was the timing fit running on one thread:
//! callgrind, whole decode, main thread / rayon workers, instructions: 32 frames 65 M / 175 M,
//! 128 frames 415 M / 604 M (the fit alone 385 M serial). With the seeds' and bands' refinements
//! run in parallel and an allocation-free residual (same arithmetic, same results bit for
//! bit): 32 frames 29 M / 192 M, 128 frames 161 M / 717 M (the fit 135 M serial): the serial
//! part −55 % / −61 %, the total −9 % / −14 %. Wall-clock medians of the shared machine at
//! load 10–17 (4 helpers on 2 cores) are not comparable. Re-measured on one quiet machine
//! (load < 2), before (430946e) and after, criterion medians: 32 frames 46.0 → 39.8 ms, 128
//! frames 122.3 → 103.2 ms; the straightforward decoder (unchanged code) 545 / 498 ms there, 1.9×
//! its 268 ms on the machine of the 20.4 / 61.9 ms figures, so this machine is about half as
//! fast and the targets are judged against the straightforward decoder's ratio (32 frames
//! 8.0 % of it, target 15 / 268 = 5.6 %; 128 frames 20.7 %, target 50 / 268 = 18.7 %).
//!
//! Session 23 (same results bit for bit): the seed scan's template scores accumulate every
//! signal-space column in one pass over the frames (frame-major, zero-padded rows: independent
//! chains, each column still summed in frame order), the Levenberg–Marquardt Jacobian's
//! columns and the rolling-shutter test's band and row compressions run in parallel.
//! Callgrind, whole decode (without the bench's frame copy), instructions: 32 frames 215 M →
//! 210 M (seed scans 19.4 M → 11.6 M; the matched filter, 137 M, is now two thirds of it);
//! 128 frames 873 M → 802 M (seed scans 226 M → 143 M, of which template filling 105 M;
//! matched filter 342 M unchanged). Criterion medians at load 6.5–7.2 (other builds on the
//! 2 cores, not comparable with the quiet figures above): 32 frames 196.6 ms against the
//! straightforward decoder's 2838 ms (6.9 %), 128 frames 628.8 ms (22.2 %). Re-measured on the
//! quiet machine (load ≈ 1, same machine as the 39.8 / 103.2 ms above): **32 frames 25.9 ms**
//! (25.5–26.4), **128 frames 94.1 ms** (91.4–95.9), straightforward decoder 463.8 ms. Ratios:
//! 32 frames 5.6 % (target 5.6 %: met), 128 frames 20.3 % (target 18.7 %: 9 % short; the
//! matched filter, 342 M instructions, is next).
//!
//! Session 24 (same results bit for bit, checked by the waveform tests): whole templates are
//! filled from the carriers' Manchester closed form with vector floors (AVX, chosen at run
//! time) instead of per-frame table look-ups. Callgrind, 128 frames, instructions between
//! entry and exit of `decode` (`--dump-before/--dump-after=meb_pipeline::demod::decode`, all threads):
//! template filling 105 M → 28.2 M (`Timing::fill_template`, inclusive), whole decode
//! 802 M → 732 M (−9 %; both "before" figures are session 23's, of the unchanged code); the
//! matched filter (342 M, `row_avx2`) unchanged and now 47 % of the decode.
//!
//! Session 26: the matched filter's report sums (saturated / under-exposed / valid counts, noise
//! power, per-LED level sums) were added pixel by pixel in f64 with a branch per pixel, a
//! quarter of the row kernel's samples (perf annotate, 32 frames); they now go into per-lane
//! f64 sums with bitwise masks, folded once per row (`LaneStats`; the counts are exact, the
//! sums equal to rounding, tested). Callgrind, whole process minus the same binary run with no
//! bench selected (frame generation): 32 frames 235.5 M → 200.0 M instructions per decode
//! (−15 %); the row kernel's share in the accumulation loop rose from 55 % to 66 % of its
//! samples. The sweep's 815 gains are unchanged to the printed digit. Wall clock on this VM
//! (load 1–2) moved by more than the change between runs of one binary (28.5–40.4 ms for the
//! same 32-frame code within minutes), so no wall-clock before/after is claimed: criterion
//! 32 frames 34.2–38.3 ms (after) against 28.5–43.7 ms (before) in alternating runs.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, Samples};
use meb_pipeline::demod::{DecodeConfig, LedCount, decode};
use protocol::carriers::chip_is_on;
use std::hint::black_box;

const WIDTH: usize = 1280;
const HEIGHT: usize = 720;

/// Frames of a 4-LED capture with full exposure and integer phases, plus ±2-code noise.
fn frames(count: usize) -> Vec<Frame> {
    let shifts = [3usize, 11, 6, 21];
    let mut state = 12345u32;
    (0..count)
        .map(|j| {
            let samples = (0..WIDTH * HEIGHT)
                .map(|p| {
                    let (x, y) = (
                        (p % WIDTH) as f32 / WIDTH as f32,
                        (p / WIDTH) as f32 / HEIGHT as f32,
                    );
                    let levels = [40.0 * x, 40.0 * (1.0 - x), 40.0 * y, 40.0 * (1.0 - y)];
                    let mut v = 20.0;
                    for (i, level) in levels.iter().enumerate() {
                        if chip_is_on(i, j + shifts[i]) {
                            v += level;
                        }
                    }
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    v += (state >> 30) as f32 - 1.5;
                    v.clamp(0.0, 255.0) as u8
                })
                .collect();
            Frame {
                index: j,
                samples: Samples::U8(samples),
            }
        })
        .collect()
}

/// The straightforward decoder: per pixel, gather its samples and solve the normal equations
/// of the K = 5 column model (templates given), single-threaded.
fn naive(frames: &[Frame], templates: &[Vec<f64>]) -> Vec<f64> {
    let k = templates.len();
    let f = frames.len();
    let t = nalgebra::DMatrix::from_fn(f, k, |j, c| templates[c][j]);
    let normal = (t.transpose() * &t)
        .try_inverse()
        .unwrap_or_else(|| nalgebra::DMatrix::zeros(k, k));
    let mut out = vec![0.0; WIDTH * HEIGHT * k];
    for p in 0..WIDTH * HEIGHT {
        let r = nalgebra::DVector::from_fn(f, |j, _| match &frames[j].samples {
            Samples::U8(v) => f64::from(v[p]),
            Samples::U16(v) => f64::from(v[p]),
        });
        let c = &normal * (t.transpose() * r);
        out[p * k..(p + 1) * k].copy_from_slice(c.as_slice());
    }
    out
}

fn bench(c: &mut Criterion) {
    let format = FrameFormat::full_range(WIDTH, HEIGHT, 8, 960.0);
    let config = DecodeConfig {
        leds: LedCount::Fixed(4),
        ..DecodeConfig::default()
    };
    let mut group = c.benchmark_group("decode_720p");
    group.sample_size(10);
    for count in [32usize, 128] {
        let input = frames(count);
        group.bench_function(format!("waveform_{count}_frames"), |b| {
            b.iter_batched(
                || {
                    MemorySource::new(format.clone(), input.clone())
                        .unwrap_or_else(|e| panic!("{e}"))
                },
                |mut source| black_box(decode(&mut source, &config, &mut |_, _| {}).is_ok()),
                BatchSize::LargeInput,
            )
        });
        if count == 32 {
            let templates: Vec<Vec<f64>> = std::iter::once(vec![1.0; count])
                .chain((0..4).map(|i| {
                    (0..count)
                        .map(|j| if chip_is_on(i, j) { 0.5 } else { -0.5 })
                        .collect()
                }))
                .collect();
            group.bench_function(format!("naive_{count}_frames"), |b| {
                b.iter(|| black_box(naive(&input, &templates).len()))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
