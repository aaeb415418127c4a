//! The viewer's egui application: run controls, the schedule panel (every system set and
//! registered phenomenon with its switch and last timing), the map with its overlays, the plate
//! inspector and authoring tools (all through the command API), parameters, save, load and
//! export. The simulation lives on the worker thread ([`super::worker`]); this side only sends
//! requests and draws snapshots.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use eframe::egui;
use egui::{Color32, ColorImage, Rect, TextureHandle};

use crate::commands::{Command, LatLon};
use crate::plugins::TectonicSystems;

use super::map::{BaseLayer, VectorLayers};
use super::worker::{Request, SimHandle, Snapshot};

mod map_view;
mod panels;

use map_view::MapPainter;
pub use panels::parse_value;
use panels::{motion_edit, param_texts, set_error};

/// Least time between two frames while the simulation runs (60 frames per second at most).
pub const FRAME_INTERVAL: std::time::Duration = std::time::Duration::from_micros(16_667);

/// Width of the maps "Export maps" writes, pixels (the height is half).
pub const EXPORT_MAP_WIDTH: u32 = 2048;

/// What a click on the map does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tool {
    /// Select the plate under the pointer.
    Select,
    /// Set the selected plate's Euler pole (in the edit fields) to the clicked point.
    PickPole,
    /// Add a point to the fracture line.
    RiftLine,
}

/// The motion being edited for the selected plate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionEdit {
    /// The plate these values were loaded from.
    pub plate: u32,
    /// Pole latitude, degrees.
    pub pole_lat: f64,
    /// Pole longitude, degrees.
    pub pole_lon: f64,
    /// Speed, mm/yr.
    pub speed_mm_per_yr: f64,
}

/// Exit after some steps, optionally writing a screenshot first (for tests and figures).
#[derive(Debug)]
pub struct ExitPlan {
    /// Steps to take (the viewer runs the simulation until then).
    pub after_steps: u64,
    /// Where to write the screenshot (PNG).
    pub screenshot: Option<PathBuf>,
    /// Instead of a step count: run until this many frames were drawn while stepping, then
    /// exit (the frame-time measurement of `planet view --fps-report N`).
    pub after_running_frames: Option<u64>,
    frames_after_done: u32,
    requested: bool,
    started: Instant,
}

impl ExitPlan {
    /// A plan to exit after `after_steps` steps.
    pub fn new(after_steps: u64, screenshot: Option<PathBuf>) -> Self {
        Self {
            after_steps,
            screenshot,
            after_running_frames: None,
            frames_after_done: 0,
            requested: false,
            started: Instant::now(),
        }
    }
}

/// Frames drawn, for the FPS figure.
#[derive(Debug, Default, Clone)]
pub struct FrameStats {
    /// Frames drawn while the simulation was running.
    pub running_frames: u64,
    /// Seconds spent drawing those frames (from the first to the last).
    pub running_secs: f64,
    /// Keep every frame's times (below; for `--fps-report`, which ends the session).
    pub record_frame_times: bool,
    /// Time from the previous frame to this one, ms, for every frame drawn while running.
    pub running_intervals_ms: Vec<f64>,
    /// Time spent in the app's UI code (layout, our painting), ms, per frame while running.
    pub running_ui_ms: Vec<f64>,
    /// The whole frame's CPU time on the UI thread as eframe reports it (UI, tessellation,
    /// rendering, present), ms, per frame while running.
    pub running_cpu_ms: Vec<f64>,
    /// New snapshots shown while running.
    pub running_snapshots: u64,
    last_running: Option<Instant>,
    recent: std::collections::VecDeque<Instant>,
}

/// Median and 90th percentile of some frame times, ms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Percentiles {
    /// Median.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
}

