//! `meb device`: a session against `meb device emulate` run as a separate process, and
//! `meb device` commands against an in-process virtual luminaire.
#![cfg(unix)]

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use meb_device::{EmulatorOptions, VirtualLuminaire};
use protocol::wire::OutputFault;

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::common;
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
fn blink_lights_each_led_alone_then_the_slow_carriers_then_restores() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    let set = [
        "set",
        "--leds",
        "2",
        "--rate",
        "30",
        "--brightness",
        "500,600",
        "--depth",
        "auto",
    ];
    stdout_of(&emulator.meb(&set));
    let shown = stdout_of(&emulator.meb(&["blink"]));
    let lines: Vec<&str> = shown.lines().collect();
    assert!(
        lines[0].contains("exempt from the IEEE 1789 check"),
        "{shown}"
    );
    assert_eq!(
        lines[1..],
        [
            "LED 1 alone",
            "LED 2 alone",
            "all 2 carriers at 4 chips per second",
            "configuration restored"
        ]
    );
    emulator.stop();
    // What the virtual LEDs played, in order: (rate in mHz, brightness of LEDs 1 and 2).
    let timeline: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("timeline.json")).unwrap())
            .unwrap();
    let played: Vec<(u64, Vec<u64>)> = timeline["segments"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            let b = s["brightness_permille"].as_array().unwrap();
            let rate = s["chip_rate_millihertz"].as_u64().unwrap();
            (rate, b[..2].iter().map(|v| v.as_u64().unwrap()).collect())
        })
        .collect();
    let expected = [
        (30_000, vec![500, 600]),
        (960_000, vec![1000, 0]),
        (960_000, vec![0, 1000]),
        (4_000, vec![1000, 1000]),
        (30_000, vec![500, 600]),
    ];
    let start = played.iter().position(|p| *p == expected[0]).unwrap();
    assert_eq!(played[start..], expected, "{played:?}");
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
    assert_eq!(message.matches("/dev/meb-none").count(), 1, "{message}");
}

#[test]
fn a_rate_beyond_the_limit_is_refused_naming_the_value_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    for rate in ["1e9", "4000.001", "0.5", "NaN"] {
        let output = emulator.meb(&["set", "--leds", "4", "--rate", rate]);
        assert!(!output.status.success(), "--rate {rate} accepted");
        let message = String::from_utf8_lossy(&output.stderr);
        assert!(message.contains("1.000..=4000.000 Hz"), "{message}");
        assert!(!message.contains("4294967295"), "{message}");
    }
    let message = String::from_utf8_lossy(
        &emulator
            .meb(&["set", "--leds", "4", "--rate", "1e9"])
            .stderr,
    )
    .into_owned();
    assert!(message.contains("--rate 1000000000 Hz"), "{message}");
    // The edges are accepted.
    stdout_of(&emulator.meb(&["set", "--leds", "4", "--rate", "4000"]));
    stdout_of(&emulator.meb(&["set", "--leds", "4", "--rate", "1", "--depth", "auto"]));
    emulator.stop();
}

