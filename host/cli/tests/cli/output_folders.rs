//! Output folders through the `meb` binary: every command replaces its `--out` whole and
//! atomically, refuses a foreign folder without `--force`, never mixes two concurrent runs,
//! and an interrupted run leaves the previous output intact and no temporary folder (a killed
//! one leaves a temporary folder that the next run removes).

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::io::Write;
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::common;
use common::{OUT_OF_PLANE_LEDS, meb, names, rig_toml, run_ok};

fn s(path: &Path) -> String {
    path.display().to_string()
}

/// Runs a command that must fail and returns its error line.
fn run_err(args: &[&str]) -> String {
    let out = meb(args);
    assert!(!out.status.success(), "meb {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).trim().to_string()
}

/// Temporary output folders (`.NAME.meb-partial-…`) in `dir`.
fn temporaries(dir: &Path) -> Vec<String> {
    names(dir)
        .into_iter()
        .filter(|n| n.contains(".meb-partial-"))
        .collect()
}

/// A simulated capture of `leds` out-of-plane LEDs on a `width`×`height` camera.
fn capture(dir: &Path, name: &str, width: usize, height: usize, leds: usize, extra: &[&str]) {
    let rig = dir.join(format!("{name}.toml"));
    std::fs::write(
        &rig,
        rig_toml(width, height, 1.0, &OUT_OF_PLANE_LEDS[..leds]),
    )
    .unwrap();
    let out = dir.join(name);
    let mut args = vec![
        "simulate",
        "--rig",
        rig.to_str().unwrap(),
        "--size-mm",
        "20",
        "--frames",
        "32",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run_ok(&args);
}

/// Waits until `child` exits (at most 60 s) and returns its status.
fn wait(child: &mut Child) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "meb did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until `dir` holds a temporary output folder.
fn wait_for_temporary(dir: &Path, child: &mut Child) {
    let start = Instant::now();
    while temporaries(dir).is_empty() {
        assert!(child.try_wait().unwrap().is_none(), "meb ended early");
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no temporary folder"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn interrupted_decode_keeps_the_previous_output_and_removes_its_temporary() {
    let tmp = tempfile::tempdir().unwrap();
    capture(tmp.path(), "cap", 32, 24, 4, &["--format", "y4m"]);
    let out = tmp.path().join("dec");
    let y4m_path = tmp.path().join("cap/capture.y4m");
    run_ok(&["decode", &s(&y4m_path), "--out", &s(&out)]);
    let before = std::fs::read(out.join("decode.json")).unwrap();

    for signal in [Signal::SIGINT, Signal::SIGTERM] {
        // The decoder reads the capture through a pipe that stops after a few frames, so it is
        // certainly mid-decode (output folder started, frames read) when the signal comes.
        let fifo = tmp.path().join("live.y4m");
        let _ = std::fs::remove_file(&fifo);
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let mut child = Command::new(env!("CARGO_BIN_EXE_meb"))
            .args(["decode", &s(&fifo), "--out", &s(&out)])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut pipe = std::fs::OpenOptions::new().write(true).open(&fifo).unwrap();
        let y4m = std::fs::read(&y4m_path).unwrap();
        pipe.write_all(&y4m[..y4m.len() / 2]).unwrap();
        pipe.flush().unwrap();
        wait_for_temporary(tmp.path(), &mut child);
        kill(Pid::from_raw(child.id() as i32), signal).unwrap();
        let status = wait(&mut child);
        drop(pipe);
        assert!(!status.success(), "{signal}: {status:?}");
        assert_eq!(status.signal(), Some(signal as i32), "{signal}: {status:?}");
        assert_eq!(temporaries(tmp.path()), Vec::<String>::new(), "{signal}");
        assert_eq!(std::fs::read(out.join("decode.json")).unwrap(), before);
        assert!(!names(&out).iter().any(|n| n.ends_with(".partial")));
    }
    // The folder is still a whole decode that reconstruct accepts.
    meb_pipeline::demod::output::read_decode_dir(&out).unwrap();
}

#[test]
fn a_killed_run_leaves_a_temporary_that_the_next_run_removes() {
    let tmp = tempfile::tempdir().unwrap();
    let rig = tmp.path().join("rig.toml");
    std::fs::write(&rig, rig_toml(64, 36, 2.0, &OUT_OF_PLANE_LEDS)).unwrap();
    let out = tmp.path().join("sim");
    // Far more frames than the test waits for.
    let mut child = Command::new(env!("CARGO_BIN_EXE_meb"))
        .args(["simulate", "--rig", &s(&rig), "--frames", "1000000"])
        .args(["--out", &s(&out)])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    wait_for_temporary(tmp.path(), &mut child);
    std::thread::sleep(Duration::from_millis(300));
    child.kill().unwrap(); // SIGKILL: no handler runs
    wait(&mut child);
    let left = temporaries(tmp.path());
    assert_eq!(left.len(), 1, "{left:?}");
    // A legacy staging folder of the old simulator, of a process that cannot exist.
    std::fs::create_dir(tmp.path().join(".sim.partial-4194305")).unwrap();
    run_ok(&[
        "simulate",
        "--rig",
        &s(&rig),
        "--frames",
        "1",
        "--out",
        &s(&out),
    ]);
    assert_eq!(names(tmp.path()), ["rig.toml", "sim"]);
}

#[test]
fn concurrent_decodes_into_one_folder_never_mix() {
    let tmp = tempfile::tempdir().unwrap();
    // Two captures that differ in size and LED count, so a mix cannot read back.
    capture(tmp.path(), "four", 32, 24, 4, &[]);
    capture(tmp.path(), "two", 40, 30, 2, &[]);
    let out = tmp.path().join("dec");
    let mut winners = [0usize; 2];
    for round in 0..25 {
        let spawn = |cap: &str, leds: &str| {
            Command::new(env!("CARGO_BIN_EXE_meb"))
                .args(["decode", &s(&tmp.path().join(cap)), "--leds", leds])
                .args(["--out", &s(&out)])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let children = [spawn("four", "4"), spawn("two", "2")];
        for child in children {
            let output = child.wait_with_output().unwrap();
            let stderr = String::from_utf8_lossy(&output.stderr);
            // Each run either succeeds or fails with a message, never half.
            assert!(
                output.status.success() || stderr.starts_with("error: "),
                "{stderr}"
            );
        }
        let decoded = meb_pipeline::demod::output::read_decode_dir(&out)
            .unwrap_or_else(|e| panic!("round {round}: {e}"));
        let leds = decoded.report.leds;
        let files: Vec<String> = names(&out)
            .into_iter()
            .filter(|n| n.starts_with("led") && n.ends_with(".npy"))
            .collect();
        assert_eq!(files.len(), leds, "round {round}: {files:?}");
        winners[usize::from(leds == 2)] += 1;
        assert_eq!(temporaries(tmp.path()), Vec::<String>::new());
    }
    println!(
        "last writer: 4-LED decode {} times, 2-LED {}",
        winners[0], winners[1]
    );
}

#[test]
fn a_rerun_replaces_the_whole_folder() {
    let tmp = tempfile::tempdir().unwrap();
    capture(tmp.path(), "four", 32, 24, 4, &[]);
    capture(tmp.path(), "two", 32, 24, 2, &[]);
    let out = tmp.path().join("dec");
    run_ok(&["decode", &s(&tmp.path().join("four")), "--out", &s(&out)]);
    assert!(out.join("led4.npy").exists());
    run_ok(&[
        "decode",
        &s(&tmp.path().join("two")),
        "--leds",
        "2",
        "--out",
        &s(&out),
    ]);
    let leds: Vec<String> = names(&out)
        .into_iter()
        .filter(|n| n.starts_with("led"))
        .collect();
    assert_eq!(leds, ["led1.npy", "led1.png", "led2.npy", "led2.png"]);

    // A reconstruction without ground truth keeps no error map of an earlier one with it.
    let dec = tmp.path().join("dec4");
    run_ok(&["decode", &s(&tmp.path().join("four")), "--out", &s(&dec)]);
    let rec = tmp.path().join("rec");
    let rig = s(&tmp.path().join("four.toml"));
    let truth = s(&tmp.path().join("four/depth.npy"));
    let reconstruct = |extra: &[&str]| {
        let mut args = vec!["reconstruct", dec.to_str().unwrap(), "--rig", &rig];
        args.extend_from_slice(&["--out", rec.to_str().unwrap()]);
        args.extend_from_slice(extra);
        run_ok(&args);
    };
    reconstruct(&["--ground-truth", &truth]);
    assert!(rec.join("depth_error.png").exists());
    reconstruct(&[]);
    assert!(rec.join("depth.npy").exists() && !rec.join("depth_error.png").exists());
}

#[test]
fn every_command_refuses_a_foreign_folder_unless_forced() {
    let tmp = tempfile::tempdir().unwrap();
    capture(tmp.path(), "cap", 32, 24, 4, &[]);
    let cap = s(&tmp.path().join("cap"));
    let dec = tmp.path().join("dec");
    run_ok(&["decode", &cap, "--out", &s(&dec)]);
    let foreign = tmp.path().join("thesis");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("chapter1.tex"), "precious").unwrap();
    let f = s(&foreign);
    let rig = s(&tmp.path().join("cap.toml"));
    let normals = s(&tmp.path().join("cap/normals.npy"));
    let mask = s(&tmp.path().join("cap/mask.png"));
    let commands: Vec<(&str, Vec<&str>)> = vec![
        ("decode", vec!["decode", &cap, "--out", &f]),
        (
            "reconstruct",
            vec!["reconstruct", &cap, "--rig", &rig, "--out", &f],
        ),
        (
            "integrate",
            vec![
                "integrate",
                &normals,
                "--mask",
                &mask,
                "--pitch",
                "1",
                "--out",
                &f,
            ],
        ),
        (
            "photometric",
            vec!["photometric", "--diligent", &cap, "--out", &f],
        ),
        (
            "simulate",
            vec!["simulate", "--rig", &rig, "--frames", "1", "--out", &f],
        ),
        (
            "simulate dataset",
            vec!["simulate", "dataset", "--count", "1", "--out", &f],
        ),
        ("demo", vec!["demo", "--out", &f]),
    ];
    for (command, args) in &commands {
        let err = run_err(args);
        assert!(
            err.contains(&format!("not an earlier `meb {command}` output"))
                && err.contains("--force"),
            "{command}: {err}"
        );
        assert_eq!(names(&foreign), ["chapter1.tex"], "{command}");
    }
    // Another command's output is not overwritten either, and the message says whose it is.
    let err = run_err(&["reconstruct", &cap, "--rig", &rig, "--out", &s(&dec)]);
    assert!(err.contains("holds a `meb decode` output"), "{err}");
    // With --force the folder is replaced whole.
    run_ok(&["decode", &cap, "--out", &f, "--force"]);
    assert!(foreign.join("decode.json").exists() && !foreign.join("chapter1.tex").exists());
    // A file is never replaced.
    let file = tmp.path().join("file.txt");
    std::fs::write(&file, "x").unwrap();
    let err = run_err(&["decode", &cap, "--out", &s(&file), "--force"]);
    assert!(err.contains("is a file"), "{err}");
    assert_eq!(temporaries(tmp.path()), Vec::<String>::new());
}
