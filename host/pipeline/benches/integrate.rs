//! Integration of one 3-D video frame: the photometric-stereo result of the thesis-dynamic
//! turning ellipsoid (1280×720, frames 4..36 decoded, near-field PS from `reconstruct`)
//! integrated by `integrate_surface` with the settings `reconstruct` gives a pass
//! ([`meb_pipeline::reconstruct::pass_integration`]): an early pass of a cold window (at most 8 two-LED
//! alternations, relative residual 10⁻⁵) for `cold` and `warm_same`, a warm window's pass (one
//! alternation, 10⁻⁴) for `warm_next`.
//!
//! Cases: `cold` (no depth, as the first pass of a cold window); `warm_same` (this window's
//! depth moved 2 mm away, as a later pass of the same window sees it after the offset search);
//! `warm_next` (the second window's PS result started from the first window's depth, as the
//! first pass of a warm window); the `_workspace` variants keep an [`IntegrationWorkspace`]
//! between calls as a caller that holds one per video would (for `warm_next` primed with the
//! first window's integration). The bench prints the per-step profile of each case once.
//!
//! `MEB_INTEGRATE_BENCH_CACHE=DIR` stores the two windows' PS results there on the first run and
//! reads them afterwards; `MEB_INTEGRATE_BENCH_CASE=NAME` with a filter matching no benchmark
//! profiles one case only (for `valgrind --tool=callgrind --collect-atstart=no
//! --toggle-collect='*integrate_surface_with*'`).
//!
//! The dated measurements (callgrind instruction counts per step, what each change saved) are in
//! `NOTES.md` beside this file.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use meb_core::capture::Samples;
use meb_core::rig::{Projection, Rig};
use meb_core::types::NormalField;
use meb_pipeline::demod::decode_frames;
use meb_pipeline::integrate::{
    IntegrateConfig, Integration, IntegrationWorkspace, NormalPlane, SurfaceEvidence,
    integrate_surface, integrate_surface_with,
};
use meb_pipeline::photometric::PhotometricResult;
use meb_pipeline::reconstruct::{Reconstruction, Request, Source, pass_integration, reconstruct};
use meb_pipeline::video::VideoConfig;
use nalgebra::Vector3;
use ndarray::Array2;
use ndarray_npy::{read_npy, write_npy};
use std::hint::black_box;
use std::path::{Path, PathBuf};

mod common;

/// What the integration of one window sees: the last photometric pass and the depth found.
struct WindowResult {
    photometric: PhotometricResult,
    depth: Array2<f32>,
}

impl WindowResult {
    fn of(reconstruction: Reconstruction) -> Self {
        Self {
            depth: reconstruction.integration.depth.depth_mm,
            photometric: reconstruction.photometric,
        }
    }

    /// Stores the parts the bench uses in `dir` (npy files; two-LED pixels as rows of row,
    /// column, across, towards, least albedo).
    fn save(&self, dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
        std::fs::create_dir_all(dir)?;
        let ps = &self.photometric;
        write_npy(dir.join("normals.npy"), &ps.field.normals)?;
        write_npy(dir.join("albedo.npy"), &ps.field.albedo)?;
        write_npy(dir.join("mask.npy"), &ps.field.mask)?;
        write_npy(dir.join("fill.npy"), &ps.fill)?;
        write_npy(dir.join("depth.npy"), &self.depth)?;
        let planes = Array2::from_shape_fn((ps.planes.len(), 11), |(i, j)| {
            let p = &ps.planes[i];
            match j {
                0 => p.pixel.0 as f64,
                1 => p.pixel.1 as f64,
                2..5 => p.across[j - 2],
                5..8 => p.towards[j - 5],
                _ => p.least_albedo[j - 8],
            }
        });
        write_npy(dir.join("planes.npy"), &planes)?;
        Ok(())
    }

