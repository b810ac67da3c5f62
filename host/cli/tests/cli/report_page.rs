//! The files a person opens: `report.html` rendered by headless Chromium (the 3-D view must
//! draw its first frame), and the PLY / OBJ surfaces parsed back by readers this project did
//! not write (`ply-rs-bw`, `tobj`), checked for vertex count, faces and bounds.
//!
//! The surface is a hemisphere of radius 10 mm integrated by `meb integrate` from its exact
//! normals on a 48×40 grid at 0.5 mm per pixel.

use ndarray::{Array2, Array3};
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;
use common::run_ok;

/// Radius of the test hemisphere, mm.
const RADIUS_MM: f32 = 10.0;
/// Grid pitch, mm per pixel.
const PITCH_MM: f32 = 0.5;

/// Writes the hemisphere's normals and mask and runs `meb integrate` with `extra` flags.
fn integrate_hemisphere(dir: &Path, extra: &[&str]) -> (PathBuf, Array2<bool>) {
    let (rows, cols) = (40, 48);
    let mut normals = Array3::<f32>::from_elem((rows, cols, 3), f32::NAN);
    let mut mask = Array2::from_elem((rows, cols), false);
    for r in 0..rows {
        for c in 0..cols {
            let x = (c as f32 + 0.5 - cols as f32 / 2.0) * PITCH_MM;
            let y = (rows as f32 / 2.0 - r as f32 - 0.5) * PITCH_MM;
            let z2 = RADIUS_MM * RADIUS_MM - x * x - y * y;
            if z2 > 4.0 {
                let z = z2.sqrt();
                for (k, v) in [x, y, z].into_iter().enumerate() {
                    normals[(r, c, k)] = v / RADIUS_MM;
                }
                mask[(r, c)] = true;
            }
        }
    }
    let npy = dir.join("normals.npy");
    ndarray_npy::write_npy(&npy, &normals).unwrap();
    let png = dir.join("mask.png");
    meb_core::io::write_mask(&png, &mask).unwrap();
    let out = dir.join("surface");
    let mut args = vec![
        "integrate",
        npy.to_str().unwrap(),
        "--mask",
        png.to_str().unwrap(),
        "--pitch",
        "0.5",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
    (out, mask)
}

#[test]
fn ply_and_obj_surfaces_read_back_with_independent_readers() {
    let tmp = tempfile::tempdir().unwrap();
    let (out, mask) = integrate_hemisphere(tmp.path(), &["--mesh", "obj"]);
    let depth: Array2<f32> = ndarray_npy::read_npy(out.join("depth.npy")).unwrap();
    let vertices = depth.iter().filter(|z| z.is_finite()).count();
    assert_eq!(vertices, mask.iter().filter(|&&m| m).count());
    // Each grid square splits into top-left/bottom-left/top-right and top-right/bottom-left/
    // bottom-right triangles; a triangle exists when its three corners have a depth.
    let mut faces = 0;
    for r in 0..depth.nrows() - 1 {
        for c in 0..depth.ncols() - 1 {
            let halves = [
                [(r, c), (r + 1, c), (r, c + 1)],
                [(r, c + 1), (r + 1, c), (r + 1, c + 1)],
            ];
            for corners in halves {
                if corners.iter().all(|&p| depth[p].is_finite()) {
                    faces += 1;
                }
            }
        }
    }
    let z_lo = depth
        .iter()
        .copied()
        .filter(|z| z.is_finite())
        .fold(f32::INFINITY, f32::min);
    let z_hi = depth
        .iter()
        .copied()
        .filter(|z| z.is_finite())
        .fold(f32::NEG_INFINITY, f32::max);
    let check_bounds = |what: &str, points: &[[f32; 3]]| {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        // x and y span the mask (a disc of radius ≈ √(R² − 4) mm), centred on the image.
        let half_width = (RADIUS_MM * RADIUS_MM - 4.0).sqrt();
        for k in 0..2 {
            assert!(
                (hi[k] - half_width).abs() < 0.6 && (lo[k] + half_width).abs() < 0.6,
                "{what}: axis {k} spans {}..{}",
                lo[k],
                hi[k]
            );
        }
        assert!(
            (lo[2] - z_lo).abs() < 1e-4 && (hi[2] - z_hi).abs() < 1e-4,
            "{what}: z"
        );
    };

    // PLY through ply-rs-bw.
    let file = std::fs::File::open(out.join("surface.ply")).unwrap();
    let parser = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new();
    let ply = parser.read_ply(&mut std::io::BufReader::new(file)).unwrap();
    let float = |e: &ply_rs_bw::ply::DefaultElement, k: &str| match e.get(k) {
        Some(ply_rs_bw::ply::Property::Float(v)) => *v,
        other => panic!("vertex {k} is {other:?}"),
    };
    let points: Vec<[f32; 3]> = ply.payload["vertex"]
        .iter()
        .map(|v| [float(v, "x"), float(v, "y"), float(v, "z")])
        .collect();
    assert_eq!(points.len(), vertices);
    let ply_faces = &ply.payload["face"];
    assert_eq!(ply_faces.len(), faces);
    for face in ply_faces {
        match face.get("vertex_indices") {
            Some(ply_rs_bw::ply::Property::ListInt(ix)) => {
                assert_eq!(ix.len(), 3);
                assert!(ix.iter().all(|&i| (i as usize) < vertices));
            }
            other => panic!("face is {other:?}"),
        }
    }
    check_bounds("PLY", &points);

    // OBJ through tobj.
    let (models, _) =
        tobj::load_obj(out.join("surface.obj"), &tobj::LoadOptions::default()).unwrap();
    assert_eq!(models.len(), 1);
    let obj = &models[0].mesh;
    assert_eq!(obj.positions.len(), 3 * vertices);
    assert_eq!(obj.indices.len(), 3 * faces);
    let points: Vec<[f32; 3]> = obj
        .positions
        .chunks(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    check_bounds("OBJ", &points);
}

/// Chromium's program name, or `None` (a failure under `CI=true`, where setup installs it).
pub(crate) fn chromium() -> Option<&'static str> {
    for name in ["chromium", "chromium-browser", "google-chrome"] {
        if Command::new(name)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
        {
            return Some(name);
        }
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "chromium is not installed but CI=true: scripts/setup.sh must install it"
    );
    eprintln!("SKIPPED: chromium not installed (apt-get install chromium); report page untested");
    None
}

/// Headless Chromium with the flags a sandboxed CI needs and a throw-away profile. Chromium
/// puts its singleton-socket folder in `TMPDIR`, not in the profile: it goes beside the
/// profile, so a test leaves nothing in /tmp.
pub(crate) fn headless(program: &str, profile: &Path) -> Command {
    let mut command = Command::new(program);
    if let Some(beside) = profile.parent() {
        command.env("TMPDIR", beside);
    }
    command.args([
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--no-first-run",
        "--enable-unsafe-swiftshader",
        "--use-angle=swiftshader",
        "--virtual-time-budget=10000",
        "--window-size=1000,1400",
    ]);
    command.arg(format!("--user-data-dir={}", profile.display()));
    command
}

#[test]
fn report_page_draws_the_surface_in_headless_chromium() {
    let Some(program) = chromium() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (out, _) = integrate_hemisphere(tmp.path(), &[]);
    let page = format!("file://{}", out.join("report.html").display());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        !html.contains("src=\"http"),
        "the page loads nothing from the network"
    );

    // The viewer marks <body> once its first frame is drawn.
    let dom = headless(program, &tmp.path().join("profile-dom"))
        .arg("--dump-dom")
        .arg(&page)
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert!(
        dom.contains("data-viewer=\"rendered\""),
        "viewer did not render: {}",
        dom.lines()
            .find(|l| l.contains("data-viewer"))
            .unwrap_or("no data-viewer mark")
    );

    // The canvas shows a shaded surface: many distinct colours, not a uniform background.
    let shot = tmp.path().join("report.png");
    let status = headless(program, &tmp.path().join("profile-shot"))
        .arg(format!("--screenshot={}", shot.display()))
        .arg(&page)
        .output()
        .unwrap();
    assert!(
        shot.is_file(),
        "no screenshot: {}",
        String::from_utf8_lossy(&status.stderr)
    );
    let image = image::open(&shot).unwrap().to_rgb8();
    if let Ok(keep) = std::env::var("MEB_KEEP_SCREENSHOT") {
        image.save(keep).unwrap();
    }
    // The canvas sits below the title and the figure table: find the viewer's dark background.
    let background = [0x18u8, 0x1a, 0x20];
    let rows: Vec<u32> = (0..image.height())
        .filter(|&y| {
            (0..image.width())
                .filter(|&x| image.get_pixel(x, y).0 == background)
                .count()
                > 200
        })
        .collect();
    assert!(!rows.is_empty(), "no viewer canvas in the screenshot");
    let (top, bottom) = (rows[0], *rows.last().unwrap());
    let mut surface = std::collections::HashSet::new();
    for y in top..=bottom {
        for x in 0..image.width().min(720) {
            let p = image.get_pixel(x, y).0;
            if p != background && p[0] > 60 {
                surface.insert(p);
            }
        }
    }
    assert!(
        surface.len() > 50,
        "only {} surface colours in the canvas",
        surface.len()
    );
}