impl Percentiles {
    /// Of `v` (`None` when empty).
    pub fn of(v: &[f64]) -> Option<Self> {
        if v.is_empty() {
            return None;
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let at = |q: f64| s[((s.len() - 1) as f64 * q).round() as usize];
        Some(Self {
            median: at(0.5),
            p90: at(0.9),
        })
    }
}

impl FrameStats {
    /// Frames per second while running.
    pub fn running_fps(&self) -> Option<f64> {
        (self.running_secs > 0.0).then(|| self.running_frames as f64 / self.running_secs)
    }
    fn tick(&mut self, running: bool) {
        let now = Instant::now();
        self.recent.push_back(now);
        while self.recent.len() > 60 {
            self.recent.pop_front();
        }
        if running {
            if let Some(t) = self.last_running {
                let dt = now.duration_since(t).as_secs_f64();
                self.running_secs += dt;
                self.running_frames += 1;
                if self.record_frame_times {
                    self.running_intervals_ms.push(dt * 1e3);
                }
            }
            self.last_running = Some(now);
        } else {
            self.last_running = None;
        }
    }
    /// Frames per second over the last frames.
    pub fn recent_fps(&self) -> f64 {
        match (self.recent.front(), self.recent.back()) {
            (Some(a), Some(b)) if self.recent.len() > 1 => {
                (self.recent.len() - 1) as f64 / b.duration_since(*a).as_secs_f64().max(1e-9)
            }
            _ => 0.0,
        }
    }
}

/// The viewer application state.
pub struct ViewerApp {
    /// The simulation thread.
    pub sim: SimHandle,
    /// The snapshot being shown.
    pub snap: Option<Arc<Snapshot>>,
    /// What the map is coloured by.
    pub base: BaseLayer,
    /// Vector layers over the map.
    pub layers: VectorLayers,
    /// The image the map texture holds now (what is drawn).
    pub map_image: Option<Arc<ColorImage>>,
    map_tex: Option<TextureHandle>,
    drawn: Option<MapKey>,
    /// The selected plate.
    pub selected: Option<u32>,
    /// The motion edit fields.
    pub edit: Option<MotionEdit>,
    /// The map tool.
    pub tool: Tool,
    /// Points of the fracture line being drawn.
    pub rift_line: Vec<LatLon>,
    /// Steps per second while running (0: as fast as possible).
    pub steps_per_second: f64,
    /// Target of "run until", My.
    pub run_until_my: f64,
    /// Steps for the "step" button.
    pub step_count: u64,
    /// Parameter edit fields (key → text), filled from the snapshot.
    pub param_text: BTreeMap<String, String>,
    /// Errors of the last parameter check (key → message).
    pub param_errors: BTreeMap<String, String>,
    /// Save / load file.
    pub file_path: String,
    /// Export folder.
    pub export_dir: String,
    /// Screen rectangles of named widgets from the last frame (for tests).
    pub rects: HashMap<String, Rect>,
    /// Exit plan, if any.
    pub exit: Option<ExitPlan>,
    /// Frame statistics.
    pub frames: FrameStats,
    /// Error to report when the viewer exits (shared with the screenshot callback).
    pub exit_error: Arc<Mutex<Option<String>>>,
    screenshot_done: Arc<Mutex<bool>>,
    status: String,
    /// Show the 3D globe instead of the 2D map.
    pub view3d: bool,
    /// The globe's camera.
    pub camera: super::globe::Camera,
    /// Elevation exaggeration of the globe.
    pub exaggeration: f32,
    /// Draw the sea surface on the globe.
    pub sea_surface: bool,
    /// Whether the globe's GPU objects exist (the wgpu renderer is running).
    pub globe_ready: bool,
    map_generation: u64,
    globe_data: Option<Arc<super::globe::GlobeData>>,
    style_set: bool,
    painter: Option<MapPainter>,
}

/// What a coloured map shows: the snapshot (by address), the base layer, and the vector layers
/// drawn into the globe's texture (none without the wgpu renderer: egui paints them).
type MapKey = (usize, BaseLayer, VectorLayers);

impl ViewerApp {
    /// A viewer of the simulation behind `sim`.
    pub fn new(sim: SimHandle) -> Self {
        Self {
            sim,
            snap: None,
            base: BaseLayer::Elevation,
            layers: VectorLayers::default(),
            map_image: None,
            map_tex: None,
            drawn: None,
            selected: None,
            edit: None,
            tool: Tool::Select,
            rift_line: Vec::new(),
            steps_per_second: 0.0,
            run_until_my: 100.0,
            step_count: 1,
            param_text: BTreeMap::new(),
            param_errors: BTreeMap::new(),
            file_path: "saves/viewer.planet".into(),
            export_dir: "out/viewer".into(),
            rects: HashMap::new(),
            exit: None,
            frames: FrameStats::default(),
            exit_error: Arc::default(),
            screenshot_done: Arc::default(),
            status: String::new(),
            view3d: false,
            camera: super::globe::Camera::default(),
            exaggeration: 40.0,
            sea_surface: true,
            globe_ready: false,
            map_generation: 0,
            globe_data: None,
            style_set: false,
            painter: None,
        }
    }