    /// Reads what [`Self::save`] stored (only the fields the integration uses).
    fn load(dir: &Path) -> Result<Self, Box<dyn std::error::Error>> {
        let mask: Array2<bool> = read_npy(dir.join("mask.npy"))?;
        let planes: Array2<f64> = read_npy(dir.join("planes.npy"))?;
        let planes = planes
            .outer_iter()
            .map(|p| NormalPlane {
                pixel: (p[0] as usize, p[1] as usize),
                across: Vector3::new(p[2], p[3], p[4]),
                towards: Vector3::new(p[5], p[6], p[7]),
                least_albedo: Vector3::new(p[8], p[9], p[10]),
            })
            .collect();
        Ok(Self {
            photometric: PhotometricResult {
                field: NormalField {
                    normals: read_npy(dir.join("normals.npy"))?,
                    albedo: read_npy(dir.join("albedo.npy"))?,
                    mask: mask.clone(),
                },
                lit_count: Array2::zeros(mask.dim()),
                highlights: Array2::zeros(mask.dim()),
                object_mask: mask,
                planes,
                fill: read_npy(dir.join("fill.npy"))?,
                noise_gains: Vec::new(),
            },
            depth: read_npy(dir.join("depth.npy"))?,
        })
    }
}

/// The two windows, from `MEB_INTEGRATE_BENCH_CACHE` (a directory) when it holds them, else
/// simulated (and stored there when it is set): repeated runs and callgrind skip the simulation.
fn windows() -> Option<(Rig, VideoConfig, WindowResult, WindowResult)> {
    let rig = Rig::preset("thesis-dynamic")?;
    let config = VideoConfig::thesis(rig.leds.len());
    let cache = std::env::var_os("MEB_INTEGRATE_BENCH_CACHE").map(PathBuf::from);
    if let Some(dir) = &cache
        && let (Ok(first), Ok(second)) = (
            WindowResult::load(&dir.join("first")),
            WindowResult::load(&dir.join("second")),
        )
    {
        return Some((rig, config, first, second));
    }
    let (first, second) = simulated_windows(&rig, &config)?;
    if let Some(dir) = &cache {
        for (name, window) in [("first", &first), ("second", &second)] {
            if let Err(e) = window.save(&dir.join(name)) {
                eprintln!("cannot store the bench's windows in {}: {e}", dir.display());
            }
        }
    }
    Some((rig, config, first, second))
}

/// The two decoded windows of the turning ellipsoid (frames 4..36 and 44..76), reconstructed
/// cold as `meb video` reconstructs its first window.
fn simulated_windows(rig: &Rig, config: &VideoConfig) -> Option<(WindowResult, WindowResult)> {
    let (format, clip) = common::turning_ellipsoid(rig, 76)?;
    let frames: Vec<Samples> = clip.into_iter().map(|f| f.samples).collect();
    let first = decode_frames(frames.get(4..36)?, &format, &config.decode).ok()?;
    let second = decode_frames(frames.get(44..76)?, &format, &config.decode).ok()?;
    let first = reconstruct(
        Source::Decoded(&first),
        rig,
        &config.reconstruct,
        Request::default(),
    )
    .ok()?;
    let second = reconstruct(
        Source::Decoded(&second),
        rig,
        &config.reconstruct,
        Request::default(),
    )
    .ok()?;
    Some((WindowResult::of(first), WindowResult::of(second)))
}

fn evidence(ps: &PhotometricResult) -> SurfaceEvidence<'_> {
    SurfaceEvidence {
        field: &ps.field,
        planes: &ps.planes,
        fill: Some(&ps.fill),
    }
}

/// Median and 90th percentile of |a − b| (mm) over pixels finite in both.
fn difference(a: &Array2<f32>, b: &Array2<f32>) -> (f32, f32, usize) {
    let mut d: Vec<f32> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (x - y).abs())
        .collect();
    d.sort_by(f32::total_cmp);
    if d.is_empty() {
        return (f32::NAN, f32::NAN, 0);
    }
    (d[d.len() / 2], d[d.len() * 9 / 10], d.len())
}

fn report(name: &str, out: &Integration, workspace: &IntegrationWorkspace) {
    let p = workspace.profile();
    eprintln!(
        "{name}: {:.1} ms, {} passes, {} CG iterations {:?}, graph reused: {}, {} pixels kept",
        p.total_ms(),
        out.passes,
        out.iterations,
        p.solve_iterations,
        p.reused_graph,
        out.kept.iter().filter(|&&k| k).count()
    );
    for step in &p.steps {
        eprintln!("  {:>8.2} ms  {}", step.ms, step.stage);
    }
    // A fingerprint of the depth map's bits: a change meant to keep results bit-identical
    // shows here.
    let fingerprint = out
        .depth
        .depth_mm
        .iter()
        .fold(0xcbf2_9ce4_8422_2325_u64, |h, z| {
            (h ^ u64::from(z.to_bits())).wrapping_mul(0x0100_0000_01b3)
        });
    eprintln!("  depth fingerprint {fingerprint:016x}");
    let cg = p.ms("conjugate gradients");
    let iterations: usize = p.solve_iterations.iter().sum();
    if iterations > 0 {
        eprintln!("  {:>8.2} ms  per CG iteration", cg / iterations as f64);
    }
}

