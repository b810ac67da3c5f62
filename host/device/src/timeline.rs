//! The light a luminaire emits, as a recorded timeline of output states, and its on/off
//! waveform (docs/maths/carriers.md#the-carrier-table: the on-mask table played cyclically at the
//! chip rate).
//!
//! The virtual luminaire appends a [`TimelineSegment`] whenever its output changes (new chip
//! table, rate, brightness, start, stop, identify). Within a segment playback starts at chip 0
//! of the phase-shifted table at the segment's start and advances at the *effective* chip rate,
//! nominal × (1 + ppm·10⁻⁶), modelling the board's crystal error. Brightness is PWM far above
//! the chip rate, so an on chip emits its on compare value/1000 of full light on average and an
//! off chip its off compare value/1000 (the off level's fraction of it, `protocol::timing`). Identify blinks
//! every LED at [`IDENTIFY_BLINK_HZ`] with 50 % duty at full brightness.
//!
//! [`TimelineWaveform`] reads the timeline in camera time (camera t = 0 at a chosen timeline
//! instant) and implements the simulator's [`LedWaveform`], so `meb simulate` can render exactly
//! what a configured luminaire emits.

use std::io::{self, Write};
use std::path::{Path, PathBuf};

use protocol::carriers::{ChipTable, MAX_LEDS};
use protocol::config::{ChipRate, LuminaireConfig};
use protocol::luminaire::OutputPlan;
use protocol::timing::{LedLevels, PWM_STEPS};
use serde::{Deserialize, Serialize};

use meb_core::led_waveform::LedWaveform;

/// `format` tag of a timeline file.
pub const TIMELINE_FORMAT: &str = "meb-luminaire-timeline";
/// Version of the timeline file layout.
pub const TIMELINE_VERSION: u32 = 1;
/// Blink rate of the identify pattern.
pub const IDENTIFY_BLINK_HZ: f64 = 2.0;

/// What the LEDs do during a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OutputMode {
    /// The carriers play.
    Playing,
    /// All LEDs off (stopped).
    Off,
    /// All LEDs blink together (identify).
    Identify,
}

/// One output state, from its start time until the next segment's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TimelineSegment {
    /// Start, in seconds since the luminaire booted.
    pub t: f64,
    /// What the LEDs do.
    pub mode: OutputMode,
    /// Number of LEDs N.
    pub led_count: u8,
    /// Configured chip rate in millihertz.
    pub chip_rate_millihertz: u32,
    /// Chip rate actually played (configured × (1 + ppm·10⁻⁶)), in Hz.
    pub effective_chip_rate_hz: f64,
    /// Per-LED on-brightness in per mille (N entries).
    pub brightness_permille: Vec<u16>,
    /// Per-LED carrier delay in chips (N entries).
    pub phase_chips: Vec<u16>,
    /// Per-LED off level in per mille of the on level (N entries; absent in timelines written
    /// before off levels, read as dark off chips).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub off_level_permille: Vec<u16>,
}

impl TimelineSegment {
    /// The segment playing `plan` from `t` with crystal error `rate_error_ppm`.
    pub fn new(t: f64, mode: OutputMode, plan: &OutputPlan, rate_error_ppm: f64) -> Self {
        let n = usize::from(plan.led_count).min(MAX_LEDS);
        Self {
            t,
            mode,
            led_count: plan.led_count,
            chip_rate_millihertz: plan.chip_rate.millihertz(),
            effective_chip_rate_hz: ChipRate::hz(plan.chip_rate) * (1.0 + rate_error_ppm * 1e-6),
            brightness_permille: plan.brightness_permille[..n].to_vec(),
            phase_chips: plan.phase_chips[..n].to_vec(),
            off_level_permille: plan.off_level_permille[..n].to_vec(),
        }
    }
}

impl TimelineSegment {
    /// Each LED's off-chip light as a fraction ℓ_i of its on light, from the compare values
    /// the PWM plays (0 for a dark LED, and for a segment written before off levels).
    pub fn off_fractions(&self) -> Vec<f64> {
        let mut config = LuminaireConfig {
            led_count: self.led_count,
            ..LuminaireConfig::FULL_DEPTH
        };
        let n = self.brightness_permille.len().min(MAX_LEDS);
        config.brightness_permille[..n].copy_from_slice(&self.brightness_permille[..n]);
        let m = self.off_level_permille.len().min(MAX_LEDS);
        config.off_level_permille[..m].copy_from_slice(&self.off_level_permille[..m]);
        crate::settings::off_fractions(&config)
    }
}

