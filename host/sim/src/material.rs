//! The objects' material: a Lambertian base with an optional glossy coat (a GGX microfacet
//! lobe), mixed as Blender's Mix Shader mixes a Diffuse and a Glossy BSDF.
//!
//! With w the coat's weight, ρ the albedo, l the unit direction to the LED, v the unit direction
//! to the camera, h = (l + v)/|l + v| the half vector and E = |L_i(X)|·(n·l) the LED's irradiance
//! (the light vector of `rig::Led::light_vector_at`), a pixel reads g·π·f·E with the BRDF
//!
//! ```text
//! f = (1 − w)·ρ/π + w·D(h)·G(l, v) / (4·(n·l)·(n·v))
//! ```
//!
//! so a matte material (w = 0) gives the Lambertian g·ρ·(L_i·n) of [`super::lighting`]. D is the
//! GGX (Trowbridge–Reitz) normal distribution and G the separable Smith shadowing–masking term
//! (B. Walter, S. R. Marschner, H. Li, K. E. Torrance, "Microfacet Models for Refraction through
//! Rough Surfaces", Eurographics Symposium on Rendering, 2007, Eqs. 33–34):
//!
//! ```text
//! D(h) = α² / (π·((n·h)²·(α² − 1) + 1)²)
//! G₁(x) = 2·(n·x) / ((n·x) + √(α² + (1 − α²)·(n·x)²)),   G = G₁(l)·G₁(v)
//! ```
//!
//! with α = r² for the perceptual roughness r (Blender's convention). The coat has no Fresnel
//! term (Blender's Glossy BSDF reflects the same share at every angle) and no colour: its
//! highlight is the LED's, whatever the albedo. At r = 0.25 the lobe's peak is about 64·w
//! times the diffuse level of a white surface facing the LED, so a 10 % coat clips a camera
//! exposed for the diffuse surface.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// The objects' material (the ground plane stays matte); the default is matte.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Material {
    /// Weight w of the glossy coat in [0, 1] (0 = matte).
    pub gloss: f64,
    /// Perceptual roughness r of the coat in (0, 1] (α = r²).
    pub roughness: f64,
}

impl Default for Material {
    fn default() -> Self {
        Self::MATTE
    }
}

impl Material {
    /// A Lambertian material.
    pub const MATTE: Material = Material {
        gloss: 0.0,
        roughness: 0.25,
    };

    /// A glossy coat of weight `gloss` and roughness `roughness` over a Lambertian base.
    pub fn glossy(gloss: f64, roughness: f64) -> Self {
        Self { gloss, roughness }
    }

    /// Whether the material is purely Lambertian.
    pub fn is_matte(&self) -> bool {
        self.gloss == 0.0
    }

    /// Why the material is invalid, if it is.
    pub fn problem(&self) -> Option<String> {
        if !(0.0..=1.0).contains(&self.gloss) {
            return Some(format!("gloss weight {} is outside [0, 1]", self.gloss));
        }
        if !(self.roughness > 0.0 && self.roughness <= 1.0) {
            return Some(format!("roughness {} is outside (0, 1]", self.roughness));
        }
        None
    }

    /// The shading factor s with A = g·s for a surface of albedo `albedo`, unit normal `n`,
    /// light vector `light` (towards the LED, length = irradiance at normal incidence) and unit
    /// view vector `v`: π·f·|L|·(n·l) of the module docs; 0 when the LED is behind the surface.
    pub fn shade(
        &self,
        albedo: f64,
        n: &Vector3<f64>,
        light: &Vector3<f64>,
        v: &Vector3<f64>,
    ) -> f64 {
        let lambert = light.dot(n);
        if lambert <= 0.0 {
            return 0.0;
        }
        let diffuse = (1.0 - self.gloss) * albedo * lambert;
        if self.is_matte() {
            return diffuse;
        }
        diffuse + self.gloss * std::f64::consts::PI * self.specular_brdf(n, light, v) * lambert
    }

