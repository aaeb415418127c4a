//! UI logic tests of the viewer, run headless: the real [`ViewerApp`] UI is laid out by an
//! `egui::Context` with synthetic pointer events (clicks land on the widgets' recorded
//! rectangles) while the simulation runs on its worker thread, as in the window.

use std::time::Duration;

use eframe::egui;

use super::app::{Tool, ViewerApp};
use super::map::{self, BaseLayer};
use super::worker::{Request, SimHandle};
use crate::prelude::*;

const WAIT: Duration = Duration::from_secs(120);

/// Counts the runs of its system (a third-party plugin, registered in the aging set).
#[derive(Resource, Default)]
struct Runs(u64);

struct CounterPlugin;

impl Plugin for CounterPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon("counter", TectonicSystems::Aging, "counts its runs");
        app.init_resource::<Runs>();
        app.add_systems(
            TectonicStep,
            (|mut r: ResMut<Runs>| r.0 += 1)
                .in_set(TectonicSystems::Aging)
                .run_if(phenomenon_enabled("counter")),
        );
    }
}

fn small_params() -> Params {
    let mut p = Params::default();
    p.planet.samples = 4000;
    p.init.plates = 8;
    p
}

fn with_counter() -> Result<Simulation, String> {
    Simulation::with_plugins(small_params(), TectonicPlugins.build().add(CounterPlugin))
        .map_err(|e| e.to_string())
}

fn plain() -> Result<Simulation, String> {
    Simulation::new(small_params()).map_err(|e| e.to_string())
}

struct Harness {
    ctx: egui::Context,
    app: ViewerApp,
    time: f64,
}

impl Harness {
    fn new(build: impl FnOnce() -> Result<Simulation, String> + Send + 'static) -> Self {
        let handle = SimHandle::spawn(build);
        handle
            .wait_ready(WAIT)
            .expect("the worker publishes a first snapshot");
        let mut h = Self {
            ctx: egui::Context::default(),
            app: ViewerApp::new(handle),
            time: 0.0,
        };
        h.frame(Vec::new());
        h.frame(Vec::new());
        h
    }

    fn frame(&mut self, events: Vec<egui::Event>) {
        let raw = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(1280.0, 800.0),
            )),
            time: Some(self.time),
            events,
            ..Default::default()
        };
        self.time += 1.0 / 60.0;
        let app = &mut self.app;
        let _ = self.ctx.run_ui(raw, |ui| app.root_ui(ui));
    }

    fn click_at(&mut self, pos: egui::Pos2) {
        let button = |pressed| egui::Event::PointerButton {
            pos,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: Default::default(),
        };
        self.frame(vec![egui::Event::PointerMoved(pos)]);
        self.frame(vec![button(true)]);
        self.frame(vec![button(false)]);
        self.frame(vec![egui::Event::PointerGone]);
    }

    fn rect(&self, key: &str) -> egui::Rect {
        *self.app.rects.get(key).unwrap_or_else(|| {
            panic!("no widget \"{key}\" was drawn; drawn: {:?}", {
                let mut k: Vec<_> = self.app.rects.keys().collect();
                k.sort();
                k
            })
        })
    }

    fn click(&mut self, key: &str) {
        let c = self.rect(key).center();
        self.click_at(c);
    }

    /// Waits until the worker has handled every request sent so far, then draws a frame.
    fn settle(&mut self) {
        let seq = self.app.sim.last_sent();
        self.app
            .sim
            .wait_for(seq, WAIT)
            .expect("the worker answers in time");
        self.frame(Vec::new());
    }

    fn step(&mut self, n: u64) {
        self.app.sim.send(Request::Step(n));
        self.settle();
    }

    /// Runs `f` with the simulation on its thread.
    fn inspect<R: Send + 'static>(
        &mut self,
        f: impl FnOnce(&mut Simulation) -> R + Send + 'static,
    ) -> R {
        self.app
            .sim
            .with_sim(WAIT, f)
            .expect("the worker answers in time")
    }

    fn finish(self) {
        let Harness { app, .. } = self;
        assert!(app.sim.shutdown(), "the simulation thread ended cleanly");
    }
}

