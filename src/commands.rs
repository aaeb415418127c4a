//! Authoring commands (paper §7.1, Fig. 15–17): what a user does to a planet between steps, as
//! data. Rust code, the CLI's scripts and the viewer all go through [`Simulation::apply`], which
//! checks a command, carries it out and records it in the run's [`CommandHistory`], so any run
//! can be replayed ([`replay`]) to the same bits.
//!
//! Plates are named by id or by a point they cover ([`PlateRef`]), so scripts stay meaningful
//! across seeds and resolutions. Scripts ([`Script`]) are TOML files of timed events:
//!
//! ```toml
//! [[event]]
//! at_my = 36.0
//! note = "the island's plate turns toward the continent"
//! command = "set_motion"
//! plate = { lat = 5.0, lon = 40.0 }
//! pole = { lat = 80.0, lon = 20.0 }
//! speed_mm_per_yr = 80.0
//! ```

use std::path::Path;

use bevy_ecs::prelude::*;
use glam::DVec3;
use serde::{Deserialize, Serialize};

use crate::components::{Plate, PlateFrame, PlateMesh, PlateMotion};
use crate::geometry::SphereMesh;
use crate::geometry::spherical::{angle_between, from_lat_lon_deg};
use crate::random::{hash3, stream};
use crate::resources::CommandHistory;
use crate::resources::params::{ParamValue, Params};
use crate::resources::{Crust, CrustType, Orogeny, ResampleRequest};
use crate::simulation::{SimError, Simulation};
use crate::systems::rifting::{self, Fracture, RiftCause};

/// Prefix of the history lines that hold an applied command (as JSON).
pub const HISTORY_PREFIX: &str = "apply ";

/// A point on the planet, degrees.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatLon {
    /// Latitude, degrees north, in [−90, 90].
    pub lat: f64,
    /// Longitude, degrees east.
    pub lon: f64,
}

impl LatLon {
    /// The unit vector of this point (world frame).
    pub fn to_unit(self) -> DVec3 {
        from_lat_lon_deg(self.lat, self.lon)
    }
    fn check(self, what: &str) -> Result<(), SimError> {
        if !self.lat.is_finite() || !self.lon.is_finite() || self.lat.abs() > 90.0 {
            return Err(bad(format!(
                "{what}: latitude must be within [-90, 90] and longitude finite, got ({}, {})",
                self.lat, self.lon
            )));
        }
        Ok(())
    }
}

/// A plate, by id or by a point it covers (world frame, now).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PlateRef {
    /// The plate with this id.
    Id(u32),
    /// The plate that covers this point (the one on top where plates overlap; the nearest
    /// plate in a gap).
    At(LatLon),
}

/// A spherical cap: every point within `radius_km` (great-circle) of the centre.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cap {
    /// Latitude of the centre, degrees.
    pub lat: f64,
    /// Longitude of the centre, degrees.
    pub lon: f64,
    /// Radius, km (great-circle distance on the planet's surface).
    pub radius_km: f64,
}

/// Crust type named in commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CrustKind {
    /// Oceanic crust.
    Oceanic,
    /// Continental crust.
    Continental,
}

