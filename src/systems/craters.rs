//! An impact-scarred start (seed 004's "meteor initialisation", a late heavy bombardment):
//! `init.craters` craters at random places, drawn one after the other on the initial crust.
//!
//! Each crater of radius R digs a bowl into the crust, removing a thickness
//! `d(r) = d₀·(1 − (r/R)²)` at a great-circle distance r < R from its centre (d₀ =
//! `init.crater_depth_ratio`·R: R/20 by default, the seed's figure), never leaving less than
//! [`MIN_CRUST_KM`]. The removed volume is thrown out as an ejecta blanket on and beyond the rim,
//! thickest at the rim and thinning as (r/R)⁻³ (McGetchin, Settle & Head 1973) out to
//! [`EJECTA_REACH`]·R, so the rim is a crest that falls away outwards instead of a cliff; the
//! blanket is scaled so that it holds exactly the volume the bowl removed (total crust volume is
//! conserved). Craters are drawn in order, each on the crust the earlier ones left: a younger
//! crater digs into older rims and buries older floors under its ejecta, so the youngest are the
//! sharpest.
//!
//! Radii follow a power law between `init.crater_min_radius_km` and
//! `init.crater_max_radius_km`: the number of craters larger than R falls as R⁻² (the slope of
//! the large lunar basins), so most are small and a few are huge. Centres and radii are drawn per
//! crater from the seed, never per sample, so every resolution gets the same craters.
//!
//! The pass changes the thickness; the elevation follows it by local Airy isostasy (continents by
//! the isostasy's law, with the water load below sea level; ocean floor by the oceanic load
//! gain), the same laws the isostasy phenomenon then keeps.

use glam::DVec3;

use crate::geometry::SphereMesh;
use crate::random::{hash3, stream, unit_f64, unit_vector};
use crate::resources::params::{Params, oceanic_load_gain};
use crate::resources::{Crust, CrustType};
use crate::systems::relief::isostasy::{IsostasyParams, airy_elevation, airy_thickness};
use crate::systems::relief::isostasy_params;

/// The thinnest crust a crater leaves, km.
pub const MIN_CRUST_KM: f64 = 1.0;
/// How far the ejecta blanket reaches, in crater radii from the centre.
pub const EJECTA_REACH: f64 = 3.0;
/// Exponent b of the cumulative size distribution N(> R) ∝ R⁻ᵇ.
pub const SIZE_EXPONENT: f64 = 2.0;

/// One impact crater.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crater {
    /// Unit vector of its centre.
    pub center: DVec3,
    /// Radius of its rim, km.
    pub radius_km: f64,
}

/// The craters of `params` (`init.craters` of them), in the order they strike.
pub fn draw_craters(params: &Params) -> Vec<Crater> {
    let i = &params.init;
    let seed = params.planet.seed;
    let (lo, hi) = (i.crater_min_radius_km, i.crater_max_radius_km);
    (0..i.craters)
        .map(|k| {
            let center = unit_vector(
                hash3(seed, stream::CRATER, 3 * k),
                hash3(seed, stream::CRATER, 3 * k + 1),
            );
            let u = unit_f64(hash3(seed, stream::CRATER, 3 * k + 2));
            Crater {
                center,
                radius_km: power_law_radius(u, lo, hi),
            }
        })
        .collect()
}

/// The radius at quantile `u` ∈ [0, 1) of the power law N(> R) ∝ R⁻ᵇ truncated to [lo, hi].
pub fn power_law_radius(u: f64, lo: f64, hi: f64) -> f64 {
    if hi <= lo {
        return lo;
    }
    let b = SIZE_EXPONENT;
    let tail = (lo / hi).powf(b);
    // P(R > x) = (x^-b − hi^-b) / (lo^-b − hi^-b); invert for the u-quantile.
    (lo * (1.0 - u * (1.0 - tail)).powf(-1.0 / b)).clamp(lo, hi)
}

/// Thickness (km) the bowl of a crater of radius `radius_km` removes at distance `r_km` from its
/// centre: `ratio·R·(1 − (r/R)²)` inside the rim, 0 outside.
pub fn bowl_depth_km(r_km: f64, radius_km: f64, ratio: f64) -> f64 {
    if !(r_km < radius_km) || radius_km <= 0.0 {
        return 0.0;
    }
    let x = r_km / radius_km;
    ratio * radius_km * (1.0 - x * x)
}

/// Relative ejecta thickness at distance `r_km`: (r/R)⁻³ on and beyond the rim, out to
/// [`EJECTA_REACH`] radii; 0 elsewhere.
pub fn ejecta_weight(r_km: f64, radius_km: f64) -> f64 {
    if radius_km <= 0.0 || r_km < radius_km || r_km >= EJECTA_REACH * radius_km {
        return 0.0;
    }
    (radius_km / r_km).powi(3)
}

/// What one crater moved.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CraterVolume {
    /// Crust removed from the bowl, km³.
    pub removed_km3: f64,
    /// Crust laid down as ejecta, km³.
    pub deposited_km3: f64,
}

/// Reusable buffers of [`apply_crater`].
#[derive(Default)]
pub struct CraterScratch {
    mark: Vec<u32>,
    epoch: u32,
    queue: Vec<u32>,
    cap: Vec<(u32, f64)>,
}

