//! `meb video`: a long or live capture → a 3-D frame per window (thesis Ch. 5), written as
//! per-frame arrays, a colour-mapped depth video, a shaded-render video, `video.json` and
//! `video.html` (the 3-D frames with a scrubber and every window's record,
//! [`meb_cli::export::video_report`]).
//!
//! A live input (`-`, a device, a FIFO: anything but a regular file or a frame folder) has no
//! end of its own, so while its frames are processed the first SIGINT or SIGTERM ends the
//! stream instead of discarding the run ([`meb_core::io::folder::on_first_interrupt`] sets a
//! [`StopSignal`] that the pipeline's reader obeys): the windows already read are finished and
//! the folder is written and committed as after a natural end, with `"end": "interrupted"`,
//! and the command exits with status 0 when the result is otherwise accepted (a stop before the
//! first whole window, or with every window failed, is an error as for any run). A second
//! interrupt, an interrupt after the stream has ended, SIGHUP, and any interrupt of a file input
//! discard the output as for every command.

use super::decode::{DecodeOptions, open_options};
use super::integrate::IntegratorArg;
use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use meb_cli::export::video_report::{VideoMeshes, write_video_report};
use meb_core::capture::open;
use meb_core::io::on_first_interrupt;
use meb_core::rig::Rig;
use meb_core::stop::StopSignal;
use meb_pipeline::reconstruct::LightModel;
use meb_pipeline::video::encode::VideoContainer;
use meb_pipeline::video::output::{OutputOptions, VideoOutput};
use meb_pipeline::video::truth::TruthFolder;
use meb_pipeline::video::writer::OutputThread;
use meb_pipeline::video::{
    EndKind, FrameStatus, MotionConfig, MotionPolicy, TruthSource, VideoConfig, VideoFrame,
    WindowSchedule, process_until,
};
use std::path::{Path, PathBuf};

