//! Reading frames: how fast `meb video` and `meb reconstruct` get camera frames into memory,
//! apart from decoding and reconstruction.
//!
//! - `y4m_file`: 200 frames of a 1280×720 8-bit 4:2:0 y4m file (the layout FFmpeg's
//!   `yuv4mpegpipe` writes) read with [`Y4mSource`], each frame into the storage of the one
//!   before ([`FrameSource::read_frame_into`]: luma straight into the frame, chroma skipped
//!   in the read buffer), as `meb video`'s reader thread does.
//! - `y4m_stream_windows`: the same file through [`FrameStream`] in windows of 40 (reader
//!   thread, bounded channel, recycled frame storage), the whole reading path of `meb video`.
//! - `png_sequence`: 32 frames of 1280×720 8-bit PNG, as `meb simulate` writes them, read with
//!   [`ImageSequence`] (decoded in parallel), the reading path of `meb reconstruct`.
//!
//! Criterion reports the time per pass; frames per second = frames / time. The file sits in
//! the page cache after the first pass, so these are the readers' own costs, not the disk's.
//!
//! Measured on the shared 2-core machine at a load average of ~10 (other builds running;
//! medians with criterion's low–high estimates): `y4m_file` 136 ms (131–142) for 200 frames,
//! ≈ 1 470 frames/s; `y4m_stream_windows` 152 ms (123–191), ≈ 1 300 frames/s;
//! `png_sequence` 312 ms (297–328) for 32 frames, ≈ 100 frames/s. The y4m reader keeps up
//! with the thesis' 1 000 fps camera even on a loaded machine; a 3-D frame's 40 frames take
//! ~30 ms to read.

use criterion::{Criterion, criterion_group, criterion_main};
use meb_core::capture::images::ImageSequence;
use meb_core::capture::y4m::Y4mSource;
use meb_core::capture::{FrameSource, Samples};
use meb_pipeline::video::FrameStream;
use std::hint::black_box;
use std::io::Write;
use std::path::Path;

const WIDTH: usize = 1280;
const HEIGHT: usize = 720;
const Y4M_FRAMES: usize = 200;
const PNG_FRAMES: usize = 32;

/// A frame with some texture (a compressible but not constant PNG).
fn picture(k: usize) -> Vec<u8> {
    (0..WIDTH * HEIGHT)
        .map(|i| ((i % WIDTH) / 4 + (i / WIDTH) / 3 + 7 * k) as u8)
        .collect()
}

fn write_y4m(path: &Path) {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(out, "YUV4MPEG2 W{WIDTH} H{HEIGHT} F1000:1 Ip A1:1 C420jpeg").unwrap();
    let chroma = vec![128u8; 2 * (WIDTH / 2) * (HEIGHT / 2)];
    for k in 0..Y4M_FRAMES {
        out.write_all(b"FRAME\n").unwrap();
        out.write_all(&picture(k)).unwrap();
        out.write_all(&chroma).unwrap();
    }
    out.flush().unwrap();
}

fn write_pngs(dir: &Path) {
    for k in 0..PNG_FRAMES {
        let image = image::GrayImage::from_raw(WIDTH as u32, HEIGHT as u32, picture(k)).unwrap();
        image.save(dir.join(format!("frame_{k:05}.png"))).unwrap();
    }
}

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let y4m = dir.path().join("clip.y4m");
    write_y4m(&y4m);
    let pngs = dir.path().join("png");
    std::fs::create_dir(&pngs).unwrap();
    write_pngs(&pngs);

    let mut group = c.benchmark_group("capture");
    group.sample_size(10);
    group.bench_function("y4m_file", |b| {
        b.iter(|| {
            let mut source = Y4mSource::open(&y4m, None).unwrap();
            let mut samples = Samples::U8(Vec::new());
            let mut frames = 0;
            while source.read_frame_into(&mut samples).unwrap().is_some() {
                frames += 1;
            }
            assert_eq!(frames, Y4M_FRAMES);
            black_box(samples.len())
        })
    });
    group.bench_function("y4m_stream_windows", |b| {
        b.iter(|| {
            let source = Box::new(Y4mSource::open(&y4m, None).unwrap());
            let mut stream = FrameStream::new(source, 40, None).unwrap();
            let mut windows = 0;
            while let Some(window) = stream.window(windows * 40..(windows + 1) * 40).unwrap() {
                black_box(window.samples.len());
                windows += 1;
            }
            assert_eq!(windows, Y4M_FRAMES / 40);
        })
    });
    group.bench_function("png_sequence", |b| {
        b.iter(|| {
            let mut source = ImageSequence::open(&pngs, 1000.0).unwrap();
            let mut frames = 0;
            while let Some(frame) = source.next_frame().unwrap() {
                black_box(frame.samples.len());
                frames += 1;
            }
            assert_eq!(frames, PNG_FRAMES);
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
