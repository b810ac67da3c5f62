//! End-to-end tests of the `meb` tool and the library crates it is built on, one module per
//! topic, in one test binary (one link for all of them).

mod analytic_sphere;
mod bad_input;
mod camera_calibration;
mod capture_readers;
mod common;
mod compressed_video;
mod decode_moving;
mod decode_simulated;
mod decode_start;
mod decode_sweep;
mod demo_end_to_end;
mod depth_cli;
mod device_cli;
mod glossy_surfaces;
mod integrate_diligent;
mod light_calibration_sweep;
mod noise_free;
mod output_folders;
mod reconstruct_cli;
mod reconstruct_targets;
mod reference_data;
mod report_page;
mod rig_calibration;
mod room_effects;
mod simulate_cli;
mod sphere_rig_check;
mod tof_calibration;
mod tof_cli;
mod tof_common;
mod tof_hybrid;
mod tof_range;
mod video_cli;
mod video_fallback;
mod video_interrupt;
mod video_live;
