//! Hotspots (phenomenon `hotspots`, off by default): mantle plumes fixed in the mantle frame that
//! build volcanic edifices on whatever plate passes over them; each edifice rides away on its
//! plate, ages and subsides, leaving a chain of islands and seamounts whose age grows along the
//! plate's motion (Hawaii–Emperor style). The paper's future work (§7.5: "hot spots ... as
//! specific sample points drifting across plates").
//!
//! Written as a third-party plugin would be: its only import from this crate is the prelude (a
//! test checks it), so everything it uses is public API. `docs/plugins.md` walks through it.
//!
//! Model, per step of δt (all in the `Aging` set, after drift, so positions are this step's):
//! - The plate above a hotspot is the one whose sample nearest the hotspot (in that plate's
//!   frame) belongs to it; where two plates overlap, the higher surface wins.
//! - That plate's samples within `radius_km` of the hotspot rise by
//!   `uplift_mm_per_yr · δt · (1 − (d/r)²)²` (great-circle distance d, crust thickens by as
//!   much), until the edifice is `max_height_km` high (a quarter of it on continental ground,
//!   where hotspots make plateaus rather than shields), and it raises no sample of its
//!   footprint more than that above the floor the edifice stands on. The uplift goes to the nearest
//!   edifice of that plate within r/2 of the hotspot, or to a new one; a new one founded on
//!   the flanks of others stands on their lowest floor, so a chain on a slow plate does not
//!   pile each edifice on the last.
//! - Edifices not over their hotspot subside: an edifice of height h loses
//!   `h · (1 − exp(−δt/τ))` (τ = `subsidence_time_my`, thermal subsidence of the lithosphere)
//!   over the same footprint, never below the floor it was built on nor the abyssal plain; the
//!   core's oceanic damping (the
//!   `erosion` phenomenon) wears them down as well.
//! - At each resampling, edifices are carried to the reference frame with their plate's
//!   frame; an edifice whose ground now belongs to another plate went down a subduction zone
//!   (or under a collision) and is removed (its relief is the crust's, resampled by the core).
//!
//! Hotspots are placed by the planet seed with their own random stream (so switching them on
//! changes no other random draw), or given by the user as [`Hotspot`] entities (with
//! `plugins.hotspots.count = 0` for only those).

use crate::prelude::*;

/// Fraction of `max_height_km` a hotspot builds on continental ground: continental hotspots
/// (Yellowstone) make plateaus and calderas of a kilometre or two, not 8-km shields.
pub const CONTINENTAL_HEIGHT_FRACTION: f64 = 0.25;

/// The phenomenon name (for `--enable hotspots`).
pub const HOTSPOTS: Phenomenon = Phenomenon::new("hotspots");

/// The random stream of hotspot positions ("HOTSPOTS" in ASCII); no core stream uses it.
pub const HOTSPOT_STREAM: u64 = 0x484f_5453_504f_5453;

/// A mantle plume, fixed in the mantle (world) frame.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Hotspot {
    /// Its number (stable; orders hotspots in every loop).
    pub index: u32,
    /// Where it is: a unit vector in the world frame.
    pub position: DVec3,
}

/// A volcanic edifice built by a hotspot, riding on a plate.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct Edifice {
    /// Order of creation (orders edifices in every loop, so results do not depend on how the
    /// ECS stores them).
    pub serial: u64,
    /// The hotspot that built it.
    pub hotspot: u32,
    /// The plate it stands on.
    pub plate: PlateId,
    /// Its centre: a unit vector in its plate's frame (the world frame at the last resampling).
    pub pos_in_plate: DVec3,
    /// Its present height above the floor it was built on, km (after subsidence).
    pub height_km: f64,
    /// Everything the hotspot built on it, km (capped by `max_height_km`).
    pub built_km: f64,
    /// Time since the hotspot last built it, My.
    pub age_my: f64,
    /// Elevation of the floor at its centre when it was founded, km: subsidence never takes
    /// its footprint below this (nor below the abyssal plain).
    pub base_km: f64,
}

impl Edifice {
    /// Its centre in the world frame, given its plate's frame.
    pub fn world_position(&self, world_from_plate: DQuat) -> DVec3 {
        (world_from_plate * self.pos_in_plate).normalize()
    }
}

