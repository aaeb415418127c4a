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
use egui::{Color32, ColorImage, Rect, Sense, Stroke, TextureHandle, TextureOptions, Vec2};

use crate::commands::{Command, CrustKind, LatLon, PlateRef};
use crate::plugins::TectonicSystems;
use crate::resources::params::{ParamKind, ParamValue, Params};

use super::map::{self, BaseLayer, VectorLayers};
use super::worker::{Request, SimHandle, Snapshot};

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

/// Width of the map on the screen the vector glyphs are laid out for, pixels (their spacing
/// and line widths scale from it to the texture).
const GLYPH_LAYOUT_WIDTH: f32 = 690.0;

/// A map to colour: a snapshot and a base layer (and, for the wgpu renderer, the elevation
/// grid and the vector layers drawn into the texture).
struct PaintJob {
    key: MapKey,
    snap: Arc<Snapshot>,
    layer: BaseLayer,
    elevation: bool,
}

/// A coloured map.
struct Painted {
    key: MapKey,
    image: Arc<ColorImage>,
    globe: Option<Arc<super::globe::GlobeData>>,
}

fn paint_job(job: PaintJob) -> Painted {
    let s = &job.snap;
    let image = Arc::new(map::render_base(s, job.layer));
    let globe = job.elevation.then(|| {
        use rayon::prelude::*;
        let lk = &s.lookup;
        let elevation_km = (0..lk.corners.len())
            .into_par_iter()
            .map(|i| lk.lerp(&s.crust.elevation_km, i))
            .collect();
        // The vector layers are drawn into the texture here, once per snapshot, instead of as
        // thousands of triangles in every frame.
        let layers = job.key.2;
        if layers == VectorLayers::default() {
            Arc::new(super::globe::GlobeData::new(&image, elevation_km))
        } else {
            let mut with = (*image).clone();
            let [w, h] = with.size;
            let rect = Rect::from_min_size(egui::Pos2::ZERO, Vec2::new(w as f32, h as f32));
            let mesh = map::vector_mesh(rect, s, layers, w as f32 / GLYPH_LAYOUT_WIDTH);
            map::rasterize_mesh(&mesh, w, h, &mut with.pixels);
            Arc::new(super::globe::GlobeData::new(&with, elevation_km))
        }
    });
    Painted {
        key: job.key,
        image,
        globe,
    }
}

