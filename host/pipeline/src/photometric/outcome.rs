//! The per-pixel result of the photometric solve, shared by the solver (which produces it) and
//! the object mask (which keeps the pixels whose outcome is usable).
//!
//! The solver returns a [`Solution`] per pixel; the image-wide map keeps only its kind
//! ([`Outcome`], one byte a pixel: a 1280×720 map of full solutions would take 74 MB to
//! allocate, fill and read back per solve), while normals, albedo and two-LED circles go to
//! their own arrays.

use nalgebra::Vector3;

/// What the solve found at one pixel, in one byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Outcome {
    /// Outside the given mask.
    Outside,
    /// A value is NaN or infinite (e.g. flagged by the decoder).
    Unusable,
    /// Fewer than two LEDs light it.
    Dark,
    /// Lit by two LEDs: the normal is on a circle.
    TwoLeds,
    /// Solved from three or more LEDs.
    Solved,
    /// Three or more LEDs light it but their light vectors do not span space.
    Singular,
    /// Every lit LED's solution contradicts it (e.g. light vectors pointing away).
    Contradictory,
}

impl Outcome {
    /// Whether the pixel carries evidence of the surface (a normal or a two-LED circle).
    pub fn is_usable(self) -> bool {
        matches!(self, Outcome::Solved | Outcome::TwoLeds)
    }
}

/// The solve of one pixel with what it found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Solution {
    /// Nothing beyond its kind (never [`Outcome::Solved`] or [`Outcome::TwoLeds`]).
    Failed(Outcome),
    /// Lit by two LEDs: the normal is on a circle (across, towards and least albedo-scaled
    /// normal of [`meb_core::types::NormalPlane`]).
    TwoLeds(Vector3<f64>, Vector3<f64>, Vector3<f64>),
    /// Normal, albedo, LEDs used and LEDs rejected as highlights (bit i = LED i).
    Solved(Vector3<f64>, f64, u8, u16),
}

impl Solution {
    /// Its kind.
    pub fn outcome(&self) -> Outcome {
        match self {
            Solution::Failed(outcome) => *outcome,
            Solution::TwoLeds(..) => Outcome::TwoLeds,
            Solution::Solved(..) => Outcome::Solved,
        }
    }
}