/// Bookkeeping of the plugin (a resource, saved in section `hotspots.state`).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct HotspotState {
    /// Whether the seeded hotspots were placed (on the first step with the phenomenon on).
    pub placed: bool,
    /// Serial number of the next edifice.
    pub next_serial: u64,
    /// Each plate's frame at the last step, `(plate id, world_from_plate)`, sorted by id: what
    /// carries edifices to the reference frame at a resampling (emptied afterwards).
    pub frames: Vec<(u32, DQuat)>,
}

/// The plugin's parameters, read from [`PluginParams`] each step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HotspotSettings {
    /// Hotspots placed by seed.
    pub count: u64,
    /// Radius of the uplift around a hotspot, km.
    pub radius_km: f64,
    /// Uplift rate at the centre, mm/yr (= km/My).
    pub uplift_mm_per_yr: f64,
    /// Highest an edifice is built above its floor, km.
    pub max_height_km: f64,
    /// E-folding time of edifice subsidence, My.
    pub subsidence_time_my: f64,
}

/// The declared parameters, in `[plugins.hotspots]`.
pub const PARAMS: [ParamSpec; 5] = [
    ParamSpec {
        key: "plugins.hotspots.count",
        section: "plugins.hotspots",
        name: "count",
        kind: ParamKind::Int,
        unit: "",
        doc: "Hotspots placed by the planet seed (their own random stream) on the first step with hotspots on.",
        default: ParamValue::Int(6),
        min: 0.0,
        max: 64.0,
    },
    ParamSpec {
        key: "plugins.hotspots.radius_km",
        section: "plugins.hotspots",
        name: "radius_km",
        kind: ParamKind::Float,
        unit: "km",
        doc: "Radius of the volcanic uplift around a hotspot (keep it above the sample spacing: about 32 km at 500,000 samples).",
        default: ParamValue::Float(150.0),
        min: 10.0,
        max: 2000.0,
    },
    ParamSpec {
        key: "plugins.hotspots.uplift_mm_per_yr",
        section: "plugins.hotspots",
        name: "uplift_mm_per_yr",
        kind: ParamKind::Float,
        unit: "mm/yr",
        doc: "Volcanic uplift rate at the centre of a hotspot (the strength of the plume).",
        default: ParamValue::Float(4.0),
        min: 0.0,
        max: 100.0,
    },
    ParamSpec {
        key: "plugins.hotspots.max_height_km",
        section: "plugins.hotspots",
        name: "max_height_km",
        kind: ParamKind::Float,
        unit: "km",
        doc: "Highest a volcanic edifice is built above the floor it stands on (Mauna Kea: about 10 km).",
        default: ParamValue::Float(8.0),
        min: 0.0,
        max: 30.0,
    },
    ParamSpec {
        key: "plugins.hotspots.subsidence_time_my",
        section: "plugins.hotspots",
        name: "subsidence_time_my",
        kind: ParamKind::Float,
        unit: "My",
        doc: "E-folding time of the subsidence of an edifice once it has left its hotspot.",
        default: ParamValue::Float(40.0),
        min: 1.0,
        max: 100000.0,
    },
];

impl HotspotSettings {
    /// The current values from the registry (declared defaults where a key is missing).
    pub fn from_registry(p: &PluginParams) -> Self {
        let f = |k: usize| match PARAMS[k].default {
            ParamValue::Float(x) => p.f64_or(PARAMS[k].key, x),
            _ => 0.0,
        };
        Self {
            count: match PARAMS[0].default {
                ParamValue::Int(n) => p.u64_or(PARAMS[0].key, n),
                _ => 0,
            },
            radius_km: f(1),
            uplift_mm_per_yr: f(2),
            max_height_km: f(3),
            subsidence_time_my: f(4),
        }
    }
}

/// The hotspot plugin: registers the phenomenon (off by default), its parameters, its save
/// section and its systems.
#[derive(Default)]
pub struct HotspotPlugin;

