//! One 3-D frame of `meb video` at the thesis' dynamic set-up: 40 camera frames of 1280×720
//! (the 100×60×60 mm ellipsoid turning at 7.5 rpm, 1000 fps, out-of-plane LEDs) already in
//! memory → decode the middle 32 → near-field photometric stereo → integration. Target: one
//! 3-D frame ≤ 40 ms (25 3-D frames per second) on 2 cores.
//!
//! `window` runs the whole pipeline as `meb video` does ([`meb_pipeline::video::process`] over one
//! window: reader thread, decode, motion check, reconstruction); the other cases time its
//! stages. `decode_carried_timing` decodes with the exposure and rate ratio carried from an
//! earlier window, as every window after the first few does; `decode_region` does so in a
//! 514×311 region of interest around the object (`meb decode --roi`). `reconstruct` is the
//! first window from scratch (cold); `window_warm` reconstructs the second window (frames
//! 44..76) started from the first window's result, as `meb video` does for every window after
//! the first ([`meb_pipeline::reconstruct::WarmStart`]). `frame_warm` is the one 3-D frame from
//! frames in memory: decode (carried timing) and warm reconstruction of the second window in series;
//! `frame_warm_bin2` bins its 32 frames first; `frame_warm_region` decodes and reconstructs in
//! the region around the object, as `meb video` does once its timing has settled
//! ([`meb_pipeline::reconstruct::Request::region`]). The bench first prints both per-stage profiles and
//! how far the warm result lies from a cold reconstruction of the same window.
//!
//! Current figures (criterion, 1280×720, an idle 2-core machine of the CI's kind, the clip in
//! the page cache): `frame_warm_region` — the 3-D frame as `meb video` runs it, decoded and
//! reconstructed in the 514×311 region around the object inside a pool of both cores — 34.1 ms
//! (33.8–34.4; 36.8 ms in a second run), against the 40 ms of 25 3-D frames per second;
//! `window_warm` 41.0 ms; `frame_warm` 50.5 ms (of which 13 ms paste the region's arrays into
//! the whole frame, which `meb video` leaves to its writer); `decode_region` 3.9 ms;
//! `frame_warm_bin2` 27.8 ms. End to end, `meb video` on the 2000-frame clip of the turning
//! ellipsoid (windows of 40, drop 4) ran at 25.1–27.3 3-D frames/s, per-window depth RMSE
//! median 0.680 mm, worst 1.194 mm. Dated measurements and what was tried are in `NOTES.md`
//! beside this file.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use meb_core::capture::binning::Binning;
use meb_core::capture::memory::MemorySource;
use meb_core::capture::{Frame, FrameFormat, FrameSource, Samples};
use meb_core::rig::Rig;
use meb_pipeline::demod::DecodeConfig;
use meb_pipeline::demod::decode_frames;
use meb_pipeline::reconstruct::{Request, Source, WarmStart, reconstruct, reconstruct_extent};
use meb_pipeline::video::{VideoConfig, process};
use std::hint::black_box;

mod common;

/// 80 frames (two thesis windows) of the turning ellipsoid on the thesis-dynamic rig.
fn clip() -> Option<(Rig, FrameFormat, Vec<Frame>)> {
    let rig = Rig::preset("thesis-dynamic")?;
    let (format, frames) = common::turning_ellipsoid(&rig, 80)?;
    Some((rig, format, frames))
}

