//! The LED light waveform seen by the camera: how much of an exposure window each LED is on.
//!
//! A neutral module shared by the two sides that produce light: the simulator's MEB-FDMA
//! carriers (`simulate::CarrierWaveform`, docs/maths/demodulation.md#the-received-signal) and the
//! virtual luminaire's recorded
//! timeline (`device::TimelineWaveform`). The simulator integrates whichever source it is given
//! over every row's exposure window.

/// A source of LED on/off waveforms in camera time.
pub trait LedWaveform: Send + Sync {
    /// Number of LEDs the waveform drives.
    fn led_count(&self) -> usize;
    /// Mean light in [0, 1] of LED `led` over the window [t0, t1) (seconds), as a fraction of
    /// its full on light: the fraction of the window it is on, plus its off level during off
    /// chips (docs/howto/flicker-safety.md). For an empty window (t1 ≤ t0) it is LED `led`'s
    /// level at t0.
    fn on_fraction(&self, led: usize, t0: f64, t1: f64) -> f64;
}