    /// Sets an exit plan and starts running the simulation toward it.
    pub fn with_exit_plan(mut self, plan: ExitPlan) -> Self {
        if plan.after_running_frames.is_some() {
            self.sim.send(Request::Run);
        } else if plan.after_steps > 0 {
            self.sim.send(Request::RunSteps(plan.after_steps));
        }
        self.exit = Some(plan);
        self
    }

    /// Creates the globe's GPU objects (needs the wgpu renderer).
    pub fn enable_globe(&mut self, rs: &eframe::egui_wgpu::RenderState) {
        super::globe::init(rs);
        self.globe_ready = true;
    }

    fn track(&mut self, key: impl Into<String>, r: &egui::Response) {
        self.rects.insert(key.into(), r.rect);
    }

    /// Takes the newest snapshot from the worker.
    pub fn poll(&mut self) {
        if let Some(s) = self.sim.latest()
            && self.snap.as_ref().is_none_or(|o| !Arc::ptr_eq(o, &s))
        {
            if self.param_text.is_empty()
                || self
                    .snap
                    .as_ref()
                    .is_some_and(|o| o.mesh_generation != s.mesh_generation)
            {
                self.param_text = param_texts(&s);
            }
            if s.running {
                self.frames.running_snapshots += 1;
            }
            if let Some(id) = self.selected
                && s.plate(id).is_none()
            {
                self.selected = None;
                self.edit = None;
            }
            self.snap = Some(s);
        }
    }