#[test]
fn unticking_a_plugin_in_the_schedule_panel_stops_its_systems() {
    let mut h = Harness::new(with_counter);
    h.step(2);
    // The third-party phenomenon is listed with a checkbox, ticked.
    let snap = h.app.snap.clone().unwrap();
    assert!(
        snap.phenomena
            .iter()
            .any(|p| p.name == "counter" && p.enabled)
    );
    h.click("phenomenon:counter");
    h.settle();
    let snap = h.app.snap.clone().unwrap();
    assert!(
        snap.phenomena
            .iter()
            .any(|p| p.name == "counter" && !p.enabled),
        "the click switched the phenomenon off"
    );
    h.step(3);
    let (step, runs, history) = h.inspect(|sim| {
        (
            sim.clock().step,
            sim.world().resource::<Runs>().0,
            sim.world()
                .resource::<crate::io::save::CommandHistory>()
                .entries
                .clone(),
        )
    });
    h.finish();
    assert_eq!(step, 5);
    assert_eq!(
        runs, 2,
        "the system ran in the two steps before the switch and in none after"
    );
    assert!(
        history
            .iter()
            .any(|(_, l)| l.contains("set_phenomenon") && l.contains("counter")),
        "the switch went through the command API: {history:?}"
    );
}

#[test]
fn ticking_it_again_resumes_its_systems() {
    let mut h = Harness::new(with_counter);
    h.click("phenomenon:counter");
    h.settle();
    h.step(2);
    h.click("phenomenon:counter");
    h.settle();
    h.step(1);
    let runs = h.inspect(|sim| sim.world().resource::<Runs>().0);
    h.finish();
    assert_eq!(runs, 1);
}

#[test]
fn selecting_a_plate_and_changing_its_speed_changes_that_plates_entity() {
    let mut h = Harness::new(plain);
    let map_rect = h.rect("map");
    // A point well inside a plate: every pixel around it shows the same plate.
    let snap0 = h.app.snap.clone().unwrap();
    let lk = &snap0.lookup;
    let plate_px = |c: u32, r: u32| snap0.crust.plate[lk.sample_of((r * lk.width + c) as usize)];
    let (w, hgt) = (lk.width, lk.height);
    let (col, row) = (w / 8..w * 7 / 8)
        .step_by(16)
        .flat_map(|c| (hgt / 4..hgt * 3 / 4).step_by(16).map(move |r| (c, r)))
        .find(|&(c, r)| {
            let p = plate_px(c, r);
            (c - 12..=c + 12)
                .step_by(3)
                .all(|cc| (r - 12..=r + 12).step_by(3).all(|rr| plate_px(cc, rr) == p))
        })
        .expect("some plate is wider than 25 pixels");
    let at = egui::pos2(
        map_rect.left() + map_rect.width() * (col as f32 + 0.5) / w as f32,
        map_rect.top() + map_rect.height() * (row as f32 + 0.5) / hgt as f32,
    );
    h.click_at(at);
    let id = h.app.selected.expect("the click selected a plate");
    // The plate under the click, as the map shows it.
    let snap = h.app.snap.clone().unwrap();
    let ll = map::from_screen(map_rect, at);
    let mut probe = Simulation::new(small_params()).unwrap();
    assert_eq!(
        crate::commands::plate_at(&mut probe, ll.to_unit()),
        Some(id),
        "the selected plate is the one under the clicked point"
    );
    let before = snap.plate(id).unwrap().speed_mm_per_yr.abs();
    let new_speed = if (before - 123.0).abs() < 1.0 {
        77.0
    } else {
        123.0
    };
    // Type a new speed into the inspector, then press "Apply motion".
    let mut e = h.app.edit.expect("the inspector loaded the plate's motion");
    assert_eq!(e.plate, id);
    e.speed_mm_per_yr = new_speed;
    h.app.edit = Some(e);
    h.frame(Vec::new());
    h.click("apply_motion");
    h.settle();
    let shown = h.app.snap.clone().unwrap();
    assert!((shown.plate(id).unwrap().speed_mm_per_yr - new_speed).abs() < 1e-6);
    let (speed, history) = h.inspect(move |sim| {
        let r = sim.params().planet.radius_km;
        let world = sim.world_mut();
        let mut q = world.query::<(&Plate, &PlateMotion)>();
        let speed = q
            .iter(world)
            .find(|(p, _)| p.id.0 == id)
            .map(|(_, m)| m.angular_speed_rad_per_my * r);
        let history = sim
            .world()
            .resource::<crate::io::save::CommandHistory>()
            .entries
            .clone();
        (speed, history)
    });
    h.finish();
    let speed = speed.expect("the plate entity exists");
    assert!(
        (speed - new_speed).abs() < 1e-6,
        "entity speed {speed} mm/yr, asked {new_speed}"
    );
    assert!(
        history.iter().any(|(_, l)| l.contains("set_motion")),
        "the change is in the history: {history:?}"
    );
}

