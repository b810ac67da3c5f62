//! PS + masked least-squares integration of one 1280×720 frame (the thesis' out-of-plane sphere
//! Ø48 mm, 4 distant lights, 27 104 mask pixels of which 17 596 are lit by ≥ 3 LEDs), against a
//! straightforward implementation: per-pixel SVD pseudo-inverse and unpreconditioned conjugate
//! gradients. The "stages" group times the two halves of "meb" separately.
//!
//! The "near-field" group times the per-pixel solve as `meb video`'s near-field stages run it:
//! light vectors per pixel from the sphere's depth (no cached inverses) and a noise map.
//!
//! Current figures (2-core machine of the CI's kind): PS + integration 13.9 ms against 86 ms
//! for the straightforward implementation (≈ 6×; photometric stereo 5.9 ms, least-squares
//! integration 9.2 ms in 9 preconditioned CG iterations); `model_misfit_at_one_offset`
//! 1.39 ms, `estimate_normals` 8.7–9.7 ms. End to end, `meb reconstruct` of a 32-frame
//! 1280×720 PNG capture takes 0.44–0.45 s against 2.91–2.99 s for the numpy/scipy pipeline
//! of `scripts/reference_pipeline.py` (6.5×). Dated measurements are in `NOTES.md`.

use criterion::{Criterion, criterion_group, criterion_main};
use meb_core::rig::Rig;
use meb_core::types::LedImages;
use meb_pipeline::integrate::{
    IntegrateConfig, Integrator, SurfaceEvidence, integrate_normals, integrate_surface,
};
use meb_pipeline::photometric::{Lights, ModelMisfit, PhotometricConfig, estimate_normals};
use nalgebra::{DMatrix, DVector, Vector3};
use ndarray::Array2;
use std::hint::black_box;

/// The sphere's height map (mm; NaN off the sphere), for near-field light vectors.
fn sphere_depth(rig: &Rig) -> Array2<f32> {
    Array2::from_shape_fn((rig.camera.height, rig.camera.width), |(r, c)| {
        let (x, y) = rig.camera.pixel_centre_xy(r as f64, c as f64);
        let s = 24.0f64.powi(2) - x * x - y * y;
        if s > 0.0 { s.sqrt() as f32 } else { f32::NAN }
    })
}

fn sphere_frame() -> (Rig, LedImages, Array2<bool>) {
    let rig = Rig::preset("thesis-out-of-plane").unwrap();
    let (rows, cols) = (rig.camera.height, rig.camera.width);
    let scale = Lights::near_field_scale(&rig);
    let mut images = vec![Array2::zeros((rows, cols)); rig.leds.len()];
    let mut mask = Array2::from_elem((rows, cols), false);
    for r in 0..rows {
        for c in 0..cols {
            let (x, y) = rig.camera.pixel_centre_xy(r as f64, c as f64);
            let s = 24.0f64.powi(2) - x * x - y * y;
            if s <= 0.0 {
                continue;
            }
            let p = Vector3::new(x, y, s.sqrt());
            let n = p / 24.0;
            mask[(r, c)] = true;
            for (im, led) in images.iter_mut().zip(&rig.leds) {
                im[(r, c)] = (0.8 * n.dot(&(led.light_vector_at(&p) * scale)).max(0.0)) as f32;
            }
        }
    }
    (rig, LedImages { images }, mask)
}