/// Error reading or writing a timeline file, or building its waveform.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TimelineError {
    /// The file could not be read or written.
    #[error("timeline file {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        #[source]
        source: io::Error,
    },
    /// The file is not JSON of a timeline.
    #[error("{path} is not a meb luminaire timeline")]
    Json {
        /// The file.
        path: PathBuf,
        /// What the JSON reader found.
        #[source]
        source: serde_json::Error,
    },
    /// The file is a timeline of another format tag or version.
    #[error("{path} is not a meb luminaire timeline: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A segment's LED count and phases do not make a chip table.
    #[error("timeline segment {index} is invalid")]
    Carriers {
        /// 0-based segment index.
        index: usize,
        /// Why the chip table could not be built.
        #[source]
        source: protocol::carriers::CarrierError,
    },
    /// A segment is inconsistent (unordered, bad LED count, rate, or list lengths).
    #[error("timeline segment {index} is invalid: {reason}")]
    Segment {
        /// 0-based segment index.
        index: usize,
        /// What is wrong.
        reason: String,
    },
    /// The timeline has no segment to play.
    #[error("the timeline is empty")]
    Empty,
    /// The chosen start lies before the luminaire's first output.
    #[error("start {offset} s lies before the timeline's first output at {first} s")]
    BeforeFirstSegment {
        /// The requested start, seconds.
        offset: f64,
        /// The first segment's start, seconds.
        first: f64,
    },
}

/// Every output state a luminaire went through, in time order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timeline {
    /// Always [`TIMELINE_FORMAT`].
    pub format: String,
    /// Always [`TIMELINE_VERSION`].
    pub version: u32,
    /// Crystal error the emulator applied, in ppm.
    pub rate_error_ppm: f64,
    /// Output states in time order.
    pub segments: Vec<TimelineSegment>,
}

impl Timeline {
    /// An empty timeline recorded with crystal error `rate_error_ppm`.
    pub fn new(rate_error_ppm: f64) -> Self {
        Self {
            format: TIMELINE_FORMAT.into(),
            version: TIMELINE_VERSION,
            rate_error_ppm,
            segments: Vec::new(),
        }
    }

    /// Reads and validates a timeline file.
    pub fn read(path: &Path) -> Result<Self, TimelineError> {
        let text = std::fs::read_to_string(path).map_err(|source| TimelineError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let format_err = |reason: String| TimelineError::Format {
            path: path.to_path_buf(),
            reason,
        };
        let timeline: Timeline =
            serde_json::from_str(&text).map_err(|source| TimelineError::Json {
                path: path.to_path_buf(),
                source,
            })?;
        if timeline.format != TIMELINE_FORMAT || timeline.version != TIMELINE_VERSION {
            return Err(format_err(format!(
                "format {:?} version {}, expected {TIMELINE_FORMAT:?} version {TIMELINE_VERSION}",
                timeline.format, timeline.version
            )));
        }
        timeline.validate()?;
        Ok(timeline)
    }

    /// Writes the timeline as JSON (temporary file, then rename).
    pub fn write(&self, path: &Path) -> Result<(), TimelineError> {
        let io_err = |source| TimelineError::Io {
            path: path.to_path_buf(),
            source,
        };
        let json = serde_json::to_vec_pretty(self).map_err(|e| io_err(e.into()))?;
        let mut temp_name = path.file_name().unwrap_or_default().to_os_string();
        temp_name.push(".tmp");
        let temp = path.with_file_name(temp_name);
        let mut file = std::fs::File::create(&temp).map_err(io_err)?;
        file.write_all(&json).map_err(io_err)?;
        drop(file);
        std::fs::rename(&temp, path).map_err(io_err)
    }

    /// Checks time order, LED counts, rates and list lengths.
    pub fn validate(&self) -> Result<(), TimelineError> {
        let mut previous = f64::NEG_INFINITY;
        for (index, s) in self.segments.iter().enumerate() {
            let bad = |reason: &str| TimelineError::Segment {
                index,
                reason: reason.into(),
            };
            if !s.t.is_finite() || s.t < previous {
                return Err(bad(
                    "start time not finite or earlier than the previous segment",
                ));
            }
            previous = s.t;
            if s.led_count == 0 || usize::from(s.led_count) > MAX_LEDS {
                return Err(bad("led_count outside 1..=8"));
            }
            if !(s.effective_chip_rate_hz.is_finite() && s.effective_chip_rate_hz > 0.0) {
                return Err(bad("effective_chip_rate_hz must be positive"));
            }
            let n = usize::from(s.led_count);
            if s.brightness_permille.len() != n || s.phase_chips.len() != n {
                return Err(bad(
                    "brightness_permille and phase_chips need led_count entries",
                ));
            }
            if s.brightness_permille.iter().any(|&b| b > 1000) {
                return Err(bad("brightness above 1000 per mille"));
            }
            if !(s.off_level_permille.is_empty() || s.off_level_permille.len() == n) {
                return Err(bad("off_level_permille needs led_count entries or none"));
            }
            if s.off_level_permille.iter().any(|&b| b > 1000) {
                return Err(bad("off level above 1000 per mille"));
            }
        }
        Ok(())
    }

    /// Whether `other` is this timeline up to float rounding of the rates and times (JSON
    /// does not round-trip every last bit of an `f64`).
    pub fn approx_eq(&self, other: &Timeline) -> bool {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0);
        self.format == other.format
            && self.version == other.version
            && close(self.rate_error_ppm, other.rate_error_ppm)
            && self.segments.len() == other.segments.len()
            && self.segments.iter().zip(&other.segments).all(|(a, b)| {
                close(a.t, b.t)
                    && close(a.effective_chip_rate_hz, b.effective_chip_rate_hz)
                    && TimelineSegment {
                        t: b.t,
                        effective_chip_rate_hz: b.effective_chip_rate_hz,
                        ..a.clone()
                    } == *b
            })
    }