/// Elevation response to a thickness change (local Airy): continents by the isostasy's own law
/// ([`airy_thickness`] then [`airy_elevation`]), ocean floor by the oceanic load gain.
struct Response {
    iso: IsostasyParams,
    oceanic: f64,
}

impl Response {
    fn of(params: &Params) -> Self {
        Self {
            iso: isostasy_params(params),
            oceanic: oceanic_load_gain(params),
        }
    }

    fn new_elevation(&self, z: f32, ct: CrustType, dt_km: f64) -> f32 {
        let z = z as f64;
        if ct == CrustType::Oceanic {
            return (z + self.oceanic * dt_km) as f32;
        }
        airy_elevation(airy_thickness(z, &self.iso) + dt_km, &self.iso) as f32
    }
}

/// Strikes `crater` into `crust` on `mesh`: the bowl removes up to `ratio`·R of crust at the
/// centre, the ejecta blanket lays the same volume on and beyond the rim, and the elevation
/// follows by local isostasy. Returns the volumes moved (equal up to rounding; both 0 when the
/// crater is smaller than the mesh can show).
pub fn apply_crater(
    mesh: &SphereMesh,
    crust: &mut Crust,
    crater: &Crater,
    ratio: f64,
    params: &Params,
    s: &mut CraterScratch,
) -> CraterVolume {
    let n = mesh.len().min(crust.len());
    let mut out = CraterVolume::default();
    if n == 0 || !(crater.radius_km > 0.0) {
        return out;
    }
    let r_planet = mesh.radius_km;
    let reach = EJECTA_REACH * crater.radius_km;
    let dist = |i: usize| -> f64 {
        mesh.positions[i].dot(crater.center).clamp(-1.0, 1.0).acos() * r_planet
    };
    // The samples within reach: breadth first from the sample nearest the centre (a cap is
    // connected on the mesh), in a fixed order.
    if s.mark.len() != n {
        s.mark = vec![0; n];
        s.epoch = 0;
    }
    s.epoch = s.epoch.wrapping_add(1);
    if s.epoch == 0 {
        s.mark.iter_mut().for_each(|m| *m = 0);
        s.epoch = 1;
    }
    let loc = mesh.locate(crater.center);
    let start = mesh.triangles[loc.triangle as usize][loc.dominant_corner()] as usize;
    s.queue.clear();
    s.cap.clear();
    s.queue.push(start as u32);
    s.mark[start] = s.epoch;
    let mut head = 0;
    while head < s.queue.len() {
        let i = s.queue[head] as usize;
        head += 1;
        let d = dist(i);
        if d >= reach {
            continue;
        }
        s.cap.push((i as u32, d));
        for &j in mesh.neighbors_of(i) {
            let j = j as usize;
            if j < n && s.mark[j] != s.epoch {
                s.mark[j] = s.epoch;
                s.queue.push(j as u32);
            }
        }
    }
    // No sample in the blanket's ring (a crater about one sample wide): nothing is moved.
    let weight_sum: f64 = s
        .cap
        .iter()
        .map(|&(i, d)| ejecta_weight(d, crater.radius_km) * mesh.area_km2[i as usize])
        .sum();
    if !(weight_sum > 0.0) {
        return out;
    }
    // The bowl.
    let response = Response::of(params);
    for &(i, d) in &s.cap {
        let i = i as usize;
        let want = bowl_depth_km(d, crater.radius_km, ratio);
        let t = crust.thickness_km[i];
        if want <= 0.0 || !t.is_finite() {
            continue;
        }
        let cut = want.min((t as f64 - MIN_CRUST_KM).max(0.0));
        let new_t = (t as f64 - cut) as f32;
        let removed = (t - new_t) as f64;
        crust.thickness_km[i] = new_t;
        crust.elevation_km[i] =
            response.new_elevation(crust.elevation_km[i], crust.crust_type[i], -removed);
        out.removed_km3 += removed * mesh.area_km2[i];
    }
    // The ejecta blanket, scaled to the removed volume.
    let scale = out.removed_km3 / weight_sum;
    for &(i, d) in &s.cap {
        let i = i as usize;
        let w = ejecta_weight(d, crater.radius_km);
        if w <= 0.0 || scale <= 0.0 {
            continue;
        }
        let t = crust.thickness_km[i];
        let new_t = (t as f64 + scale * w) as f32;
        let added = (new_t - t) as f64;
        crust.thickness_km[i] = new_t;
        crust.elevation_km[i] =
            response.new_elevation(crust.elevation_km[i], crust.crust_type[i], added);
        out.deposited_km3 += added * mesh.area_km2[i];
    }
    out
}

/// What [`bombard`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Bombardment {
    /// Craters drawn.
    pub craters: usize,
    /// Crust removed from the bowls, km³.
    pub removed_km3: f64,
    /// Crust laid down as ejecta, km³.
    pub deposited_km3: f64,
}

/// Strikes the craters of `params` ([`draw_craters`]) into `crust`, in order.
pub fn bombard(mesh: &SphereMesh, crust: &mut Crust, params: &Params) -> Bombardment {
    let craters = draw_craters(params);
    let mut s = CraterScratch::default();
    let mut out = Bombardment {
        craters: craters.len(),
        ..Default::default()
    };
    for c in &craters {
        let v = apply_crater(
            mesh,
            crust,
            c,
            params.init.crater_depth_ratio,
            params,
            &mut s,
        );
        out.removed_km3 += v.removed_km3;
        out.deposited_km3 += v.deposited_km3;
    }
    out
}