/// `meb device set` refuses flicker above IEEE 1789 low risk, naming the line, the 3–60 Hz
/// band, a low-risk depth and rate; `--depth auto` and `--allow-flicker` are accepted; `save`
/// asks for the flag again; `blink` says it is exempt.
#[test]
fn set_and_save_refuse_flicker_above_low_risk_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    // The thesis' settings at a phone's slow-motion rate: LED 4 at 7.5 Hz.
    let refused = emulator.meb(&["set", "--leds", "4", "--rate", "240", "--depth", "1"]);
    assert!(!refused.status.success());
    let message = String::from_utf8_lossy(&refused.stderr);
    assert!(message.contains("IEEE 1789 low risk"), "{message}");
    assert!(message.contains("3–60 Hz"), "{message}");
    assert!(message.contains("--depth auto"), "{message}");
    assert!(message.contains("--allow-flicker"), "{message}");
    // Nothing was applied.
    let get = stdout_of(&emulator.meb(&["get", "--json"]));
    assert!(get.contains("\"chip_rate_millihertz\": 960000"), "{get}");
    // The largest low-risk depths are accepted and reported.
    let auto =
        stdout_of(&emulator.meb(&["set", "--leds", "4", "--rate", "240", "--depth", "auto"]));
    assert!(auto.contains("depth"), "{auto}");
    let status = stdout_of(&emulator.meb(&["save"]));
    assert!(status.contains("saved"), "{status}");
    // On purpose: applied with a warning, then saving needs the flag again.
    let allowed = emulator.meb(&[
        "set",
        "--leds",
        "4",
        "--rate",
        "960",
        "--depth",
        "1",
        "--allow-flicker",
    ]);
    assert!(
        allowed.status.success(),
        "{}",
        String::from_utf8_lossy(&allowed.stderr)
    );
    let save = emulator.meb(&["save"]);
    assert!(!save.status.success());
    assert!(String::from_utf8_lossy(&save.stderr).contains("refusing to save"));
    stdout_of(&emulator.meb(&["save", "--allow-flicker"]));
    emulator.stop();
}

#[test]
fn ping_count_zero_is_refused() {
    let output = Command::new(MEB)
        .args(["device", "--port", "/dev/meb-none", "ping", "--count", "0"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let message = String::from_utf8_lossy(&output.stderr);
    assert!(
        message.contains("--count") && message.contains('0'),
        "{message}"
    );
    assert!(
        !message.contains("no device"),
        "refused before connecting: {message}"
    );
}

#[test]
fn ping_prints_each_round_trip_as_it_arrives_and_keeps_them_when_the_link_breaks() {
    let dir = tempfile::tempdir().unwrap();
    let emulator = Emulator::start(dir.path());
    let mut ping = Command::new(MEB)
        .args([
            "device",
            "--port",
            &emulator.port,
            "--timeout-ms",
            "200",
            "--attempts",
            "1",
        ])
        .args(["ping", "--count", "1000000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(ping.stdout.take().unwrap());
    let (lines, received) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        while stdout.read_line(&mut line).is_ok_and(|n| n > 0) {
            let _ = lines.send(std::mem::take(&mut line));
        }
    });
    // The first round trip shows up while the pinging goes on.
    let first = received
        .recv_timeout(Duration::from_secs(20))
        .expect("no round trip printed while pinging");
    assert!(first.starts_with("pong in "), "{first}");
    drop(emulator); // the luminaire goes away mid-run
    let status = ping.wait().unwrap();
    assert!(!status.success(), "a broken link is a failure");
    let mut stderr = String::new();
    ping.stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert!(stderr.contains("of 1000000 failed"), "{stderr}");
    let kept: Vec<String> = received.try_iter().collect();
    assert!(kept.iter().all(|l| l.starts_with("pong in ")), "{kept:?}");
}

#[test]
fn status_reports_an_output_fault() {
    let emulator = VirtualLuminaire::spawn(EmulatorOptions::default()).unwrap();
    let port = emulator.port_path().to_string_lossy().into_owned();
    let status = |json: bool| {
        let mut args = vec!["device", "--port", &port, "status"];
        if json {
            args.push("--json");
        }
        stdout_of(&Command::new(MEB).args(&args).output().unwrap())
    };
    assert!(status(false).contains("output fault      none"));
    emulator.inject_output_fault(OutputFault::DmaTransferError);
    let mut text = String::new();
    for _ in 0..100 {
        text = status(false);
        if !text.contains("output fault      none") {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        text.contains("output fault      DMA transfer error"),
        "{text}"
    );
    assert!(text.contains("running           no"), "{text}");
    let json: serde_json::Value = serde_json::from_str(&status(true)).unwrap();
    assert_eq!(json["output_fault"], "DmaTransferError");
    assert_eq!(json["running"], false);
}
