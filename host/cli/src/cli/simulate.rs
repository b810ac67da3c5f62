//! `meb simulate`: render a synthetic MEB-FDMA capture with ground truth, or the Ch. 7 data set.

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use meb_core::rig::Rig;
use meb_device::settings::{self, DepthRequest, Spelling};
use meb_pipeline::demod::ModulationDepths;
use meb_sim::dataset::{DatasetConfig, write_dataset};
use meb_sim::exposure::expose_without_clipping;
use meb_sim::output::{OutputOptions, VideoFormat, write_capture};
use meb_sim::rig_error::RigError;
use meb_sim::tof::thesis_hybrid_scene;
use meb_sim::{
    GroundPlane, NoiseModel, Scene, SceneObject, Shape, SimConfig, SimulatedCapture, Spin,
    ToneCurve, TriMesh,
};
use nalgebra::{Unit, UnitQuaternion, Vector3};
use protocol::config::LuminaireConfig;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Arguments of `meb simulate`.
#[derive(Args)]
#[command(
    args_conflicts_with_subcommands = true,
    after_help = "Thesis scenes:\n  \
  Ch. 4 sphere:      meb simulate --rig thesis-out-of-plane --scene sphere --size-mm 48 --frames 128 --out sphere\n  \
  Ch. 4 cube face:   meb simulate --rig thesis-out-of-plane --scene cube --size-mm 75 --frames 128 --out cube\n  \
  Ch. 4 cube corner: meb simulate --rig thesis-out-of-plane --scene cube --corner --size-mm 75 --frames 128 --out corner\n  \
  Ch. 5 ellipsoid:   meb simulate --rig thesis-dynamic --scene ellipsoid --axes-mm 100,60,60 --rpm 7.5 --frames 400 --format y4m --truth-every 20 --out ellipsoid\n  \
  Ch. 6 hybrid:      meb simulate --rig thesis-hybrid --scene hybrid --tof --camera-size 384x216 --frames 128 --out hybrid\n  \
  Ch. 7 data set:    meb simulate dataset --count 100 --out dataset"
)]
pub struct SimulateArgs {
    #[command(subcommand)]
    command: Option<SimulateCommand>,
    #[command(flatten)]
    capture: CaptureArgs,
}

#[derive(Subcommand)]
enum SimulateCommand {
    /// Write the thesis' Ch. 7 data set: per blobby object, N noise-free LED images, mask,
    /// light vectors and ground-truth depth (top-down in-plane rig, 480×270).
    Dataset(DatasetArgs),
}

/// The scene kinds.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum SceneKind {
    /// A sphere of diameter --size-mm (default 48).
    Sphere,
    /// A cube of edge --size-mm (default 75); face-on, or corner-on with --corner.
    Cube,
    /// An ellipsoid with axis lengths --axes-mm (default 100,60,60).
    Ellipsoid,
    /// A seeded random smooth shape of largest extent --size-mm (default 60).
    Blobby,
    /// An STL or OBJ mesh (--mesh FILE), scaled to --size-mm if given (else file units = mm).
    Mesh,
    /// Several objects at different depths: sphere Ø48 at z = 0, cube 40 at z = −70.
    Multi,
    /// The thesis' hybrid scene (Fig. 6.4): a Ø48 sphere, a head and a 75 mm cube 100 mm apart
    /// in depth before a wall, each with its own albedo.
    Hybrid,
}

/// Frame containers.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum FormatArg {
    /// frame_00000.png … (8-bit, or 16-bit for deeper captures).
    Png,
    /// capture.y4m (mono / mono16).
    Y4m,
    /// capture.mp4, lossless H.264 through the ffmpeg program.
    Mp4,
}