/// The map painter thread's ends.
struct MapPainter {
    tx: std::sync::mpsc::Sender<PaintJob>,
    rx: std::sync::mpsc::Receiver<Painted>,
    busy: bool,
}

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
                    "{:.0} My · step {} · {} plates · land {:.1}% · {} samples · {:.0} fps",
                    s.time_my,
                    s.step,
                    s.plates.len(),
                    100.0 * s.stats.land_fraction,
                    s.samples,
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

    /// Rebuilds the map image when the snapshot or the base layer changed.
    pub fn refresh_map(&mut self, ctx: &egui::Context) {
        let Some(s) = self.snap.clone() else { return };
        let drawn_layers = if self.globe_ready {
            self.layers
        } else {
            VectorLayers::default()
        };
        let key = (Arc::as_ptr(&s) as usize, self.base, drawn_layers);
        // With a painter thread: install what it finished, and give it the next job when idle.
        if let Some(p) = self.painter.as_mut() {
            if let Ok(done) = p.rx.try_recv() {
                p.busy = false;
                self.install_map(ctx, done.key, done.image, done.globe);
            }
            let p = self.painter.as_mut().expect("painter checked above");
            if !p.busy && self.drawn != Some(key) {
                p.busy =
                    p.tx.send(PaintJob {
                        key,
                        snap: s,
                        layer: self.base,
                        elevation: self.globe_ready,
                    })
                    .is_ok();
            }
            return;
        }
        if self.drawn == Some(key) && self.map_tex.is_some() {
            return;
        }
        let done = paint_job(PaintJob {
            key,
            snap: s,
            layer: self.base,
            elevation: self.globe_ready,
        });
        self.install_map(ctx, done.key, done.image, done.globe);
    }

    fn install_map(
        &mut self,
        ctx: &egui::Context,
        key: MapKey,
        img: Arc<ColorImage>,
        globe: Option<Arc<super::globe::GlobeData>>,
    ) {
        // With the wgpu renderer the map is drawn from the globe's textures (uploaded by its
        // paint callback); egui's texture is only for the other renderers and headless runs.
        if !self.globe_ready {
            match &mut self.map_tex {
                Some(t) => t.set(img.clone(), TextureOptions::LINEAR),
                None => {
                    self.map_tex =
                        Some(ctx.load_texture("map", img.clone(), TextureOptions::LINEAR))
                }
            }
        }
        if globe.is_some() {
            self.globe_data = globe;
        }
        self.map_image = Some(img);
        self.map_generation += 1;
        self.drawn = Some(key);
    }

    /// Colours the map on a thread of its own from now on (the window does this; headless
    /// tests colour it in the frame, so that a frame shows its result at once).
    pub fn start_map_painter(&mut self, ctx: &egui::Context) {
        let (tx, jobs) = std::sync::mpsc::channel::<PaintJob>();
        let (done_tx, rx) = std::sync::mpsc::channel();
        let ctx = ctx.clone();
        let spawned = std::thread::Builder::new()
            .name("planet-map".into())
            .spawn(move || {
                while let Ok(mut job) = jobs.recv() {
                    // Only the newest job matters.
                    while let Ok(newer) = jobs.try_recv() {
                        job = newer;
                    }
                    if done_tx.send(paint_job(job)).is_err() {
                        return;
                    }
                    ctx.request_repaint();
                }
            });
        match spawned {
            Ok(_) => {
                self.painter = Some(MapPainter {
                    tx,
                    rx,
                    busy: false,
                })
            }
            Err(e) => tracing::warn!("no map painter thread ({e}); colouring in the frame"),
        }
    }

    fn map_ui(&mut self, ui: &mut egui::Ui) {
        self.refresh_map(ui.ctx());
        let Some(s) = self.snap.clone() else {
            ui.centered_and_justified(|ui| ui.label("building the planet…"));
            return;
        };
        let avail = ui.available_size();
        let w = avail.x.min(avail.y * 2.0).max(64.0);
        let (rect, resp) = ui.allocate_exact_size(Vec2::new(w, w / 2.0), Sense::click());
        self.track("map", &resp);
        let painter = ui.painter_at(rect);
        if self.globe_ready
            && let Some(data) = self.globe_data.clone()
        {
            // With the wgpu renderer the map is one quad of the globe's pipeline (cheaper per
            // pixel than an egui image on a software rasteriser).
            painter.add(super::globe::map_callback(
                rect,
                super::globe::MapCallback {
                    generation: self.map_generation,
                    data,
                },
            ));
        } else if let Some(t) = &self.map_tex {
            painter.image(
                t.id(),
                rect,
                Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        if !self.globe_ready {
            // With the wgpu renderer they are in the texture.
            map::paint_vectors(&painter, rect, &s, self.layers);
        }
        // Selected plate: its pole and its centroid.
        if let Some(p) = self.selected.and_then(|id| s.plate(id)) {
            let c = map::to_screen(rect, p.centroid_world);
            painter.circle_stroke(c, 6.0, Stroke::new(2.0, Color32::WHITE));
            let pole = match self.edit {
                Some(e) => LatLon {
                    lat: e.pole_lat,
                    lon: e.pole_lon,
                }
                .to_unit(),
                None => p.pole_unit,
            };
            let pp = map::to_screen(rect, pole);
            painter.circle_filled(pp, 5.0, Color32::YELLOW);
            painter.text(
                pp + Vec2::new(7.0, -7.0),
                egui::Align2::LEFT_BOTTOM,
                format!("pole of plate {}", p.id),
                egui::FontId::proportional(12.0),
                Color32::YELLOW,
            );
        }
        if !self.rift_line.is_empty() {
            let pts: Vec<egui::Pos2> = self
                .rift_line
                .iter()
                .map(|p| map::to_screen(rect, p.to_unit()))
                .collect();
            for w in pts.windows(2) {
                painter.line_segment([w[0], w[1]], Stroke::new(2.5, Color32::RED));
            }
            for p in &pts {
                painter.circle_filled(*p, 3.5, Color32::RED);
            }
        }
        if let Some(pos) = resp.hover_pos() {
            let ll = map::from_screen(rect, pos);
            let plate = self.plate_under(&s, ll);
            resp.clone().on_hover_text(format!(
                "{:.1}°, {:.1}° · plate {}",
                ll.lat,
                ll.lon,
                plate.map_or("–".into(), |p| p.to_string())
            ));
        }
        if resp.clicked()
            && let Some(pos) = resp.interact_pointer_pos()
        {
            self.point_click(&s, map::from_screen(rect, pos));
        }
    }

    /// The 3D globe: drag to orbit (with the "pick pole" tool: drag the selected plate's pole),
    /// wheel to zoom, click to use the current tool.
    fn globe_ui(&mut self, ui: &mut egui::Ui) {
        self.refresh_map(ui.ctx());
        let Some(s) = self.snap.clone() else { return };
        let avail = ui.available_size().max(Vec2::splat(64.0));
        let (rect, resp) = ui.allocate_exact_size(avail, Sense::click_and_drag());
        self.track("globe", &resp);
        let aspect = rect.width() / rect.height().max(1.0);
        let to_point = |cam: &super::globe::Camera, pos: egui::Pos2| {
            let ndc = [
                (pos.x - rect.left()) / rect.width() * 2.0 - 1.0,
                1.0 - (pos.y - rect.top()) / rect.height() * 2.0,
            ];
            cam.pick(aspect, ndc).map(|p| {
                let (lat, lon) = crate::geometry::spherical::to_lat_lon_deg(glam::DVec3::new(
                    p.x as f64, p.y as f64, p.z as f64,
                ));
                LatLon { lat, lon }
            })
        };
        if resp.dragged() {
            if self.tool == Tool::PickPole && self.edit.is_some() {
                if let Some(ll) = resp
                    .interact_pointer_pos()
                    .and_then(|p| to_point(&self.camera, p))
                    && let Some(e) = self.edit.as_mut()
                {
                    e.pole_lat = ll.lat;
                    e.pole_lon = ll.lon;
                }
            } else {
                let d = resp.drag_delta();
                self.camera.yaw -= d.x * 0.006;
                self.camera.pitch = (self.camera.pitch + d.y * 0.006).clamp(-1.55, 1.55);
            }
        }
        if resp.drag_stopped()
            && self.tool == Tool::PickPole
            && let Some(e) = self.edit
        {
            // Releasing the dragged pole applies it (through the command API).
            self.sim.send(Request::Apply(Command::SetMotion {
                plate: PlateRef::Id(e.plate),
                pole: LatLon {
                    lat: e.pole_lat,
                    lon: e.pole_lon,
                },
                speed_mm_per_yr: e.speed_mm_per_yr,
            }));
            self.tool = Tool::Select;
        }
        if resp.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.camera.distance =
                    (self.camera.distance * (1.0 - scroll * 0.002)).clamp(1.2, 12.0);
            }
        }
        if resp.clicked()
            && let Some(ll) = resp
                .interact_pointer_pos()
                .and_then(|p| to_point(&self.camera, p))
        {
            self.point_click(&s, ll);
        }
        if !self.globe_ready {
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "the 3D globe needs the wgpu renderer",
                egui::FontId::proportional(16.0),
                Color32::LIGHT_GRAY,
            );
            return;
        }
        let Some(data) = self.globe_data.clone() else {
            return;
        };
        let eye = self.camera.eye().normalize();
        let side = glam::Vec3::Z.cross(eye).normalize_or_zero();
        let light = (eye + 0.4 * glam::Vec3::Z + 0.4 * side).normalize();
        let uniforms = super::globe::GlobeUniforms {
            view_proj: self.camera.view_proj(aspect).to_cols_array_2d(),
            light_dir: [light.x, light.y, light.z, 0.0],
            params: [
                self.exaggeration / s.radius_km as f32,
                if self.sea_surface { 1.0 } else { 0.0 },
                0.0,
                0.0,
            ],
        };
        ui.painter().add(super::globe::paint_callback(
            rect,
            super::globe::GlobeCallback {
                uniforms,
                generation: self.map_generation,
                data,
            },
        ));
    }

    fn plate_under(&self, s: &Snapshot, ll: LatLon) -> Option<u32> {
        let lk = &s.lookup;
        let u = ((ll.lon + 180.0) / 360.0).clamp(0.0, 0.99999);
        let v = ((90.0 - ll.lat) / 180.0).clamp(0.0, 0.99999);
        let i =
            (v * lk.height as f64) as usize * lk.width as usize + (u * lk.width as f64) as usize;
        s.crust.plate.get(lk.sample_of(i)).copied()
    }

    /// What a click on the point `ll` (of the map or the globe) does, by tool.
    pub fn point_click(&mut self, s: &Snapshot, ll: LatLon) {
        match self.tool {
            Tool::Select => {
                self.selected = self.plate_under(s, ll);
                self.edit = self.selected.and_then(|id| s.plate(id)).map(motion_edit);
            }
            Tool::PickPole => {
                if let Some(e) = self.edit.as_mut() {
                    e.pole_lat = ll.lat;
                    e.pole_lon = ll.lon;
                }
                self.tool = Tool::Select;
            }
            Tool::RiftLine => self.rift_line.push(ll),
        }
    }

    /// The selected plate: its motion (editable), crust type, rift tools.
    pub fn inspector_ui(&mut self, ui: &mut egui::Ui) {
        ui.heading("Plate");
        let Some(s) = self.snap.clone() else { return };
        ui.horizontal(|ui| {
            ui.label("Tool:");
            ui.selectable_value(&mut self.tool, Tool::Select, "select");
            ui.selectable_value(&mut self.tool, Tool::PickPole, "pick pole");
            let r = ui.selectable_value(&mut self.tool, Tool::RiftLine, "fracture line");
            self.track("tool:rift", &r);
        });
        let Some(p) = self.selected.and_then(|id| s.plate(id)).cloned() else {
            ui.label("Click a plate on the map to select it.");
            self.rift_ui(ui);
            return;
        };
        ui.label(format!(
            "plate {} · {:.2} M km² · {:.0}% continental",
            p.id,
            p.area_km2 / 1e6,
            100.0 * p.continental_area_km2 / p.area_km2.max(1.0)
        ));
        let mut e = match self.edit {
            Some(e) if e.plate == p.id => e,
            _ => motion_edit(&p),
        };
        egui::Grid::new("motion").num_columns(2).show(ui, |ui| {
            ui.label("pole latitude");
            ui.add(
                egui::DragValue::new(&mut e.pole_lat)
                    .range(-90.0..=90.0)
                    .speed(0.5)
                    .suffix("°"),
            );
            ui.end_row();
            ui.label("pole longitude");
            ui.add(
                egui::DragValue::new(&mut e.pole_lon)
                    .range(-180.0..=180.0)
                    .speed(0.5)
                    .suffix("°"),
            );
            ui.end_row();
            ui.label("speed");
            let r = ui.add(
                egui::DragValue::new(&mut e.speed_mm_per_yr)
                    .range(0.0..=1000.0)
                    .speed(0.5)
                    .suffix(" mm/yr"),
            );
            self.track("speed", &r);
            ui.end_row();
        });
        self.edit = Some(e);
        ui.horizontal(|ui| {
            let r = ui.button("Apply motion");
            self.track("apply_motion", &r);
            if r.clicked() {
                self.sim.send(Request::Apply(Command::SetMotion {
                    plate: PlateRef::Id(p.id),
                    pole: LatLon {
                        lat: e.pole_lat,
                        lon: e.pole_lon,
                    },
                    speed_mm_per_yr: e.speed_mm_per_yr,
                }));
            }
            if ui.button("Reset").clicked() {
                self.edit = Some(motion_edit(&p));
            }
        });
        ui.horizontal(|ui| {
            ui.label("Crust:");
            for (label, kind) in [
                ("make continental", CrustKind::Continental),
                ("make oceanic", CrustKind::Oceanic),
            ] {
                if ui.button(label).clicked() {
                    self.sim.send(Request::Apply(Command::SetCrustType {
                        plate: Some(PlateRef::Id(p.id)),
                        cap: None,
                        crust: kind,
                    }));
                }
            }
        });
        if ui.button("Random rift (2 fragments)").clicked() {
            self.sim.send(Request::Apply(Command::RiftAt {
                plate: PlateRef::Id(p.id),
                fragments: 2,
            }));
        }
        self.rift_ui(ui);
    }

    fn rift_ui(&mut self, ui: &mut egui::Ui) {
        ui.label(format!(
            "Fracture line: {} points (choose the \"fracture line\" tool and click on the map)",
            self.rift_line.len()
        ));
        ui.horizontal(|ui| {
            let r = ui.add_enabled(
                self.rift_line.len() >= 2,
                egui::Button::new("Rift along line"),
            );
            self.track("rift_line", &r);
            if r.clicked() {
                self.sim.send(Request::Apply(Command::RiftLine {
                    line: std::mem::take(&mut self.rift_line),
                    plate: None,
                }));
                self.tool = Tool::Select;
            }
            if ui.button("Clear line").clicked() {
                self.rift_line.clear();
            }
        });
    }

    /// Every core and plugin parameter with its unit and range; checked before it is sent.
    pub fn params_ui(&mut self, ui: &mut egui::Ui) {
        let Some(s) = self.snap.clone() else { return };
        let shown = egui::CollapsingHeader::new("Parameters")
            .default_open(false)
            .show(ui, |ui| {
                if let Some(e) = self.param_errors.get("") {
                    ui.colored_label(Color32::from_rgb(230, 80, 60), e);
                }
                ui.horizontal(|ui| {
                    let r = ui.button("Apply to this planet");
                    self.track("params:apply", &r);
                    if r.clicked() {
                        self.apply_params(&s, false);
                    }
                    if ui.button("New planet").clicked() {
                        self.apply_params(&s, true);
                    }
                    if ui.button("Revert").clicked() {
                        self.param_text = param_texts(&s);
                        self.param_errors.clear();
                    }
                });
                let mut section = "";
                let specs: Vec<crate::resources::params::ParamSpec> = Params::schema()
                    .iter()
                    .copied()
                    .chain(s.plugin_params.iter().map(|p| p.spec))
                    .collect();
                for spec in specs {
                    if spec.section != section {
                        section = spec.section;
                        ui.strong(format!("[{section}]"));
                    }
                    ui.horizontal(|ui| {
                        let text = self.param_text.entry(spec.key.to_string()).or_default();
                        let r = ui
                            .add(egui::TextEdit::singleline(text).desired_width(80.0))
                            .on_hover_text(format!(
                                "{}\nrange {}..={}, default {}",
                                spec.doc, spec.min, spec.max, spec.default
                            ));
                        self.rects.insert(format!("param:{}", spec.key), r.rect);
                        ui.label(format!("{} {}", spec.name, spec.unit));
                    });
                    if let Some(e) = self.param_errors.get(spec.key) {
                        ui.colored_label(Color32::from_rgb(230, 80, 60), e);
                    }
                }
            });
        self.track("params:header", &shown.header_response);
    }

    /// Checks the parameter fields; sends them when all are valid: to the running planet as
    /// one `set_param` command per changed key (recorded in the history), or as a new planet.
    /// Returns whether they were sent; otherwise `param_errors` says why, by key.
    pub fn apply_params(&mut self, s: &Snapshot, new_planet: bool) -> bool {
        self.param_errors.clear();
        let mut params = s.params.clone();
        let mut changes = Vec::new();
        for (key, text) in &self.param_text {
            let spec = Params::schema()
                .iter()
                .chain(s.plugin_params.iter().map(|p| &p.spec))
                .find(|p| p.key == key.as_str());
            let Some(spec) = spec else { continue };
            let value = match parse_value(spec.kind, text) {
                Ok(v) => v,
                Err(e) => {
                    self.param_errors.insert(key.clone(), format!("{key}: {e}"));
                    continue;
                }
            };
            if key.starts_with("plugins.") {
                let current = s.plugin_params.iter().find(|p| p.spec.key == key);
                match crate::resources::params::check_value(spec, bounds(spec), value) {
                    Err(e) => {
                        self.param_errors.insert(key.clone(), e.to_string());
                    }
                    Ok(v) if current.is_some_and(|c| c.value != v) => {
                        changes.push((key.clone(), v));
                    }
                    Ok(_) => {}
                }
            } else if let Err(e) = params.set(key, value) {
                self.param_errors.insert(key.clone(), e.to_string());
            } else if params.get(key) != s.params.get(key) {
                if !new_planet && (key.starts_with("planet.") || key.starts_with("init.")) {
                    self.param_errors.insert(
                        key.clone(),
                        format!("{key} only applies to a new planet (press \"New planet\")"),
                    );
                } else if let Some(v) = params.get(key) {
                    changes.push((key.clone(), v));
                }
            }
        }
        if self.param_errors.is_empty()
            && let Err(e) = params.validate()
        {
            self.param_errors.insert("".into(), e.to_string());
        }
        if !self.param_errors.is_empty() {
            self.status = format!(
                "{} parameter(s) refused: {}",
                self.param_errors.len(),
                self.param_errors.values().next().map_or("", |e| e.as_str())
            );
            return false;
        }
        if new_planet {
            let plugin_changes: Vec<_> = changes
                .into_iter()
                .filter(|(k, _)| k.starts_with("plugins."))
                .collect();
            self.sim.send(Request::NewPlanet(Box::new(params)));
            for (k, v) in plugin_changes {
                self.sim.send(Request::SetPluginParam(k, v));
            }
        } else {
            for (key, v) in changes {
                self.sim.send(Request::Apply(Command::SetParam {
                    key,
                    value: v.into(),
                }));
            }
        }
        self.status.clear();
        true
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

fn motion_edit(p: &super::worker::PlateRow) -> MotionEdit {
    // Commands take a non-negative speed: a clockwise plate is the same turn about the antipode.
    let (lat, lon, speed) = if p.speed_mm_per_yr < 0.0 {
        let lon = if p.pole.lon > 0.0 {
            p.pole.lon - 180.0
        } else {
            p.pole.lon + 180.0
        };
        (-p.pole.lat, lon, -p.speed_mm_per_yr)
    } else {
        (p.pole.lat, p.pole.lon, p.speed_mm_per_yr)
    };
    MotionEdit {
        plate: p.id,
        pole_lat: lat,
        pole_lon: lon,
        speed_mm_per_yr: speed,
    }
}

fn param_texts(s: &Snapshot) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for spec in Params::schema() {
        if let Some(v) = s.params.get(spec.key) {
            out.insert(spec.key.to_string(), v.to_string());
        }
    }
    for p in &s.plugin_params {
        out.insert(p.spec.key.to_string(), p.value.to_string());
    }
    out
}