impl Plugin for HotspotPlugin {
    fn build(&self, app: &mut App) {
        app.register_phenomenon_with_default(
            HOTSPOTS,
            TectonicSystems::Aging,
            "mantle plumes build island chains on the plates passing over them",
            false,
        );
        for spec in PARAMS {
            app.register_plugin_param(spec);
        }
        app.init_resource::<HotspotState>();
        app.register_save_section(SaveSection {
            name: "hotspots.state",
            version: 1,
            save: save_state,
            load: load_state,
            default: Some(|_| Ok(())),
        });
        app.add_systems(
            TectonicStep,
            (
                place_hotspots.run_if(phenomenon_enabled(HOTSPOTS)),
                build_and_subside.run_if(phenomenon_enabled(HOTSPOTS)),
                // Bookkeeping that keeps edifices on their plates runs while any exist, even
                // with the phenomenon off (it never touches the crust).
                remember_frames.run_if(any_with_component::<Edifice>),
            )
                .chain()
                .in_set(AgingSystems::After),
        );
        app.add_systems(
            AfterResample,
            carry_edifices
                .in_set(AfterResampleSystems::Carry)
                .run_if(any_with_component::<Edifice>),
        );
    }
}

/// Places the seeded hotspots once.
fn place_hotspots(
    mut commands: Commands,
    mut state: ResMut<HotspotState>,
    params: Res<Params>,
    plugin_params: Res<PluginParams>,
    existing: Query<&Hotspot>,
) {
    if state.placed {
        return;
    }
    state.placed = true;
    let settings = HotspotSettings::from_registry(&plugin_params);
    let first = existing.iter().map(|h| h.index + 1).max().unwrap_or(0);
    let seed = params.planet.seed;
    for k in 0..settings.count {
        let position = unit_vector(
            hash3(seed, HOTSPOT_STREAM, 2 * k),
            hash3(seed, HOTSPOT_STREAM, 2 * k + 1),
        );
        commands.spawn(Hotspot {
            index: first + k as u32,
            position,
        });
    }
}

/// Visited marks for footprint searches, reused between calls.
#[derive(Default)]
struct Marks {
    stamp: Vec<u32>,
    generation: u32,
}

/// The samples of `plate` within `radius_rad` of `center` (plate frame), found by walking the
/// mesh from the sample nearest `center`, with their distance in radians.
fn footprint(
    mesh: &SphereMesh,
    crust: &Crust,
    plate: u32,
    center: DVec3,
    radius_rad: f64,
    marks: &mut Marks,
    out: &mut Vec<(usize, f64)>,
) {
    out.clear();
    if marks.stamp.len() != mesh.len() {
        marks.stamp = vec![0; mesh.len()];
        marks.generation = 0;
    }
    marks.generation = marks.generation.wrapping_add(1);
    if marks.generation == 0 {
        marks.stamp.iter_mut().for_each(|s| *s = 0);
        marks.generation = 1;
    }
    let loc = mesh.locate(center);
    let Some(start) = mesh
        .triangles
        .get(loc.triangle as usize)
        .map(|t| t[loc.dominant_corner()] as usize)
    else {
        return;
    };
    let mut stack = vec![start];
    marks.stamp[start] = marks.generation;
    while let Some(s) = stack.pop() {
        let d = angle_between(center, mesh.positions[s]);
        if d > radius_rad {
            continue;
        }
        if crust.plate[s] == plate {
            out.push((s, d));
        }
        for &n in mesh.neighbors_of(s) {
            let n = n as usize;
            if marks.stamp[n] != marks.generation {
                marks.stamp[n] = marks.generation;
                stack.push(n);
            }
        }
    }
    // Walk order depends only on the mesh, but sort anyway: sums below are order-free, this
    // keeps the list canonical.
    out.sort_unstable_by_key(|&(s, _)| s);
}

/// The uplift profile: 1 at the centre, 0 at the radius, smooth at both.
fn profile(d_over_r: f64) -> f64 {
    let x = (1.0 - d_over_r * d_over_r).max(0.0);
    x * x
}