/// Arguments of `meb video`.
#[derive(Args)]
pub struct VideoArgs {
    /// A capture (frame folder, TIFF, .y4m, raw or video file) or `-` for a y4m (or, with
    /// --raw, raw) stream on standard input, e.g. from
    /// `ffmpeg -f v4l2 -i /dev/video0 -f yuv4mpegpipe -`.
    input: PathBuf,
    /// Rig: a TOML file or a preset (thesis-dynamic for the thesis' Ch. 5 set-up).
    #[arg(long)]
    rig: String,
    /// Output folder (depth_NNNNN.npy…, depth.mp4, shaded.mp4, video.json, video.html), replaced whole
    /// and atomically when the run ends.
    #[arg(long)]
    out: PathBuf,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// Camera frames per window (thesis: 40).
    #[arg(long, default_value_t = 40)]
    window: usize,
    /// Frames dropped at each end of a window (thesis: 4); 2^(N+1) frames must be left.
    #[arg(long, default_value_t = 4)]
    drop: usize,
    /// Frames from one window's start to the next (default: the window, back to back; 1
    /// gives a 3-D frame per camera frame).
    #[arg(long)]
    hop: Option<usize>,
    /// What to do with windows in which the object moved.
    #[arg(long, value_enum, default_value_t = MotionArg::Mark)]
    motion: MotionArg,
    /// A window moves when more than this fraction of its lit pixels do.
    #[arg(long, default_value_t = 0.02)]
    motion_threshold: f64,
    /// Also write per-frame normals_NNNNN.npy and/or albedo_NNNNN.npy.
    #[arg(long, value_delimiter = ',', value_enum)]
    save: Vec<SaveArg>,
    /// Ground truth: a depth .npy (still scene), or a folder with depth_FFFFF.npy files per
    /// camera frame (e.g. a `meb simulate --truth-every K` output) to score every 3-D frame.
    #[arg(long)]
    ground_truth: Option<PathBuf>,
    /// Largest width of the output videos in pixels (0 = the camera's).
    #[arg(long, default_value_t = 640)]
    video_width: usize,
    /// Depth range of the colour video LO,HI in mm (default: from the first 3-D frame).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    depth_range: Option<Vec<f32>>,
    /// Write animated PNGs instead of MP4 (the default when FFmpeg is missing).
    #[arg(long)]
    apng: bool,
    /// Stop after this many camera frames. A live stream (`-`, a device, a FIFO) may also be
    /// ended with Ctrl-C: the first interrupt ends the stream and the output folder is written
    /// and put in place as at its end; a second one discards it (as any interrupt of a file).
    #[arg(long)]
    max_frames: Option<usize>,
    /// Bin every camera frame into BIN×BIN pixel blocks before decoding: 3-D frames of 1/BIN
    /// the width and height at about 1/BIN² of the cost (a live preview). --roi and
    /// --ground-truth stay in camera pixels; codes must be linear (no --linearize).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
    bin: u16,
    /// Decode every N-th window over the whole frame and the others only around the object
    /// (the box of the previous window's lit pixels, grown by 32 pixels; a window whose object
    /// leaves that box is decoded whole): an object appearing elsewhere is found within N
    /// windows. 1 decodes every window whole. Without effect with --roi.
    #[arg(long, default_value_t = meb_pipeline::video::FULL_FRAME_EVERY as u32,
          value_parser = clap::value_parser!(u32).range(1..))]
    full_frame_every: u32,
    /// Normal integrator.
    #[arg(long, value_enum, default_value = "least-squares")]
    integrator: IntegratorArg,
    /// Fit the waveform's exposure and rate ratio in every window on its own, instead of
    /// carrying the best fit so far from window to window.
    #[arg(long)]
    fit_every_window: bool,
    /// Reconstruct every window from scratch at full resolution instead of starting from the
    /// previous window's depth, or the first window from its own reconstruction binned 2×2
    /// (slower; each 3-D frame is then independent of the ones before it).
    #[arg(long)]
    cold_start: bool,
    /// Use distant light vectors L_i(0) (the thesis' model) instead of near-field refinement.
    #[arg(long)]
    no_near_field: bool,
    /// Serve a live view while the video runs: a local web page with the newest 3-D frame,
    /// its pictures, verdict and timings (docs/live-view.md). Its URL is printed on stderr.
    #[arg(long)]
    live: bool,
    /// Port of the live view (0: a free one).
    #[arg(long, requires = "live", default_value_t = meb_cli::live::DEFAULT_PORT)]
    port: u16,
    /// Address the live view listens on (default 127.0.0.1, this machine only; e.g. 0.0.0.0
    /// opens it to the network).
    #[arg(long, requires = "live")]
    listen: Option<std::net::IpAddr>,
    /// Decoder settings.
    #[command(flatten)]
    decode: DecodeOptions,
}

/// `--motion` values.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum MotionArg {
    /// Reconstruct every window and record its motion.
    Mark,
    /// Leave windows in which the object moved out.
    Skip,
    /// Move a moving window later until the object is still in it.
    Place,
}

/// `--save` values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum SaveArg {
    /// normals_NNNNN.npy (H×W×3).
    Normals,
    /// albedo_NNNNN.npy.
    Albedo,
}