#[derive(Args)]
struct CaptureArgs {
    /// Rig: a TOML file or a preset (thesis-in-plane, thesis-out-of-plane, thesis-dynamic,
    /// thesis-hybrid).
    #[arg(long, default_value = "thesis-out-of-plane")]
    rig: String,
    /// What is in front of the camera.
    #[arg(long, value_enum, default_value_t = SceneKind::Sphere)]
    scene: SceneKind,
    /// Size in mm: sphere diameter, cube edge, blobby or mesh largest extent.
    #[arg(long)]
    size_mm: Option<f64>,
    /// Ellipsoid axis lengths x,y,z in mm.
    #[arg(long, value_delimiter = ',', default_values_t = [100.0, 60.0, 60.0])]
    axes_mm: Vec<f64>,
    /// Cube corner-on (a body diagonal towards the camera).
    #[arg(long)]
    corner: bool,
    /// Mesh file (.stl or .obj) for --scene mesh.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Shade meshes with interpolated vertex normals instead of flat faces.
    #[arg(long)]
    smooth_normals: bool,
    /// Object centre x,y,z in mm.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    position_mm: Option<Vec<f64>>,
    /// Object rotation: angles about x, then y, then z, in degrees.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    rotate_deg: Option<Vec<f64>>,
    /// Object albedo in [0, 1] (default 1; the hybrid scene's objects keep their own unless
    /// this is given).
    #[arg(long)]
    albedo: Option<f64>,
    /// Add a ground plane at this z (mm, e.g. -24 under a Ø48 sphere).
    #[arg(long, allow_hyphen_values = true)]
    ground_mm: Option<f64>,
    /// Albedo of the ground plane.
    #[arg(long, default_value_t = 0.5)]
    ground_albedo: f64,
    /// Spin the object(s) at this many revolutions per minute (thesis Ch. 5: 7.5).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    rpm: f64,
    /// Spin axis x,y,z (through the object centre).
    #[arg(long, value_delimiter = ',', default_values_t = [0.0, 1.0, 0.0], allow_hyphen_values = true)]
    spin_axis: Vec<f64>,
    /// Number of frames.
    #[arg(long, default_value_t = 128)]
    frames: usize,
    /// Output folder, replaced whole and atomically.
    #[arg(long)]
    out: Option<PathBuf>,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
    /// Frame container.
    #[arg(long, value_enum, default_value_t = FormatArg::Png)]
    format: FormatArg,
    /// Exposure as a fraction of the frame period, in (0, 1].
    #[arg(long, default_value_t = 1.0)]
    exposure: f64,
    /// Rolling-shutter line time in microseconds (0 = global shutter).
    #[arg(long, default_value_t = 0.0)]
    line_time_us: f64,
    /// Bits per sample: 8, 10, 12 or 16.
    #[arg(long, default_value_t = 8)]
    bit_depth: u8,
    /// Gaussian read noise σ as a fraction of full scale.
    #[arg(long, default_value_t = 0.005)]
    noise: f64,
    /// Full-well capacity in electrons: adds Poisson shot noise.
    #[arg(long)]
    full_well: Option<f64>,
    /// Unmodulated background light as SNR in dB (thesis Eq. 4.3); default: dark room.
    #[arg(long, allow_hyphen_values = true)]
    snr_db: Option<f64>,
    /// Encode with a power-law tone curve code ∝ light^(1/G).
    #[arg(long, conflicts_with = "srgb")]
    gamma: Option<f64>,
    /// Encode with the sRGB tone curve.
    #[arg(long)]
    srgb: bool,
    /// Global gain (full-scale fraction per unit Φ·cos^m θ/d²); default: brightest LED peaks
    /// at --peak on a Ø48 mm white sphere.
    #[arg(long)]
    gain: Option<f64>,
    /// Peak of the brightest LED on the reference sphere when --gain is not given (default
    /// 0.4; 0.15 for the hybrid scene, whose sphere stands 100 mm nearer the LEDs and would
    /// otherwise saturate).
    #[arg(long)]
    peak: Option<f64>,
    /// Weight of a glossy coat over the objects' Lambertian base, in [0, 1] (a GGX lobe mixed
    /// as Blender mixes a Glossy BSDF into a Diffuse one; 0 = matte).
    #[arg(long, default_value_t = 0.0)]
    gloss: f64,
    /// Roughness of the glossy coat in (0, 1] (α = roughness²).
    #[arg(long, default_value_t = 0.25)]
    roughness: f64,
    /// Lower the gain, as an auto-exposed camera would, until the brightest pixel of the first
    /// frame with every LED on stays below 90 % of full scale (faces lit by several LEDs at
    /// once, e.g. `--scene cube --corner`, clip at the default gain and hide LEDs from the
    /// decoder).
    #[arg(long, conflicts_with = "gain")]
    auto_exposure: bool,
    /// The luminaire's modulation depths, as `meb device set --depth` takes them: `auto`
    /// (each LED's largest IEEE 1789 low-risk depth at the chip rate), one depth in (0, 1] for
    /// every LED or one per LED, or `factory` (the factory default's off levels); the off
    /// chips then keep the share of the on light the luminaire's PWM would
    /// [default: 1, off chips dark].
    #[arg(long, value_parser = super::parse::depth, conflicts_with = "timeline")]
    depth: Option<ModulationDepths>,
    /// Per-LED time shifts in chips, comma-separated (default: random from --seed).
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    phases: Option<Vec<f64>>,
    /// Chip rate in Hz: one value for all LEDs or one per LED (default: the camera's fps).
    #[arg(long, value_delimiter = ',')]
    chip_rate: Option<Vec<f64>>,
    /// Seed of the phases, the noise and blobby shapes.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Real-room effects.
    #[command(flatten)]
    room: super::room_args::RoomArgs,
    /// Light the scene with a luminaire timeline recorded by `meb device emulate --timeline`
    /// (replaces --phases/--chip-rate: the capture shows exactly what that luminaire emits).
    #[arg(long, conflicts_with_all = ["phases", "chip_rate"])]
    timeline: Option<std::path::PathBuf>,
    /// Timeline time (s) at camera time 0 (default: the timeline's last output change).
    #[arg(long, requires = "timeline")]
    timeline_start: Option<f64>,
    /// Resize the rig's camera to WxH pixels, keeping its field of view (e.g. 384x216 for a
    /// quick run of a 1280x720 preset).
    #[arg(long, value_name = "WxH", value_parser = super::parse::size)]
    camera_size: Option<(usize, usize)>,
    /// Also render the rig's time-of-flight camera (thesis Ch. 6): SPAD histograms of the
    /// scene and of a reference board, chequerboard images in both cameras and the truth, in
    /// tof/ (see tof/tof.json for the `meb tof` and `meb reconstruct --tof` commands).
    #[arg(long)]
    tof: bool,
    /// With --tof: TCSPC exposures (frames of 1 ms) per histogram (thesis: 10 000).
    #[arg(long, default_value_t = 10_000, requires = "tof")]
    tof_frames: usize,
    /// Frame whose start time the ground-truth files describe.
    #[arg(long, default_value_t = 0)]
    truth_frame: usize,
    /// Also write the true depth every K frames as truth/depth_FFFFF.npy (a moving scene,
    /// for `meb video --ground-truth`).
    #[arg(long)]
    truth_every: Option<usize>,
    /// Also write rig-nominal.toml: the rig with every LED moved this many mm in a random
    /// direction, as a rough measurement would give (the capture is rendered with rig.toml,
    /// the truth; hand the nominal rig to `meb reconstruct` or `meb calibrate lights`).
    #[arg(long, value_name = "MM")]
    perturb_leds_mm: Option<f64>,
    /// Also write rig-nominal.toml with every LED's intensity multiplied by a random factor
    /// in [1 − F, 1 + F] (with --perturb-leds-mm, both).
    #[arg(long, value_name = "F")]
    perturb_intensity: Option<f64>,
    /// Seed of the nominal rig's errors (default: --seed).
    #[arg(long)]
    perturb_seed: Option<u64>,
}