fn bench(c: &mut Criterion) {
    // As `meb` does first thing: windows reuse their arrays' pages.
    // SAFETY: criterion calls this on its main thread before any other thread starts (the
    // clip is simulated below).
    unsafe { meb_core::memory::keep_freed_memory() };
    let Some((rig, format, frames)) = clip() else {
        eprintln!("cannot simulate the clip");
        return;
    };
    let config = VideoConfig::thesis(rig.leds.len());
    let decoded_frames: Vec<Samples> = frames[4..36].iter().map(|f| f.samples.clone()).collect();
    let Ok(decoded) = decode_frames(&decoded_frames, &format, &config.decode) else {
        eprintln!("the clip does not decode");
        return;
    };
    let carried = DecodeConfig {
        rate_ratio: Some(decoded.report.rate_ratio),
        exposure: Some(decoded.report.exposure),
        ..config.decode.clone()
    };
    let second_frames: Vec<Samples> = frames[44..76].iter().map(|f| f.samples.clone()).collect();
    let Ok(second) = decode_frames(&second_frames, &format, &carried) else {
        eprintln!("the second window does not decode");
        return;
    };
    // The per-stage profile of one reconstruction, cold and warm, printed once (criterion times
    // the whole).
    let Ok(first) = reconstruct(
        Source::Decoded(&decoded),
        &rig,
        &config.reconstruct,
        Request::default(),
    ) else {
        eprintln!("the first window does not reconstruct");
        return;
    };
    let warm = WarmStart::of(&first);
    let profile = |name: &str, reconstruction: &meb_pipeline::reconstruct::Reconstruction| {
        eprintln!("{name}: {:?}", reconstruction.start);
        for stage in &reconstruction.timings {
            eprintln!("stage {:>8.1} ms  {}", stage.ms, stage.stage);
        }
    };
    profile("first window, cold", &first);
    let warm_second = reconstruct(
        Source::Decoded(&second),
        &rig,
        &config.reconstruct,
        Request {
            warm: Some(&warm),
            ..Request::default()
        },
    );
    let cold_second = reconstruct(
        Source::Decoded(&second),
        &rig,
        &config.reconstruct,
        Request::default(),
    );
    if let (Ok(warm_second), Ok(cold_second)) = (&warm_second, &cold_second) {
        profile("second window, warm", warm_second);
        profile("second window, cold", cold_second);
        // How far the warm result lies from the cold one (the accuracy is 0.5–1 mm).
        let (a, b) = (
            &warm_second.integration.depth.depth_mm,
            &cold_second.integration.depth.depth_mm,
        );
        let mut diff: Vec<f32> = a
            .iter()
            .zip(b)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| (x - y).abs())
            .collect();
        diff.sort_by(f32::total_cmp);
        if !diff.is_empty() {
            let rms = (diff.iter().map(|d| d * d).sum::<f32>() / diff.len() as f32).sqrt();
            eprintln!(
                "warm vs cold, second window: median {:.3} mm, 90 % {:.3} mm, RMS {rms:.3} mm over {} pixels",
                diff[diff.len() / 2],
                diff[diff.len() * 9 / 10],
                diff.len()
            );
        }
    }
    let mut group = c.benchmark_group("video_1280x720");
    group.sample_size(10);
    group.bench_function("window", |b| {
        b.iter_batched(
            || -> Box<dyn FrameSource> {
                Box::new(
                    MemorySource::new(format.clone(), frames[..40].to_vec()).expect("frames fit"),
                )
            },
            |source| black_box(process(source, &rig, &config, None, &mut |_| Ok(())).ok()),
            BatchSize::PerIteration,
        )
    });
    group.bench_function("decode", |b| {
        b.iter(|| black_box(decode_frames(&decoded_frames, &format, &config.decode).ok()))
    });
    group.bench_function("decode_carried_timing", |b| {
        b.iter(|| black_box(decode_frames(&decoded_frames, &format, &carried).ok()))
    });
    // A decoder's region of interest around the object (`meb decode --roi`, `meb video` with
    // a region): the frames are cut to it first.
    let around_object = DecodeConfig {
        roi: Some(meb_pipeline::demod::Roi {
            x: 383,
            y: 180,
            width: 514,
            height: 311,
        }),
        ..carried.clone()
    };
    group.bench_function("decode_region", |b| {
        b.iter(|| black_box(decode_frames(&second_frames, &format, &around_object).ok()))
    });
    group.bench_function("reconstruct", |b| {
        b.iter(|| {
            black_box(
                reconstruct(
                    Source::Decoded(&decoded),
                    &rig,
                    &config.reconstruct,
                    Request::default(),
                )
                .ok(),
            )
        })
    });
    group.bench_function("window_warm", |b| {
        b.iter(|| {
            black_box(
                reconstruct(
                    Source::Decoded(&second),
                    &rig,
                    &config.reconstruct,
                    Request {
                        warm: Some(&warm),
                        ..Request::default()
                    },
                )
                .ok(),
            )
        })
    });
    // The one 3-D frame: decode (carried timing) and warm reconstruction in series.
    group.bench_function("frame_warm", |b| {
        b.iter(|| {
            let decoded = decode_frames(&second_frames, &format, &carried).ok()?;
            black_box(
                reconstruct(
                    Source::Decoded(&decoded),
                    &rig,
                    &config.reconstruct,
                    Request {
                        warm: Some(&warm),
                        ..Request::default()
                    },
                )
                .ok(),
            )
        })
    });
    // The same 3-D frame as `meb video` runs it after its first window: decoded in the region
    // around the object and reconstructed there, the result kept in the region (the writer
    // pastes it into the frame's files on its own thread), inside a pool of every core (from
    // outside a pool each of a window's parallel loops would be injected into the global pool
    // with the caller asleep).
    let Ok(pool) = rayon::ThreadPoolBuilder::new().build() else {
        eprintln!("cannot start a thread pool");
        return;
    };
    group.bench_function("frame_warm_region", |b| {
        b.iter(|| {
            pool.install(|| {
                let decoded = decode_frames(&second_frames, &format, &around_object).ok()?;
                let roi = around_object.roi?;
                black_box(
                    reconstruct_extent(
                        Source::Decoded(&decoded),
                        &rig,
                        &config.reconstruct,
                        Request {
                            warm: Some(&warm),
                            region: Some(roi),
                            ..Request::default()
                        },
                    )
                    .ok(),
                )
            })
        })
    });
    binned(&mut group, &rig, &format, &frames, &config);
    group.finish();
}