    /// D·G / (4·(n·l)·(n·v)) of the module docs (the coat's BRDF at weight 1).
    pub fn specular_brdf(&self, n: &Vector3<f64>, light: &Vector3<f64>, v: &Vector3<f64>) -> f64 {
        let l = light.normalize();
        let (nl, nv) = (n.dot(&l), n.dot(v));
        if nl <= 0.0 || nv <= 0.0 {
            return 0.0;
        }
        let half = l + v;
        let norm = half.norm();
        if norm <= 0.0 {
            return 0.0;
        }
        let nh = n.dot(&half) / norm;
        let a2 = self.roughness.powi(4);
        let denominator = nh * nh * (a2 - 1.0) + 1.0;
        let d = a2 / (std::f64::consts::PI * denominator * denominator);
        let g1 = |x: f64| 2.0 * x / (x + (a2 + (1.0 - a2) * x * x).sqrt());
        d * g1(nl) * g1(nv) / (4.0 * nl * nv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn unit(theta: f64, phi: f64) -> Vector3<f64> {
        Vector3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// The matte material is the Lambertian ρ·(L·n).
    #[test]
    fn matte_is_lambertian() {
        let n = unit(0.3, 1.0);
        let l = unit(0.7, 2.0) * 3.0;
        let s = Material::MATTE.shade(0.6, &n, &l, &Vector3::z());
        assert!((s - 0.6 * l.dot(&n)).abs() < 1e-12);
        assert_eq!(Material::MATTE.shade(0.6, &n, &(-l), &Vector3::z()), 0.0);
    }

    /// The GGX distribution is normalised: ∫ D(h)·(n·h) dω_h = 1 over the hemisphere
    /// (midpoint rule in θ, φ), at three roughnesses.
    #[test]
    fn ggx_distribution_is_normalised() {
        for r in [0.15, 0.25, 0.4] {
            let a2: f64 = f64::powi(r, 4);
            let steps = 4000;
            let dt = std::f64::consts::FRAC_PI_2 / f64::from(steps);
            let integral: f64 = (0..steps)
                .map(|k| {
                    let t = (f64::from(k) + 0.5) * dt;
                    let c = t.cos();
                    let den = c * c * (a2 - 1.0) + 1.0;
                    let d = a2 / (std::f64::consts::PI * den * den);
                    d * c * t.sin() * dt * std::f64::consts::TAU
                })
                .sum();
            assert!((integral - 1.0).abs() < 1e-3, "r = {r}: {integral}");
        }
    }

    /// The coat reflects no more than it receives: the directional albedo of the lobe,
    /// ∫ f·(n·l) dω_l, is at most 1 for random view directions (Monte Carlo, fixed seed), and the
    /// mirror direction is the brightest.
    #[test]
    fn coat_conserves_energy_and_peaks_at_the_mirror_direction() {
        let material = Material::glossy(1.0, 0.3);
        let n = Vector3::z();
        let mut rng = ChaCha8Rng::seed_from_u64(57);
        for _ in 0..5 {
            let v = unit(
                rng.random_range(0.0..1.2),
                rng.random_range(0.0..std::f64::consts::TAU),
            );
            let samples = 200_000;
            let mut sum = 0.0;
            for _ in 0..samples {
                // Uniform on the hemisphere: pdf 1/(2π).
                let l = unit(
                    rng.random_range(0.0f64..1.0).acos(),
                    rng.random_range(0.0..std::f64::consts::TAU),
                );
                sum += material.specular_brdf(&n, &l, &v) * l.z * std::f64::consts::TAU;
            }
            let albedo = sum / f64::from(samples);
            assert!(albedo <= 1.02 && albedo > 0.5, "{albedo}");
            let mirror = Vector3::new(-v.x, -v.y, v.z);
            let peak = material.specular_brdf(&n, &mirror, &v);
            let off = material.specular_brdf(&n, &unit(0.2, 0.0), &v);
            assert!(peak >= off, "{peak} < {off}");
        }
    }

    #[test]
    fn out_of_range_materials_are_named() {
        assert!(
            Material::glossy(1.5, 0.2)
                .problem()
                .unwrap()
                .contains("gloss")
        );
        assert!(
            Material::glossy(0.1, 0.0)
                .problem()
                .unwrap()
                .contains("roughness")
        );
        assert!(Material::MATTE.problem().is_none());
    }
}
