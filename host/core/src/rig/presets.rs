//! The thesis' rigs, built in by name.

use super::{Camera, Led, Rig, TofCamera};

/// Names of the built-in rigs (docs/formats/rig.md#presets).
pub const PRESETS: [&str; 4] = [
    "thesis-in-plane",
    "thesis-out-of-plane",
    "thesis-dynamic",
    "thesis-hybrid",
];

impl Rig {
    /// A built-in thesis rig by name (docs/formats/rig.md#presets), or `None`.
    pub fn preset(name: &str) -> Option<Self> {
        let out_of_plane_leds = [
            [-270.0, 420.0, 100.0],
            [-140.0, 420.0, 350.0],
            [140.0, 420.0, 350.0],
            [270.0, 420.0, 100.0],
        ];
        let phone = |distance_mm: f64, fov_deg: f64, fps: f64| Camera {
            width: 1280,
            height: 720,
            fps,
            distance_mm,
            fov_deg: Some(fov_deg),
            pixel_pitch_mm: None,
            intrinsics: None,
            axis_px: None,
        };
        let (camera, positions): (Camera, Vec<[f64; 3]>) = match name {
            // Four LEDs 100 mm left/right/top/bottom of a camera looking down from 460 mm.
            // The thesis does not give this rig's FOV; the out-of-plane phone's 43° is assumed.
            "thesis-in-plane" => (
                phone(460.0, 43.0, 960.0),
                vec![
                    [-100.0, 0.0, 460.0],
                    [100.0, 0.0, 460.0],
                    [0.0, 100.0, 460.0],
                    [0.0, -100.0, 460.0],
                ],
            ),
            "thesis-out-of-plane" => (phone(420.0, 43.0, 960.0), out_of_plane_leds.to_vec()),
            "thesis-dynamic" => (phone(420.0, 43.0, 1000.0), out_of_plane_leds.to_vec()),
            "thesis-hybrid" => (
                phone(500.0, 32.0, 960.0),
                vec![
                    [-145.0, 90.0, 250.0],
                    [-145.0, -50.0, 250.0],
                    [145.0, 90.0, 250.0],
                    [145.0, -50.0, 250.0],
                ],
            ),
            _ => return None,
        };
        // Thesis Ch. 6: a 192×128 SPAD with a 16° lens, 80 cm from the sphere (which stands
        // 100 mm in front of the scene centre); placed 40 mm beside the phone, aimed at the centre.
        let tof_camera = (name == "thesis-hybrid").then_some(TofCamera {
            width: 192,
            height: 128,
            fov_deg: 16.0,
            position_mm: [40.0, 0.0, 900.0],
            look_at_mm: [0.0; 3],
        });
        let leds = positions
            .into_iter()
            .map(|position_mm| Led {
                position_mm,
                axis: None,
                intensity: 1.0,
                lambert_order: 1.0,
            })
            .collect();
        Some(Self {
            camera,
            leds,
            tof_camera,
        })
    }
}