    /// The whole UI, inside the root `ui`.
    pub fn root_ui(&mut self, ui: &mut egui::Ui) {
        if !self.style_set {
            // Panels are not filled: the frame is cleared to their colour instead (see
            // `clear_color`), so each pixel is shaded once less. On a software rasteriser the
            // panel fills were the largest share of a frame.
            self.style_set = true;
            ui.ctx()
                .global_style_mut(|s| s.visuals.panel_fill = Color32::TRANSPARENT);
        }
        self.poll();
        let running = self.snap.as_ref().is_some_and(|s| s.running);
        self.frames.tick(running);
        self.exit_plan_ui(ui.ctx());
        egui::Panel::top("controls").show(ui, |ui| self.controls_ui(ui));
        egui::Panel::left("schedule")
            .default_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().id_salt("left").show(ui, |ui| {
                    self.schedule_ui(ui);
                    ui.separator();
                    self.params_ui(ui);
                });
            });
        egui::Panel::right("inspector")
            .default_size(290.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical()
                    .id_salt("right")
                    .show(ui, |ui| {
                        self.inspector_ui(ui);
                        ui.separator();
                        self.file_ui(ui);
                        ui.separator();
                        self.history_ui(ui);
                    });
            });
        egui::CentralPanel::default().show(ui, |ui| {
            self.overlay_ui(ui);
            if self.view3d {
                self.globe_ui(ui);
            } else {
                self.map_ui(ui);
            }
        });
        if running {
            // A steady frame rate while stepping (new snapshots also ask for a frame), not a
            // busy loop.
            ui.ctx().request_repaint_after(FRAME_INTERVAL);
        }
    }

    fn exit_plan_ui(&mut self, ctx: &egui::Context) {
        let Some(plan) = self.exit.as_mut() else {
            return;
        };
        let Some(s) = self.snap.clone() else { return };
        if let Some(n) = plan.after_running_frames {
            if self.frames.running_frames >= n {
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            } else if plan.started.elapsed().as_secs() > 1200 {
                set_error(
                    &self.exit_error,
                    format!("fewer than {n} frames were drawn within 1200 s"),
                );
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            return;
        }
        if plan.started.elapsed().as_secs() > 600 {
            set_error(
                &self.exit_error,
                "the exit plan did not finish within 600 s".into(),
            );
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        let drawn_now = self
            .drawn
            .is_some_and(|(p, _, _)| p == Arc::as_ptr(&s) as usize);
        if s.steps_taken < plan.after_steps || s.running || !drawn_now {
            return;
        }
        plan.frames_after_done += 1;
        if plan.frames_after_done < 3 {
            ctx.request_repaint();
            return;
        }
        match (&plan.screenshot, plan.requested) {
            (Some(path), false) => {
                plan.requested = true;
                let path = path.clone();
                let err = self.exit_error.clone();
                let done = self.screenshot_done.clone();
                let ctx2 = ctx.clone();
                ctx.request_screenshot(move |img| {
                    if let Err(e) = save_color_image(&img, &path) {
                        set_error(&err, e);
                    }
                    if let Ok(mut d) = done.lock() {
                        *d = true;
                    }
                    ctx2.request_repaint();
                });
                ctx.request_repaint();
            }
            (Some(_), true) => {
                if self.screenshot_done.lock().is_ok_and(|d| *d) {
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                } else {
                    ctx.request_repaint();
                }
            }
            (None, _) => ctx.send_viewport_cmd(egui::ViewportCommand::Close),
        }
    }

    fn controls_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal_wrapped(|ui| {
            let running = self.snap.as_ref().is_some_and(|s| s.running);
            let r = ui.add_enabled(!running, egui::Button::new("Run"));
            self.track("run", &r);
            if r.clicked() {
                self.sim.send(Request::Run);
            }
            let r = ui.add_enabled(running, egui::Button::new("Pause"));
            self.track("pause", &r);
            if r.clicked() {
                self.sim.send(Request::Pause);
            }
            let r = ui.button("Step");
            self.track("step", &r);
            if r.clicked() {
                self.sim.send(Request::Step(self.step_count));
            }
            ui.add(
                egui::DragValue::new(&mut self.step_count)
                    .range(1..=1000)
                    .suffix(" steps"),
            );
            ui.separator();
            if ui.button("Run until").clicked() {
                self.sim.send(Request::RunUntil(self.run_until_my));
            }
            ui.add(
                egui::DragValue::new(&mut self.run_until_my)
                    .range(0.0..=100_000.0)
                    .suffix(" My"),
            );
            ui.separator();
            ui.label("Speed");
            let r = ui.add(
                egui::Slider::new(&mut self.steps_per_second, 0.0..=60.0)
                    .suffix(" steps/s")
                    .custom_formatter(|v, _| {
                        if v == 0.0 {
                            "max".into()
                        } else {
                            format!("{v:.0}")
                        }
                    }),
            );
            if r.changed() {
                self.sim.send(Request::SetSpeed(self.steps_per_second));
            }
            ui.separator();
            if let Some(s) = &self.snap {
                ui.label(format!(
                    "{:.0} My · step {} · {} plates · land {:.1}% · {} samples · {} · {:.0} fps",
                    s.time_my,
                    s.step,
                    s.plates.len(),
                    100.0 * s.stats.land_fraction,
                    s.samples,
                    super::worker::backend_name(s.backend),
                    self.frames.recent_fps()
                ));
            } else {
                ui.label("building the planet…");
            }
        });
    }

    /// The schedule panel: every set in step order with its last timing, and under it every
    /// phenomenon registered in it with its switch (through the command API).
    pub fn schedule_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Schedule");
        let Some(s) = self.snap.clone() else { return };
        if let Some(ms) = s.step_ms {
            ui.label(format!("last step: {ms:.1} ms"));
        }
        egui::Grid::new("schedule_grid")
            .num_columns(2)
            .striped(true)
            .show(ui, |ui| {
                for (set, ms) in &s.set_timings_ms {
                    ui.strong(set_label(*set));
                    ui.label(ms.map_or("–".into(), |m| format!("{m:.2} ms")));
                    ui.end_row();
                    for p in s.phenomena.iter().filter(|p| p.set == *set) {
                        let mut on = p.enabled;
                        let r = ui.checkbox(&mut on, p.name).on_hover_text(p.description);
                        self.track(format!("phenomenon:{}", p.name), &r);
                        if r.changed() {
                            self.sim.send(Request::Apply(Command::SetPhenomenon {
                                name: p.name.to_string(),
                                enabled: on,
                            }));
                        }
                        ui.label(if p.enabled { "on" } else { "off" });
                        ui.end_row();
                    }
                }
            });
    }

    fn overlay_ui(&mut self, ui: &mut egui::Ui) {
        ui.horizontal_wrapped(|ui| {
            ui.label("View:");
            let r = ui.selectable_value(&mut self.view3d, false, "2D map");
            self.track("view:map", &r);
            let r = ui.selectable_value(&mut self.view3d, true, "3D globe");
            self.track("view:globe", &r);
            if self.view3d {
                ui.add(
                    egui::Slider::new(&mut self.exaggeration, 1.0..=200.0)
                        .logarithmic(true)
                        .text("exaggeration"),
                );
                ui.checkbox(&mut self.sea_surface, "sea surface");
            }
        });
        ui.horizontal_wrapped(|ui| {
            ui.label("Overlay:");
            for layer in BaseLayer::ALL {
                let r = ui.selectable_label(self.base == layer, layer.label());
                self.track(format!("overlay:{}", layer.label()), &r);
                if r.clicked() {
                    self.base = layer;
                }
            }
        });
        ui.horizontal_wrapped(|ui| {
            ui.label("Draw:");
            let l = &mut self.layers;
            ui.checkbox(&mut l.folds, "fold directions");
            ui.checkbox(&mut l.ridges, "ridge directions");
            ui.checkbox(&mut l.velocity, "plate velocities");
            ui.checkbox(&mut l.fronts, "subduction fronts");
            ui.checkbox(&mut l.terranes, "terranes");
        });
    }

    fn file_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Files");
        ui.horizontal(|ui| {
            ui.label("planet file");
            ui.text_edit_singleline(&mut self.file_path);
        });
        ui.horizontal(|ui| {
            let r = ui.button("Save");
            self.track("save", &r);
            if r.clicked() {
                self.sim.send(Request::Save(PathBuf::from(&self.file_path)));
            }
            let r = ui.button("Load");
            self.track("load", &r);
            if r.clicked() {
                self.sim.send(Request::Load(PathBuf::from(&self.file_path)));
            }
        });
        ui.horizontal(|ui| {
            ui.label("export folder");
            ui.text_edit_singleline(&mut self.export_dir);
        });
        ui.horizontal(|ui| {
            let r = ui.button("Export maps (PNG)");
            self.track("export_maps", &r);
            if r.clicked() {
                self.sim.send(Request::ExportMaps(
                    PathBuf::from(&self.export_dir),
                    EXPORT_MAP_WIDTH,
                ));
            }
            let r = ui.button("Export view (PNG)");
            self.track("export_view", &r);
            if r.clicked() {
                self.export_view(ui.ctx());
            }
        });
        if !self.status.is_empty() {
            ui.label(&self.status);
        }
    }

    fn export_view(&mut self, ctx: &egui::Context) {
        let dir = PathBuf::from(&self.export_dir);
        if let Err(e) = std::fs::create_dir_all(&dir) {
            self.status = format!("could not create {}: {e}", dir.display());
            return;
        }
        let path = dir.join("view.png");
        let p2 = path.clone();
        ctx.request_screenshot(move |img| match save_color_image(&img, &p2) {
            Ok(()) => tracing::info!("wrote {}", p2.display()),
            Err(e) => tracing::error!("{e}"),
        });
        self.status = format!("writing {}", path.display());
    }

    fn history_ui(&mut self, ui: &mut egui::Ui) {
        let Some(s) = self.snap.clone() else { return };
        egui::CollapsingHeader::new(format!("History ({})", s.history.len()))
            .default_open(true)
            .show(ui, |ui| {
                for (step, line) in s.history.iter().rev().take(12) {
                    ui.label(format!("step {step}: {line}"));
                }
            });
        egui::CollapsingHeader::new("Messages")
            .default_open(true)
            .show(ui, |ui| {
                for m in s.log.iter().rev().take(8) {
                    ui.label(m);
                }
            });
    }
}

