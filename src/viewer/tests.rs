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

fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("planet-viewer-unit-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Distinct colours in a PNG file, and its size.
fn png_colours(path: &std::path::Path) -> (u32, u32, usize) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{} is not a readable image: {e}", path.display()))
        .to_rgba8();
    let colours: std::collections::HashSet<[u8; 4]> = img.pixels().map(|p| p.0).collect();
    (img.width(), img.height(), colours.len())
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

/// The harness's screen, points: a 1280×1024 display (the left panel scrolls; at 800 points
/// the parameters header sits below the schedule's fourteen sets).
const SCREEN: (f32, f32) = (1280.0, 1024.0);

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

    fn frame(&mut self, events: Vec<egui::Event>) -> egui::FullOutput {
        let raw = egui::RawInput {
            screen_rect: Some(egui::Rect::from_min_size(
                egui::Pos2::ZERO,
                egui::vec2(SCREEN.0, SCREEN.1),
            )),
            time: Some(self.time),
            events,
            ..Default::default()
        };
        self.time += 1.0 / 60.0;
        let app = &mut self.app;
        self.ctx.run_ui(raw, |ui| app.root_ui(ui))
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

    /// Presses at `from`, moves to `to` in a few frames, releases there.
    fn drag(&mut self, from: egui::Pos2, to: egui::Pos2) {
        let button = |pos, pressed| egui::Event::PointerButton {
            pos,
            button: egui::PointerButton::Primary,
            pressed,
            modifiers: Default::default(),
        };
        self.frame(vec![egui::Event::PointerMoved(from)]);
        self.frame(vec![button(from, true)]);
        for k in 1..=6 {
            let p = from + (to - from) * (k as f32 / 6.0);
            self.frame(vec![egui::Event::PointerMoved(p)]);
        }
        self.frame(vec![button(to, false)]);
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
        assert!(
            c.x > 0.0 && c.y > 0.0 && c.x < SCREEN.0 && c.y < SCREEN.1,
            "\"{key}\" is off the screen, at {c:?}"
        );
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

    /// Saves the planet to `file` from the file panel, loads it back, and returns the
    /// snapshot after the load.
    fn save_and_load(&mut self, file: &std::path::Path) -> std::sync::Arc<super::worker::Snapshot> {
        self.app.file_path = file.display().to_string();
        self.frame(Vec::new());
        self.click("save");
        self.settle();
        self.click("load");
        self.settle();
        self.app.snap.clone().unwrap()
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
fn the_rivers_basins_and_thickness_overlays_render() {
    let mut h = Harness::new(plain);
    h.step(3);
    let snap = h.app.snap.clone().unwrap();
    let drawn = |h: &Harness| map::image_hash(h.app.map_image.as_ref().expect("a map is drawn"));
    let elevation = map::render_base(&snap, BaseLayer::Elevation);
    let mut hashes = std::collections::HashSet::new();
    for layer in [
        BaseLayer::Rivers,
        BaseLayer::Basins,
        BaseLayer::Thickness,
        BaseLayer::Rain,
        BaseLayer::PelagicRain,
    ] {
        h.click(&format!("overlay:{}", layer.label()));
        h.frame(Vec::new());
        assert_eq!(h.app.base, layer);
        let now = drawn(&h);
        assert_eq!(
            now,
            map::image_hash(&map::render_base(&snap, layer)),
            "the texture holds the {layer:?} map"
        );
        assert_ne!(
            now,
            map::image_hash(&elevation),
            "{layer:?} looks like the elevation map"
        );
        assert!(hashes.insert(now), "{layer:?} looks like another overlay");
    }
    h.finish();
    // Rivers: the elevation map with (bluer) rivers drawn, nothing else changed much.
    let net = snap.rivers();
    assert!(!net.reaches.is_empty(), "no river on the planet");
    let rivers = map::render_base(&snap, BaseLayer::Rivers);
    let bluer = rivers
        .pixels
        .iter()
        .zip(&elevation.pixels)
        .filter(|(r, e)| r != e)
        .inspect(|(r, e)| assert!(r.b() >= e.b() || r.r() < e.r(), "{r:?} over {e:?}"))
        .count();
    assert!(
        bluer > 100 && bluer < rivers.pixels.len() / 5,
        "{bluer} pixels show rivers or lakes"
    );
    // Along the largest river (away from lakes), the map is river-coloured.
    let big = net.reaches.iter().find(|r| r.rank == 1).expect("a river");
    let lk = &snap.lookup;
    let (w, hgt) = (lk.width as f64, lk.height as f64);
    let on_river = big.samples[..big.samples.len() - 1]
        .iter()
        .filter(|&&s| !net.is_lake(s as usize))
        .map(|&s| {
            let (lat, lon) = crate::geometry::spherical::to_lat_lon_deg(snap.positions[s as usize]);
            let x = (((lon + 180.0) / 360.0 * w) as usize).min(lk.width as usize - 1);
            let y = (((90.0 - lat) / 180.0 * hgt) as usize).min(lk.height as usize - 1);
            y * lk.width as usize + x
        })
        .collect::<Vec<_>>();
    let blue = on_river
        .iter()
        .filter(|&&i| {
            let p = rivers.pixels[i];
            p != elevation.pixels[i] && p.b() > p.r() + 60
        })
        .count();
    assert!(
        !on_river.is_empty() && blue * 10 >= on_river.len() * 8,
        "{blue} of {} points of the largest river are drawn",
        on_river.len()
    );
    // Basins: one colour per outlet, many basins on land.
    let basins = map::render_base(&snap, BaseLayer::Basins);
    let colours: std::collections::HashSet<_> = basins.pixels.iter().collect();
    assert!(colours.len() > 20, "{} basin colours", colours.len());
    // Thickness: continents (thick) and ocean floor (thin) in different colours.
    let thick = map::render_base(&snap, BaseLayer::Thickness);
    let lk = &snap.lookup;
    let (mut oc, mut co) = (None, None);
    for i in 0..lk.corners.len() {
        let d = lk.sample_of(i);
        let t = snap.crust.thickness_km[d];
        if t < 10.0 && oc.is_none() && lk.lerp(&snap.crust.thickness_km, i) < 10.0 {
            oc = Some(thick.pixels[i]);
        }
        if t > 30.0 && co.is_none() && lk.lerp(&snap.crust.thickness_km, i) > 30.0 {
            co = Some(thick.pixels[i]);
        }
    }
    assert_ne!(oc.expect("thin crust"), co.expect("thick crust"));
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

#[test]
fn save_then_load_from_the_viewer_restores_the_same_state() {
    let dir = temp_dir("save");
    let file = dir.join("viewer-test.planet");
    let mut h = Harness::new(plain);
    h.step(2);
    h.app.file_path = file.display().to_string();
    h.frame(Vec::new());
    h.click("save");
    h.settle();
    assert!(file.is_file(), "no save at {}", file.display());
    let saved = h.inspect(|sim| sim.state_hash());
    h.step(2);
    let moved_on = h.inspect(|sim| sim.state_hash());
    assert_ne!(moved_on, saved, "two more steps changed the planet");
    h.click("load");
    h.settle();
    let (loaded, step) = h.inspect(|sim| (sim.state_hash(), sim.clock().step));
    let snap = h.app.snap.clone().unwrap();
    h.finish();
    assert_eq!(
        loaded, saved,
        "the loaded planet is the saved one, bit for bit"
    );
    assert_eq!(step, 2);
    assert_eq!(snap.step, 2, "the view shows the loaded planet");
    assert!(
        snap.log.iter().any(|l| l.starts_with("loaded")),
        "{:?}",
        snap.log
    );
}

#[test]
fn load_of_a_missing_file_says_so_and_keeps_the_planet() {
    let mut h = Harness::new(plain);
    h.step(1);
    let before = h.inspect(|sim| sim.state_hash());
    h.app.file_path = "/nonexistent/dir/none.planet".into();
    h.frame(Vec::new());
    h.click("load");
    h.settle();
    let after = h.inspect(|sim| sim.state_hash());
    let snap = h.app.snap.clone().unwrap();
    h.finish();
    assert_eq!(after, before);
    let last = snap.log.last().cloned().unwrap_or_default();
    assert!(
        last.contains("load failed") && last.contains("none.planet"),
        "{last}"
    );
}

#[test]
fn export_maps_writes_pngs_of_the_planet() {
    let dir = temp_dir("maps");
    let mut h = Harness::new(plain);
    h.step(1);
    h.app.export_dir = dir.display().to_string();
    h.frame(Vec::new());
    h.click("export_maps");
    h.settle();
    h.finish();
    // At least as many colours as the map has kinds of things (crust type: ocean, land and
    // coast; plates: one each).
    for (name, least) in [
        ("elevation.png", 16),
        ("plates.png", 8),
        ("crust_age.png", 8),
        ("crust_type.png", 2),
    ] {
        let path = dir.join(name);
        assert!(path.is_file(), "{name} was not written");
        let (w, hgt, colours) = png_colours(&path);
        assert_eq!(
            (w, hgt),
            (
                super::app::EXPORT_MAP_WIDTH,
                super::app::EXPORT_MAP_WIDTH / 2
            )
        );
        assert!(
            colours >= least,
            "{name} is (nearly) blank: {colours} colours"
        );
    }
}

#[test]
fn export_view_writes_the_window_image() {
    let dir = temp_dir("view");
    let mut h = Harness::new(plain);
    h.app.export_dir = dir.display().to_string();
    h.frame(Vec::new());
    // The press and release of the button, then the frame that follows: the release frame asks
    // the window for a screenshot.
    let c = h.rect("export_view").center();
    let button = |pressed| egui::Event::PointerButton {
        pos: c,
        button: egui::PointerButton::Primary,
        pressed,
        modifiers: Default::default(),
    };
    let mut outputs = vec![
        h.frame(vec![egui::Event::PointerMoved(c)]),
        h.frame(vec![button(true)]),
        h.frame(vec![button(false)]),
    ];
    outputs.push(h.frame(vec![egui::Event::PointerGone]));
    // Here the window would render and read back its pixels; stand in with the map the view
    // shows (1280x800, the map scaled into it).
    let map = h.app.map_image.clone().expect("a map is drawn");
    let [mw, mh] = map.size;
    let (w, hgt) = (1280usize, 800usize);
    let pixels = (0..w * hgt)
        .map(|i| map.pixels[((i / w) * mh / hgt) * mw + (i % w) * mw / w])
        .collect();
    let shot = std::sync::Arc::new(egui::ColorImage::new([w, hgt], pixels));
    let mut asked = 0;
    for out in outputs {
        for (_, vp) in out.viewport_output {
            for cmd in vp.commands {
                if let egui::ViewportCommand::Screenshot(cb) = cmd {
                    asked += 1;
                    cb.complete(shot.clone());
                }
            }
        }
    }
    h.finish();
    assert_eq!(asked, 1, "the button asks for one screenshot");
    let path = dir.join("view.png");
    assert!(path.is_file(), "view.png was not written");
    let (pw, ph, colours) = png_colours(&path);
    assert_eq!((pw, ph), (1280, 800));
    assert!(
        colours >= 4,
        "view.png is (nearly) blank: {colours} colours"
    );
}

#[test]
fn dragging_the_pole_on_the_globe_sets_the_plates_motion_through_a_command() {
    let mut h = Harness::new(plain);
    h.click("view:globe");
    assert!(h.app.view3d);
    let snap = h.app.snap.clone().unwrap();
    let plate = snap
        .plates
        .iter()
        .max_by(|a, b| a.area_km2.total_cmp(&b.area_km2))
        .unwrap()
        .clone();
    // Select it and take the "pick pole" tool.
    h.app.selected = Some(plate.id);
    h.app.edit = None;
    h.frame(Vec::new());
    h.app.tool = Tool::PickPole;
    h.frame(Vec::new());
    let globe = h.rect("globe");
    let (from, to) = (
        globe.center() + egui::vec2(-30.0, 20.0),
        globe.center() + egui::vec2(40.0, -35.0),
    );
    h.drag(from, to);
    h.settle();
    // Where the pole was dropped: the point of the globe under the release position.
    let aspect = globe.width() / globe.height();
    let ndc = [
        (to.x - globe.left()) / globe.width() * 2.0 - 1.0,
        1.0 - (to.y - globe.top()) / globe.height() * 2.0,
    ];
    let hit = h
        .app
        .camera
        .pick(aspect, ndc)
        .expect("the drop is on the globe");
    let dropped = glam::DVec3::new(hit.x as f64, hit.y as f64, hit.z as f64).normalize();
    assert_eq!(h.app.tool, Tool::Select, "the drop ends the pick");
    let id = plate.id;
    let (pole, history) = h.inspect(move |sim| {
        let world = sim.world_mut();
        let pole = world
            .query::<(&Plate, &PlateMotion)>()
            .iter(world)
            .find(|(p, _)| p.id.0 == id)
            .map(|(_, m)| m.euler_pole);
        let history = sim
            .world()
            .resource::<crate::io::save::CommandHistory>()
            .entries
            .clone();
        (pole, history)
    });
    h.finish();
    let pole = pole.expect("the plate entity exists").normalize();
    assert!(
        pole.dot(dropped) > 0.99999,
        "the plate's pole {pole:?} is where it was dropped {dropped:?}"
    );
    let line = history
        .iter()
        .map(|(_, l)| l)
        .find(|l| l.contains("set_motion"))
        .unwrap_or_else(|| panic!("no set_motion in the history: {history:?}"));
    assert!(line.contains(&format!("\"plate\":{id}")), "{line}");
}

#[test]
fn an_out_of_range_parameter_typed_in_the_panel_is_refused_with_a_message() {
    let mut h = Harness::new(plain);
    h.click("params:header");
    h.frame(Vec::new());
    let before = h.inspect(|sim| sim.params().continent.erosion_mm_per_yr);
    let spec = *Params::schema()
        .iter()
        .find(|s| s.key == "continent.erosion_mm_per_yr")
        .unwrap();
    let too_big = spec.max * 10.0 + 1.0;
    h.app
        .param_text
        .insert(spec.key.into(), format!("{too_big}"));
    let sent = h.app.sim.last_sent();
    h.click("params:apply");
    h.settle();
    let message = h
        .app
        .param_errors
        .get(spec.key)
        .cloned()
        .unwrap_or_else(|| panic!("no message for the key: {:?}", h.app.param_errors));
    assert!(message.contains(spec.key), "{message}");
    assert_eq!(h.app.sim.last_sent(), sent, "nothing was sent");
    let (after, history) = h.inspect(|sim| {
        (
            sim.params().continent.erosion_mm_per_yr,
            sim.world()
                .resource::<crate::io::save::CommandHistory>()
                .entries
                .len(),
        )
    });
    h.finish();
    assert_eq!(after, before, "the planet kept its value");
    assert_eq!(history, 0, "nothing was recorded");
}

#[test]
fn a_planet_parameter_is_refused_for_the_running_planet() {
    let mut h = Harness::new(plain);
    let snap = h.app.snap.clone().unwrap();
    h.app.param_text.insert("init.plates".into(), "9".into());
    let sent = h.app.sim.last_sent();
    assert!(!h.app.apply_params(&snap, false));
    assert_eq!(h.app.sim.last_sent(), sent);
    assert!(
        h.app.param_errors["init.plates"].contains("new planet"),
        "{:?}",
        h.app.param_errors
    );
    // As a new planet it is taken.
    assert!(h.app.apply_params(&snap, true), "{:?}", h.app.param_errors);
    h.settle();
    let plates = h.inspect(|sim| sim.params().init.plates);
    h.finish();
    assert_eq!(plates, 9);
}

#[test]
fn a_parameter_change_from_the_panel_is_recorded_and_replays() {
    use crate::commands::{commands_in_history, replay};
    let mut h = Harness::new(plain);
    h.step(1);
    h.click("params:header");
    h.frame(Vec::new());
    h.app
        .param_text
        .insert("rivers.erodibility_per_my".into(), "0.75".into());
    h.click("params:apply");
    h.settle();
    assert!(h.app.param_errors.is_empty(), "{:?}", h.app.param_errors);
    h.step(2);
    let (live, history, value) = h.inspect(|sim| {
        (
            sim.state_hash(),
            sim.world()
                .resource::<crate::io::save::CommandHistory>()
                .clone(),
            sim.params().rivers.erodibility_per_my,
        )
    });
    h.finish();
    assert_eq!(value, 0.75);
    let commands = commands_in_history(&history).expect("the history parses");
    assert_eq!(commands.len(), 1, "one change: {commands:?}");
    assert_eq!(commands[0].0, 1, "applied after the first step");
    assert!(
        matches!(&commands[0].1, crate::commands::Command::SetParam { key, .. } if key == "rivers.erodibility_per_my"),
        "{commands:?}"
    );
    let mut again = replay(small_params(), &commands, 3).expect("the run replays");
    assert_eq!(again.state_hash(), live, "the replay is the same planet");
    // Without the change the planet differs, so the replay did depend on it.
    let mut without = replay(small_params(), &[], 3).unwrap();
    assert_ne!(without.state_hash(), live);
}

#[test]
fn set_param_commands_are_checked_like_parameter_files() {
    use crate::commands::{Command, SettingValue};
    let mut sim = Simulation::new(small_params()).unwrap();
    let set = |key: &str, value| Command::SetParam {
        key: key.into(),
        value,
    };
    for (cmd, why) in [
        (set("planet.samples", SettingValue::Int(5000)), "built"),
        (
            set("continent.erosion_mm_per_yr", SettingValue::Float(-1.0)),
            "erosion",
        ),
        (set("no.such_key", SettingValue::Float(1.0)), "no.such_key"),
        (
            set("continent.erosion_mm_per_yr", SettingValue::Bool(true)),
            "erosion",
        ),
    ] {
        let e = sim.apply(&cmd).expect_err(&format!("{cmd:?} is refused"));
        assert!(e.to_string().contains(why), "{cmd:?}: {e}");
    }
    assert!(
        sim.world()
            .resource::<crate::io::save::CommandHistory>()
            .entries
            .is_empty()
    );
    // JSON round trip of what the history records.
    let ok = set("continent.erosion_mm_per_yr", SettingValue::Int(1));
    sim.apply(&ok).unwrap();
    assert_eq!(sim.params().continent.erosion_mm_per_yr, 1.0);
    let back: Command = serde_json::from_str(&ok.to_json()).unwrap();
    assert_eq!(back, ok);
}

fn counter_plugins() -> bevy_app::PluginGroupBuilder {
    TectonicPlugins.build().add(CounterPlugin)
}

#[test]
fn new_and_loaded_planets_keep_the_viewers_plugins() {
    let dir = temp_dir("plugins");
    let file = dir.join("with-counter.planet");
    let handle = SimHandle::spawn_with_plugins(std::sync::Arc::new(counter_plugins), || {
        Simulation::with_plugins(small_params(), counter_plugins()).map_err(|e| e.to_string())
    });
    handle.wait_ready(WAIT).unwrap();
    let mut h = Harness {
        ctx: egui::Context::default(),
        app: ViewerApp::new(handle),
        time: 0.0,
    };
    h.frame(Vec::new());
    let has_counter = |h: &Harness| {
        h.app
            .snap
            .as_ref()
            .unwrap()
            .phenomena
            .iter()
            .any(|p| p.name == "counter")
    };
    assert!(has_counter(&h));
    // New planet from the parameters panel.
    let snap = h.app.snap.clone().unwrap();
    h.app.param_text.insert("planet.seed".into(), "77".into());
    assert!(h.app.apply_params(&snap, true), "{:?}", h.app.param_errors);
    h.settle();
    assert_eq!(h.app.snap.as_ref().unwrap().params.planet.seed, 77);
    assert!(has_counter(&h), "the new planet has the third-party plugin");
    h.step(1);
    assert_eq!(h.inspect(|sim| sim.world().resource::<Runs>().0), 1);
    // Save and load it back.
    let snap = h.save_and_load(&file);
    assert!(
        snap.log.iter().any(|l| l.starts_with("loaded")),
        "{:?}",
        snap.log
    );
    assert!(
        has_counter(&h),
        "the loaded planet has the third-party plugin"
    );
    h.step(1);
    let runs = h.inspect(|sim| sim.world().get_resource::<Runs>().map(|r| r.0));
    h.finish();
    assert!(
        runs.is_some(),
        "the plugin's resource exists after the load"
    );
}

#[test]
fn a_triangle_rasterized_into_the_map_covers_the_pixels_inside_it() {
    let (w, h) = (16usize, 16usize);
    let mut pixels = vec![egui::Color32::WHITE; w * h];
    let mut mesh = egui::Mesh::default();
    let red = egui::Color32::RED;
    // Inside the image, away from its borders; wound clockwise on the screen (y down): the
    // fill must not depend on the winding.
    // No edge along an axis, so that every edge decides some pixels of the bounding box.
    let corners = [(1.0f32, 7.0f32), (14.0, 1.0), (9.0, 14.0)];
    for (x, y) in corners {
        mesh.colored_vertex(egui::pos2(x, y), red);
    }
    mesh.add_triangle(0, 2, 1);
    map::rasterize_mesh(&mesh, w, h, &mut pixels);
    // Left of each directed edge (clockwise corners, y down): the inside.
    let side = |(ax, ay): (f32, f32), (bx, by): (f32, f32), (px, py): (f32, f32)| {
        (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    };
    let mut filled = 0;
    for y in 0..h {
        for x in 0..w {
            let c = (x as f32 + 0.5, y as f32 + 0.5);
            let inside = (0..3).all(|k| side(corners[k], corners[(k + 1) % 3], c) >= 0.0);
            assert_eq!(pixels[y * w + x] == red, inside, "pixel ({x}, {y})");
            filled += usize::from(inside);
        }
    }
    assert!(filled > 40, "{filled}");
}

#[test]
fn velocity_arrows_drawn_into_the_map_texture_change_it_in_their_colour_only() {
    let h = Harness::new(plain);
    let snap = h.app.snap.clone().unwrap();
    h.finish();
    let base = map::render_base(&snap, BaseLayer::Plates);
    let [w, hgt] = base.size;
    let rect = egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(w as f32, hgt as f32));
    let layers = map::VectorLayers {
        velocity: true,
        ..Default::default()
    };
    let mesh = map::vector_mesh(rect, &snap, layers, w as f32 / 690.0);
    assert!(!mesh.is_empty());
    let mut with = base.pixels.clone();
    map::rasterize_mesh(&mesh, w, hgt, &mut with);
    let changed: Vec<_> = with
        .iter()
        .zip(&base.pixels)
        .filter(|(a, b)| a != b)
        .map(|(a, _)| *a)
        .collect();
    assert!(
        changed.len() > 1000,
        "only {} pixels show arrows",
        changed.len()
    );
    assert!(
        changed
            .iter()
            .all(|c| *c == egui::Color32::from_rgb(15, 15, 15)),
        "arrows are drawn in their colour"
    );
}

#[test]
fn a_new_or_loaded_planet_stays_on_the_gpu_backend() {
    // Needs a wgpu adapter (lavapipe in CI); without one there is nothing to keep.
    let mut probe = Simulation::new(small_params()).unwrap();
    if probe.set_backend(crate::gpu::BackendChoice::Gpu).is_err() {
        eprintln!("no wgpu adapter: skipped");
        return;
    }
    drop(probe);
    let dir = temp_dir("backend");
    let file = dir.join("gpu.planet");
    let mut h = Harness::new(|| {
        let mut sim = Simulation::new(small_params()).map_err(|e| e.to_string())?;
        sim.set_backend(crate::gpu::BackendChoice::Gpu)
            .map_err(|e| e.to_string())?;
        Ok(sim)
    });
    let on = |h: &Harness| h.app.snap.as_ref().unwrap().backend;
    assert_eq!(on(&h), crate::gpu::ComputeBackend::Gpu);
    h.step(1);
    // New planet from the parameters panel.
    let snap = h.app.snap.clone().unwrap();
    h.app.param_text.insert("planet.seed".into(), "78".into());
    assert!(h.app.apply_params(&snap, true), "{:?}", h.app.param_errors);
    h.settle();
    assert_eq!(h.app.snap.as_ref().unwrap().params.planet.seed, 78);
    assert_eq!(on(&h), crate::gpu::ComputeBackend::Gpu, "new planet");
    h.step(1);
    // Saved and loaded back.
    let snap = h.save_and_load(&file);
    assert!(
        snap.log
            .iter()
            .any(|l| l.starts_with("loaded") && l.contains("(GPU)")),
        "{:?}",
        snap.log
    );
    assert_eq!(on(&h), crate::gpu::ComputeBackend::Gpu, "loaded planet");
    h.finish();
}

/// The Pelagic rain layer draws the field the run's rain uses: heavier rain darker over the
/// sea, the land grey; the mean's colour over the whole sea once the rain is made the same
/// everywhere (`set_param`), and a dark sea once the sediment that lays it is switched off.
#[test]
fn the_pelagic_rain_layer_shows_the_rain_the_run_uses() {
    use crate::commands::{Command, SettingValue};
    let mut h = Harness::new(|| {
        let mut p = small_params();
        p.sediment.pelagic_variability = 1.0;
        Simulation::new(p).map_err(|e| e.to_string())
    });
    h.step(2);
    let snap = h.app.snap.clone().unwrap();
    let used = h.inspect(|sim| sim.pelagic_rate().unwrap().to_vec());
    assert_eq!(used.len(), snap.positions.len(), "the rain varies");
    let rate = snap.pelagic_rate.clone().expect("the sediment is on");
    assert_eq!(*rate, used, "the snapshot holds the run's field");
    let lk = &snap.lookup;
    let sea: Vec<usize> = (0..lk.corners.len())
        .filter(|&i| lk.lerp(&snap.crust.elevation_km, i) <= 0.0)
        .collect();
    assert!(sea.len() > lk.corners.len() / 4, "{} sea pixels", sea.len());
    let img = map::render_base(&snap, BaseLayer::PelagicRain);
    let [gr, gg, gb] = crate::io::maps::PELAGIC_LAND;
    let grey = egui::Color32::from_rgb(gr, gg, gb);
    for i in 0..lk.corners.len() {
        if lk.lerp(&snap.crust.elevation_km, i) > 0.0 {
            assert_eq!(img.pixels[i], grey, "land pixel {i}");
        }
    }
    // Over the sea, the quarter with the heaviest rain is darker than the quarter with the
    // lightest.
    let mut by_rain: Vec<(f32, usize)> = sea.iter().map(|&i| (lk.lerp(&rate, i), i)).collect();
    by_rain.sort_by(|a, b| a.0.total_cmp(&b.0));
    let q = by_rain.len() / 4;
    let red = |part: &[(f32, usize)]| {
        part.iter()
            .map(|&(_, i)| img.pixels[i].r() as f64)
            .sum::<f64>()
            / part.len() as f64
    };
    let (light, heavy) = (red(&by_rain[..q]), red(&by_rain[by_rain.len() - q..]));
    assert!(
        by_rain[by_rain.len() - q].0 > 1.5 * by_rain[q].0,
        "the rain spreads: {} .. {}",
        by_rain[q].0,
        by_rain[by_rain.len() - q].0
    );
    assert!(
        heavy + 60.0 < light,
        "heavy rain {heavy}, light rain {light}"
    );
    // The same rain everywhere: the mean's colour over all the sea.
    h.app.sim.send(Request::Apply(Command::SetParam {
        key: "sediment.pelagic_variability".into(),
        value: SettingValue::Float(0.0),
    }));
    h.step(1);
    let snap = h.app.snap.clone().unwrap();
    assert!(snap.pelagic_rate.as_ref().is_some_and(|r| r.is_empty()));
    let img = map::render_base(&snap, BaseLayer::PelagicRain);
    let [mr, mg, mb] = crate::io::maps::pelagic_colour(1.0);
    let mean = egui::Color32::from_rgb(mr, mg, mb);
    // Share of the sea pixels of `snap`'s map `img` in colour `c`.
    let sea_in = |snap: &super::worker::Snapshot, img: &egui::ColorImage, c: egui::Color32| {
        let lk = &snap.lookup;
        let sea: Vec<usize> = (0..lk.corners.len())
            .filter(|&i| lk.lerp(&snap.crust.elevation_km, i) <= 0.0)
            .collect();
        sea.iter().filter(|&&i| img.pixels[i] == c).count() as f64 / sea.len() as f64
    };
    assert_eq!(sea_in(&snap, &img, mean), 1.0, "uniform rain");
    // No sediment: no rain settles.
    h.click("phenomenon:sediment");
    h.settle();
    h.step(1);
    let snap = h.app.snap.clone().unwrap();
    assert!(snap.pelagic_rate.is_none());
    let img = map::render_base(&snap, BaseLayer::PelagicRain);
    assert_eq!(sea_in(&snap, &img, mean), 0.0, "the sediment is off");
    h.finish();
}

/// The Rain layer shows the climate's rain while the climate is on, and the mean's colour over
/// all the land once it is switched off in the schedule panel (the drainage then has uniform
/// rain, and so do the layers drawn from it).
#[test]
fn the_rain_layer_follows_the_climate_switch() {
    let mut h = Harness::new(plain);
    h.step(2);
    let snap = h.app.snap.clone().unwrap();
    assert_eq!(
        snap.rivers().rain.len(),
        snap.positions.len(),
        "climate on: rain"
    );
    // Share of the land pixels in the mean's colour.
    let mean_share = |snap: &super::worker::Snapshot| {
        let img = map::render_base(snap, BaseLayer::Rain);
        let lk = &snap.lookup;
        let [r, g, b] = crate::io::rivers::rain_colour(1.0);
        let mean = egui::Color32::from_rgb(r, g, b);
        let land: Vec<usize> = (0..lk.corners.len())
            .filter(|&i| lk.lerp(&snap.crust.elevation_km, i) > 0.0)
            .collect();
        land.iter().filter(|&&i| img.pixels[i] == mean).count() as f64 / land.len() as f64
    };
    let on = mean_share(&snap);
    assert!(on < 0.2, "the climate's rain varies over the land ({on})");
    h.click("phenomenon:climate");
    h.settle();
    h.step(1);
    let snap = h.app.snap.clone().unwrap();
    assert!(
        snap.phenomena
            .iter()
            .any(|p| p.name == "climate" && !p.enabled)
    );
    assert!(snap.rivers().rain.is_empty(), "climate off: uniform rain");
    // Land pixels: the mean's colour, but where a river is drawn over it.
    let off = mean_share(&snap);
    assert!(off > 0.8, "uniform rain: the mean's colour ({off})");
    h.finish();
}
