//! New oceanic crust in the gaps opened by diverging plates (paper §4.3, Driftworld §3.7).
//!
//! Choices where the paper is vague, written down here as the design asks:
//! - The ridge lies halfway between the two nearest plates: with d1 ≤ d2 the distances to the
//!   nearest covered samples of the nearest and second-nearest plates, the distance to the ridge
//!   is d_Γ = (d2 − d1)/2 and to the plate d_P = d1, so α = d_Γ/(d_Γ + d_P) = (d2 − d1)/(d2 + d1).
//! - Age: the gap opened since the last resampling, at a steady rate, so crust at fraction α of
//!   the way from the ridge to the plate formed α·T ago (T = time since the last resampling):
//!   zero at the ridge, growing away from it.
//! - Ridge profile z_Γ(age): the elevation that crust born at the ridge (z_r) reaches after
//!   `age` of oceanic damping ([`ocean_floor_elevation_km`]). Crust made in one big gap and crust
//!   made a little at a time therefore end at the same depth, whatever the resampling interval.
//! - Elevation: z = α·z̄ + (1 − α)·z_Γ(age), z̄ the linear interpolation between the two plate
//!   edges, capped at the ridge height z_r so that new ocean floor next to a continent does not
//!   come out as dry land.
//! - Ridge direction r = (p − q) × p, q the projection on the ridge: the tangent direction at p
//!   perpendicular to the line joining the two plates' nearest samples.

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use crate::geometry::SphereMesh;
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType, Orogeny, ReliefMode};
use crate::systems::relief::isostasy::ocean_floor_km;
use crate::systems::resample::{GapSample, ResampleWork};

/// Elevation of ocean floor that formed at the ridge `age_my` ago: the exact solution of the
/// paper's damping law dz/dt = −(1 − z/z_t)·ε_o, starting at z_r, which approaches the trench
/// depth z_t; damping stops at the abyssal depth z_a (see the erosion system), so the profile
/// does too.
pub fn ocean_floor_elevation_km(age_my: f64, params: &Params) -> f64 {
    let o = &params.ocean;
    let k = o.damping_mm_per_yr / o.trench_elevation_km.abs().max(1e-9);
    let z = o.trench_elevation_km
        + (o.ridge_elevation_km - o.trench_elevation_km) * (-k * age_my.max(0.0)).exp();
    z.max(o.abyssal_elevation_km)
}

/// Inverse of [`ocean_floor_elevation_km`]: the age at which ridge-born crust reaches elevation
/// `z_km` (0 above the ridge height; the age of reaching the abyssal plain below it).
pub fn ocean_floor_age_my(z_km: f64, params: &Params) -> f64 {
    let o = &params.ocean;
    let k = o.damping_mm_per_yr / o.trench_elevation_km.abs().max(1e-9);
    if k <= 0.0 {
        return 0.0;
    }
    let z = z_km.clamp(o.abyssal_elevation_km, o.ridge_elevation_km);
    let ratio = (z - o.trench_elevation_km) / (o.ridge_elevation_km - o.trench_elevation_km);
    (-ratio.max(1e-12).ln() / k).max(0.0)
}

/// One gap sample turned into ridge crust: (elevation km, age My, ridge direction). With
/// `isostatic` (the isostasy phenomenon on) the elevation is the age–depth law's floor for the
/// crust's age, the one isostasy gives bare new floor; otherwise the paper's ridge profile blended
/// with the plates' edges.
pub fn ridge_crust(
    mesh: &SphereMesh,
    params: &Params,
    isostatic: bool,
    elevation_km: &[f32],
    elapsed_my: f64,
    g: &GapSample,
) -> Option<(f32, f32, [f32; 3])> {
    let a = g.nearest?;
    let q = mesh.positions[g.sample as usize];
    let z1 = elevation_km[a.seed as usize] as f64;
    let (alpha, z_bar, ridge) = match g.second {
        Some(b) => {
            let (d1, d2) = (
                a.distance_rad.min(b.distance_rad),
                a.distance_rad.max(b.distance_rad),
            );
            let z2 = elevation_km[b.seed as usize] as f64;
            let (za, zb) = if a.distance_rad <= b.distance_rad {
                (z1, z2)
            } else {
                (z2, z1)
            };
            let sum = d1 + d2;
            let alpha = if sum > 0.0 { (d2 - d1) / sum } else { 0.0 };
            let z_bar = if sum > 0.0 {
                (d2 * za + d1 * zb) / sum
            } else {
                za
            };
            let across = mesh.positions[b.seed as usize] - mesh.positions[a.seed as usize];
            let across = across - q * q.dot(across);
            let ridge = q.cross(across).try_normalize().unwrap_or(DVec3::ZERO);
            (alpha, z_bar, ridge)
        }
        None => (1.0, z1, DVec3::ZERO),
    };
    let age = alpha * elapsed_my;
    if isostatic {
        let z = ocean_floor_km(age, params);
        return Some((
            z as f32,
            age as f32,
            [ridge.x as f32, ridge.y as f32, ridge.z as f32],
        ));
    }
    let z_ridge = ocean_floor_elevation_km(age, params);
    let z = (alpha * z_bar + (1.0 - alpha) * z_ridge).min(params.ocean.ridge_elevation_km);
    Some((
        z as f32,
        age as f32,
        [ridge.x as f32, ridge.y as f32, ridge.z as f32],
    ))
}

/// Fills the gaps of the resampling in progress with new oceanic crust.
pub fn generate_oceanic_crust(
    mesh: Res<SphereMesh>,
    params: Res<Params>,
    mode: Option<Res<ReliefMode>>,
    mut work: ResMut<ResampleWork>,
) {
    if !work.active {
        return;
    }
    let work = &mut *work;
    let isostatic = mode.is_some_and(|m| m.isostatic);
    fill_ridge_crust(
        &mesh,
        &params,
        isostatic,
        work.elapsed_my,
        &work.gaps,
        &mut work.next,
    );
}

/// Writes new ridge crust into every gap sample of `next` (gaps opened over `elapsed_my`); see
/// [`ridge_crust`] for `isostatic`.
pub fn fill_ridge_crust(
    mesh: &SphereMesh,
    params: &Params,
    isostatic: bool,
    elapsed_my: f64,
    gaps: &[GapSample],
    next: &mut Crust,
) {
    let made: Vec<Option<(f32, f32, [f32; 3])>> = gaps
        .par_iter()
        .map(|g| ridge_crust(mesh, params, isostatic, &next.elevation_km, elapsed_my, g))
        .collect();
    let thickness = params.init.oceanic_thickness_km as f32;
    for (g, m) in gaps.iter().zip(made) {
        let Some((z, age, ridge)) = m else { continue };
        let j = g.sample as usize;
        next.elevation_km[j] = z;
        next.age_my[j] = age;
        next.ridge_dir[j] = ridge;
        next.thickness_km[j] = thickness;
        next.crust_type[j] = CrustType::Oceanic;
        next.orogeny[j] = Orogeny::None;
        next.orogeny_age_my[j] = 0.0;
        next.fold_dir[j] = [0.0; 3];
    }
}
