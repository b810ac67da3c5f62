//! The per-pixel, shadow-aware least-squares solve G = L⁺A, ρ = |G|, n = G/ρ (SPEC §5).
//!
//! For each pixel the LEDs whose value is below `shadow_fraction` of the brightest one (or below
//! `shadow_sigmas` noise σ) are treated as shadowed and left out; the normal equations
//! (Σ L_i L_iᵀ) G = Σ A_i L_i over the remaining LEDs are solved (3×3). LEDs the solution itself
//! says cannot light the pixel (n·L_i ≤ 0) are dropped and the pixel solved again. Pixels with
//! fewer than `min_lit_leds` usable LEDs are flagged, not filled in. For distant lights the 3×3
//! inverses are cached per subset of lit LEDs.

use super::{Lights, PhotometricConfig, PhotometricError, check_shape, mask::object_mask};
use crate::types::{LedImages, NormalField};
use nalgebra::{Matrix3, Vector3};
use ndarray::{Array2, Array3};
use rayon::prelude::*;

/// Normals and albedo plus the number of LEDs each pixel was solved from.
#[derive(Debug, Clone)]
pub struct PhotometricResult {
    /// Normals, albedo and the mask of solved pixels (inside the object mask).
    pub field: NormalField,
    /// LEDs used per pixel (0 where not solved).
    pub lit_count: Array2<u8>,
    /// The object mask used (given, or found automatically).
    pub object_mask: Array2<bool>,
}

/// Image rows per parallel task.
const ROWS_PER_TASK: usize = 8;

/// One solved pixel: normal, albedo, LEDs used.
type PixelSolution = Option<(Vector3<f64>, f64, u8)>;

/// Largest LED count for which inverses are cached per lit subset (2^k entries).
const MAX_CACHED_LEDS: usize = 10;