/// One authoring command. In TOML and JSON the variant is named by a `command` key
/// (`command = "set_motion"`) next to its fields.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Sets a plate's Euler pole and speed (the speed of a point 90° from the pole).
    SetMotion {
        /// The plate.
        plate: PlateRef,
        /// The Euler pole; the plate turns counter-clockwise about it seen from above.
        pole: LatLon,
        /// Surface speed at 90° from the pole, mm/yr (= km/My), 0 to 1000.
        speed_mm_per_yr: f64,
    },
    /// Switches the crust of a whole plate, or of a spherical cap, to one type. Continental
    /// crust made from ocean rises to at least `init.continental_elevation_km` and thickens to
    /// `init.continental_thickness_km`; oceanic crust made from continent sinks to at most
    /// `init.oceanic_elevation_km` and thins to `init.oceanic_thickness_km`.
    SetCrustType {
        /// The plate (give this or `cap`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        plate: Option<PlateRef>,
        /// The cap (give this or `plate`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        cap: Option<Cap>,
        /// The new type.
        crust: CrustKind,
    },
    /// Rifts a plate along a line (great-circle arcs through the points): the two sides become
    /// two plates that move apart.
    RiftLine {
        /// The fracture line, at least two points.
        line: Vec<LatLon>,
        /// The plate to split; by default the plate under the line's middle point.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        plate: Option<PlateRef>,
    },
    /// Rifts a plate into `fragments` pieces along warped Voronoi borders, as random rifts do.
    RiftAt {
        /// The plate.
        plate: PlateRef,
        /// Number of fragments, 2 to 4.
        fragments: u32,
    },
    /// Raises (or lowers, when negative) the elevation in a cap, most at its centre and
    /// smoothly less toward its rim (a raised-cosine profile).
    Uplift {
        /// Where.
        cap: Cap,
        /// Change at the centre, km, within ±20.
        delta_km: f64,
    },
    /// Switches a phenomenon (plugin) on or off.
    SetPhenomenon {
        /// Its name (see `planet plugins`).
        name: String,
        /// On or off.
        enabled: bool,
    },
    /// Sets one parameter of the running planet, checked as in a parameter file: a core key
    /// such as `continent.erosion_mm_per_yr`, or a plugin key `plugins.…` (see `planet
    /// params`). `[planet]` and `[init]` keys only mean something when a planet is built and
    /// are refused.
    SetParam {
        /// The parameter's key.
        key: String,
        /// Its new value.
        value: SettingValue,
    },
}

/// A parameter value in a command (a number or a flag; integers are accepted for real
/// parameters, as in parameter files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum SettingValue {
    /// A flag.
    Bool(bool),
    /// A non-negative integer.
    Int(u64),
    /// A real number.
    Float(f64),
}

impl From<SettingValue> for ParamValue {
    fn from(v: SettingValue) -> Self {
        match v {
            SettingValue::Bool(b) => ParamValue::Bool(b),
            SettingValue::Int(n) => ParamValue::Int(n),
            SettingValue::Float(x) => ParamValue::Float(x),
        }
    }
}

impl From<ParamValue> for SettingValue {
    fn from(v: ParamValue) -> Self {
        match v {
            ParamValue::Bool(b) => SettingValue::Bool(b),
            ParamValue::Int(n) => SettingValue::Int(n),
            ParamValue::Float(x) => SettingValue::Float(x),
        }
    }
}

/// What a command did, for reports.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// A plate's motion was set.
    Motion {
        /// Which plate.
        plate: u32,
    },
    /// Samples changed crust type.
    CrustType {
        /// How many samples changed.
        samples: usize,
    },
    /// A plate broke.
    Rift {
        /// The fragments, the parent's id first.
        fragments: Vec<u32>,
    },
    /// Samples were raised or lowered.
    Uplift {
        /// How many samples changed.
        samples: usize,
    },
    /// A phenomenon was switched.
    Phenomenon,
    /// A parameter was set.
    Param {
        /// Its key.
        key: String,
    },
}

fn bad(msg: String) -> SimError {
    SimError::BadArgument(msg)
}

fn check_cap(cap: &Cap, radius_km: f64) -> Result<(), SimError> {
    LatLon {
        lat: cap.lat,
        lon: cap.lon,
    }
    .check("cap centre")?;
    let max = std::f64::consts::PI * radius_km;
    if !cap.radius_km.is_finite() || cap.radius_km <= 0.0 || cap.radius_km > max {
        return Err(bad(format!(
            "cap radius must be within (0, {max:.0}] km, got {}",
            cap.radius_km
        )));
    }
    Ok(())
}