fn set_label(set: TectonicSystems) -> String {
    let n = set.name().replace('_', " ");
    let mut c = n.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => n,
    }
}

/// Writes an egui image as PNG.
pub fn save_color_image(img: &ColorImage, path: &std::path::Path) -> Result<(), String> {
    let [w, h] = img.size;
    let mut rgba = Vec::with_capacity(w * h * 4);
    for p in &img.pixels {
        rgba.extend_from_slice(&p.to_srgba_unmultiplied());
    }
    let buf = image::RgbaImage::from_raw(w as u32, h as u32, rgba)
        .ok_or_else(|| format!("screenshot of {w}x{h} has the wrong number of pixels"))?;
    if let Some(dir) = path.parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("could not create {}: {e}", dir.display()))?;
    }
    buf.save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| format!("could not write {}: {e}", path.display()))
}

/// What the window is cleared to: the panels' colour (they are drawn without a fill).
pub const BACKGROUND: Color32 = Color32::from_gray(27);

impl eframe::App for ViewerApp {
    fn clear_color(&self, _visuals: &egui::Visuals) -> [f32; 4] {
        BACKGROUND.to_normalized_gamma_f32()
    }

    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let t = Instant::now();
        self.root_ui(ui);
        if self.frames.record_frame_times && self.frames.last_running.is_some() {
            self.frames
                .running_ui_ms
                .push(t.elapsed().as_secs_f64() * 1e3);
            if let Some(cpu) = frame.info().cpu_usage {
                self.frames.running_cpu_ms.push(cpu as f64 * 1e3);
            }
        }
    }
}
