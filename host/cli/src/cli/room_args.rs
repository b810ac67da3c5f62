//! `meb simulate` options for real-room effects: a lamp flickering on the mains, a drifting
//! auto-exposure, dropped and repeated frames (the simulator's `room` module).

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use meb_sim::{LampWaveform, RoomEffects, RoomLamp};

/// A lamp's light waveform over one mains half-period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LampShape {
    /// 2·sin²: a pure tone at twice the mains frequency, 100 % flicker.
    Sin2,
    /// |sin|: harmonics at every multiple of twice the mains frequency.
    AbsSin,
    /// sin² with a flat top at 60 % of its peak.
    Clipped,
}

/// Real-room effects added to a simulated capture (all off by default).
#[derive(Debug, Clone, Args)]
pub struct RoomArgs {
    /// Add a room lamp on mains of this frequency (Hz, e.g. 50 or 60.2): it flickers at twice it.
    #[arg(long)]
    lamp_mains: Option<f64>,
    /// The lamp's mean light on the scene, fraction of full scale.
    #[arg(long, default_value_t = 0.01, requires = "lamp_mains")]
    lamp_level: f64,
    /// The lamp's waveform.
    #[arg(long, value_enum, default_value_t = LampShape::Sin2, requires = "lamp_mains")]
    lamp_waveform: LampShape,
    /// Auto-exposure drift: relative change of the camera's gain from the first frame to the
    /// last (e.g. 0.05).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    gain_ramp: f64,
    /// The camera drops the frame that would be written at this index (repeatable).
    #[arg(long, value_delimiter = ',')]
    drop_frame: Vec<usize>,
    /// The camera writes the frame at this index twice (repeatable).
    #[arg(long, value_delimiter = ',')]
    duplicate_frame: Vec<usize>,
}

impl RoomArgs {
    /// The effects these options ask for.
    pub fn effects(&self) -> Result<RoomEffects> {
        let lamp = self.lamp_mains.map(|mains| {
            let waveform = match self.lamp_waveform {
                LampShape::Sin2 => LampWaveform::SinSquared,
                LampShape::AbsSin => LampWaveform::AbsSin,
                LampShape::Clipped => LampWaveform::Clipped(0.6),
            };
            RoomLamp::new(mains, self.lamp_level, waveform)
        });
        let mut dropped = self.drop_frame.clone();
        let mut duplicated = self.duplicate_frame.clone();
        dropped.sort_unstable();
        duplicated.sort_unstable();
        let effects = RoomEffects {
            lamp,
            gain_ramp: self.gain_ramp,
            dropped,
            duplicated,
        };
        if let Err((field, reason)) = effects.validate() {
            bail!("--{field} {reason}");
        }
        Ok(effects)
    }
}