/// Estimates normals and albedo from per-LED images.
///
/// `mask` restricts the solve (otherwise the object is found with [`object_mask`]); `noise` is a
/// per-pixel σ of the LED images in the same units, used for shadow and mask decisions.
pub fn estimate_normals(
    images: &LedImages,
    lights: &Lights,
    mask: Option<&Array2<bool>>,
    noise: Option<&Array2<f32>>,
    config: &PhotometricConfig,
) -> Result<PhotometricResult, PhotometricError> {
    let k = images.images.len();
    if k < 3 {
        return Err(PhotometricError::TooFewLeds(k));
    }
    if lights.count() != k {
        return Err(PhotometricError::LightCountMismatch {
            images: k,
            lights: lights.count(),
        });
    }
    let shape = images.images[0].dim();
    for (i, im) in images.images.iter().enumerate() {
        check_shape(&format!("image {}", i + 1), im, shape)?;
    }
    if let Some(m) = mask {
        check_shape("mask", m, shape)?;
        if !m.iter().any(|&v| v) {
            return Err(PhotometricError::EmptyMask(
                "the given mask has no pixel set".into(),
            ));
        }
    }
    if let Some(n) = noise {
        check_shape("noise map", n, shape)?;
    }
    match lights {
        Lights::Distant(v) => {
            for (i, l) in v.iter().enumerate() {
                if !l.iter().all(|c| c.is_finite()) || l.norm() == 0.0 {
                    return Err(PhotometricError::BadLight(i + 1));
                }
            }
        }
        Lights::NearField { rig, depth_mm, .. } => {
            let cam = (rig.camera.height, rig.camera.width);
            if cam != shape {
                return Err(PhotometricError::SizeMismatch {
                    what: "LED images vs the rig's camera".into(),
                    got_rows: shape.0,
                    got_cols: shape.1,
                    rows: cam.0,
                    cols: cam.1,
                });
            }
            if let Some(d) = depth_mm {
                check_shape("depth estimate", d, shape)?;
            }
        }
    }
    let cache = subset_inverses(lights, config.min_lit_leds);
    let (rows, cols) = shape;
    // Zero-filled outputs are allocated lazily; each row band then writes every one of its pixels.
    let mut normals = Array3::<f32>::zeros((rows, cols, 3));
    let mut albedo = Array2::<f32>::zeros(shape);
    let mut lit_count = Array2::<u8>::zeros(shape);
    let mut valid = Array2::from_elem(shape, false);
    // Freshly allocated arrays are contiguous in row-major order.
    let (Some(n_all), Some(rho_all), Some(lit_all), Some(valid_all)) = (
        normals.as_slice_mut(),
        albedo.as_slice_mut(),
        lit_count.as_slice_mut(),
        valid.as_slice_mut(),
    ) else {
        unreachable!("new arrays are in standard layout")
    };
    let band = ROWS_PER_TASK * cols;
    let solved: usize = n_all
        .par_chunks_mut(3 * band)
        .zip(rho_all.par_chunks_mut(band))
        .zip(lit_all.par_chunks_mut(band))
        .zip(valid_all.par_chunks_mut(band))
        .enumerate()
        .map(|(chunk, (((n_out, rho_out), lit_out), valid_out))| {
            let mut values = vec![0.0f64; k];
            let mut l = vec![Vector3::zeros(); k];
            if let Lights::Distant(v) = lights {
                l.copy_from_slice(v);
            }
            let mut count = 0;
            for dr in 0..rho_out.len() / cols {
                let r = chunk * ROWS_PER_TASK + dr;
                let image_rows: Vec<_> = images.images.iter().map(|im| im.row(r)).collect();
                let mask_row = mask.map(|m| m.row(r));
                for c in 0..cols {
                    let solution = if mask_row.is_some_and(|m| !m[c]) {
                        None
                    } else {
                        for (v, im) in values.iter_mut().zip(&image_rows) {
                            *v = f64::from(im[c]);
                        }
                        if !lights.is_distant() {
                            lights.at(r, c, &mut l);
                        }
                        let sigma = noise.map_or(0.0, |n| f64::from(n[(r, c)]));
                        solve_pixel(&values, &l, sigma, config, cache.as_deref())
                    };
                    let p = dr * cols + c;
                    match solution {
                        Some((n, rho, used)) => {
                            for j in 0..3 {
                                n_out[3 * p + j] = n[j] as f32;
                            }
                            rho_out[p] = rho as f32;
                            lit_out[p] = used;
                            valid_out[p] = true;
                            count += 1;
                        }
                        None => {
                            n_out[3 * p..3 * p + 3].fill(f32::NAN);
                            rho_out[p] = f32::NAN;
                        }
                    }
                }
            }
            count
        })
        .sum();

    // A given mask was applied during the solve; a found one is applied now.
    let (object, any) = match mask {
        Some(m) => (m.clone(), solved > 0),
        None => {
            let object = object_mask(images, &albedo, &valid, noise, &config.mask);
            let mut any = false;
            for ((r, c), v) in valid.indexed_iter_mut() {
                if !object[(r, c)] && *v {
                    *v = false;
                    albedo[(r, c)] = f32::NAN;
                    lit_count[(r, c)] = 0;
                    for j in 0..3 {
                        normals[(r, c, j)] = f32::NAN;
                    }
                }
                any |= *v;
            }
            (object, any)
        }
    };
    if !any {
        return Err(PhotometricError::EmptyMask(format!(
            "no pixel inside the object mask is lit by {} or more LEDs",
            config.min_lit_leds
        )));
    }
    Ok(PhotometricResult {
        field: NormalField {
            normals,
            albedo,
            mask: valid,
        },
        lit_count,
        object_mask: object,
    })
}

