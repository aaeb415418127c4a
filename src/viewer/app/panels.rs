//! The viewer's side panels: the plate inspector and its authoring tools (motion, crust type,
//! rift), and the parameter editor (checked before it is applied, through `set_param`).

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use eframe::egui;
use egui::Color32;

use crate::commands::{Command, CrustKind, LatLon, PlateRef};
use crate::resources::params::{ParamKind, ParamValue, Params};

use crate::viewer::worker::{Request, Snapshot};

use super::*;

pub(super) fn motion_edit(p: &crate::viewer::worker::PlateRow) -> MotionEdit {
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

pub(super) fn param_texts(s: &Snapshot) -> BTreeMap<String, String> {
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

pub(super) fn bounds(spec: &crate::resources::params::ParamSpec) -> (ParamValue, ParamValue) {
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

pub(super) fn set_error(slot: &Arc<Mutex<Option<String>>>, e: String) {
    if let Ok(mut s) = slot.lock()
        && s.is_none()
    {
        *s = Some(e);
    }
}

impl ViewerApp {
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

    pub(super) fn rift_ui(&mut self, ui: &mut egui::Ui) {
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
}