#[derive(Args)]
struct DatasetArgs {
    /// Number of objects.
    #[arg(long, default_value_t = 100)]
    count: usize,
    /// Output folder, replaced whole and atomically.
    #[arg(long)]
    out: PathBuf,
    /// Rig (default: thesis-in-plane); its camera is resized to --width × --height.
    #[arg(long, default_value = "thesis-in-plane")]
    rig: String,
    /// Image width.
    #[arg(long, default_value_t = 480)]
    width: usize,
    /// Image height.
    #[arg(long, default_value_t = 270)]
    height: usize,
    /// Largest extent of each object in mm.
    #[arg(long, default_value_t = 120.0)]
    size_mm: f64,
    /// Seed of the shapes and poses.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    #[arg(long, help = super::common::FORCE_HELP)]
    force: bool,
}

/// Runs `meb simulate`.
pub fn run(args: &SimulateArgs) -> Result<()> {
    match &args.command {
        Some(SimulateCommand::Dataset(d)) => run_dataset(d),
        None => run_capture(&args.capture),
    }
}

fn progress_bar(total: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(total as u64);
    if let Ok(style) = ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} [{{elapsed}} < {{eta}}]"
    )) {
        bar.set_style(style);
    }
    bar
}

fn run_capture(args: &CaptureArgs) -> Result<()> {
    let out = args
        .out
        .as_ref()
        .context("--out DIR is required (where to write the capture)")?;
    let mut rig = Rig::load(&args.rig)?;
    if let Some(size) = args.camera_size {
        resize_camera(&mut rig, size)?;
    }
    if args.tof && rig.tof_camera.is_none() {
        bail!(
            "--tof needs a rig with a [tof_camera] (the SPAD's pose, size and field of view); rig {} has none (try --rig thesis-hybrid)",
            args.rig
        );
    }
    let (scene, groups, description) = build_scene(args)?;
    let folder = super::common::output_folder(out, "simulate", args.force)?;
    let tone = match (args.gamma, args.srgb) {
        (Some(g), _) => ToneCurve::Gamma(g),
        (None, true) => ToneCurve::Srgb,
        (None, false) => ToneCurve::Linear,
    };
    let config = SimConfig {
        frames: args.frames,
        exposure: args.exposure,
        line_time_s: args.line_time_us * 1e-6,
        start_time_s: 0.0,
        bit_depth: args.bit_depth,
        noise: NoiseModel {
            sigma: args.noise,
            full_well_electrons: args.full_well,
        },
        tone,
        snr_db: args.snr_db,
        gain: args.gain,
        peak: args.peak.unwrap_or(match args.scene {
            SceneKind::Hybrid => 0.15,
            _ => 0.4,
        }),
        phases_chips: args.phases.clone(),
        chip_rates_hz: args.chip_rate.clone(),
        off_levels: args
            .depth
            .as_ref()
            .map(|depth| luminaire_off_fractions(depth, &rig, args.chip_rate.as_deref()))
            .transpose()?,
        seed: args.seed,
        material: meb_sim::Material::glossy(args.gloss, args.roughness),
        room: args.room.effects()?,
    };
    if args.truth_frame >= args.frames.max(1) {
        bail!(
            "--truth-frame {} is past the last frame ({})",
            args.truth_frame,
            args.frames
        );
    }
    let config = if args.auto_exposure {
        expose_without_clipping(&rig, &scene, config)?
    } else {
        config
    };
    let nominal = (args.perturb_leds_mm.is_some() || args.perturb_intensity.is_some())
        .then(|| {
            RigError {
                position_mm: args.perturb_leds_mm.unwrap_or(0.0),
                intensity: args.perturb_intensity.unwrap_or(0.0),
                seed: args.perturb_seed.unwrap_or(args.seed),
            }
            .apply(&rig)
        })
        .transpose()?;
    let started = Instant::now();
    let mut capture = SimulatedCapture::new(rig, scene.clone(), config)?;
    if let Some(path) = &args.timeline {
        let waveform = meb_device::TimelineWaveform::load(path, args.timeline_start)?;
        capture = capture.with_waveform(std::sync::Arc::new(waveform))?;
    }
    let options = OutputOptions {
        video: match args.format {
            FormatArg::Png => VideoFormat::Png,
            FormatArg::Y4m => VideoFormat::Y4m,
            FormatArg::Mp4 => VideoFormat::Mp4,
        },
        truth_frame: args.truth_frame,
        scene: description,
        truth_every: args.truth_every,
    };
    let bar = progress_bar(args.frames, "rendering");
    write_capture(&mut capture, folder.path(), &options, &mut |done, _| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    if let Some(nominal) = &nominal {
        let path = folder.path().join("rig-nominal.toml");
        std::fs::write(&path, nominal.to_toml_string())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let tof_ranges = if args.tof {
        let settings = super::simulate_tof::TofSettings {
            scene: &scene,
            groups: &groups.members,
            names: &groups.names,
            frames: args.tof_frames,
            seed: args.seed,
        };
        eprintln!(
            "rendering the SPAD histograms ({} frames)…",
            args.tof_frames
        );
        let ranges = super::simulate_tof::write_tof(
            folder.path(),
            folder.target(),
            capture.rig(),
            &settings,
        )?;
        Some(ranges)
    } else {
        None
    };
    let path = super::common::commit(folder)?;
    let info = capture.info();
    eprintln!(
        "wrote {} frames ({}x{}, {}-bit) and ground truth to {} in {:.1} s; phases {:?} chips, gain {:.4e}",
        info.frames,
        capture.rig().camera.width,
        capture.rig().camera.height,
        info.bit_depth,
        path.display(),
        started.elapsed().as_secs_f64(),
        info.phases_chips
            .iter()
            .map(|p| (p * 1000.0).round() / 1000.0)
            .collect::<Vec<_>>(),
        info.gain
    );
    if let Some(ranges) = tof_ranges {
        eprintln!(
            "wrote SPAD histograms, reference, chequerboards (ranges {ranges:?} mm) and truth to {}; commands for the hybrid chain: {}",
            path.join("tof").display(),
            path.join("tof/tof.json").display()
        );
    }
    Ok(())
}

/// The off fractions a luminaire driving the rig's LEDs at full brightness plays for `depth`
/// (configured as `meb device set --depth` configures it, at the first chip rate or the
/// camera's frame rate).
fn luminaire_off_fractions(
    depth: &ModulationDepths,
    rig: &Rig,
    chip_rates: Option<&[f64]>,
) -> Result<Vec<f64>> {
    let leds = u8::try_from(rig.leds.len())
        .ok()
        .filter(|&n| (1..=8).contains(&n))
        .with_context(|| {
            format!(
                "--depth: a luminaire drives 1 to 8 LEDs, the rig has {}",
                rig.leds.len()
            )
        })?;
    let request = match depth {
        ModulationDepths::Factory => None,
        ModulationDepths::LowRiskAuto => Some(DepthRequest::Auto),
        ModulationDepths::Depths(d) => {
            Some(DepthRequest::Depths(d.iter().map(|&v| v as f32).collect()))
        }
        ModulationDepths::Full => Some(DepthRequest::Depths(vec![1.0])),
        ModulationDepths::OffFractions(l) => return Ok(l.clone()),
    };
    let rate_hz = chip_rates
        .and_then(|r| r.first().copied())
        .unwrap_or(rig.camera.fps);
    let config = settings::configure(
        &settings::SettingsRequest {
            leds,
            rate_hz,
            brightness: None,
            phase: None,
            depth: request.as_ref(),
            allow_flicker: true,
        },
        &LuminaireConfig::DEFAULT,
        &Spelling::CLI,
    )?;
    Ok(settings::off_fractions(&config))
}

/// Sets the rig camera's size to (width, height), keeping its field of view.
fn resize_camera(rig: &mut Rig, (width, height): (usize, usize)) -> Result<()> {
    let camera = &mut rig.camera;
    if camera.intrinsics.is_some() {
        bail!(
            "--camera-size cannot resize a pinhole camera with intrinsics; write a rig file of that size instead"
        );
    }
    if let Some(pitch) = camera.pixel_pitch_mm {
        camera.pixel_pitch_mm = Some(pitch * camera.width as f64 / width as f64);
    }
    camera.width = width;
    camera.height = height;
    Ok(())
}

/// Which object group each scene object belongs to (several analytic parts may form one
/// object, e.g. the hybrid scene's head).
struct Groups {
    members: Vec<usize>,
    names: Vec<String>,
}

impl Groups {
    /// One group per object.
    fn each(objects: usize) -> Self {
        Self {
            members: (0..objects).collect(),
            names: (1..=objects).map(|k| format!("object {k}")).collect(),
        }
    }
}

fn vec3(values: &[f64], name: &str) -> Result<Vector3<f64>> {
    match values {
        [x, y, z] if values.iter().all(|v| v.is_finite()) => Ok(Vector3::new(*x, *y, *z)),
        _ => bail!("{name} needs three finite numbers x,y,z"),
    }
}

fn positive(value: f64, name: &str) -> Result<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        bail!("{name} must be a positive number, got {value}")
    }
}