fn bounds(spec: &crate::resources::params::ParamSpec) -> (ParamValue, ParamValue) {
    match spec.kind {
        ParamKind::Float => (ParamValue::Float(spec.min), ParamValue::Float(spec.max)),
        ParamKind::Int => (
            ParamValue::Int(spec.min.max(0.0) as u64),
            ParamValue::Int(spec.max.max(0.0) as u64),
        ),
        ParamKind::Bool => (ParamValue::Bool(false), ParamValue::Bool(true)),
    }
}

/// Parses a parameter field; the message names what was expected.
pub fn parse_value(kind: ParamKind, text: &str) -> Result<ParamValue, String> {
    let t = text.trim();
    match kind {
        ParamKind::Float => t
            .parse::<f64>()
            .map(ParamValue::Float)
            .map_err(|_| format!("\"{t}\" is not a number")),
        ParamKind::Int => t
            .parse::<u64>()
            .map(ParamValue::Int)
            .map_err(|_| format!("\"{t}\" is not a non-negative integer")),
        ParamKind::Bool => t
            .parse::<bool>()
            .map(ParamValue::Bool)
            .map_err(|_| format!("\"{t}\" is not true or false")),
    }
}

fn set_error(slot: &Arc<Mutex<Option<String>>>, e: String) {
    if let Ok(mut s) = slot.lock()
        && s.is_none()
    {
        *s = Some(e);
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