impl Command {
    /// Checks the command's own values (ranges, counts) without looking at the planet.
    pub fn validate(&self, params: &Params) -> Result<(), SimError> {
        let r = params.planet.radius_km;
        match self {
            Command::SetMotion {
                pole,
                speed_mm_per_yr,
                plate,
            } => {
                pole.check("pole")?;
                if let PlateRef::At(p) = plate {
                    p.check("plate")?;
                }
                if !speed_mm_per_yr.is_finite() || !(0.0..=1000.0).contains(speed_mm_per_yr) {
                    return Err(bad(format!(
                        "speed_mm_per_yr must be within [0, 1000], got {speed_mm_per_yr}"
                    )));
                }
            }
            Command::SetCrustType { plate, cap, .. } => match (plate, cap) {
                (Some(_), Some(_)) | (None, None) => {
                    return Err(bad(
                        "set_crust_type needs exactly one of `plate` and `cap`".into()
                    ));
                }
                (Some(PlateRef::At(p)), None) => p.check("plate")?,
                (None, Some(c)) => check_cap(c, r)?,
                _ => {}
            },
            Command::RiftLine { line, plate } => {
                if line.len() < 2 {
                    return Err(bad(format!(
                        "rift_line needs at least 2 points, got {}",
                        line.len()
                    )));
                }
                for p in line {
                    p.check("line point")?;
                }
                if let Some(PlateRef::At(p)) = plate {
                    p.check("plate")?;
                }
            }
            Command::RiftAt { plate, fragments } => {
                if let PlateRef::At(p) = plate {
                    p.check("plate")?;
                }
                if !(2..=4).contains(fragments) {
                    return Err(bad(format!(
                        "rift_at makes 2 to 4 fragments, got {fragments}"
                    )));
                }
            }
            Command::Uplift { cap, delta_km } => {
                check_cap(cap, r)?;
                if !delta_km.is_finite() || delta_km.abs() > 20.0 {
                    return Err(bad(format!(
                        "uplift delta_km must be within [-20, 20], got {delta_km}"
                    )));
                }
            }
            Command::SetPhenomenon { .. } => {}
            Command::SetParam { key, value } => {
                if key.starts_with("planet.") || key.starts_with("init.") {
                    return Err(bad(format!(
                        "set_param: {key} only applies when a planet is built (start a new planet)"
                    )));
                }
                // Plugin keys are checked against the planet's plugins when applied.
                if !key.starts_with("plugins.") {
                    let mut p = params.clone();
                    p.set(key, (*value).into())
                        .and_then(|()| p.validate())
                        .map_err(|e| bad(format!("set_param: {e}")))?;
                }
            }
        }
        Ok(())
    }

    /// The command's name as scripts write it (`set_motion`, `rift_at`, ...).
    pub fn name(&self) -> &'static str {
        match self {
            Command::SetMotion { .. } => "set_motion",
            Command::SetCrustType { .. } => "set_crust_type",
            Command::RiftLine { .. } => "rift_line",
            Command::RiftAt { .. } => "rift_at",
            Command::Uplift { .. } => "uplift",
            Command::SetPhenomenon { .. } => "set_phenomenon",
            Command::SetParam { .. } => "set_param",
        }
    }

    /// The command as one line of JSON (what the history records).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Every plate's rotation from its frame to the world, indexed by plate id.
fn frames_by_plate(world: &mut World) -> Vec<Option<glam::DMat3>> {
    let mut out: Vec<Option<glam::DMat3>> = Vec::new();
    for (p, f) in world.query::<(&Plate, &PlateFrame)>().iter(world) {
        let id = p.id.0 as usize;
        if out.len() <= id {
            out.resize(id + 1, None);
        }
        out[id] = Some(f.world_from_plate_mat());
    }
    out
}

/// The plate covering the world point `q` now: the highest-ranked plate whose triangle under `q`
/// (in that plate's frame) has its dominant corner on the plate; in a gap, the plate of the
/// nearest sample.
pub fn plate_at(sim: &mut Simulation, q: DVec3) -> Option<u32> {
    let table = sim.plate_table();
    let world = sim.world();
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    for &slot in &table.by_rank {
        let p = &table.plates[slot as usize];
        let local = p.plate_from_world * q;
        let loc = mesh.locate(local);
        let tri = mesh.triangles[loc.triangle as usize];
        let s = tri[loc.dominant_corner()] as usize;
        if crust.plate[s] == p.id {
            return Some(p.id);
        }
    }
    // In a gap: the nearest sample's plate.
    let mut best = (f64::INFINITY, None);
    for (s, &id) in crust.plate.iter().enumerate() {
        let Some(p) = table.get(id) else { continue };
        let d = angle_between(p.world_from_plate * mesh.positions[s], q);
        if d < best.0 {
            best = (d, Some(id));
        }
    }
    best.1
}

fn resolve(sim: &mut Simulation, plate: &PlateRef) -> Result<u32, SimError> {
    match plate {
        PlateRef::Id(id) => {
            if sim.plate_table().get(*id).is_some() {
                Ok(*id)
            } else {
                Err(bad(format!("no plate with id {id}")))
            }
        }
        PlateRef::At(p) => plate_at(sim, p.to_unit())
            .ok_or_else(|| bad(format!("no plate at ({}, {})", p.lat, p.lon))),
    }
}