#[test]
fn the_overlay_menu_switches_what_is_drawn() {
    let mut h = Harness::new(plain);
    assert_eq!(h.app.base, BaseLayer::Elevation);
    let snap = h.app.snap.clone().unwrap();
    let drawn = |h: &Harness| map::image_hash(h.app.map_image.as_ref().expect("a map is drawn"));
    let elevation = drawn(&h);
    assert_eq!(
        elevation,
        map::image_hash(&map::render_base(&snap, BaseLayer::Elevation))
    );
    for layer in [
        BaseLayer::Plates,
        BaseLayer::OceanicAge,
        BaseLayer::CrustType,
    ] {
        h.click(&format!("overlay:{}", layer.label()));
        h.frame(Vec::new());
        assert_eq!(h.app.base, layer);
        let now = drawn(&h);
        assert_ne!(now, elevation, "{layer:?} looks like the elevation map");
        assert_eq!(
            now,
            map::image_hash(&map::render_base(&snap, layer)),
            "the texture holds the {layer:?} map"
        );
    }
    h.finish();
}

#[test]
fn a_fracture_line_drawn_on_the_map_rifts_the_plate() {
    let mut h = Harness::new(plain);
    let before = h.app.snap.clone().unwrap().plates.len();
    h.click("tool:rift");
    assert_eq!(h.app.tool, Tool::RiftLine);
    // Find a plate covering a long horizontal run of the map, and draw a line across it.
    let snap = h.app.snap.clone().unwrap();
    let map_rect = h.rect("map");
    let biggest = snap
        .plates
        .iter()
        .max_by(|a, b| a.area_km2.total_cmp(&b.area_km2))
        .unwrap()
        .clone();
    let c = map::to_screen(map_rect, biggest.centroid_world);
    let dx = map_rect.width() * 0.03;
    h.click_at(c - egui::vec2(dx, 0.0));
    h.click_at(c + egui::vec2(dx, 0.0));
    assert_eq!(h.app.rift_line.len(), 2);
    h.click("rift_line");
    h.settle();
    let snap = h.app.snap.clone().unwrap();
    assert!(
        snap.plates.len() > before,
        "no new plate: {:?}",
        snap.log.last()
    );
    assert!(
        snap.history.iter().any(|(_, l)| l.contains("rift_line")),
        "the rift is in the history"
    );
    h.finish();
}

#[test]
fn bad_parameters_are_refused_with_the_key_and_nothing_is_sent() {
    let mut h = Harness::new(plain);
    let snap = h.app.snap.clone().unwrap();
    let sent = h.app.sim.last_sent();
    h.app
        .param_text
        .insert("time.time_step_my".into(), "-3".into());
    h.app
        .param_text
        .insert("subduction.distance_km".into(), "far".into());
    assert!(!h.app.apply_params(&snap, false));
    assert_eq!(h.app.sim.last_sent(), sent, "nothing was sent");
    let e = &h.app.param_errors;
    assert!(
        e["time.time_step_my"].contains("time.time_step_my"),
        "{e:?}"
    );
    assert!(
        e["subduction.distance_km"].contains("not a number"),
        "{e:?}"
    );
    // A valid change goes to the running planet.
    h.app.param_text = Default::default();
    h.frame(Vec::new());
    h.app.param_errors.clear();
    let mut texts = h.app.param_text.clone();
    if texts.is_empty() {
        for spec in Params::schema() {
            texts.insert(
                spec.key.to_string(),
                snap.params.get(spec.key).unwrap().to_string(),
            );
        }
    }
    texts.insert("continent.erosion_mm_per_yr".into(), "0.5".into());
    h.app.param_text = texts;
    assert!(h.app.apply_params(&snap, false), "{:?}", h.app.param_errors);
    h.settle();
    let snap = h.app.snap.clone().unwrap();
    assert_eq!(snap.params.continent.erosion_mm_per_yr, 0.5);
    h.finish();
}

#[test]
fn run_until_stops_at_the_target_time() {
    let mut h = Harness::new(plain);
    h.app.sim.send(Request::RunUntil(10.0));
    let deadline = std::time::Instant::now() + WAIT;
    loop {
        h.frame(Vec::new());
        let s = h.app.snap.clone().unwrap();
        if !s.running && s.time_my >= 10.0 {
            assert!(
                (s.time_my - 10.0).abs() < 1e-9,
                "stopped at {} My",
                s.time_my
            );
            break;
        }
        assert!(std::time::Instant::now() < deadline, "did not reach 10 My");
        std::thread::sleep(Duration::from_millis(20));
    }
    h.finish();
}