    /// The segment playing at timeline time `t` (the last one for `None`, what
    /// [`TimelineWaveform::load`] starts from).
    pub fn segment_at(&self, t: Option<f64>) -> Result<&TimelineSegment, TimelineError> {
        let first = self.segments.first().ok_or(TimelineError::Empty)?;
        let Some(t) = t else {
            return self.segments.last().ok_or(TimelineError::Empty);
        };
        let at = self.segments.partition_point(|s| s.t <= t);
        at.checked_sub(1).and_then(|i| self.segments.get(i)).ok_or(
            TimelineError::BeforeFirstSegment {
                offset: t,
                first: first.t,
            },
        )
    }

    /// Start time of the last segment: from then on the luminaire's output is steady.
    pub fn last_change(&self) -> Option<f64> {
        self.segments.last().map(|s| s.t)
    }
}

/// One segment prepared for fast evaluation.
#[derive(Debug, Clone)]
struct PlayedSegment {
    t: f64,
    mode: OutputMode,
    rate_hz: f64,
    table: ChipTable,
    /// Light during on chips, fraction of full.
    gain: [f64; MAX_LEDS],
    /// Light during off chips, fraction of full.
    off_gain: [f64; MAX_LEDS],
}

/// A recorded timeline as LED light in camera time: camera t ↦ timeline t + `offset`.
#[derive(Debug, Clone)]
pub struct TimelineWaveform {
    segments: Vec<PlayedSegment>,
    offset: f64,
    led_count: usize,
}

impl TimelineWaveform {
    /// The waveform of `timeline` with camera time 0 at timeline time `offset` seconds.
    /// Its LED count is that of the segment playing at `offset`.
    pub fn new(timeline: &Timeline, offset: f64) -> Result<Self, TimelineError> {
        timeline.validate()?;
        let mut segments = Vec::with_capacity(timeline.segments.len());
        for (index, s) in timeline.segments.iter().enumerate() {
            let mut phases = [0u16; MAX_LEDS];
            phases[..s.phase_chips.len()].copy_from_slice(&s.phase_chips);
            let table = ChipTable::with_phases(s.led_count, &phases)
                .map_err(|source| TimelineError::Carriers { index, source })?;
            let mut brightness = [0u16; MAX_LEDS];
            brightness[..s.brightness_permille.len()].copy_from_slice(&s.brightness_permille);
            let mut off_level = [0u16; MAX_LEDS];
            off_level[..s.off_level_permille.len()].copy_from_slice(&s.off_level_permille);
            let levels = LedLevels::new(&brightness, &off_level);
            let steps = f64::from(PWM_STEPS);
            let gain = levels.on.map(|v| f64::from(v) / steps);
            let off_gain = levels.off.map(|v| f64::from(v) / steps);
            segments.push(PlayedSegment {
                t: s.t,
                mode: s.mode,
                rate_hz: s.effective_chip_rate_hz,
                table,
                gain,
                off_gain,
            });
        }
        let at = segments.partition_point(|s| s.t <= offset);
        let led_count = match (
            at.checked_sub(1).and_then(|i| segments.get(i)),
            segments.first(),
        ) {
            (Some(s), _) => usize::from(s.table.led_count()),
            (None, Some(first)) => {
                return Err(TimelineError::BeforeFirstSegment {
                    offset,
                    first: first.t,
                });
            }
            (None, None) => return Err(TimelineError::Empty),
        };
        Ok(Self {
            segments,
            offset,
            led_count,
        })
    }