/// Samples whose current world position lies within `cap` (with their distance to its centre,
/// radians).
fn samples_in_cap(world: &mut World, cap: &Cap) -> Vec<(usize, f64)> {
    let frames = frames_by_plate(world);
    let r = world.resource::<Params>().planet.radius_km;
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let c = from_lat_lon_deg(cap.lat, cap.lon);
    let max = cap.radius_km / r;
    let cos_max = max.min(std::f64::consts::PI).cos();
    let mut out = Vec::new();
    for (s, &p) in crust.plate.iter().enumerate() {
        let Some(Some(f)) = frames.get(p as usize) else {
            continue;
        };
        let w = *f * mesh.positions[s];
        if w.dot(c) >= cos_max {
            out.push((s, angle_between(w, c)));
        }
    }
    out
}

fn set_crust_type(world: &mut World, samples: &[usize], kind: CrustKind) -> usize {
    let init = world.resource::<Params>().init.clone();
    let mut crust = world.resource_mut::<Crust>();
    let mut changed = 0;
    for &s in samples {
        match kind {
            CrustKind::Continental => {
                if crust.crust_type[s] == CrustType::Continental {
                    continue;
                }
                crust.crust_type[s] = CrustType::Continental;
                crust.elevation_km[s] =
                    crust.elevation_km[s].max(init.continental_elevation_km as f32);
                crust.thickness_km[s] =
                    crust.thickness_km[s].max(init.continental_thickness_km as f32);
                crust.orogeny[s] = Orogeny::None;
                crust.orogeny_age_my[s] = 0.0;
            }
            CrustKind::Oceanic => {
                if crust.crust_type[s] == CrustType::Oceanic {
                    continue;
                }
                crust.crust_type[s] = CrustType::Oceanic;
                crust.elevation_km[s] = crust.elevation_km[s].min(init.oceanic_elevation_km as f32);
                crust.thickness_km[s] = init.oceanic_thickness_km as f32;
                crust.orogeny[s] = Orogeny::None;
                crust.orogeny_age_my[s] = 0.0;
                crust.fold_dir[s] = [0.0; 3];
            }
        }
        changed += 1;
    }
    changed
}

/// Refreshes the plates' continental areas after crust types changed (overlap order, rifting
/// rates and collisions read them).
fn refresh_all_plate_geometry(world: &mut World) {
    let ids: Vec<u32> = world
        .query::<&Plate>()
        .iter(world)
        .map(|p| p.id.0)
        .collect();
    rifting::refresh_plate_geometry(world, &ids);
}