/// Grows the edifices over hotspots and lets the others subside (one step).
#[allow(clippy::too_many_arguments)]
fn build_and_subside(
    mut commands: Commands,
    mut state: ResMut<HotspotState>,
    params: Res<Params>,
    plugin_params: Res<PluginParams>,
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    plates: Query<(&Plate, &PlateFrame, &PlateBounds)>,
    hotspots: Query<&Hotspot>,
    mut edifices: Query<(Entity, &mut Edifice)>,
    mut marks: Local<Marks>,
    mode: Option<Res<ReliefMode>>,
    mut gpu: Option<ResMut<GpuContext>>,
) {
    // With isostatic relief the elevation follows from the crust at the next step: an edifice is
    // built (and subsides) in thickness, by its height over the surface rise per km of crust
    // there (about 0.15 on land, 0.35 on the sea floor), so it keeps the height it is given.
    let isostatic = mode.is_some_and(|m| m.isostatic);
    let (land_gain, sea_gain) = (
        dry_isostatic_gain(&params) as f32,
        oceanic_load_gain(&params) as f32,
    );
    let thickening = |crust: &Crust, i: usize, dz: f32| -> f32 {
        if !isostatic {
            dz
        } else if crust.crust_type[i] == CrustType::Continental {
            dz / land_gain
        } else {
            dz / sea_gain
        }
    };
    // On the GPU backend: the elevation is read, so it comes down; the writes touch only
    // elevation and thickness, so when the device is otherwise in sync they are declared and
    // only those two fields go up afterwards (8 B/sample) instead of the whole crust. When
    // they cannot be declared, every stale field comes down first and the next kernel uploads
    // the whole crust.
    const WRITES: FieldMask = FieldMask(FieldMask::ELEVATION.0 | FieldMask::THICKNESS.0);
    let declared = gpu.as_mut().is_some_and(|g| {
        pull_or_record(g, &mut crust, FieldMask::ELEVATION)
            && g.can_declare_host_write(WRITES, crust.len(), crust.last_changed())
    });
    if !declared && let Some(g) = gpu.as_mut() {
        pull_or_record(g, &mut crust, FieldMask::ALL);
    }
    let s = HotspotSettings::from_registry(&plugin_params);
    let dt = params.time.time_step_my;
    let radius_km = params.planet.radius_km;
    let r_rad = s.radius_km / radius_km;
    let floor_km = params.ocean.abyssal_elevation_km as f32;
    let mut plate_list: Vec<(u32, DQuat, PlateBounds)> = plates
        .iter()
        .map(|(p, f, b)| (p.id.0, f.world_from_plate, *b))
        .collect();
    plate_list.sort_by_key(|p| p.0);
    let mut spots: Vec<Hotspot> = hotspots.iter().copied().collect();
    spots.sort_by_key(|h| h.index);
    let mut list: Vec<(Entity, Edifice)> = edifices.iter().map(|(e, d)| (e, *d)).collect();
    list.sort_by_key(|(_, d)| d.serial);
    let mut grown = vec![false; list.len()];
    let mut fresh: Vec<Edifice> = Vec::new();
    let mut samples = Vec::new();
    let mut crust_res = crust;
    let crust = &mut *crust_res;
    for spot in &spots {
        // The plate over the hotspot: highest surface among the plates owning the nearest
        // sample in their own frame.
        // (plate, hotspot in the plate's frame, elevation under it, continental ground)
        let mut best: Option<(u32, DVec3, f32, bool)> = None;
        for &(id, frame, bounds) in &plate_list {
            let q = (frame.inverse() * spot.position).normalize();
            if angle_between(q, bounds.centroid) > bounds.cap_radius_rad {
                continue;
            }
            let loc = mesh.locate(q);
            let Some(j) = mesh
                .triangles
                .get(loc.triangle as usize)
                .map(|t| t[loc.dominant_corner()] as usize)
            else {
                continue;
            };
            if crust.plate[j] != id {
                continue;
            }
            let z = crust.elevation_km[j];
            if best.is_none_or(|b| z > b.2) {
                let continental = crust.crust_type[j] == CrustType::Continental;
                best = Some((id, q, z, continental));
            }
        }
        let Some((plate, q, z_under, continental)) = best else {
            continue;
        };
        // Its edifice: the nearest on this plate within r/2, else a new one.
        let near = list
            .iter()
            .enumerate()
            .filter(|(_, (_, d))| d.plate.0 == plate)
            .map(|(k, (_, d))| (k, angle_between(d.pos_in_plate, q)))
            .filter(|&(_, a)| a <= 0.5 * r_rad)
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        let built = near.map_or(0.0, |(k, _)| list[k].1.built_km);
        // The floor the edifice stands on: its own, or for a new one the lowest floor of the
        // edifices of this plate whose footprint it is founded on (the flank of the last one
        // of its chain), so a chain on a slow plate does not stack each new edifice on the
        // last one's flank (summits 12 km above the floor where the cap says 8).
        let base_km = match near {
            Some((k, _)) => list[k].1.base_km,
            None => list
                .iter()
                .filter(|(_, d)| d.plate.0 == plate && angle_between(d.pos_in_plate, q) < r_rad)
                .map(|(_, d)| d.base_km)
                .fold(f64::from(z_under), f64::min),
        };
        let cap_km = if continental {
            CONTINENTAL_HEIGHT_FRACTION * s.max_height_km
        } else {
            s.max_height_km
        };
        // The edifice's own budget, and the summit at most the cap above its floor.
        let dz_km = (s.uplift_mm_per_yr * dt)
            .min(cap_km - built)
            .min(base_km + cap_km - f64::from(z_under))
            .max(0.0);
        footprint(&mesh, crust, plate, q, r_rad, &mut marks, &mut samples);
        // Nowhere above the cap over the floor: the flank of an older edifice of the chain
        // can stand higher than the surface at the hotspot.
        let ceiling = (base_km + cap_km) as f32;
        for &(i, d) in &samples {
            let z = crust.elevation_km[i];
            let dz = ((dz_km * profile(d / r_rad)) as f32)
                .min(ceiling - z)
                .max(0.0);
            crust.elevation_km[i] = z + dz;
            crust.thickness_km[i] += thickening(crust, i, dz);
        }
        match near {
            Some((k, _)) => {
                let e = &mut list[k].1;
                e.height_km += dz_km;
                e.built_km += dz_km;
                e.age_my = 0.0;
                grown[k] = true;
            }
            None if dz_km > 0.0 => {
                fresh.push(Edifice {
                    serial: state.next_serial,
                    hotspot: spot.index,
                    plate: PlateId(plate),
                    pos_in_plate: q,
                    height_km: dz_km,
                    built_km: dz_km,
                    age_my: 0.0,
                    base_km,
                });
                state.next_serial += 1;
            }
            None => {}
        }
    }
    // Subsidence of the edifices that were not built this step.
    let keep = (-dt / s.subsidence_time_my).exp();
    for (k, (entity, e)) in list.iter_mut().enumerate() {
        if grown[k] {
            continue;
        }
        let loss_km = e.height_km * (1.0 - keep);
        let floor = floor_km.max(e.base_km as f32);
        footprint(
            &mesh,
            crust,
            e.plate.0,
            e.pos_in_plate,
            r_rad,
            &mut marks,
            &mut samples,
        );
        for &(i, d) in &samples {
            let z = crust.elevation_km[i];
            let dz = ((loss_km * profile(d / r_rad)) as f32).min((z - floor).max(0.0));
            crust.elevation_km[i] = z - dz;
            if isostatic {
                crust.thickness_km[i] -= thickening(crust, i, dz);
            }
        }
        e.height_km -= loss_km;
        e.age_my += dt;
        if e.height_km < 1e-3 {
            commands.entity(*entity).despawn();
        }
    }
    for (entity, e) in &list {
        if let Ok((_, mut slot)) = edifices.get_mut(*entity) {
            *slot = *e;
        }
    }
    for e in fresh {
        commands.spawn(e);
    }
    if declared
        && let Some(g) = gpu.as_mut()
        && let Err(e) = g.note_host_write(&crust_res, WRITES, crust_res.last_changed())
        && g.failure.is_none()
    {
        g.failure = Some(e);
    }
}

