//! The windowed flyover under Xvfb: it starts and renders, dragging the detail slider with
//! xdotool changes the reported triangle count, F12 writes a screenshot that is not uniform.
//! Needs `Xvfb`, `xdotool` and the `flyover` binary (`cargo build --bins`, as tests/run.sh does
//! before the tests). Outside CI a missing tool skips the test with a printed reason.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn have(tool: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {tool}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// The flyover binary to drive: `FLYOVER_BIN` when set (tests/run.sh sets it to the binary it
/// has just built), else the debug build of this workspace. Never "whichever is newer": a stale
/// release build must not stand in for the code under test.
fn flyover_binary() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("FLYOVER_BIN") {
        return Some(PathBuf::from(p));
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| tests::workspace_root().join("target"), PathBuf::from);
    Some(target.join("debug").join("flyover")).filter(|p| p.exists())
}

fn read_stats(p: &Path) -> Option<serde_json::Value> {
    serde_json::from_str(&std::fs::read_to_string(p).ok()?).ok()
}

/// Waits until `ok` holds for the stats file, or panics after `timeout`.
fn wait_for(
    p: &Path,
    log: &Path,
    timeout: Duration,
    what: &str,
    ok: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        if let Some(v) = read_stats(p)
            && ok(&v)
        {
            return v;
        }
        assert!(
            t0.elapsed() < timeout,
            "timed out waiting for {what}; last stats: {:?}\nviewer log:\n{}",
            read_stats(p),
            std::fs::read_to_string(log).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Runs xdotool, then waits a little so the viewer sees each step in a separate frame (the
/// viewer runs at a few frames per second on a software adapter).
fn xdotool(display: &str, args: &[&str]) {
    let s = Command::new("xdotool")
        .args(args)
        .env("DISPLAY", display)
        .status()
        .expect("xdotool runs");
    assert!(s.success(), "xdotool {args:?} failed");
    std::thread::sleep(Duration::from_millis(300));
}

fn idle(v: &serde_json::Value) -> bool {
    let s = &v["stats"];
    s["triangles"].as_u64().unwrap_or(0) > 0
        && s["jobs_queued"].as_u64() == Some(0)
        && s["jobs_running"].as_u64() == Some(0)
        && s["pop_debt_nodes"].as_u64() == Some(0)
}

/// An `XDG_RUNTIME_DIR` under `tmp` (mode 700, as the spec requires).
fn runtime_dir(tmp: &std::path::Path) -> PathBuf {
    let runtime = tmp.join("xdg");
    std::fs::create_dir_all(&runtime).expect("runtime dir");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&runtime, std::fs::Permissions::from_mode(0o700)).expect("chmod");
    }
    runtime
}

/// The flyover binary when Xvfb, xdotool and the binary are there; None (a recorded skip)
/// otherwise, outside CI.
fn tools() -> Option<PathBuf> {
    let missing: Vec<&str> = ["Xvfb", "xdotool"]
        .into_iter()
        .filter(|t| !have(t))
        .collect();
    let bin = flyover_binary();
    if !missing.is_empty() || bin.is_none() {
        let why = format!(
            "missing {missing:?}, flyover binary found: {}",
            bin.is_some()
        );
        assert!(!tests::in_ci(), "CI must run the viewer test: {why}");
        tests::skip(
            "viewer under Xvfb",
            &format!("{why} (tests/run.sh installs the tools and builds the binaries)"),
        );
        return None;
    }
    bin
}

/// Starts Xvfb on display `:n` and waits for its socket.
fn xvfb(n: u32) -> (Killed, String) {
    let display = format!(":{n}");
    let xvfb = Killed(
        Command::new("Xvfb")
            .args([
                display.as_str(),
                "-screen",
                "0",
                "1280x720x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb starts"),
    );
    let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
    let t0 = Instant::now();
    while !socket.exists() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "Xvfb did not come up on {display}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    (xvfb, display)
}

#[test]
fn viewer_under_xvfb_renders_reacts_to_the_slider_and_writes_a_screenshot() {
    let Some(bin) = tools() else {
        return;
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let runtime = runtime_dir(tmp.path());
    let (_xvfb, display) = xvfb(90 + std::process::id() % 100);
    let stats = tmp.path().join("stats.json");
    let out = tmp.path().join("out");
    let log_path = tmp.path().join("viewer.log");
    let log = std::fs::File::create(&log_path).expect("log file");
    let _viewer = Killed(
        Command::new(&bin)
            .args(["--map"])
            .arg(tests::tiny_map_dir())
            .args(["--size", "960x540", "--tau", "1", "--exit-after-s", "300"])
            .arg("--stats-file")
            .arg(&stats)
            .arg("--out")
            .arg(&out)
            .env("DISPLAY", &display)
            .env("XDG_RUNTIME_DIR", &runtime)
            .env_remove("WAYLAND_DISPLAY")
            .stdout(log.try_clone().expect("dup log"))
            .stderr(log)
            .spawn()
            .expect("flyover starts"),
    );
    let log_text = || std::fs::read_to_string(tmp.path().join("viewer.log")).unwrap_or_default();
    let timeout = Duration::from_mins(4);
    // Rendering, streaming settled: stop the automatic flyover so the view stays put.
    let first = wait_for(&stats, &log_path, timeout, "first frames", |v| {
        v["stats"]["triangles"].as_u64().unwrap_or(0) > 0
    });
    let _ = first;
    let win = window_id(&display);
    assert!(
        !win.is_empty(),
        "no flyover window found; log:\n{}",
        log_text()
    );
    xdotool(&display, &["windowfocus", "--sync", &win]);
    xdotool(&display, &["key", "space"]);
    let before = wait_for(&stats, &log_path, timeout, "streaming to settle", idle);
    // Flown by hand now (the automatic flyover is off): a settled view shows no node over τ,
    // and the panel's pop debt of the last seconds is in the stats file.
    assert_eq!(
        before["stats"]["pop_excess_px"].as_f64(),
        Some(0.0),
        "a settled view shows a node over τ: {before}"
    );
    let last = &before["pop_debt_last"];
    assert!(
        last["window_s"].as_f64() == Some(5.0)
            && last["frames"].as_u64().unwrap_or(0) > 0
            && last["share"]
                .as_f64()
                .is_some_and(|s| (0.0..=1.0).contains(&s)),
        "{last}"
    );
    let tau0 = before["tau_px"].as_f64().expect("tau");
    let tri0 = before["stats"]["triangles"].as_u64().expect("triangles");
    // Drag the slider from its left end to its right end (τ up: fewer triangles).
    let r: Vec<f64> = before["slider_rect_points"]
        .as_array()
        .expect("slider rect")
        .iter()
        .map(|x| x.as_f64().unwrap_or(0.0))
        .collect();
    let ppp = before["pixels_per_point"].as_f64().unwrap_or(1.0);
    let y = ((r[1] + r[3]) * 0.5 * ppp).round().to_string();
    let x0 = ((r[0] + 4.0) * ppp).round().to_string();
    let x1 = ((r[0] + (r[2] - r[0]) * 0.45) * ppp).round().to_string();
    xdotool(&display, &["mousemove", "--window", &win, &x0, &y]);
    xdotool(&display, &["mousedown", "1"]);
    for k in 1..=10 {
        let x = (r[0] + 4.0 + (r[2] - r[0]) * 0.45 * f64::from(k) / 10.0) * ppp;
        xdotool(
            &display,
            &["mousemove", "--window", &win, &x.round().to_string(), &y],
        );
    }
    xdotool(&display, &["mousemove", "--window", &win, &x1, &y]);
    xdotool(&display, &["mouseup", "1"]);
    let after = wait_for(
        &stats,
        &log_path,
        timeout,
        "τ to change and streaming to settle",
        |v| v["tau_px"].as_f64().is_some_and(|t| (t - tau0).abs() > 0.5) && idle(v),
    );
    let tau1 = after["tau_px"].as_f64().expect("tau");
    let tri1 = after["stats"]["triangles"].as_u64().expect("triangles");
    println!("slider: tau {tau0:.2} -> {tau1:.2} px, triangles {tri0} -> {tri1}");
    assert!(tau1 > tau0, "dragging right should raise τ");
    assert!(tri1 < tri0, "triangles did not drop: {tri0} -> {tri1}");
    // Screenshot.
    xdotool(&display, &["key", "F12"]);
    wait_for(&stats, &log_path, timeout, "a screenshot", |v| {
        v["screenshots"].as_u64().unwrap_or(0) >= 1
    });
    let shot = out.join("screenshot_000.png");
    let f = std::fs::File::open(&shot).unwrap_or_else(|e| panic!("{}: {e}", shot.display()));
    let mut rd = png::Decoder::new(std::io::BufReader::new(f))
        .read_info()
        .expect("png");
    let mut buf = vec![0; rd.output_buffer_size().expect("size")];
    let info = rd.next_frame(&mut buf).expect("frame");
    let distinct: std::collections::HashSet<&[u8]> =
        buf[..info.buffer_size()].chunks_exact(4).collect();
    println!(
        "screenshot {}x{}, {} distinct colours",
        info.width,
        info.height,
        distinct.len()
    );
    assert!(
        distinct.len() > 100,
        "screenshot is (nearly) uniform: {} colours",
        distinct.len()
    );
}

/// Starts the flyover on `display` with the tiny map and `extra` arguments; returns it, its
/// stats file and its log file.
fn spawn_viewer(
    bin: &Path,
    display: &str,
    tmp: &Path,
    extra: &[&str],
) -> (Killed, PathBuf, PathBuf) {
    let stats = tmp.join("stats.json");
    let log_path = tmp.join("viewer.log");
    let log = std::fs::File::create(&log_path).expect("log file");
    let child = Command::new(bin)
        .args(["--map"])
        .arg(tests::tiny_map_dir())
        .args(["--size", "640x360", "--exit-after-s", "300"])
        .args(extra)
        .arg("--stats-file")
        .arg(&stats)
        .arg("--out")
        .arg(tmp.join("out"))
        .env("DISPLAY", display)
        .env("XDG_RUNTIME_DIR", runtime_dir(tmp))
        .env_remove("WAYLAND_DISPLAY")
        .stdout(log.try_clone().expect("dup log"))
        .stderr(log)
        .spawn()
        .expect("flyover starts");
    (Killed(child), stats, log_path)
}

fn window_id(display: &str) -> String {
    let out = Command::new("xdotool")
        .args(["search", "--sync", "--name", "flyover"])
        .env("DISPLAY", display)
        .output()
        .expect("xdotool search");
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .next()
        .unwrap_or_default()
        .to_string()
}

/// Resize storms (down to 1x1 and up past the screen) and hiding/showing the window while the
/// automatic flight runs: the viewer keeps drawing, at the size it was left at. (Without a
/// window manager Xvfb cannot minimise to 0x0; that case skips drawing until the window has an
/// area again, see `flyover/window.rs`.)
#[test]
fn viewer_survives_resize_storms_and_hiding() {
    let Some(bin) = tools() else {
        return;
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let (_xvfb, display) = xvfb(200 + std::process::id() % 100);
    let (mut viewer, stats, log) = spawn_viewer(&bin, &display, tmp.path(), &[]);
    let timeout = Duration::from_mins(4);
    let frame = |v: &serde_json::Value| v["stats"]["frame"].as_u64().unwrap_or(0);
    let first = wait_for(&stats, &log, timeout, "first frames", |v| {
        v["stats"]["triangles"].as_u64().unwrap_or(0) > 0
    });
    let win = window_id(&display);
    assert!(!win.is_empty(), "no flyover window");
    let sizes = [
        (1, 1),
        (2000, 1200),
        (320, 200),
        (17, 931),
        (1, 600),
        (800, 1),
    ];
    for round in 0..4 {
        for (w, h) in sizes {
            xdotool(
                &display,
                &["windowsize", &win, &w.to_string(), &h.to_string()],
            );
        }
        xdotool(&display, &["windowunmap", &win]);
        xdotool(&display, &["windowmap", &win]);
        assert!(
            viewer.0.try_wait().expect("viewer status").is_none(),
            "the viewer exited during round {round}:\n{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
    }
    xdotool(&display, &["windowsize", &win, "500", "300"]);
    let f0 = frame(&first);
    let after = wait_for(&stats, &log, timeout, "frames at the final size", |v| {
        frame(v) > f0 + 10 && v["surface_px"] == serde_json::json!([500, 300])
    });
    println!(
        "resize storm: frames {f0} -> {}, surface {}",
        frame(&after),
        after["surface_px"]
    );
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(!text.contains("panicked"), "viewer log:\n{text}");
}

/// A lost GPU device (a driver reset; here the device destroyed by a test hook): the viewer
/// exits with an error that says so, not a panic. It does not recreate the device.
#[test]
fn viewer_exits_with_a_clear_message_when_the_device_is_lost() {
    let Some(bin) = tools() else {
        return;
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let (_xvfb, display) = xvfb(300 + std::process::id() % 100);
    let (mut viewer, stats, log) = spawn_viewer(
        &bin,
        &display,
        tmp.path(),
        &["--debug-lose-device-after-s", "3"],
    );
    wait_for(&stats, &log, Duration::from_mins(4), "first frames", |v| {
        v["stats"]["triangles"].as_u64().unwrap_or(0) > 0
    });
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = viewer.0.try_wait().expect("viewer status") {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_mins(2),
            "the viewer kept running after losing its device:\n{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    println!(
        "device lost: {status}; log tail: {}",
        text.lines().last().unwrap_or("")
    );
    assert!(!status.success(), "exit status {status}");
    assert!(
        text.contains("GPU device was lost") && text.contains("does not recreate"),
        "log:\n{text}"
    );
    assert!(!text.contains("panicked"), "log:\n{text}");
}