impl Simulation {
    /// Checks and carries out `cmd` now (between steps), and records it in the history.
    /// Plate references by place are resolved against the planet as it is now.
    pub fn apply(&mut self, cmd: &Command) -> Result<Outcome, SimError> {
        cmd.validate(self.params())?;
        let outcome = match cmd {
            Command::SetMotion {
                plate,
                pole,
                speed_mm_per_yr,
            } => {
                let id = resolve(self, plate)?;
                let motion = PlateMotion {
                    euler_pole: pole.to_unit(),
                    angular_speed_rad_per_my: speed_mm_per_yr / self.params().planet.radius_km,
                };
                self.set_plate_motion(id, motion)?;
                Outcome::Motion { plate: id }
            }
            Command::SetCrustType { plate, cap, crust } => {
                let samples: Vec<usize> = match (plate, cap) {
                    (Some(p), _) => {
                        let id = resolve(self, p)?;
                        let world = self.world_mut();
                        world
                            .query::<(&Plate, &PlateMesh)>()
                            .iter(world)
                            .find(|(p, _)| p.id.0 == id)
                            .map(|(_, m)| m.samples.iter().map(|&s| s as usize).collect())
                            .unwrap_or_default()
                    }
                    (None, Some(c)) => samples_in_cap(self.world_mut(), c)
                        .into_iter()
                        .map(|(s, _)| s)
                        .collect(),
                    (None, None) => Vec::new(),
                };
                let changed = set_crust_type(self.world_mut(), &samples, *crust);
                refresh_all_plate_geometry(self.world_mut());
                // Terranes and fronts depend on crust types: rebuild them at the next step.
                self.world_mut().resource_mut::<ResampleRequest>().0 = true;
                Outcome::CrustType { samples: changed }
            }
            Command::RiftLine { line, plate } => {
                let mid = line[line.len() / 2];
                let id = match plate {
                    Some(p) => resolve(self, p)?,
                    None => resolve(self, &PlateRef::At(mid))?,
                };
                let frame = self
                    .plate_table()
                    .get(id)
                    .map(|p| p.plate_from_world)
                    .ok_or_else(|| bad(format!("no plate with id {id}")))?;
                let points: Vec<DVec3> = line.iter().map(|p| frame * p.to_unit()).collect();
                if points.windows(2).any(|w| w[0].cross(w[1]).length() < 1e-9) {
                    return Err(bad(
                        "rift_line: two consecutive points are equal or antipodal".into(),
                    ));
                }
                let seed = self.jitter_seed(id);
                let fragments = rifting::rift_plate(
                    self.world_mut(),
                    id,
                    &Fracture::Line(points),
                    seed,
                    RiftCause::Command,
                )
                .map_err(|e| bad(e.to_string()))?;
                Outcome::Rift { fragments }
            }
            Command::RiftAt { plate, fragments } => {
                let id = resolve(self, plate)?;
                let seed = self.jitter_seed(id);
                let fragments = rifting::random_rift(
                    self.world_mut(),
                    id,
                    Some(*fragments as usize),
                    seed,
                    RiftCause::Command,
                )
                .map_err(|e| bad(e.to_string()))?;
                Outcome::Rift { fragments }
            }
            Command::Uplift { cap, delta_km } => {
                let r = self.params().planet.radius_km;
                let samples = samples_in_cap(self.world_mut(), cap);
                let max = cap.radius_km / r;
                let mut crust = self.world_mut().resource_mut::<Crust>();
                for &(s, d) in &samples {
                    let w = 0.5 * (1.0 + (std::f64::consts::PI * (d / max).min(1.0)).cos());
                    crust.elevation_km[s] += (delta_km * w) as f32;
                }
                Outcome::Uplift {
                    samples: samples.len(),
                }
            }
            Command::SetPhenomenon { name, enabled } => {
                self.set_enabled(name, *enabled)?;
                Outcome::Phenomenon
            }
            Command::SetParam { key, value } => {
                let value = ParamValue::from(*value);
                if key.starts_with("plugins.") {
                    self.plugin_params_mut()
                        .set(key, value)
                        .map_err(|e| bad(format!("set_param: {e}")))?;
                } else {
                    // Checked by `validate` above.
                    let mut p = self.params().clone();
                    p.set(key, value)
                        .and_then(|()| p.validate())
                        .map_err(|e| bad(format!("set_param: {e}")))?;
                    *self.world_mut().resource_mut::<Params>() = p;
                }
                Outcome::Param { key: key.clone() }
            }
        };
        let step = self.clock().step;
        self.world_mut()
            .resource_mut::<CommandHistory>()
            .record(step, format!("{HISTORY_PREFIX}{}", cmd.to_json()));
        Ok(outcome)
    }

    /// Seed of a command's random draws: the planet's seed, the step and the plate.
    fn jitter_seed(&self, plate: u32) -> u64 {
        let step = self.clock().step;
        hash3(
            self.params().planet.seed,
            stream::RIFT_COMMAND,
            step.wrapping_mul(1 << 20) ^ plate as u64,
        )
    }
}

/// The commands recorded in a history, with the step each was applied at.
pub fn commands_in_history(history: &CommandHistory) -> Result<Vec<(u64, Command)>, SimError> {
    history
        .entries
        .iter()
        .filter_map(|(step, line)| line.strip_prefix(HISTORY_PREFIX).map(|j| (*step, j)))
        .map(|(step, json)| {
            serde_json::from_str(json).map(|c| (step, c)).map_err(|e| {
                bad(format!(
                    "history entry at step {step} is not a command: {e}"
                ))
            })
        })
        .collect()
}

/// Rebuilds a run from its parameters and recorded commands: a new planet, stepped to `steps`,
/// with each command applied at the step it was first applied at.
pub fn replay(
    params: Params,
    commands: &[(u64, Command)],
    steps: u64,
) -> Result<Simulation, SimError> {
    let mut sim = Simulation::new(params)?;
    let mut next = 0;
    loop {
        let step = sim.clock().step;
        while next < commands.len() && commands[next].0 <= step {
            sim.apply(&commands[next].1)?;
            next += 1;
        }
        if step >= steps {
            break;
        }
        sim.step()?;
    }
    Ok(sim)
}

