//! Smoke test of `planet view` in a real window: under Xvfb (on lavapipe in CI) the viewer steps
//! a small planet, writes a screenshot and exits 0; the screenshot must not be blank. Without
//! `xvfb-run` the test fails when `CI=true` and is skipped (with a message) otherwise. Also: with
//! no display, `planet view` fails with a clear message instead of panicking.
#![cfg(feature = "viewer")]

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("planet-viewer-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Pixels of a screenshot that are ocean blue and land green (the elevation map's colours).
fn blue_and_green(img: &image::RgbImage) -> (usize, usize) {
    let (mut blue, mut green) = (0usize, 0usize);
    for p in img.pixels() {
        let [r, g, b] = p.0.map(i32::from);
        if b > r + 40 && b > g {
            blue += 1;
        }
        if g > r + 15 && g > b + 15 {
            green += 1;
        }
    }
    (blue, green)
}

fn have(cmd: &str) -> bool {
    Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {cmd}"))
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Runs `cmd` with a time limit; returns (success, stdout+stderr).
fn run_with_limit(mut cmd: Command, limit: Duration) -> (bool, String) {
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start the command");
    let start = Instant::now();
    loop {
        if let Some(_status) = child.try_wait().unwrap() {
            break;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "timed out after {limit:?}\n{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.success(),
        format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
    )
}

#[test]
fn view_steps_writes_a_screenshot_and_exits_under_xvfb() {
    if !have("xvfb-run") {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("xvfb-run is missing on CI: install the `xvfb` package (.ci/run does)");
        }
        eprintln!(
            "SKIPPED: xvfb-run is not installed (apt-get install xvfb); the viewer smoke test did not run"
        );
        return;
    }
    let dir = temp_dir("smoke");
    let shot = dir.join("shot.png");
    let runtime = dir.join("xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    let mut cmd = Command::new("xvfb-run");
    cmd.args(["-a", "-s", "-screen 0 1280x800x24"])
        .arg(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "--samples", "20000", "--plates", "12"])
        .args(["--exit-after-steps", "4", "--screenshot"])
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", &runtime)
        .env_remove("WAYLAND_DISPLAY");
    let (ok, out) = run_with_limit(cmd, Duration::from_secs(300));
    assert!(ok, "planet view failed:\n{out}");
    assert!(out.contains("4 steps") || out.contains("steps"), "{out}");
    let img = image::open(&shot)
        .unwrap_or_else(|e| panic!("no readable screenshot at {}: {e}\n{out}", shot.display()))
        .to_rgb8();
    assert!(
        img.width() >= 640 && img.height() >= 400,
        "{}x{}",
        img.width(),
        img.height()
    );
    // Not blank: many distinct colours, and the map's ocean blues and land greens are there.
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    let (blue, green) = blue_and_green(&img);
    let n = (img.width() * img.height()) as usize;
    assert!(
        colours.len() > 500,
        "only {} colours: blank screenshot?",
        colours.len()
    );
    assert!(
        blue > n / 20,
        "almost no ocean in the screenshot ({blue} of {n} pixels)"
    );
    assert!(
        green > n / 200,
        "almost no land in the screenshot ({green} of {n} pixels)"
    );
}

#[test]
fn fps_report_measures_frames_while_stepping_under_xvfb() {
    if !have("xvfb-run") {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("xvfb-run is missing on CI: install the `xvfb` package (.ci/run does)");
        }
        eprintln!("SKIPPED: xvfb-run is not installed; the frame-rate report did not run");
        return;
    }
    let dir = temp_dir("fps");
    let runtime = dir.join("xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    let mut cmd = Command::new("xvfb-run");
    cmd.args(["-a", "-s", "-screen 0 1280x800x24"])
        .arg(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "--samples", "2000", "--plates", "6"])
        .args(["--fps-report", "20"])
        .env("XDG_RUNTIME_DIR", &runtime)
        .env_remove("WAYLAND_DISPLAY");
    let (ok, out) = run_with_limit(cmd, Duration::from_secs(300));
    assert!(ok, "planet view --fps-report failed:\n{out}");
    // The figure itself depends on the machine; the report must be there and name 20+ frames.
    let line = out
        .lines()
        .find(|l| l.starts_with("fps report:"))
        .unwrap_or_else(|| panic!("no report:\n{out}"));
    let frames: u64 = line
        .split(", ")
        .find_map(|part| part.strip_suffix(" frames while stepping"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no frame count in \"{line}\""));
    assert!(frames >= 20, "{line}");
    assert!(out.contains("frame interval: median"), "{out}");
}

#[test]
fn fps_report_of_zero_frames_is_refused() {
    let out = Command::new(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "--samples", "2000", "--fps-report", "0"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--fps-report"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn view_without_a_display_fails_with_a_clear_message() {
    let out = Command::new(env!("CARGO_BIN_EXE_planet"))
        .args([
            "view",
            "--samples",
            "2000",
            "--plates",
            "4",
            "--exit-after-steps",
            "1",
        ])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no display"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn view_of_a_missing_save_names_the_file() {
    let out = Command::new(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "/nonexistent/dir/none.planet"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("none.planet"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// `planet view --from-earth` opens today's Earth (its screenshot has ocean and land), and a
/// saved planet cannot be combined with a map start.
#[test]
fn view_starts_from_earth_under_xvfb() {
    let dir = temp_dir("earth");
    let o = Command::new(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "some.planet", "--from-earth"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--from-earth"), "{err}");
    if !have("xvfb-run") {
        if std::env::var("CI").is_ok_and(|v| v == "true") {
            panic!("xvfb-run is missing on CI: install the `xvfb` package (.ci/run does)");
        }
        eprintln!("SKIPPED: xvfb-run is not installed (apt-get install xvfb)");
        return;
    }
    let shot = dir.join("earth.png");
    let runtime = dir.join("xdg");
    std::fs::create_dir_all(&runtime).unwrap();
    let mut cmd = Command::new("xvfb-run");
    cmd.args(["-a", "-s", "-screen 0 1280x800x24"])
        .arg(env!("CARGO_BIN_EXE_planet"))
        .args(["view", "--samples", "20000", "--from-earth"])
        .args(["--exit-after-steps", "1", "--screenshot"])
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", &runtime)
        .env_remove("WAYLAND_DISPLAY");
    let (ok, out) = run_with_limit(cmd, Duration::from_secs(300));
    assert!(ok, "planet view --from-earth failed:\n{out}");
    let img = image::open(&shot)
        .unwrap_or_else(|e| panic!("no readable screenshot at {}: {e}\n{out}", shot.display()))
        .to_rgb8();
    let (blue, green) = blue_and_green(&img);
    let n = (img.width() * img.height()) as usize;
    assert!(
        blue * 10 > n && green * 50 > n,
        "blue {blue}, green {green} of {n} pixels"
    );
}
