//! Auto-exposure of a simulated capture: the gain a camera would choose so that nothing clips.
//!
//! Like a real capture, a simulated one should be exposed so that nothing saturates: the
//! simulator's default gain lets background + all LEDs exceed full scale (at 0 dB background
//! SNR the thesis sphere saturated 1 777 of its pixels, which biased the decoded LED gains by
//! 2–9 % and the depth by 1.3 mm RMSE). [`expose_without_clipping`] lowers the gain until the
//! brightest possible frame stays below [`HEADROOM_CODE`] of full scale after the tone curve.

use super::{Scene, SimConfig, SimulateError, SimulatedCapture, ToneCurve};
use meb_core::rig::Rig;

/// Code value (fraction of full scale, after the tone curve) the brightest frame may reach.
pub const HEADROOM_CODE: f64 = 0.9;

/// Inverse of a tone curve (monotone on [0, 1]) by bisection.
fn tone_inverse(tone: ToneCurve, code: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for _ in 0..50 {
        let mid = 0.5 * (lo + hi);
        if tone.encode(mid) < code {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Returns `sim` with the gain lowered (never raised) so that the brightest possible frame —
/// background plus every LED fully on, plus 3 σ read noise — stays below [`HEADROOM_CODE`]
/// after the tone curve at time 0, as an auto-exposed camera would capture it.
pub fn expose_without_clipping(
    rig: &Rig,
    scene: &Scene,
    sim: SimConfig,
) -> Result<SimConfig, SimulateError> {
    let capture = SimulatedCapture::new(rig.clone(), scene.clone(), sim.clone())?;
    let truth = capture.truth_at(0.0);
    let info = capture.info();
    let mut brightest = 0.0f64;
    for ((r, c), &inside) in truth.mask.indexed_iter() {
        let mut v: f64 = truth
            .led_true
            .images
            .iter()
            .map(|im| f64::from(im[[r, c]]))
            .sum();
        if inside {
            let (albedo, nz) = (truth.albedo[[r, c]], truth.normals[[r, c, 2]]);
            v += info.background_irradiance * f64::from(albedo) * (1.0 + f64::from(nz)) / 2.0;
        }
        if v.is_finite() {
            brightest = brightest.max(v);
        }
    }
    let allowed = tone_inverse(sim.tone, HEADROOM_CODE) - 3.0 * sim.noise.sigma;
    if brightest <= allowed || allowed <= 0.0 {
        return Ok(sim);
    }
    Ok(SimConfig {
        gain: Some(info.gain * allowed / brightest),
        ..sim
    })
}