/// Why a script could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// The file could not be read.
    #[error("could not read script {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// The file is missing, a folder, too large, not text or unreadable.
    #[error("script {path} {problem}")]
    File {
        /// The file.
        path: String,
        /// What is wrong with it.
        problem: crate::resources::input::TextFileError,
    },
    /// The file is not a valid script.
    #[error("script {path}: {msg}")]
    Invalid {
        /// The file.
        path: String,
        /// What is wrong, naming the event.
        msg: String,
    },
}

/// One timed event of a script.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptEvent {
    /// Its position in the file, from 1 (messages name events by it).
    pub number: usize,
    /// When, My since the start of the run.
    pub at_my: f64,
    /// A free-text note printed when the event fires.
    pub note: Option<String>,
    /// What to do.
    pub command: Command,
}

/// A script: timed events, applied in time order (file order for equal times) by
/// [`Script::apply_due`] before each step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Script {
    /// The events, sorted by time.
    pub events: Vec<ScriptEvent>,
    next: usize,
}

impl ScriptEvent {
    /// The event as messages name it: `event 3 (at 190 My, set_phenomenon)`.
    pub fn label(&self) -> String {
        format!(
            "event {} (at {} My, {})",
            self.number,
            crate::resources::input::num(self.at_my),
            self.command.name()
        )
    }
}

