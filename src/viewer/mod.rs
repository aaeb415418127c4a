//! The egui viewer (`planet view`): watch, steer and toggle the stepped schedule live. An
//! eframe window (wgpu renderer) shows the planet as an equirectangular map with overlays, the
//! schedule with a switch and a timing per set and phenomenon, a plate inspector whose edits
//! go through the command API, parameters, save, load and export. The simulation runs on its
//! own thread ([`worker`]); the UI ([`app`]) only draws the snapshots it publishes.

pub mod app;
pub mod globe;
pub mod map;
pub mod worker;

#[cfg(test)]
mod tests;

use std::path::PathBuf;

pub use app::{ExitPlan, Percentiles, ViewerApp};
pub use worker::{PluginsFn, Request, SimFactory, SimHandle, Snapshot, builtin_plugins};

use crate::Simulation;

/// How long the first planet may take to build before the viewer gives up.
const BUILD_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(900);

/// Why the viewer could not run.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The planet could not be built or loaded.
    #[error("{0}")]
    Planet(String),
    /// No display to open a window on.
    #[error(
        "no display: neither DISPLAY nor WAYLAND_DISPLAY is set (run under a desktop session, or under `xvfb-run -a`)"
    )]
    NoDisplay,
    /// The window or its renderer could not start (no X server, no GPU adapter...).
    #[error("could not open the viewer window: {0}")]
    Window(String),
    /// The viewer ran but something it was asked to do failed (e.g. writing the screenshot).
    #[error("{0}")]
    Failed(String),
}

/// How to open the viewer.
#[derive(Debug, Clone)]
pub struct ViewerOptions {
    /// Window size in logical pixels.
    pub window_size: [f32; 2],
    /// Exit after this many steps (the simulation runs until then).
    pub exit_after_steps: Option<u64>,
    /// Write a screenshot here before exiting (with `exit_after_steps`).
    pub screenshot: Option<PathBuf>,
    /// Start in the 3D globe view.
    pub globe: bool,
    /// Steps per second while running (0: as fast as possible).
    pub steps_per_second: f64,
    /// Measure frame times: run the simulation, exit after this many frames drawn while it
    /// steps, and report the median frame time ([`ViewerReport`]).
    pub fps_report: Option<u64>,
    /// The map's base layer at start.
    pub base: map::BaseLayer,
    /// Vector layers drawn at start.
    pub layers: map::VectorLayers,
}

impl Default for ViewerOptions {
    fn default() -> Self {
        Self {
            window_size: [1280.0, 800.0],
            exit_after_steps: None,
            screenshot: None,
            globe: false,
            steps_per_second: 0.0,
            fps_report: None,
            base: map::BaseLayer::Elevation,
            layers: map::VectorLayers::default(),
        }
    }
}

/// What the viewer measured, reported when it exits.
#[derive(Debug, Clone, Default)]
pub struct ViewerReport {
    /// Frames drawn while the simulation was running.
    pub running_frames: u64,
    /// Frames per second while the simulation was running.
    pub running_fps: Option<f64>,
    /// Steps taken.
    pub steps: u64,
    /// Samples of the planet shown last.
    pub samples: usize,
    /// Time between frames while running, ms.
    pub frame_ms: Option<Percentiles>,
    /// Time in the app's UI code per frame while running, ms.
    pub ui_ms: Option<Percentiles>,
    /// eframe's CPU time per frame (UI, tessellation, rendering, present) while running, ms.
    pub cpu_ms: Option<Percentiles>,
    /// Snapshots shown while running (each is a new picture of the planet).
    pub snapshots: u64,
}

/// Opens the viewer on the planet `build` makes (on the simulation thread: a bevy app cannot
/// move between threads) and returns when its window closes. The planet is built before the
/// window opens, so a bad file or parameter is reported without one.
pub fn run(
    build: impl FnOnce() -> Result<Simulation, String> + Send + 'static,
    opts: ViewerOptions,
) -> Result<ViewerReport, ViewerError> {
    run_with_plugins(build, builtin_plugins(), opts)
}