/// Relative least-squares misfit Σ‖A − L·G‖² / Σ‖A‖² of the Lambertian model over `pixels`
/// (lit LEDs only). With more lit LEDs than three it depends on the light vectors, which lets the
/// near-field stage find the object's absolute depth.
pub fn model_misfit(
    images: &LedImages,
    lights: &Lights,
    pixels: &[(usize, usize)],
    config: &PhotometricConfig,
) -> f64 {
    let k = images.images.len();
    let (misfit, energy) = pixels
        .par_chunks(1024)
        .map(|chunk| {
            let mut values = vec![0.0f64; k];
            let mut l = vec![Vector3::zeros(); k];
            if let Lights::Distant(v) = lights {
                l.copy_from_slice(v);
            }
            let (mut misfit, mut energy) = (0.0, 0.0);
            for &(r, c) in chunk {
                for (v, im) in values.iter_mut().zip(&images.images) {
                    *v = f64::from(im[(r, c)]);
                }
                if !lights.is_distant() {
                    lights.at(r, c, &mut l);
                }
                if let Some((n, rho, _)) = solve_pixel(&values, &l, 0.0, config, None) {
                    let g = n * rho;
                    let threshold = f64::from(config.shadow_fraction)
                        * values.iter().copied().fold(0.0, f64::max);
                    for (v, li) in values.iter().zip(&l) {
                        if *v > threshold {
                            misfit += (v - g.dot(li)).powi(2);
                            energy += v * v;
                        }
                    }
                }
            }
            (misfit, energy)
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    if energy > 0.0 {
        misfit / energy
    } else {
        f64::INFINITY
    }
}

/// For distant lights with few LEDs: (Σ_{i∈S} L_i L_iᵀ)⁻¹ for every subset S (bit i = LED i).
fn subset_inverses(lights: &Lights, min_lit: usize) -> Option<Vec<Option<Matrix3<f64>>>> {
    let Lights::Distant(v) = lights else {
        return None;
    };
    if v.len() > MAX_CACHED_LEDS {
        return None;
    }
    let table = (0..1usize << v.len())
        .map(|bits| {
            if (bits.count_ones() as usize) < min_lit.max(3) {
                return None;
            }
            let m = v
                .iter()
                .enumerate()
                .filter(|(i, _)| bits & (1 << i) != 0)
                .fold(Matrix3::zeros(), |m, (_, l)| m + l * l.transpose());
            well_conditioned_inverse(&m)
        })
        .collect();
    Some(table)
}

/// Inverse of a symmetric 3×3 matrix unless it is (nearly) singular.
fn well_conditioned_inverse(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let scale = m.trace();
    if scale.is_nan() || scale <= 0.0 || m.determinant().abs() < 1e-9 * scale.powi(3) {
        return None;
    }
    m.try_inverse()
}

/// Solves one pixel from its LED values `a` and light vectors `l` (see the module docs).
fn solve_pixel(
    a: &[f64],
    l: &[Vector3<f64>],
    sigma: f64,
    config: &PhotometricConfig,
    cache: Option<&[Option<Matrix3<f64>>]>,
) -> PixelSolution {
    if a.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let brightest = a.iter().copied().fold(0.0, f64::max);
    if brightest <= 0.0 {
        return None;
    }
    let threshold = (f64::from(config.shadow_fraction) * brightest)
        .max(f64::from(config.shadow_sigmas) * sigma);
    let mut bits = 0usize;
    for (i, (&v, li)) in a.iter().zip(l).enumerate() {
        if v > threshold && li.norm_squared() > 0.0 {
            bits |= 1 << i;
        }
    }
    let min_lit = config.min_lit_leds.max(3);
    // At most one refinement: drop LEDs that the first solution says cannot light the pixel.
    for _ in 0..2 {
        if (bits.count_ones() as usize) < min_lit {
            return None;
        }
        let mut b = Vector3::zeros();
        for (i, (&v, li)) in a.iter().zip(l).enumerate() {
            if bits & (1 << i) != 0 {
                b += li * v;
            }
        }
        let inverse = match cache {
            Some(table) => table[bits],
            None => {
                let m = l
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| bits & (1 << i) != 0)
                    .fold(Matrix3::zeros(), |m, (_, li)| m + li * li.transpose());
                well_conditioned_inverse(&m)
            }
        }?;
        let g = inverse * b;
        let rho = g.norm();
        if !rho.is_finite() || rho <= 0.0 {
            return None;
        }
        let n = g / rho;
        let mut refined = bits;
        for (i, li) in l.iter().enumerate() {
            if bits & (1 << i) != 0 && n.dot(li) <= 0.0 {
                refined &= !(1 << i);
            }
        }
        if refined == bits {
            return Some((n, rho, bits.count_ones() as u8));
        }
        bits = refined;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photometric::Lights;

    fn lights() -> Vec<Vector3<f64>> {
        vec![
            Vector3::new(0.5, 0.0, 0.866),
            Vector3::new(-0.5, 0.0, 0.866),
            Vector3::new(0.0, 0.5, 0.866),
            Vector3::new(0.0, -0.5, 0.866),
        ]
    }

    /// A_i = ρ max(0, n·L_i) for one normal over a small image.
    fn render(n: Vector3<f64>, rho: f64, l: &[Vector3<f64>]) -> LedImages {
        LedImages {
            images: l
                .iter()
                .map(|li| Array2::from_elem((4, 5), (rho * n.dot(li).max(0.0)) as f32))
                .collect(),
        }
    }

    #[test]
    fn recovers_normal_and_albedo() {
        let n = Vector3::new(0.2, -0.1, 1.0).normalize();
        let im = render(n, 0.7, &lights());
        let mask = Array2::from_elem((4, 5), true);
        let res = estimate_normals(
            &im,
            &Lights::Distant(lights()),
            Some(&mask),
            None,
            &PhotometricConfig::default(),
        )
        .unwrap();
        let got = [
            res.field.normals[(2, 3, 0)],
            0.0,
            res.field.normals[(2, 3, 2)],
        ];
        assert!((f64::from(got[0]) - n.x).abs() < 1e-5);
        assert!((f64::from(got[2]) - n.z).abs() < 1e-5);
        assert!((res.field.albedo[(0, 0)] - 0.7).abs() < 1e-5);
        assert_eq!(res.lit_count[(1, 1)], 4);
    }

    #[test]
    fn shadowed_led_is_left_out() {
        // Tilted so that LED 2 (from −x) sees the back side: only three LEDs light it.
        let n = Vector3::new(0.8, 0.0, 0.4).normalize();
        let im = render(n, 1.0, &lights());
        assert_eq!(im.images[1][(0, 0)], 0.0);
        let mask = Array2::from_elem((4, 5), true);
        let res = estimate_normals(
            &im,
            &Lights::Distant(lights()),
            Some(&mask),
            None,
            &PhotometricConfig::default(),
        )
        .unwrap();
        assert_eq!(res.lit_count[(0, 0)], 3);
        assert!((f64::from(res.field.normals[(0, 0, 0)]) - n.x).abs() < 1e-5);
    }

    #[test]
    fn pixel_lit_by_two_is_flagged() {
        let l = lights();
        let mut im = render(Vector3::z(), 1.0, &l);
        im.images[0].fill(0.0);
        im.images[2].fill(0.0);
        let mask = Array2::from_elem((4, 5), true);
        let err = estimate_normals(
            &im,
            &Lights::Distant(l),
            Some(&mask),
            None,
            &PhotometricConfig::default(),
        )
        .unwrap_err();
        assert!(matches!(err, PhotometricError::EmptyMask(_)), "{err}");
    }

    #[test]
    fn bad_inputs_give_errors() {
        let l = lights();
        let mut im = render(Vector3::z(), 1.0, &l);
        let cfg = PhotometricConfig::default();
        let two = Lights::Distant(l[..2].to_vec());
        let few = LedImages {
            images: im.images[..2].to_vec(),
        };
        assert!(matches!(
            estimate_normals(&few, &two, None, None, &cfg),
            Err(PhotometricError::TooFewLeds(2))
        ));
        im.images[3] = Array2::zeros((3, 3));
        assert!(matches!(
            estimate_normals(&im, &Lights::Distant(l.clone()), None, None, &cfg),
            Err(PhotometricError::SizeMismatch { .. })
        ));
        let im = render(Vector3::z(), 1.0, &l);
        let empty = Array2::from_elem((4, 5), false);
        assert!(matches!(
            estimate_normals(&im, &Lights::Distant(l), Some(&empty), None, &cfg),
            Err(PhotometricError::EmptyMask(_))
        ));
    }
}