    /// Waveform starting at the timeline's last change (the steady, final configuration).
    pub fn from_last_change(timeline: &Timeline) -> Result<Self, TimelineError> {
        Self::new(
            timeline,
            timeline.last_change().ok_or(TimelineError::Empty)?,
        )
    }

    /// Reads a timeline file; camera time 0 is timeline time `offset` seconds, or the last
    /// change when `None` (what `meb simulate --timeline` uses).
    pub fn load(path: &Path, offset: Option<f64>) -> Result<Self, TimelineError> {
        let timeline = Timeline::read(path)?;
        match offset {
            Some(offset) => Self::new(&timeline, offset),
            None => Self::from_last_change(&timeline),
        }
    }

    /// Number of LEDs the luminaire drives at camera time 0.
    pub fn led_count(&self) -> usize {
        self.led_count
    }

    /// Mean light of LED `led` over camera window [t0, t1) as a fraction of full brightness
    /// (on-time fraction × brightness); for an empty window, the level at t0.
    pub fn on_fraction(&self, led: usize, t0: f64, t1: f64) -> f64 {
        let (a, b) = (t0 + self.offset, t1 + self.offset);
        if b <= a {
            return self.level_at(led, a);
        }
        let first = self
            .segments
            .partition_point(|s| s.t <= a)
            .saturating_sub(1);
        let mut light = 0.0;
        for (i, segment) in self.segments.iter().enumerate().skip(first) {
            let end = self.segments.get(i + 1).map_or(f64::INFINITY, |s| s.t);
            let (lo, hi) = (a.max(segment.t), b.min(end));
            if segment.t >= b {
                break;
            }
            if hi > lo {
                light += segment.light(led, lo, hi);
            }
        }
        (light / (b - a)).clamp(0.0, 1.0)
    }

    fn level_at(&self, led: usize, t: f64) -> f64 {
        let i = self.segments.partition_point(|s| s.t <= t);
        match i.checked_sub(1).and_then(|i| self.segments.get(i)) {
            Some(segment) => segment.level_at(led, t),
            None => 0.0,
        }
    }
}

impl LedWaveform for TimelineWaveform {
    fn led_count(&self) -> usize {
        TimelineWaveform::led_count(self)
    }

    fn on_fraction(&self, led: usize, t0: f64, t1: f64) -> f64 {
        TimelineWaveform::on_fraction(self, led, t0, t1)
    }
}

impl PlayedSegment {
    fn is_on(&self, led: usize, chip: f64) -> bool {
        let masks = self.table.masks();
        let index = (chip as i64).rem_euclid(masks.len() as i64) as usize;
        masks[index] & (1 << led) != 0
    }

    fn level_at(&self, led: usize, t: f64) -> f64 {
        if led >= usize::from(self.table.led_count()) {
            return 0.0;
        }
        match self.mode {
            OutputMode::Off => 0.0,
            OutputMode::Identify => {
                let phase = ((t - self.t) * IDENTIFY_BLINK_HZ).fract();
                if phase < 0.5 { 1.0 } else { 0.0 }
            }
            OutputMode::Playing => {
                let chip = ((t - self.t) * self.rate_hz).floor();
                if self.is_on(led, chip) {
                    self.gain[led]
                } else {
                    self.off_gain[led]
                }
            }
        }
    }