/// The same window with every frame binned 2×2 (`meb video --bin 2`: 640×360 3-D frames):
/// `bin_frames` bins the 40 frames of a window (the reader thread's extra work),
/// `decode_bin2` decodes 32 binned frames with carried timing, `window_warm_bin2` reconstructs
/// the binned second window warm-started from the binned first, and `window_bin2` is the whole
/// pipeline over one window as `window` is.
fn binned(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    rig: &Rig,
    format: &FrameFormat,
    frames: &[Frame],
    config: &VideoConfig,
) {
    let Ok(binning) = Binning::new(format, 2) else {
        eprintln!("cannot bin the clip");
        return;
    };
    let bin = |f: &Frame| {
        let mut out = Samples::U8(Vec::new());
        binning.bin(&f.samples, f.index, &mut out).map(|_| out)
    };
    let Ok(binned) = frames.iter().map(bin).collect::<Result<Vec<Samples>, _>>() else {
        eprintln!("cannot bin the clip");
        return;
    };
    let (binned_rig, binned_format) = (rig.binned(2), binning.format().clone());
    let Ok(first) = decode_frames(&binned[4..36], &binned_format, &config.decode) else {
        eprintln!("the binned clip does not decode");
        return;
    };
    let carried = DecodeConfig {
        rate_ratio: Some(first.report.rate_ratio),
        exposure: Some(first.report.exposure),
        ..config.decode.clone()
    };
    let (Ok(second), Ok(first)) = (
        decode_frames(&binned[44..76], &binned_format, &carried),
        reconstruct(
            Source::Decoded(&first),
            &binned_rig,
            &config.reconstruct,
            Request::default(),
        ),
    ) else {
        eprintln!("the binned clip does not reconstruct");
        return;
    };
    let warm = WarmStart::of(&first);
    if let Ok(warm_second) = reconstruct(
        Source::Decoded(&second),
        &binned_rig,
        &config.reconstruct,
        Request {
            warm: Some(&warm),
            ..Request::default()
        },
    ) {
        eprintln!("second window binned 2x2, warm: {:?}", warm_second.start);
        for stage in &warm_second.timings {
            eprintln!("stage {:>8.1} ms  {}", stage.ms, stage.stage);
        }
    }
    group.bench_function("bin_frames", |b| {
        b.iter(|| black_box(frames[..40].iter().map(bin).count()))
    });
    group.bench_function("decode_bin2", |b| {
        b.iter(|| black_box(decode_frames(&binned[4..36], &binned_format, &carried).ok()))
    });
    group.bench_function("frame_warm_bin2", |b| {
        b.iter(|| {
            let binned_frames = frames[44..76]
                .iter()
                .map(bin)
                .collect::<Result<Vec<_>, _>>();
            let decoded = decode_frames(&binned_frames.ok()?, &binned_format, &carried).ok()?;
            black_box(
                reconstruct(
                    Source::Decoded(&decoded),
                    &binned_rig,
                    &config.reconstruct,
                    Request {
                        warm: Some(&warm),
                        ..Request::default()
                    },
                )
                .ok(),
            )
        })
    });
    group.bench_function("window_warm_bin2", |b| {
        b.iter(|| {
            black_box(
                reconstruct(
                    Source::Decoded(&second),
                    &binned_rig,
                    &config.reconstruct,
                    Request {
                        warm: Some(&warm),
                        ..Request::default()
                    },
                )
                .ok(),
            )
        })
    });
    let binned_config = VideoConfig {
        bin: 2,
        ..config.clone()
    };
    group.bench_function("window_bin2", |b| {
        b.iter_batched(
            || -> Box<dyn FrameSource> {
                Box::new(
                    MemorySource::new(format.clone(), frames[..40].to_vec()).expect("frames fit"),
                )
            },
            |source| black_box(process(source, rig, &binned_config, None, &mut |_| Ok(())).ok()),
            BatchSize::PerIteration,
        )
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