/// Remembers every plate's frame before a possible resampling.
fn remember_frames(mut state: ResMut<HotspotState>, plates: Query<(&Plate, &PlateFrame)>) {
    state.frames = plates
        .iter()
        .map(|(p, f)| (p.id.0, f.world_from_plate))
        .collect();
    state.frames.sort_by_key(|f| f.0);
}

/// After a resampling: carries every edifice to the reference frame with its plate's frame;
/// removes those whose ground now belongs to another plate.
fn carry_edifices(
    mut commands: Commands,
    mut state: ResMut<HotspotState>,
    mesh: Res<SphereMesh>,
    crust: Res<Crust>,
    mut edifices: Query<(Entity, &mut Edifice)>,
) {
    let frames = std::mem::take(&mut state.frames);
    for (entity, mut e) in &mut edifices {
        let frame = frames
            .binary_search_by_key(&e.plate.0, |f| f.0)
            .ok()
            .and_then(|k| frames.get(k))
            .map_or(DQuat::IDENTITY, |f| f.1);
        let world = e.world_position(frame);
        let loc = mesh.locate(world);
        let owner = mesh
            .triangles
            .get(loc.triangle as usize)
            .and_then(|t| crust.plate.get(t[loc.dominant_corner()] as usize))
            .copied();
        if owner == Some(e.plate.0) {
            e.pos_in_plate = world;
        } else {
            commands.entity(entity).despawn();
        }
    }
}