/// Runs `meb video`.
pub fn run(args: &VideoArgs) -> Result<()> {
    let rig = Rig::load(&args.rig).with_context(|| format!("cannot load rig {}", args.rig))?;
    let config = video_config(args, &rig)?;
    let depth_range = match args.depth_range.as_deref() {
        None => None,
        Some([lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => Some((*lo, *hi)),
        Some(_) => bail!("--depth-range needs LO,HI in mm with LO < HI"),
    };
    let shape = (rig.camera.height, rig.camera.width);
    let mut truth = args
        .ground_truth
        .as_deref()
        .map(|path| TruthFolder::open(path, shape))
        .transpose()?;
    let live = args.live.then(|| start_live_view(args)).transpose()?;
    let folder = super::common::output_folder(&args.out, "video", args.force)?;
    let source = open(&args.input, &open_options(&args.decode)?)
        .with_context(|| format!("cannot open {}", args.input.display()))?;
    let fps = config.decode.fps.unwrap_or(source.format().fps);
    let rate = config.schedule.rate(fps);
    // The 3-D frames are seen by the binned camera.
    let frame_camera = rig.binned(config.bin).camera;
    let output = VideoOutput::create(
        folder.path(),
        frame_camera.width,
        frame_camera.height,
        frame_camera.pitch_mm(),
        OutputOptions {
            normals: args.save.contains(&SaveArg::Normals),
            albedo: args.save.contains(&SaveArg::Albedo),
            video_width: args.video_width,
            depth_range,
            container: if args.apng {
                VideoContainer::Apng
            } else {
                VideoContainer::Auto
            },
            display_fps: if rate.is_finite() && rate > 0.0 {
                rate
            } else {
                25.0
            },
        },
    )?;
    // Writing overlaps the reconstruction of the next windows.
    let mut output = OutputThread::start(output)?;
    // Decimated meshes of the 3-D frames for video.html.
    let mut meshes = VideoMeshes::new(frame_camera.projection());
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {pos}/{len} camera frames [{elapsed}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let mut done = 0usize;
    // While a live stream runs, its first interrupt ends it (module docs).
    let stop = StopSignal::new();
    let interrupt_hook = is_live(&args.input).then(|| {
        let (stop, bar) = (stop.clone(), bar.clone());
        on_first_interrupt(move |_| {
            bar.suspend(|| {
                eprintln!(
                    "interrupted: the stream ends here and what was read is written; a second \
                     interrupt discards the output"
                );
            });
            stop.stop();
        })
    });
    let summary = process_until(
        source,
        &rig,
        &config,
        truth.as_mut().map(|t| t as &mut dyn TruthSource),
        &stop,
        &mut |frame: &VideoFrame| {
            output.add(frame)?;
            if let Some(reconstruction) = frame.reconstruction {
                meshes.add(frame.record.index, reconstruction.depth_mm());
            }
            done += 1;
            if let Some(live) = &live {
                let seconds = started.elapsed().as_secs_f64();
                live.publish(frame, done, seconds, frame_camera.pitch_mm());
            }
            bar.set_length(frame.total_frames.unwrap_or(frame.camera_frames) as u64);
            bar.set_position(frame.camera_frames as u64);
            bar.set_message(progress_message(
                frame,
                done,
                started.elapsed().as_secs_f64(),
            ));
            Ok(())
        },
    );
    // The stream has ended: from here on an interrupt discards the output.
    drop(interrupt_hook);
    bar.finish_and_clear();
    let summary =
        summary.with_context(|| format!("cannot make a 3-D video of {}", args.input.display()))?;
    let settings = serde_json::json!({
        "input": args.input.display().to_string(),
        "rig": args.rig,
        "camera_fps": fps,
        "bin": config.bin,
        "full_frame_every": config.full_frame_every,
        "rate_3d_fps": rate,
        "schedule": config.schedule,
        "motion": config.motion,
        "decode": config.decode,
        "reconstruct": config.reconstruct,
        "ground_truth": args.ground_truth.as_ref().map(|p| p.display().to_string()),
    });
    let output = output.finish()?;
    let mean = output.timing().clone();
    let written = output.finish(settings, &summary)?;
    write_video_report(folder.path(), &meshes)?;
    let out = super::common::commit(folder)?;
    println!(
        "{} 3-D frames from {} camera frames in {:.1} s ({:.1} 3-D frames/s): {} reconstructed, \
         {} skipped, {} failed, {} with motion",
        summary.windows,
        summary.camera_frames,
        summary.wall_s,
        summary.frames_per_second,
        summary.reconstructed,
        summary.skipped,
        summary.failed,
        summary.moving
    );
    println!(
        "per 3-D frame: read {:.1} ms, decode {:.1} ms, motion {:.1} ms, waiting for the decode \
         {:.1} ms, reconstruct {:.1} ms, write {:.1} ms (decoding and writing overlap the \
         reconstruction)",
        mean.mean.read_ms,
        mean.mean.decode_ms,
        mean.mean.motion_ms,
        mean.mean.wait_ms,
        mean.mean.reconstruct_ms,
        mean.mean.write_ms
    );
    for video in [&written.depth_video, &written.shaded_video]
        .into_iter()
        .flatten()
    {
        println!("video: {}", out.join(video).display());
    }
    if let Some(reason) = &written.video_fallback {
        eprintln!("note: {reason} (install FFmpeg for MP4 videos)");
    }
    println!("wrote {}", out.join("video.json").display());
    println!("wrote {}", out.join("video.html").display());
    if summary.end == EndKind::Cut {
        bail!(
            "the input stopped early: {}; the {} 3-D frames before it were written to {}",
            summary.input_error.unwrap_or_default(),
            summary.windows,
            out.display()
        );
    }
    Ok(())
}

/// Starts the live view (`--live`) and prints its URL.
fn start_live_view(args: &VideoArgs) -> Result<meb_cli::live::LiveView> {
    let ip = args
        .listen
        .unwrap_or(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST));
    let live = meb_cli::live::LiveView::start(std::net::SocketAddr::new(ip, args.port))?;
    eprintln!("live view: {}", live.url());
    Ok(live)
}

/// Whether `input` is a live stream, which an interrupt ends instead of discarding the run:
/// standard input, or anything that is neither a regular file nor a frame folder (a device, a
/// FIFO, a socket).
fn is_live(input: &Path) -> bool {
    meb_core::capture::stdin::is_stdin(input)
        || std::fs::metadata(input).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// The progress bar's message: 3-D frames done and their rate, and the last one's state.
fn progress_message(frame: &VideoFrame, done: usize, seconds: f64) -> String {
    let state = match frame.record.status {
        FrameStatus::Reconstructed if frame.record.motion.is_some_and(|m| m.moving) => "moving",
        FrameStatus::Reconstructed => "ok",
        FrameStatus::Skipped => "skipped",
        FrameStatus::Failed => "failed",
    };
    let accuracy = frame
        .record
        .accuracy
        .as_ref()
        .and_then(|a| a.rmse_mm)
        .map(|r| format!(", RMSE {r:.1} mm"))
        .unwrap_or_default();
    format!(
        "{done} 3-D frames, {:.1} 3-D fps (last: {state}{accuracy})",
        done as f64 / seconds.max(1e-9)
    )
}

/// The library settings from the command line.
fn video_config(args: &VideoArgs, rig: &Rig) -> Result<VideoConfig> {
    let mut decode = super::decode::config(&args.decode, rig.leds.len(), args.force)?;
    let mut max_frames = args.max_frames;
    if let Some(frames) = decode.frames.take() {
        max_frames = Some(max_frames.map_or(frames, |m| m.min(frames)));
    }
    let mut config = VideoConfig::thesis(rig.leds.len());
    config.decode = decode;
    config.max_frames = max_frames;
    config.carry_timing = !args.fit_every_window;
    config.warm_start = !args.cold_start;
    config.reconstruct.coarse_start = !args.cold_start;
    config.bin = usize::from(args.bin);
    config.full_frame_every = args.full_frame_every as usize;
    config.schedule = WindowSchedule::new(
        args.window,
        args.drop,
        args.hop.unwrap_or(args.window),
        1usize << (rig.leds.len() + 1),
    )?;
    config.motion = MotionConfig {
        policy: match args.motion {
            MotionArg::Mark => MotionPolicy::Mark,
            MotionArg::Skip => MotionPolicy::Skip,
            MotionArg::Place => MotionPolicy::Place,
        },
        threshold: args.motion_threshold,
        ..MotionConfig::default()
    };
    config.reconstruct.integrate.integrator = args.integrator.into();
    if args.no_near_field {
        config.reconstruct.light_model = LightModel::Distant;
    }
    Ok(config)
}