    /// ∫ light dt over [lo, hi) (seconds × fraction of full brightness), inside this segment.
    fn light(&self, led: usize, lo: f64, hi: f64) -> f64 {
        if led >= usize::from(self.table.led_count()) {
            return 0.0;
        }
        match self.mode {
            OutputMode::Off => 0.0,
            OutputMode::Identify => {
                // Square wave of period P, on for the first half: on-time up to x is
                // floor(x/P)·P/2 + min(x mod P, P/2).
                let period = 1.0 / IDENTIFY_BLINK_HZ;
                let on_until = |x: f64| {
                    let x = x - self.t;
                    (x / period).floor() * period / 2.0 + (x.rem_euclid(period)).min(period / 2.0)
                };
                on_until(hi) - on_until(lo)
            }
            OutputMode::Playing => {
                let c0 = (lo - self.t) * self.rate_hz;
                let c1 = (hi - self.t) * self.rate_hz;
                let n = self.table.chips() as f64;
                // Whole table periods are on for exactly half their chips (50 % duty,
                // docs/maths/carriers.md#duty-runs-and-half-period-negation).
                let periods = ((c1 - c0) / n).floor();
                let mut on_chips = periods * n / 2.0;
                let mut c = c0 + periods * n;
                while c < c1 {
                    let chip = c.floor();
                    let end = (chip + 1.0).min(c1);
                    if self.is_on(led, chip) {
                        on_chips += end - c;
                    }
                    c = end;
                }
                let off_chips = (c1 - c0) - on_chips;
                (on_chips * self.gain[led] + off_chips * self.off_gain[led]) / self.rate_hz
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::config::LuminaireConfig;

    fn plan(leds: u8, rate_mhz: u32) -> OutputPlan {
        let mut config = LuminaireConfig::FULL_DEPTH;
        config.led_count = leds;
        config.chip_rate = ChipRate(rate_mhz);
        OutputPlan::of(&config)
    }

    fn sign(w: &TimelineWaveform, led: usize, t0: f64, t1: f64) -> f64 {
        2.0 * w.on_fraction(led, t0, t1) - 1.0
    }

    #[test]
    fn full_chip_windows_reproduce_the_chip_table() {
        let mut timeline = Timeline::new(0.0);
        timeline.segments.push(TimelineSegment::new(
            1.25,
            OutputMode::Playing,
            &plan(4, 960_000),
            0.0,
        ));
        let w = TimelineWaveform::from_last_change(&timeline).unwrap();
        assert_eq!(w.led_count(), 4);
        let table = ChipTable::new(4).unwrap();
        let dt = 1.0 / 960.0;
        for j in 0..64 {
            for led in 0..4 {
                let want = table.masks()[j % 32] & (1 << led) != 0;
                let got = w.on_fraction(led, j as f64 * dt, (j + 1) as f64 * dt);
                assert!(
                    (got - f64::from(u8::from(want))).abs() < 1e-6,
                    "chip {j} led {led}"
                );
            }
        }
        // Half a chip late: docs/maths/demodulation.md#the-received-signal's (1-α)s[j] + αs[j+1]
        // with α = 0.5.
        let (s, t0) = (
            |j: usize| {
                if table.masks()[j % 32] & 1 != 0 {
                    1.0
                } else {
                    -1.0
                }
            },
            0.5 * dt,
        );
        for j in 0..32 {
            let got = sign(&w, 0, t0 + j as f64 * dt, t0 + (j + 1) as f64 * dt);
            assert!((got - 0.5 * (s(j) + s(j + 1))).abs() < 1e-6);
        }
    }

    /// A steady timeline plays exactly what the simulator's own carrier model plays.
    #[test]
    fn matches_the_simulators_carrier_waveform() {
        use meb_sim::CarrierWaveform;
        let mut p = plan(4, 960_000);
        p.phase_chips[..4].copy_from_slice(&[0, 5, 0, 17]);
        // The factory default's off levels at full brightness: off compare = off level.
        p.off_level_permille = protocol::config::LuminaireConfig::DEFAULT.off_level_permille;
        let mut timeline = Timeline::new(0.0);
        timeline
            .segments
            .push(TimelineSegment::new(3.0, OutputMode::Playing, &p, 0.0));
        let recorded: &dyn LedWaveform = &TimelineWaveform::from_last_change(&timeline).unwrap();
        let table = ChipTable::with_phases(4, &p.phase_chips).unwrap();
        let model = CarrierWaveform::new(table, &[960.0; 4], &[0.0; 4])
            .unwrap()
            .with_off_levels(
                &p.off_level_permille[..4]
                    .iter()
                    .map(|&l| f64::from(l) / 1000.0)
                    .collect::<Vec<_>>(),
            )
            .unwrap();
        assert_eq!(recorded.led_count(), 4);
        for k in 0..200 {
            let t0 = k as f64 * 0.000_731;
            for led in 0..4 {
                let (a, b) = (
                    recorded.on_fraction(led, t0, t0 + 0.0008),
                    model.on_fraction(led, t0, t0 + 0.0008),
                );
                assert!((a - b).abs() < 1e-6, "t0 {t0} led {led}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn rate_error_brightness_and_stop_are_played() {
        let mut p = plan(2, 1_000_000);
        p.brightness_permille[1] = 500;
        let mut timeline = Timeline::new(1000.0);
        timeline
            .segments
            .push(TimelineSegment::new(0.0, OutputMode::Playing, &p, 1000.0));
        timeline
            .segments
            .push(TimelineSegment::new(2.0, OutputMode::Off, &p, 1000.0));
        assert!((timeline.segments[0].effective_chip_rate_hz - 1001.0).abs() < 1e-9);
        let w = TimelineWaveform::new(&timeline, 0.0).unwrap();
        // Long window while playing: 50 % duty × brightness.
        assert!((w.on_fraction(0, 0.1, 1.1) - 0.5).abs() < 1e-3);
        assert!((w.on_fraction(1, 0.1, 1.1) - 0.25).abs() < 1e-3);
        // Half playing, half off.
        assert!((w.on_fraction(0, 1.0, 3.0) - 0.25).abs() < 1e-3);
        assert_eq!(w.on_fraction(0, 2.5, 3.5), 0.0);
        // Nothing before the first segment, nothing for LEDs the segment lacks.
        assert_eq!(w.on_fraction(5, 0.1, 1.1), 0.0);
        assert!(TimelineWaveform::new(&timeline, -1.0).is_err());
    }

    #[test]
    fn identify_blinks_at_half_duty() {
        let mut timeline = Timeline::new(0.0);
        timeline.segments.push(TimelineSegment::new(
            0.0,
            OutputMode::Identify,
            &plan(3, 960_000),
            0.0,
        ));
        let w = TimelineWaveform::new(&timeline, 0.0).unwrap();
        assert!((w.on_fraction(2, 0.0, 0.25) - 1.0).abs() < 1e-9);
        assert!(w.on_fraction(2, 0.25, 0.5).abs() < 1e-9);
        assert!((w.on_fraction(0, 0.1, 2.1) - 0.5).abs() < 1e-9);
    }

    #[test]
    fn file_round_trip_and_rejects() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.json");
        let mut timeline = Timeline::new(-20.0);
        timeline.segments.push(TimelineSegment::new(
            0.5,
            OutputMode::Playing,
            &plan(4, 960_000),
            -20.0,
        ));
        timeline.write(&path).unwrap();
        assert!(Timeline::read(&path).unwrap().approx_eq(&timeline));
        assert_eq!(TimelineWaveform::load(&path, None).unwrap().led_count(), 4);
        assert!(matches!(
            TimelineWaveform::load(&path, Some(0.1)),
            Err(TimelineError::BeforeFirstSegment { .. })
        ));
        std::fs::write(&path, "{\"format\":\"x\"}").unwrap();
        let err = Timeline::read(&path).unwrap_err();
        assert!(matches!(err, TimelineError::Json { .. }), "{err:?}");
        // The JSON reader's own error is kept as the source, not copied into the message.
        assert!(std::error::Error::source(&err).is_some());
        assert!(!err.to_string().contains("missing field"), "{err}");
        let mut wrong_version = serde_json::to_value(&timeline).unwrap();
        wrong_version["version"] = serde_json::json!(99);
        std::fs::write(&path, wrong_version.to_string()).unwrap();
        assert!(matches!(
            Timeline::read(&path),
            Err(TimelineError::Format { .. })
        ));
        timeline.segments[0].phase_chips.pop();
        timeline.write(&path).unwrap();
        assert!(matches!(
            Timeline::read(&path),
            Err(TimelineError::Segment { index: 0, .. })
        ));
        assert!(matches!(
            TimelineWaveform::from_last_change(&Timeline::new(0.0)),
            Err(TimelineError::Empty)
        ));
    }
}
