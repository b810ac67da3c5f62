//! The per-pixel result of the photometric solve, shared by the solver (which produces it) and
//! the object mask (which keeps the pixels whose outcome is usable).

use nalgebra::Vector3;

/// What the solve found at one pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Outcome {
    /// Outside the given mask.
    Outside,
    /// A value is NaN or infinite (e.g. flagged by the decoder).
    Unusable,
    /// Fewer than two LEDs light it.
    Dark,
    /// Lit by two LEDs: the normal is on a circle (across, towards and least albedo-scaled
    /// normal of [`crate::types::NormalPlane`]).
    TwoLeds(Vector3<f64>, Vector3<f64>, Vector3<f64>),
    /// Normal, albedo and LEDs used.
    Solved(Vector3<f64>, f64, u8),
    /// Three or more LEDs light it but their light vectors do not span space.
    Singular,
    /// Every lit LED's solution contradicts it (e.g. light vectors pointing away).
    Contradictory,
}