/// As [`run`], for a planet built with other plugins than the built-in ones (third-party
/// plugins): `plugins` makes the group `build` uses, and "New planet" and "Load" in the viewer
/// rebuild with it.
pub fn run_with_plugins(
    build: impl FnOnce() -> Result<Simulation, String> + Send + 'static,
    plugins: PluginsFn,
    opts: ViewerOptions,
) -> Result<ViewerReport, ViewerError> {
    let has_display = ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()));
    if !has_display {
        return Err(ViewerError::NoDisplay);
    }
    // The simulation's threads yield to the window's: a frame is drawn (on lavapipe, by the
    // CPU) before the next step's work. The global pool exists already when `--threads` was
    // given; then it keeps its priority.
    let _ = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("planet-rayon-{i}"))
        .start_handler(|_| worker::lower_thread_priority())
        .build_global();
    let handle = SimHandle::spawn_with_plugins(plugins, move || {
        // The factory runs on the simulation thread.
        worker::lower_thread_priority();
        build()
    });
    handle
        .wait_ready(BUILD_TIMEOUT)
        .map_err(ViewerError::Planet)?;
    let mut wgpu_options = eframe::egui_wgpu::WgpuConfiguration::default();
    // Frames come as fast as they are drawn (Xvfb has no vertical blank to wait for).
    wgpu_options.surface.present_mode = eframe::wgpu::PresentMode::AutoNoVsync;
    let native = eframe::NativeOptions {
        viewport: eframe::egui::ViewportBuilder::default()
            .with_title("planet view")
            .with_inner_size(opts.window_size),
        renderer: eframe::Renderer::Wgpu,
        wgpu_options,
        // Dithering adds work to every fragment of every frame; on a software rasteriser
        // (lavapipe) that is a large share of the frame (set PLANET_VIEW_DITHER=1 for it).
        dithering: std::env::var_os("PLANET_VIEW_DITHER").is_some_and(|v| v == "1"),
        ..Default::default()
    };
    let report = std::sync::Arc::new(std::sync::Mutex::new(ViewerReport::default()));
    let exit_error = std::sync::Arc::new(std::sync::Mutex::new(None::<String>));
    let (report2, err2) = (report.clone(), exit_error.clone());
    let result = eframe::run_native(
        "planet view",
        native,
        Box::new(move |cc| {
            let ctx = cc.egui_ctx.clone();
            handle.set_repaint(move || ctx.request_repaint());
            let mut app = ViewerApp::new(handle);
            match &cc.wgpu_render_state {
                Some(rs) => app.enable_globe(rs),
                None => tracing::warn!("no wgpu render state: the 3D globe is off"),
            }
            app.exit_error = err2;
            app.view3d = opts.globe;
            app.base = opts.base;
            app.layers = opts.layers;
            app.start_map_painter(&cc.egui_ctx);
            if opts.steps_per_second > 0.0 {
                app.steps_per_second = opts.steps_per_second;
                app.sim.send(Request::SetSpeed(opts.steps_per_second));
            }
            if let Some(n) = opts.fps_report {
                app.frames.record_frame_times = true;
                let mut plan = ExitPlan::new(0, None);
                plan.after_running_frames = Some(n);
                app = app.with_exit_plan(plan);
            } else if let Some(n) = opts.exit_after_steps {
                app = app.with_exit_plan(ExitPlan::new(n, opts.screenshot.clone()));
            }
            Ok(Box::new(ReportingApp {
                app,
                report: report2,
            }))
        }),
    );
    result.map_err(|e| ViewerError::Window(e.to_string()))?;
    if let Some(e) = exit_error.lock().ok().and_then(|e| e.clone()) {
        return Err(ViewerError::Failed(e));
    }
    let r = report.lock().map(|r| r.clone()).unwrap_or_default();
    Ok(r)
}

/// The app plus a report written as it goes (eframe drops the app on exit).
struct ReportingApp {
    app: ViewerApp,
    report: std::sync::Arc<std::sync::Mutex<ViewerReport>>,
}

impl eframe::App for ReportingApp {
    fn clear_color(&self, visuals: &eframe::egui::Visuals) -> [f32; 4] {
        eframe::App::clear_color(&self.app, visuals)
    }

    fn ui(&mut self, ui: &mut eframe::egui::Ui, frame: &mut eframe::Frame) {
        eframe::App::ui(&mut self.app, ui, frame);
        if let Ok(mut r) = self.report.lock() {
            r.running_frames = self.app.frames.running_frames;
            r.running_fps = self.app.frames.running_fps();
            r.steps = self.app.snap.as_ref().map_or(0, |s| s.steps_taken);
            r.samples = self.app.snap.as_ref().map_or(0, |s| s.samples);
            if self.app.frames.record_frame_times {
                r.frame_ms = Percentiles::of(&self.app.frames.running_intervals_ms);
                r.ui_ms = Percentiles::of(&self.app.frames.running_ui_ms);
                r.cpu_ms = Percentiles::of(&self.app.frames.running_cpu_ms);
            }
            r.snapshots = self.app.frames.running_snapshots;
        }
    }
}
