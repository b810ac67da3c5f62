//! The decoding stage of [`super::process`]: each window read from the stream, decoded with the
//! carried timing around the object or whole, checked for motion and, with
//! [`MotionPolicy::Place`], placed where the object is still; the chosen try goes on to the
//! reconstruction with its truth.

use super::*;

/// A window's frames decoded around the object or whole ([`focus`]).
pub(super) struct Decode {
    pub(super) decoded: Result<Decoded, DemodError>,
    pub(super) source: TimingSource,
    /// The region decoded (`None`: the whole frame).
    pub(super) region: Option<FocusRegion>,
    /// The lit pixels, when the video decodes around the object.
    pub(super) lit: Option<LitBox>,
    /// Whether a region was chosen but given up for the whole frame.
    pub(super) widened: bool,
}

/// One decoded try of a window (several with [`MotionPolicy::Place`]).
pub(super) struct Try {
    pub(super) start: usize,
    pub(super) decode: Decode,
    pub(super) motion: Option<MotionEstimate>,
    pub(super) verdict: Option<WindowVerdict>,
}

impl Try {
    /// The camera frames the try decoded: its window without the dropped ends.
    pub(super) fn decoded_frames(&self, schedule: &WindowSchedule) -> Range<usize> {
        self.start + schedule.drop..self.start + schedule.window - schedule.drop
    }

    /// Whether the try decoded and the decoder's verdict calls it plausible.
    pub(super) fn is_plausible(&self) -> bool {
        self.verdict == Some(WindowVerdict::Plausible)
    }

    /// Whether the object moved during the try, by its motion estimate.
    pub(super) fn moving(&self) -> bool {
        self.motion.is_some_and(|m| m.moving)
    }

    /// Why a decoded try is not reconstructed, if it is not: its verdict refuses it, or
    /// `policy` skips it for motion.
    pub(super) fn left_out(&self, policy: MotionPolicy) -> Option<LeftOut> {
        if self.verdict == Some(WindowVerdict::Refused) {
            Some(LeftOut::Refused)
        } else if policy == MotionPolicy::Skip && self.moving() {
            Some(LeftOut::Skipped)
        } else {
            None
        }
    }

    /// Whether the try goes on to a reconstruction: it decoded and is not left out
    /// ([`Try::left_out`]). The decoding stage reads the truth only for such tries.
    pub(super) fn would_reconstruct(&self, policy: MotionPolicy) -> bool {
        self.decode.decoded.is_ok() && self.left_out(policy).is_none()
    }
}

/// Why [`reconstruct_window`] does not reconstruct a decoded try.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum LeftOut {
    /// The decode is implausible and motion does not explain it.
    Refused,
    /// The object moved and the policy is [`MotionPolicy::Skip`].
    Skipped,
}

/// A window chosen by the decoding stage, on its way to the reconstruction.
pub(super) struct Chosen {
    /// 3-D frame number.
    pub(super) index: usize,
    /// First camera frame the schedule gave the window.
    pub(super) scheduled: usize,
    /// The chosen try.
    pub(super) attempt: Try,
    /// Timing so far (reading, decoding, motion).
    pub(super) timing: FrameTiming,
    /// Camera frames read when it was chosen.
    pub(super) camera_frames: usize,
    /// Camera frames in the stream, when known.
    pub(super) total_frames: Option<usize>,
    /// The true depth for the decoded frames, when there is truth and the try goes on to a
    /// reconstruction ([`Try::would_reconstruct`]).
    pub(super) truth: Option<TruthDepth>,
}

/// Where the decoding stage left the stream.
pub(super) struct StreamState {
    /// Camera frames read.
    pub(super) received: usize,
    /// How the stream ended.
    pub(super) end: Option<StreamEnd>,
}

/// The decoding stage: windows read, decoded, checked for motion and placed.
#[derive(Clone, Copy)]
pub(super) struct DecodeStage<'a> {
    pub(super) schedule: WindowSchedule,
    pub(super) format: &'a meb_core::capture::FrameFormat,
    pub(super) code_map: &'a CodeMap,
    pub(super) config: &'a VideoConfig,
    /// The reconstruction's pool, idle until the first window is decoded: that window is
    /// decoded there, on every core (a decode does not depend on its thread count). The first
    /// window's decode, 2000 frames of 1280×720: 71 → 56 ms.
    pub(super) first_pool: &'a rayon::ThreadPool,
}