/// Straightforward: per-pixel SVD pseudo-inverse over the lit LEDs, then plain CG.
fn naive(rig: &Rig, images: &LedImages, mask: &Array2<bool>) -> Vec<f64> {
    let scale = Lights::near_field_scale(rig);
    let l: Vec<Vector3<f64>> = rig
        .distant_light_vectors()
        .iter()
        .map(|v| v * scale)
        .collect();
    let (rows, cols) = mask.dim();
    let mut gx = Array2::zeros((rows, cols));
    let mut gy = Array2::zeros((rows, cols));
    let mut valid = Array2::from_elem((rows, cols), false);
    for r in 0..rows {
        for c in 0..cols {
            if !mask[(r, c)] {
                continue;
            }
            let lit: Vec<usize> = (0..l.len())
                .filter(|&i| images.images[i][(r, c)] > 0.0)
                .collect();
            if lit.len() < 3 {
                continue;
            }
            let m = DMatrix::from_fn(lit.len(), 3, |i, j| l[lit[i]][j]);
            let a = DVector::from_fn(lit.len(), |i, _| f64::from(images.images[lit[i]][(r, c)]));
            let Ok(pinv) = m.pseudo_inverse(1e-12) else {
                continue;
            };
            let g = pinv * a;
            if g[2] > 1e-6 {
                gx[(r, c)] = -g[0] / g[2];
                gy[(r, c)] = -g[1] / g[2];
                valid[(r, c)] = true;
            }
        }
    }
    // Plain CG on the masked Laplacian.
    let h = rig.camera.pitch_mm();
    let idx = Array2::from_shape_fn((rows, cols), |p| p);
    let pixels: Vec<(usize, usize)> = idx.iter().copied().filter(|&p| valid[p]).collect();
    let mut number = Array2::from_elem((rows, cols), usize::MAX);
    for (k, &p) in pixels.iter().enumerate() {
        number[p] = k;
    }
    let n = pixels.len();
    let nbrs: Vec<Vec<usize>> = pixels
        .iter()
        .map(|&(r, c)| {
            [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ]
            .iter()
            .filter(|q| q.0 < rows && q.1 < cols && number[**q] != usize::MAX)
            .map(|q| number[*q])
            .collect()
        })
        .collect();
    let mut b = vec![0.0; n];
    for (k, &(r, c)) in pixels.iter().enumerate() {
        if c + 1 < cols && number[(r, c + 1)] != usize::MAX {
            let g = 0.5 * h * (gx[(r, c)] + gx[(r, c + 1)]);
            b[k] -= g;
            b[number[(r, c + 1)]] += g;
        }
        if r + 1 < rows && number[(r + 1, c)] != usize::MAX {
            let g = -0.5 * h * (gy[(r, c)] + gy[(r + 1, c)]);
            b[k] -= g;
            b[number[(r + 1, c)]] += g;
        }
    }
    let apply = |x: &[f64], y: &mut [f64]| {
        for k in 0..n {
            y[k] =
                (nbrs[k].len() as f64 + 1e-10) * x[k] - nbrs[k].iter().map(|&j| x[j]).sum::<f64>();
        }
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut x = vec![0.0; n];
    let mut r = b.clone();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    let stop = 1e-14 * dot(&b, &b);
    let mut ap = vec![0.0; n];
    for _ in 0..20_000 {
        if rr <= stop {
            break;
        }
        apply(&p, &mut ap);
        let alpha = rr / dot(&p, &ap);
        for k in 0..n {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        let rr_new = dot(&r, &r);
        for k in 0..n {
            p[k] = r[k] + rr_new / rr * p[k];
        }
        rr = rr_new;
    }
    x
}

fn bench(c: &mut Criterion) {
    let (rig, images, mask) = sphere_frame();
    let scale = Lights::near_field_scale(&rig);
    let lights = Lights::Distant(
        rig.distant_light_vectors()
            .iter()
            .map(|v| v * scale)
            .collect(),
    );
    let pitch = rig.camera.pitch_mm();
    let least_squares = IntegrateConfig {
        integrator: Integrator::LeastSquares,
        ..IntegrateConfig::default()
    };
    let bilateral = IntegrateConfig {
        integrator: Integrator::Bilateral,
        ..IntegrateConfig::default()
    };
    let mut group = c.benchmark_group("ps+integration 1280x720 sphere");
    group.sample_size(10);
    group.bench_function("meb", |b| {
        b.iter(|| {
            let ps = estimate_normals(
                &images,
                &lights,
                Some(&mask),
                None,
                &PhotometricConfig::default(),
            )
            .unwrap();
            black_box(integrate_normals(&ps.field, pitch, &least_squares, None).unwrap())
        })
    });
    group.bench_function("straightforward", |b| {
        b.iter(|| black_box(naive(&rig, &images, &mask)))
    });
    group.finish();

    // The stages of "meb" separately, and the other integrators.
    let config = PhotometricConfig::default();
    let ps = estimate_normals(&images, &lights, Some(&mask), None, &config).unwrap();
    let mut stages = c.benchmark_group("stages 1280x720 sphere");
    stages.sample_size(10);
    stages.bench_function("photometric stereo", |b| {
        b.iter(|| {
            black_box(estimate_normals(&images, &lights, Some(&mask), None, &config).unwrap())
        })
    });
    stages.bench_function("least-squares integration", |b| {
        b.iter(|| black_box(integrate_normals(&ps.field, pitch, &least_squares, None).unwrap()))
    });
    stages.bench_function("bilateral integration", |b| {
        b.iter(|| black_box(integrate_normals(&ps.field, pitch, &bilateral, None).unwrap()))
    });
    // With the pixels lit by two LEDs (circles) and the holes.
    let evidence = SurfaceEvidence {
        field: &ps.field,
        planes: &ps.planes,
        fill: Some(&ps.fill),
    };
    let projection = rig.camera.projection();
    stages.bench_function("bilateral integration with two-LED pixels", |b| {
        b.iter(|| black_box(integrate_surface(&evidence, &projection, &bilateral, None).unwrap()))
    });
    stages.finish();

    // The per-pixel solve as the near-field stages run it: light vectors per pixel from a depth
    // estimate (no cached inverses) and a noise map (the shadow and consistency tests).
    let depth = sphere_depth(&rig);
    let noise = Array2::from_elem(mask.dim(), 0.002f32);
    let near = Lights::near_field(&rig, Some(&depth));
    let mut near_field = c.benchmark_group("near-field photometric stereo 1280x720 sphere");
    near_field.sample_size(20);
    near_field.bench_function("estimate_normals", |b| {
        b.iter(|| {
            black_box(estimate_normals(&images, &near, Some(&mask), Some(&noise), &config).unwrap())
        })
    });
    let pixels: Vec<(usize, usize)> = mask
        .indexed_iter()
        .filter(|&(_, &m)| m)
        .map(|(p, _)| p)
        .collect();
    let model = ModelMisfit::new(
        &images,
        &near,
        &pixels,
        Some(&noise),
        &vec![1.0; rig.leds.len()],
        &config,
    );
    near_field.bench_function("model_misfit_at_one_offset", |b| {
        b.iter(|| black_box(model.at(0.3)))
    });
    near_field.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
