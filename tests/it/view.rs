//! `vortex-tiler view` in a real window: an X server of our own (Xvfb, `apt-get install xvfb`)
//! and the window's surface on lavapipe. Its `--screenshot` must be the picture `render` makes of
//! the same view headless, and it must refuse to overwrite a file that is not its own. Without
//! Xvfb the tests print a note and pass, except under `CI=true`, where they fail.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, ChildStdout, Command, Output, Stdio};

use crate::common::cli::{BIN, fails_with, fixture, run, s};
use crate::common::compare::{Picture, Tolerance, assert_close};

/// An Xvfb server on a free display, stopped on drop.
pub(crate) struct Xvfb {
    child: Child,
    display: String,
    /// Held open: a write by Xvfb after its display number must not meet a closed pipe.
    _stdout: BufReader<ChildStdout>,
}

impl Xvfb {
    /// A server, or `None` (with a note) when Xvfb is not installed outside CI.
    pub(crate) fn start() -> Option<Xvfb> {
        if !crate::common::have_program("Xvfb", "-help", "xvfb") {
            return None;
        }
        // Xvfb picks a free display itself and writes its number to `-displayfd` (here its
        // stdout, a pipe) once it accepts clients: the line is the readiness signal, and the
        // pipe's end (Xvfb gone) the failure, with nothing polled.
        let mut child = Command::new("Xvfb")
            .args(["-displayfd", "1", "-screen", "0", "1024x768x24", "-nolisten", "tcp"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("Xvfb starts");
        let mut line = String::new();
        let mut stdout = BufReader::new(child.stdout.take().expect("Xvfb's stdout"));
        stdout.read_line(&mut line).expect("Xvfb's display number");
        let n: u32 = line.trim().parse().unwrap_or_else(|_| panic!("Xvfb exited before it took a display: {line:?}"));
        let display = format!(":{n}");
        Some(Xvfb { child, display, _stdout: stdout })
    }

    /// `vortex-tiler view ARGS` on this display.
    pub(crate) fn view(&self, args: &[&str]) -> Output {
        let mut cmd = Command::new(BIN);
        cmd.arg("view").args(args).env("NO_COLOR", "1").env("DISPLAY", &self.display).env_remove("WAYLAND_DISPLAY");
        cmd.envs(vortex_vt_wgpu::device::lavapipe_env());
        cmd.output().expect("binary runs")
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn rgba(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut pixels).unwrap();
    pixels.truncate(info.buffer_size());
    (info.width, info.height, pixels)
}

#[test]
fn the_windows_screenshot_is_the_headless_render_of_the_same_view() {
    let Some(x) = Xvfb::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("sample.vtpk");
    let split = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--codec", "png"]);
    assert!(split.status.success(), "{}", String::from_utf8_lossy(&split.stderr));

    // The view opens on the whole image; zoom in with a scene to cross page edges at LOD 0.
    let scene = dir.path().join("scene.json");
    let json = r#"{"view": {"window": {"path": [{"frame": 0, "center": [0.4, 0.55], "width": 0.35}]}}}"#;
    std::fs::write(&scene, json).unwrap();
    for (name, scene_args) in [("whole", vec![]), ("zoomed", vec!["--scene", s(&scene)])] {
        let shot = dir.path().join(format!("{name}.png"));
        let mut args = vec![s(&pack), "--size", "320x240", "--screenshot", s(&shot), "--frame-count", "12"];
        args.extend(&scene_args);
        let out = x.view(&args);
        assert!(out.status.success(), "view {name}: {}", String::from_utf8_lossy(&out.stderr));

        let frames = dir.path().join(format!("frames-{name}"));
        let whole = dir.path().join("whole.json");
        if scene_args.is_empty() {
            std::fs::write(
                &whole,
                r#"{"view": {"window": {"path": [{"frame": 0, "center": [0.5, 0.5], "width": 1.0}]}}}"#,
            )
            .unwrap();
        }
        let scene_file = if scene_args.is_empty() { &whole } else { &scene };
        let out = run(&[
            "render",
            "--pack",
            s(&pack),
            "--scene",
            s(scene_file),
            "--size",
            "320x240",
            "--frame-count",
            "12",
            "--frames",
            s(&frames),
            "-q",
        ]);
        assert!(out.status.success(), "render {name}: {}", String::from_utf8_lossy(&out.stderr));
        let (w, h, window) = rgba(&shot);
        let (rw, rh, headless) = rgba(&frames.join("frame-0011.png"));
        assert_eq!((w, h), (rw, rh), "{name}");
        // The bound this test always had; no measurement was written down with it.
        let why = "the same shaders drawn into the window's surface and into render's frame";
        let c = window.len() / (w * h) as usize;
        let (window, headless) = (Picture::new(w, h, c, &window), Picture::new(w, h, c, &headless));
        assert_close(&format!("view-{name}"), window, headless, Tolerance::max(2, why));
    }
}

#[test]
fn a_screenshot_never_replaces_a_file_it_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let mine = dir.path().join("holiday.png");
    std::fs::write(&mine, b"my own picture").unwrap();
    // Refused before any window opens, so no display is needed.
    let out = run(&["view", s(&fixture("sample.png")), "--screenshot", s(&mine), "--frame-count", "2"]);
    fails_with(&out, &["holiday.png", "not a screenshot of vortex-tiler view"]);
    assert_eq!(std::fs::read(&mine).unwrap(), b"my own picture");
}

#[test]
fn frame_counts_render_refuses_are_refused_before_any_window_opens() {
    let dir = tempfile::tempdir().unwrap();
    let shot = dir.path().join("shot.png");
    for (count, needle) in [("0", "frames must be at least 1"), ("4294967295", "more than the 1000000 a run may draw")]
    {
        let out = run(&["view", s(&fixture("sample.png")), "--screenshot", s(&shot), "--frame-count", count]);
        fails_with(&out, &[needle]);
        let render = run(&["render", "--pack", s(&fixture("sample.png")), "--frame-count", count]);
        fails_with(&render, &[needle]);
    }
    assert!(!shot.exists());
}

#[test]
fn a_screenshot_of_pages_that_failed_to_load_fails_as_render_does() {
    let Some(x) = Xvfb::start() else { return };
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("sample.vtpk");
    let split = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack)]);
    assert!(split.status.success(), "{}", String::from_utf8_lossy(&split.stderr));
    crate::render::damage_every_tile(&pack);
    let shot = dir.path().join("shot.png");
    let out = x.view(&[s(&pack), "--size", "64x48", "--screenshot", s(&shot), "--frame-count", "3"]);
    let render = run(&["render", "--pack", s(&pack), "--size", "64x48", "--frame-count", "3", "-q"]);
    for out in [out, render] {
        fails_with(&out, &["page(s) failed to load and were drawn as a stand-in", "sample.vtpk: tile (lod"]);
    }
}