fn save_state(world: &mut World, w: &mut SectionWriter) -> Result<(), SectionError> {
    let state = world.resource::<HotspotState>().clone();
    w.u8(u8::from(state.placed));
    w.u64(state.next_serial);
    w.u32(state.frames.len() as u32);
    for (id, q) in &state.frames {
        w.u32(*id);
        for v in q.to_array() {
            w.f64(v);
        }
    }
    let mut spots: Vec<Hotspot> = world.query::<&Hotspot>().iter(world).copied().collect();
    spots.sort_by_key(|h| h.index);
    w.u32(spots.len() as u32);
    for h in &spots {
        w.u32(h.index);
        for v in h.position.to_array() {
            w.f64(v);
        }
    }
    let mut list: Vec<Edifice> = world.query::<&Edifice>().iter(world).copied().collect();
    list.sort_by_key(|e| e.serial);
    w.u32(list.len() as u32);
    for e in &list {
        w.u64(e.serial);
        w.u32(e.hotspot);
        w.u32(e.plate.0);
        for v in e.pos_in_plate.to_array() {
            w.f64(v);
        }
        w.f64(e.height_km);
        w.f64(e.built_km);
        w.f64(e.age_my);
        w.f64(e.base_km);
    }
    Ok(())
}

fn unit(r: &mut SectionReader, what: &str) -> Result<DVec3, SectionError> {
    let v = DVec3::new(
        r.finite_f64(what)?,
        r.finite_f64(what)?,
        r.finite_f64(what)?,
    );
    if (v.length() - 1.0).abs() > 1e-6 {
        return Err(format!("{what} is not a unit vector").into());
    }
    Ok(v)
}

fn load_state(world: &mut World, r: &mut SectionReader, _v: u32) -> Result<(), SectionError> {
    let placed = match r.u8()? {
        0 => false,
        1 => true,
        b => return Err(format!("placed flag {b} is neither 0 nor 1").into()),
    };
    let next_serial = r.u64()?;
    let n = r.u32()? as usize;
    if r.remaining() < n.saturating_mul(36) {
        return Err("plate frames are truncated".into());
    }
    let mut frames = Vec::with_capacity(n);
    for _ in 0..n {
        let id = r.u32()?;
        let q = DQuat::from_xyzw(
            r.finite_f64("frame")?,
            r.finite_f64("frame")?,
            r.finite_f64("frame")?,
            r.finite_f64("frame")?,
        );
        frames.push((id, q));
    }
    let n = r.u32()? as usize;
    if r.remaining() < n.saturating_mul(28) {
        return Err("hotspots are truncated".into());
    }
    let mut spots = Vec::with_capacity(n);
    for _ in 0..n {
        let index = r.u32()?;
        spots.push(Hotspot {
            index,
            position: unit(r, "hotspot position")?,
        });
    }
    let n = r.u32()? as usize;
    if r.remaining() < n.saturating_mul(72) {
        return Err("edifices are truncated".into());
    }
    let mut plates = world.resource::<Crust>().plate.clone();
    plates.sort_unstable();
    plates.dedup();
    let mut list = Vec::with_capacity(n);
    for _ in 0..n {
        let e = Edifice {
            serial: r.u64()?,
            hotspot: r.u32()?,
            plate: PlateId(r.u32()?),
            pos_in_plate: unit(r, "edifice position")?,
            height_km: r.finite_f64("edifice height")?,
            built_km: r.finite_f64("edifice build")?,
            age_my: r.finite_f64("edifice age")?,
            base_km: r.finite_f64("edifice base")?,
        };
        if e.serial >= next_serial || plates.binary_search(&e.plate.0).is_err() {
            return Err(format!(
                "edifice {} names a serial or plate that does not exist",
                e.serial
            )
            .into());
        }
        list.push(e);
    }
    r.finish()?;
    *world.resource_mut::<HotspotState>() = HotspotState {
        placed,
        next_serial,
        frames,
    };
    let old: Vec<Entity> = world
        .query_filtered::<Entity, Or<(With<Hotspot>, With<Edifice>)>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    world.spawn_batch(spots);
    world.spawn_batch(list);
    Ok(())
}
