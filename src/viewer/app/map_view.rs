//! The map and the globe of the viewer: the painter thread that colours each snapshot, the map
//! and globe widgets with their pointer handling (picking a plate, a pole, a fracture line).

use std::sync::Arc;

use eframe::egui;
use egui::{Color32, ColorImage, Rect, Sense, Stroke, TextureOptions, Vec2};

use crate::commands::{Command, LatLon, PlateRef};

use crate::viewer::map::{self, BaseLayer, VectorLayers};
use crate::viewer::worker::{Request, Snapshot};

use super::*;

/// Width of the map on the screen the vector glyphs are laid out for, pixels (their spacing
/// and line widths scale from it to the texture).
pub(super) const GLYPH_LAYOUT_WIDTH: f32 = 690.0;

/// A map to colour: a snapshot and a base layer (and, for the wgpu renderer, the elevation
/// grid and the vector layers drawn into the texture).
pub(super) struct PaintJob {
    key: MapKey,
    snap: Arc<Snapshot>,
    layer: BaseLayer,
    elevation: bool,
}

/// A coloured map.
pub(super) struct Painted {
    key: MapKey,
    image: Arc<ColorImage>,
    globe: Option<Arc<crate::viewer::globe::GlobeData>>,
}

pub(super) fn paint_job(job: PaintJob) -> Painted {
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
            Arc::new(crate::viewer::globe::GlobeData::new(&image, elevation_km))
        } else {
            let mut with = (*image).clone();
            let [w, h] = with.size;
            let rect = Rect::from_min_size(egui::Pos2::ZERO, Vec2::new(w as f32, h as f32));
            let mesh = map::vector_mesh(rect, s, layers, w as f32 / GLYPH_LAYOUT_WIDTH);
            map::rasterize_mesh(&mesh, w, h, &mut with.pixels);
            Arc::new(crate::viewer::globe::GlobeData::new(&with, elevation_km))
        }
    });
    Painted {
        key: job.key,
        image,
        globe,
    }
}

/// The map painter thread's ends.
pub(super) struct MapPainter {
    tx: std::sync::mpsc::Sender<PaintJob>,
    rx: std::sync::mpsc::Receiver<Painted>,
    busy: bool,
}

impl ViewerApp {
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

    pub(super) fn install_map(
        &mut self,
        ctx: &egui::Context,
        key: MapKey,
        img: Arc<ColorImage>,
        globe: Option<Arc<crate::viewer::globe::GlobeData>>,
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

    pub(super) fn map_ui(&mut self, ui: &mut egui::Ui) {
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
            painter.add(crate::viewer::globe::map_callback(
                rect,
                crate::viewer::globe::MapCallback {
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
    pub(super) fn globe_ui(&mut self, ui: &mut egui::Ui) {
        self.refresh_map(ui.ctx());
        let Some(s) = self.snap.clone() else { return };
        let avail = ui.available_size().max(Vec2::splat(64.0));
        let (rect, resp) = ui.allocate_exact_size(avail, Sense::click_and_drag());
        self.track("globe", &resp);
        let aspect = rect.width() / rect.height().max(1.0);
        let to_point = |cam: &crate::viewer::globe::Camera, pos: egui::Pos2| {
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
        let uniforms = crate::viewer::globe::GlobeUniforms {
            view_proj: self.camera.view_proj(aspect).to_cols_array_2d(),
            light_dir: [light.x, light.y, light.z, 0.0],
            params: [
                self.exaggeration / s.radius_km as f32,
                if self.sea_surface { 1.0 } else { 0.0 },
                0.0,
                0.0,
            ],
        };
        ui.painter().add(crate::viewer::globe::paint_callback(
            rect,
            crate::viewer::globe::GlobeCallback {
                uniforms,
                generation: self.map_generation,
                data,
            },
        ));
    }

    pub(super) fn plate_under(&self, s: &Snapshot, ll: LatLon) -> Option<u32> {
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
}
