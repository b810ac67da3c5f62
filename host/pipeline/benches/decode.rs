//! Decoding speed: 1280×720 8-bit, 4 LEDs, 32 and 128 frames (targets ≤ 15 ms and ≤ 50 ms on
//! 2 cores), against a straightforward per-pixel least-squares implementation.
//!
//! Current figures (criterion medians, 1280×720, a quiet 2-core machine of the CI's kind): 32
//! frames 20.4 ms, 128 frames 61.9 ms; the straightforward decoder about 13× and 4× slower.
//! Machines of this kind differ by up to 2× in speed, so compare with the straightforward
//! decoder measured in the same run. The dated measurements are in `NOTES.md` beside this file.

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