/// Builds the scene, its object groups and a JSON description of it for truth.json.
fn build_scene(args: &CaptureArgs) -> Result<(Scene, Groups, serde_json::Value)> {
    let size = args.size_mm.map(|s| positive(s, "--size-mm")).transpose()?;
    let mut groups = None;
    let mut ground = args.ground_mm.map(|z| GroundPlane {
        z_mm: z,
        albedo: args.ground_albedo,
    });
    let mut objects = match args.scene {
        SceneKind::Sphere => vec![SceneObject::sphere(size.unwrap_or(48.0))],
        SceneKind::Cube => vec![SceneObject::cube(size.unwrap_or(75.0), args.corner)],
        SceneKind::Ellipsoid => {
            let axes = vec3(&args.axes_mm, "--axes-mm")?;
            for a in axes.iter() {
                positive(*a, "--axes-mm")?;
            }
            vec![SceneObject::ellipsoid([axes.x, axes.y, axes.z])]
        }
        SceneKind::Blobby => {
            let mesh = meb_sim::mesh::blobby(args.seed, size.unwrap_or(60.0));
            vec![SceneObject::new(Shape::Mesh(Arc::new(mesh)))]
        }
        SceneKind::Mesh => {
            let path = args
                .mesh
                .as_ref()
                .context("--scene mesh needs --mesh FILE.stl|FILE.obj")?;
            let mesh = TriMesh::load(path)?;
            let area: f64 = mesh
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| mesh.vertices[i]);
                    0.5 * (b - a).cross(&(c - a)).norm()
                })
                .sum();
            if area.is_nan() || area <= 0.0 {
                bail!(
                    "mesh {} has no surface: its {} triangles have zero total area",
                    path.display(),
                    mesh.triangles.len()
                );
            }
            let mut mesh = mesh.centred(size);
            if args.smooth_normals {
                mesh = mesh.with_smooth_normals();
            }
            vec![SceneObject::new(Shape::Mesh(Arc::new(mesh)))]
        }
        SceneKind::Multi => {
            let mut sphere = SceneObject::sphere(48.0);
            sphere.position_mm = Vector3::new(-40.0, 0.0, 0.0);
            let mut cube = SceneObject::cube(40.0, false);
            cube.position_mm = Vector3::new(45.0, 0.0, -70.0);
            vec![sphere, cube]
        }
        SceneKind::Hybrid => {
            let hybrid = thesis_hybrid_scene();
            groups = Some(Groups {
                members: hybrid.groups,
                names: hybrid.names,
            });
            ground = ground.or(hybrid.scene.ground);
            hybrid.scene.objects
        }
    };
    let groups = groups.unwrap_or_else(|| Groups::each(objects.len()));
    let rotation = match &args.rotate_deg {
        Some(r) => {
            let r = vec3(r, "--rotate-deg")?;
            Some(UnitQuaternion::from_euler_angles(
                r.x.to_radians(),
                r.y.to_radians(),
                r.z.to_radians(),
            ))
        }
        None => None,
    };
    let position = args
        .position_mm
        .as_ref()
        .map(|p| vec3(p, "--position-mm"))
        .transpose()?;
    let spin = if args.rpm != 0.0 {
        let axis = vec3(&args.spin_axis, "--spin-axis")?;
        let axis = Unit::try_new(axis, 1e-12).context("--spin-axis must not be zero")?;
        Some(Spin {
            axis,
            rpm: args.rpm,
        })
    } else {
        None
    };
    for object in &mut objects {
        if let Some(r) = rotation {
            object.rotation = r * object.rotation;
        }
        if let Some(p) = position {
            object.position_mm += p;
        }
        if let Some(albedo) = args.albedo {
            object.albedo = albedo;
        }
        object.spin = spin.clone();
    }
    let description = serde_json::json!({
        "kind": format!("{:?}", args.scene).to_lowercase(),
        "size_mm": size,
        "axes_mm": matches!(args.scene, SceneKind::Ellipsoid).then(|| args.axes_mm.clone()),
        "corner": args.corner,
        "mesh": args.mesh.as_ref().map(|p| p.display().to_string()),
        "position_mm": args.position_mm,
        "rotate_deg": args.rotate_deg,
        "albedo": args.albedo,
        "ground_mm": args.ground_mm,
        "rpm": args.rpm,
        "spin_axis": args.spin_axis,
        "objects": groups.names,
    });
    Ok((Scene { objects, ground }, groups, description))
}

fn run_dataset(args: &DatasetArgs) -> Result<()> {
    let mut rig = Rig::load(&args.rig)?;
    if args.width == 0 || args.height == 0 {
        bail!("--width and --height must be positive");
    }
    rig.camera.width = args.width;
    rig.camera.height = args.height;
    let config = DatasetConfig {
        count: args.count,
        rig,
        size_mm: args.size_mm,
        seed: args.seed,
    };
    let folder = super::common::output_folder(&args.out, "simulate dataset", args.force)?;
    let bar = progress_bar(args.count, "objects");
    write_dataset(&config, folder.path(), &mut |done, _| {
        bar.set_position(done as u64)
    })?;
    bar.finish_and_clear();
    let path = super::common::commit(folder)?;
    eprintln!("wrote {} objects to {}", args.count, path.display());
    Ok(())
}
