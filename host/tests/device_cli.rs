//! `meb device`: a session against `meb device emulate` run as a separate process.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

mod common;
use common::{OUT_OF_PLANE_LEDS, rig_toml, stdout_of};

const MEB: &str = env!("CARGO_BIN_EXE_meb");

struct Emulator {
    child: Child,
    port: String,
}

impl Emulator {
    fn start(dir: &Path) -> Self {
        let mut child = Command::new(MEB)
            .args(["device", "emulate", "--rate-error-ppm", "-25", "--storage"])
            .arg(dir.join("flash.rec"))
            .arg("--timeline")
            .arg(dir.join("timeline.json"))
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let port = line.trim().to_string();
        assert!(port.starts_with("/dev/"), "emulator printed {port:?}");
        Self { child, port }
    }

    fn meb(&self, args: &[&str]) -> Output {
        Command::new(MEB)
            .args(["device", "--port", &self.port])
            .args(args)
            .output()
            .unwrap()
    }

    /// SIGTERM, then the exit status must be success.
    fn stop(mut self) {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGTERM).unwrap();
        let status = self.child.wait().unwrap();
        assert!(status.success(), "emulator exited with {status}");
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn set_get_save_survives_emulator_restart() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    stdout_of(&emulator.meb(&["ping"]));
    stdout_of(&emulator.meb(&[
        "set",
        "--leds",
        "4",
        "--rate",
        "959.5",
        "--brightness",
        "1000,800,1000,900",
        "--phase",
        "0,3,0,7",
    ]));
    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&emulator.meb(&["get", "--json"]))).unwrap();
    assert_eq!(json["chip_rate_millihertz"], 959_500);
    assert_eq!(
        json["brightness_permille"],
        serde_json::json!([1000, 800, 1000, 900])
    );
    assert_eq!(json["phase_chips"], serde_json::json!([0, 3, 0, 7]));

    // The device's own validation error reaches the user, naming the field.
    let rejected = emulator.meb(&["set", "--leds", "2", "--rate", "960", "--phase", "0,8"]);
    assert!(!rejected.status.success());
    let message = String::from_utf8_lossy(&rejected.stderr);
    assert!(message.contains("phase_chips[1]"), "{message}");

    assert!(stdout_of(&emulator.meb(&["save"])).contains("saved"));
    let status: serde_json::Value =
        serde_json::from_str(&stdout_of(&emulator.meb(&["status", "--json"]))).unwrap();
    assert_eq!(status["unsaved_changes"], false);
    emulator.stop();

    let timeline = std::fs::read_to_string(dir.path().join("timeline.json")).unwrap();
    assert!(timeline.contains("959.47"), "{timeline}"); // 959.5 Hz × (1 − 25 ppm)

    let emulator = Emulator::start(dir.path());
    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&emulator.meb(&["get", "--json"]))).unwrap();
    assert_eq!(json["phase_chips"], serde_json::json!([0, 3, 0, 7]));
    let status: serde_json::Value =
        serde_json::from_str(&stdout_of(&emulator.meb(&["status", "--json"]))).unwrap();
    assert_eq!(status["config_source"], "Restored");
    emulator.stop();
}

#[test]
fn simulate_renders_what_the_emulated_luminaire_emits() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    stdout_of(&emulator.meb(&[
        "set",
        "--leds",
        "4",
        "--rate",
        "960",
        "--phase",
        "0,9,17,26",
    ]));
    emulator.stop();
    let rig = dir.path().join("rig.toml");
    std::fs::write(&rig, rig_toml(64, 48, 1.0, &OUT_OF_PLANE_LEDS)).unwrap();
    let out = dir.path().join("capture");
    let simulate = |leds_out: &Path, timeline: &str| {
        Command::new(MEB)
            .args(["simulate", "--frames", "8", "--rig"])
            .arg(&rig)
            .arg("--timeline")
            .arg(dir.path().join(timeline))
            .arg("--out")
            .arg(leds_out)
            .output()
            .unwrap()
    };
    stdout_of(&simulate(&out, "timeline.json"));
    assert!(out.join("frame_00007.png").exists());
    // A timeline that is not one is a clear error, not a capture.
    std::fs::write(dir.path().join("bad.json"), "{}").unwrap();
    let bad = simulate(&dir.path().join("bad"), "bad.json");
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("not a meb luminaire timeline"));
}

#[test]
fn missing_port_fails_with_one_clear_line() {
    let output = Command::new(MEB)
        .args(["device", "--port", "/dev/meb-none", "get"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(message.contains("no device at /dev/meb-none"), "{message}");
}