impl Script {
    /// Reads a script file, once and at most
    /// [`MAX_SCRIPT_BYTES`](crate::resources::input::MAX_SCRIPT_BYTES) of it.
    pub fn load(path: &Path) -> Result<Self, ScriptError> {
        use crate::resources::input::{MAX_SCRIPT_BYTES, read_text_capped};
        let text =
            read_text_capped(path, MAX_SCRIPT_BYTES).map_err(|problem| ScriptError::File {
                path: path.display().to_string(),
                problem,
            })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses a script's text (`origin` names it in errors).
    pub fn parse(text: &str, origin: &str) -> Result<Self, ScriptError> {
        use crate::resources::input::{clip, clip_lines};
        let invalid = |msg: String| ScriptError::Invalid {
            path: origin.to_string(),
            msg: clip_lines(&msg, 12),
        };
        let mut doc: toml::Table = toml::from_str(text).map_err(|e| invalid(e.to_string()))?;
        if let Some(k) = doc.keys().find(|k| k.as_str() != "event") {
            return Err(invalid(format!(
                "unknown top-level key `{}` (a script is a list of [[event]] tables)",
                clip(k)
            )));
        }
        let events = match doc.remove("event") {
            None => Vec::new(),
            Some(toml::Value::Array(a)) => a,
            Some(_) => {
                return Err(invalid(
                    "`event` must be an array of tables ([[event]])".into(),
                ));
            }
        };
        let mut out = Vec::with_capacity(events.len());
        for (i, e) in events.into_iter().enumerate() {
            let which = format!("event {} ", i + 1);
            let number = i + 1;
            let toml::Value::Table(mut t) = e else {
                return Err(invalid(format!("{which}is not a table")));
            };
            let at_my = match t.remove("at_my") {
                Some(toml::Value::Float(f)) => f,
                Some(toml::Value::Integer(n)) => n as f64,
                Some(v) => {
                    return Err(invalid(format!(
                        "{which}: at_my must be a number, got {}",
                        clip(&v.to_string())
                    )));
                }
                None => return Err(invalid(format!("{which}has no at_my"))),
            };
            if !at_my.is_finite() || at_my < 0.0 {
                return Err(invalid(format!(
                    "{which}: at_my must be finite and non-negative, got {}",
                    crate::resources::input::num(at_my)
                )));
            }
            let note = match t.remove("note") {
                Some(toml::Value::String(s)) => Some(s),
                Some(v) => {
                    return Err(invalid(format!(
                        "{which}: note must be a string, got {}",
                        clip(&v.to_string())
                    )));
                }
                None => None,
            };
            let command: Command = toml::Value::Table(t).try_into().map_err(|e| {
                invalid(format!(
                    "{which}(at {} My): {e}",
                    crate::resources::input::num(at_my)
                ))
            })?;
            out.push(ScriptEvent {
                number,
                at_my,
                note,
                command,
            });
        }
        out.sort_by(|a, b| a.at_my.total_cmp(&b.at_my));
        Ok(Self {
            events: out,
            next: 0,
        })
    }

    /// Checks every event's values against `params` (before a long run starts).
    pub fn validate(&self, params: &Params) -> Result<(), SimError> {
        for e in &self.events {
            e.command
                .validate(params)
                .map_err(|err| bad(format!("script {}: {err}", e.label())))?;
        }
        Ok(())
    }

    /// Checks every event against the planet it will run on, before the run starts: the
    /// values ([`Self::validate`]), phenomenon names, plugin parameter keys and values, and
    /// plate ids that can never exist (an id below the next plate id that names no plate now:
    /// ids are never reused). Returns notes on what cannot be decided yet: plate ids not made
    /// so far, which a rift must make before the event.
    pub fn validate_for(&self, sim: &mut Simulation) -> Result<Vec<String>, SimError> {
        self.validate(sim.params())?;
        let phenomena = sim.phenomena();
        let next_id = sim.world().resource::<crate::resources::NextPlateId>().0;
        let world = sim.world_mut();
        let mut ids: Vec<u32> = world
            .query::<&Plate>()
            .iter(world)
            .map(|p| p.id.0)
            .collect();
        ids.sort_unstable();
        let mut notes = Vec::new();
        for e in &self.events {
            let fail = |msg: String| bad(format!("script {}: {msg}", e.label()));
            let mut plates: Vec<u32> = Vec::new();
            match &e.command {
                Command::SetPhenomenon { name, .. }
                    if !phenomena.iter().any(|p| p.name == name) =>
                {
                    let names: Vec<&str> = phenomena.iter().map(|p| p.name).collect();
                    return Err(fail(format!(
                        "unknown phenomenon \"{}\"; registered: {}",
                        crate::resources::input::clip(name),
                        names.join(", ")
                    )));
                }
                Command::SetParam { key, value } if key.starts_with("plugins.") => {
                    let mut p = sim.plugin_params().clone();
                    p.set(key, (*value).into())
                        .map_err(|err| fail(format!("set_param: {err}")))?;
                }
                Command::SetMotion {
                    plate: PlateRef::Id(id),
                    ..
                }
                | Command::RiftAt {
                    plate: PlateRef::Id(id),
                    ..
                }
                | Command::SetCrustType {
                    plate: Some(PlateRef::Id(id)),
                    ..
                }
                | Command::RiftLine {
                    plate: Some(PlateRef::Id(id)),
                    ..
                } => plates.push(*id),
                _ => {}
            }
            for id in plates {
                if ids.binary_search(&id).is_ok() {
                    continue;
                }
                if id < next_id {
                    return Err(fail(format!(
                        "plate {id} no longer exists (plates now: {}), and plate ids are never reused",
                        id_list(&ids)
                    )));
                }
                notes.push(format!(
                    "script {}: plate {id} does not exist yet (plates now: {}); a rift must make it before the event, or the run stops there",
                    e.label(),
                    id_list(&ids)
                ));
            }
        }
        Ok(notes)
    }

    /// Applies every event whose time has come (`at_my` ≤ the planet's time, within half a
    /// step); returns them with their outcomes.
    pub fn apply_due(
        &mut self,
        sim: &mut Simulation,
    ) -> Result<Vec<(ScriptEvent, Outcome)>, SimError> {
        let now = sim.time_my() + 0.5 * sim.params().time.time_step_my;
        let mut done = Vec::new();
        while self.next < self.events.len() && self.events[self.next].at_my < now {
            let e = self.events[self.next].clone();
            self.next += 1;
            let outcome = sim
                .apply(&e.command)
                .map_err(|err| bad(format!("script {}: {err}", e.label())))?;
            done.push((e, outcome));
        }
        Ok(done)
    }

    /// Events not applied yet.
    pub fn remaining(&self) -> &[ScriptEvent] {
        &self.events[self.next..]
    }
}

/// A list of plate ids for messages: all of them when few, else the first and last few.
fn id_list(ids: &[u32]) -> String {
    let show = |v: &[u32]| {
        v.iter()
            .map(|i| i.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    if ids.len() <= 12 {
        show(ids)
    } else {
        format!(
            "{}, …, {}: {} plates",
            show(&ids[..6]),
            show(&ids[ids.len() - 3..]),
            ids.len()
        )
    }
}