fn bench(c: &mut Criterion) {
    // As `meb` does first thing: repeated integrations reuse their arrays' pages.
    // SAFETY: criterion calls this on its main thread before any other thread starts (the
    // windows are simulated or read below).
    unsafe { meb_core::memory::keep_freed_memory() };
    let Some((rig, config, first, second)) = windows() else {
        eprintln!("cannot simulate, decode or reconstruct the turning ellipsoid");
        return;
    };
    let projection: Projection = rig.camera.projection();
    // An early pass of a cold window (`cold`, `warm_same`) and a warm window's pass
    // (`warm_next`), as `reconstruct` sets them.
    let early = pass_integration(&config.reconstruct, false, false);
    let warm_window = pass_integration(&config.reconstruct, false, true);
    let shifted = first.depth.mapv(|z| z + 2.0);
    let previous = &first.depth;
    let (one, two) = (evidence(&first.photometric), evidence(&second.photometric));
    eprintln!(
        "mask: {} measured, {} two-LED, {} filled pixels (first window)",
        first.photometric.field.mask.iter().filter(|&&m| m).count(),
        first.photometric.planes.len(),
        first.photometric.fill.iter().filter(|&&m| m).count()
    );
    // Profiles, and how far each result lies from a cold solve to the reconstruction's
    // final tolerance.
    // `MEB_INTEGRATE_BENCH_CASE=NAME` profiles only that case (for callgrind, with the bench
    // filter set to match nothing).
    let only = std::env::var("MEB_INTEGRATE_BENCH_CASE").ok();
    let exact = match only {
        Some(_) => None,
        None => integrate_surface(&one, &projection, &config.reconstruct.integrate, None).ok(),
    };
    let cases: [(
        &str,
        &SurfaceEvidence,
        Option<&Array2<f32>>,
        &IntegrateConfig,
    ); 3] = [
        ("cold", &one, None, &early),
        ("warm_same", &one, Some(&shifted), &early),
        ("warm_next", &two, Some(previous), &warm_window),
    ];
    for (name, evidence, depth, settings) in cases {
        if only.as_ref().is_some_and(|o| o != name) {
            continue;
        }
        let mut workspace = IntegrationWorkspace::new();
        if name == "warm_next" {
            let _ = integrate_surface_with(&one, &projection, &early, None, &mut workspace);
        }
        for round in ["", "_workspace"] {
            match integrate_surface_with(evidence, &projection, settings, depth, &mut workspace) {
                Ok(out) => {
                    report(&format!("{name}{round}"), &out, &workspace);
                    if let (Some(exact), true) = (&exact, name != "warm_next") {
                        let (median, p90, n) =
                            difference(&out.depth.depth_mm, &exact.depth.depth_mm);
                        eprintln!(
                            "  vs cold solve to 1e-7: median {median:.4} mm, 90 % {p90:.4} mm \
                             over {n} pixels (after anchoring)"
                        );
                    }
                }
                Err(e) => eprintln!("{name}: {e}"),
            }
            if name == "warm_next" {
                break;
            }
        }
    }
    let mut group = c.benchmark_group("integrate_1280x720");
    group.sample_size(10);
    for (name, evidence, depth, settings) in cases {
        group.bench_function(name, |b| {
            b.iter(|| black_box(integrate_surface(evidence, &projection, settings, depth).ok()))
        });
    }
    group.bench_function("warm_same_workspace", |b| {
        let mut workspace = IntegrationWorkspace::new();
        b.iter(|| {
            black_box(
                integrate_surface_with(&one, &projection, &early, Some(&shifted), &mut workspace)
                    .ok(),
            )
        })
    });
    group.bench_function("warm_next_workspace", |b| {
        b.iter_batched(
            || {
                let mut workspace = IntegrationWorkspace::new();
                let _ = integrate_surface_with(&one, &projection, &early, None, &mut workspace);
                workspace
            },
            |mut workspace| {
                black_box(
                    integrate_surface_with(
                        &two,
                        &projection,
                        &warm_window,
                        Some(previous),
                        &mut workspace,
                    )
                    .ok(),
                )
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