impl DecodeStage<'_> {
    /// Sends every window's chosen try to `sender`, with the truth for it when there is a
    /// `truth` source and the try goes on to a reconstruction ([`Try::would_reconstruct`]),
    /// until the stream ends, an error (sent too) or the reconstruction hangs up; returns
    /// where the stream was left. The truth is read here, off the reconstruction's thread:
    /// reading a 1280×720 depth file took ≈ 3–4 ms of each window.
    pub(super) fn run(
        self,
        mut stream: FrameStream,
        sender: &SyncSender<Result<Chosen, VideoError>>,
        mut truth: Option<&mut dyn TruthSource>,
    ) -> StreamState {
        let mut carry = TimingCarry::new(self.config.carry_timing);
        let mut focus = Focus::new(
            self.config.full_frame_every,
            (self.format.width, self.format.height),
        );
        for k in 0.. {
            let window = if k == 0 {
                self.first_pool
                    .install(|| self.window(&mut stream, &mut carry, &mut focus, k))
            } else {
                self.window(&mut stream, &mut carry, &mut focus, k)
            };
            let window = window.and_then(|chosen| match (chosen, truth.as_deref_mut()) {
                (Some(mut chosen), Some(truth))
                    if chosen.attempt.would_reconstruct(self.config.motion.policy) =>
                {
                    let time = Instant::now();
                    chosen.truth =
                        truth.depth_for(chosen.attempt.decoded_frames(&self.schedule))?;
                    chosen.timing.compare_ms += time.elapsed().as_secs_f64() * 1e3;
                    Ok(Some(chosen))
                }
                (chosen, _) => Ok(chosen),
            });
            match window {
                Ok(Some(chosen)) => {
                    if sender.send(Ok(chosen)).is_err() {
                        break;
                    }
                }
                Ok(None) => break,
                Err(error) => {
                    let _ = sender.send(Err(error));
                    break;
                }
            }
        }
        StreamState {
            received: stream.received(),
            end: stream.take_end(),
        }
    }

    /// Whether windows are decoded around the object ([`focus`]).
    pub(super) fn focusing(&self) -> bool {
        self.config.full_frame_every > 1 && self.config.decode.roi.is_none()
    }

    /// Decodes a window's `frames` in the region `focus` chose for window `k` once the carry
    /// has settled, or whole; a region whose decode fails, that holds no lit pixel (the object
    /// jumped away) or whose lit pixels reach its edge is given up for the whole frame.
    pub(super) fn decode_try(
        &self,
        frames: &[meb_core::capture::Samples],
        carry: &mut TimingCarry,
        focus: &Focus,
        k: usize,
        config: &DecodeConfig,
    ) -> Decode {
        let frame = (self.format.width, self.format.height);
        let mask = &self.config.reconstruct.photometric.mask;
        let region = focus
            .region(k)
            .filter(|_| self.focusing() && carry.settled());
        if let Some(region) = region {
            let in_region = DecodeConfig {
                roi: Some(region.roi),
                ..config.clone()
            };
            let (decoded, source) =
                carry.decode_region(frames, self.format, &in_region, region.reference_noise);
            let lit = decoded
                .as_ref()
                .ok()
                .map(|d| lit_box(d, Some(region.roi), frame, mask));
            // The object must be in the region, and not reach out of it.
            if let Some(lit) = lit.filter(|l| l.bounds.is_some() && !l.reaches_edge) {
                return Decode {
                    decoded,
                    source,
                    region: Some(region),
                    lit: Some(lit),
                    widened: false,
                };
            }
        }
        let (decoded, source) = carry.decode(frames, self.format, config);
        let lit = decoded
            .as_ref()
            .ok()
            .filter(|_| self.focusing())
            .map(|d| lit_box(d, None, frame, mask));
        Decode {
            decoded,
            source,
            region: None,
            lit,
            widened: region.is_some(),
        }
    }

    /// Window `k`: decoded where the schedule puts it (or, placing, where the object is
    /// still); `None` when the stream ends first.
    pub(super) fn window(
        &self,
        stream: &mut FrameStream,
        carry: &mut TimingCarry,
        focus: &mut Focus,
        k: usize,
    ) -> Result<Option<Chosen>, VideoError> {
        let (config, schedule, format) = (self.config, &self.schedule, self.format);
        let base = config.decode.start;
        let decoded_len = schedule.decoded();
        // The verdict is applied here, with the window's motion ([`judge`]).
        let force = config.decode.on_implausible == OnImplausible::Keep;
        let decode_config = DecodeConfig {
            on_implausible: OnImplausible::Keep,
            ..config.decode.clone()
        };
        let place_step = config.motion.place_step.max(1);
        let scheduled = base + k * schedule.hop;
        let mut timing = FrameTiming::default();
        let mut best: Option<Try> = None;
        let mut offset = 0;
        loop {
            let start = scheduled + offset;
            // The whole window: the dropped frames serve the period-difference motion test.
            let needed = start..start + schedule.window;
            let Some(window) = stream.window(needed)? else {
                if k == 0 && best.is_none() {
                    return Err(too_short(stream, base, *schedule));
                }
                break;
            };
            let time = Instant::now();
            let decoded_frames = schedule.drop..schedule.drop + decoded_len;
            let mut decode = self.decode_try(
                &window.samples[decoded_frames],
                carry,
                focus,
                k,
                &decode_config,
            );
            timing.decode_ms += time.elapsed().as_secs_f64() * 1e3;
            // A setting wrong for the stream fails every window alike: stop at once.
            decode.decoded = match decode.decoded {
                Err(error @ (DemodError::InvalidConfig(_) | DemodError::Capture(_))) => {
                    return Err(VideoError::Decode(error));
                }
                other => other,
            };
            let time = Instant::now();
            let motion = decode.decoded.as_ref().ok().map(|d| {
                let frames = PeriodFrames {
                    frames: window.samples,
                    map: self.code_map,
                    width: format.width,
                    roi: decode.region.map(|r| r.roi).or(config.decode.roi),
                    period: 1usize << (d.report.leds + 1),
                };
                detect_motion(d, Some(&frames), &config.motion)
            });
            let verdict = decode
                .decoded
                .as_ref()
                .ok()
                .map(|d| judge::judge(d, motion.as_ref(), force));
            timing.motion_ms += time.elapsed().as_secs_f64() * 1e3;
            timing.read_ms += stream.take_waited().as_secs_f64() * 1e3;
            let attempt = Try {
                start,
                decode,
                motion,
                verdict,
            };
            // A window cut across a sudden change of pose raises every pixel's residual alike,
            // so its relative motion score can look still: only a plausible decode counts.
            let plausible = attempt.is_plausible();
            let still = plausible && attempt.motion.is_some_and(|m| !m.moving);
            carry.observe(still);
            // Placing keeps the scheduled try unless a later one is still: a try that is only
            // "least moving" is no better placed than where the schedule put it.
            let better = best.is_none() || still;
            if better {
                best = Some(attempt);
            }
            let can_move =
                config.motion.policy == MotionPolicy::Place && offset + place_step < schedule.hop;
            if still || !can_move {
                break;
            }
            offset += place_step;
        }
        if self.focusing() {
            let learnt = best.as_ref().and_then(|b| {
                let decoded = b.decode.decoded.as_ref().ok()?;
                Some((decoded, b.decode.lit?))
            });
            focus.learn(learnt, best.as_ref().and_then(|b| b.decode.region));
        }
        Ok(best.map(|attempt| Chosen {
            index: k,
            scheduled,
            attempt,
            timing,
            camera_frames: stream.received(),
            total_frames: stream.total_hint(),
            truth: None,
        }))
    }
}

/// The error for a stream that ended before its first window.
pub(super) fn too_short(
    stream: &mut FrameStream,
    base: usize,
    schedule: WindowSchedule,
) -> VideoError {
    let cut = match stream.take_end() {
        Some(StreamEnd::Cut(error)) => Some(error.to_string()),
        Some(StreamEnd::Stopped) => Some("an interrupt ended the stream".into()),
        _ => None,
    };
    VideoError::ClipTooShort {
        frames: stream.received(),
        first: base,
        end: base + schedule.window,
        cut,
    }
}
