//! Subduction uplift (paper §4.1): the overriding plate rises by u0·f(d)·g(v)·h(z̃) near its
//! fronts (and its crust thickens by that rise over 1 − ρ_c/ρ_m, so that once isostasy
//! compensates it the surface stands that much higher; see [`crate::systems::relief`]), with Andean orogeny and fold directions; the subducting plate bends into a trench.
//! CPU kernel [`subduction_uplift_cpu`], GPU kernel [`crate::gpu::subduction_uplift`]. See
//! [`super`] for the model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::gpu::subduction_uplift::UpliftConstants;
use crate::gpu::{FieldMask, GpuContext, run_or_record};
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{ConvergenceField, Crust, CrustType, FrontPoints, Orogeny, ReliefMode};

/// Driftworld's cubic distance transfer: 1 at the control distance `rc`, 0 at `rs` (and beyond),
/// clipped at 0 near the front.
pub fn distance_transfer(d: f64, rc: f64, rs: f64) -> f64 {
    if d >= rs {
        return 0.0;
    }
    let num = d.powi(3) / 3.0 - (rc + rs) * d * d / 2.0 + rc * rs * d + rs.powi(3) / 6.0
        - rs * rs * rc / 2.0;
    let den = (rs.powi(3) - rc.powi(3)) / 6.0 + (rc * rc * rs - rs * rs * rc) / 2.0;
    if den.abs() < 1e-12 {
        return 0.0;
    }
    (num / den).max(0.0)
}

/// The CPU kernel (reference of `shaders/subduction_uplift.wgsl`): one step of subduction
/// uplift, fold directions, Andean orogeny and trenches on every sample, in place. `field` must
/// have one entry per sample of `crust`.
pub fn subduction_uplift_cpu(
    k: &UpliftConstants,
    fp: &FrontPoints,
    field: &ConvergenceField,
    crust: &mut Crust,
) {
    let UpliftConstants {
        rs,
        rc,
        dt,
        u0,
        v0,
        z_t,
        z_c,
        z_a,
        beta,
        wt,
        rate,
        z_r,
        thickening,
        max_thickness_km,
        oceanic_thickening,
        max_oceanic_thickness_km,
        isostatic,
    } = *k;
    (
        crust.elevation_km.par_iter_mut(),
        crust.thickness_km.par_iter_mut(),
        crust.orogeny.par_iter_mut(),
        crust.orogeny_age_my.par_iter_mut(),
        crust.fold_dir.par_iter_mut(),
        crust.crust_type.par_iter(),
        field.overriding_distance_km.par_iter(),
        field.overriding_point.par_iter(),
        field.subducting_distance_km.par_iter(),
        field.subducting_point.par_iter(),
    )
        .into_par_iter()
        .with_min_len(4096)
        .for_each(|(z, th, og, oga, fold, ct, &od, &op, &sd, &sp)| {
            if op != NONE && (od as f64) < rs && fp.active[op as usize] {
                let k = op as usize;
                let rel = fp.relative_velocity[k];
                let zs = fp.subducting_elevation_km[k] as f64;
                let zn = ((zs - z_t) / (z_c - z_t)).clamp(0.0, 1.0);
                let u = u0
                    * distance_transfer(od as f64, rc, rs)
                    * (rel.length() / v0).min(1.0)
                    * zn
                    * zn;
                if u > 0.0 {
                    if isostatic {
                        let (gain, cap) = match *ct {
                            CrustType::Continental => (thickening, max_thickness_km),
                            CrustType::Oceanic => (oceanic_thickening, max_oceanic_thickness_km),
                        };
                        // Never thinner than it was: the cap only stops thickening.
                        *th = (*th + (u * dt * gain) as f32).min((cap as f32).max(*th));
                        if *z > 0.0 && u * dt > 1e-4 {
                            *og = Orogeny::Andean;
                            *oga = 0.0;
                        }
                    } else {
                        let znew = (*z as f64 + u * dt).min(z_c);
                        *z = znew as f32;
                        if znew > 0.0 && u * dt > 1e-4 {
                            *og = Orogeny::Andean;
                            *oga = 0.0;
                        }
                    }
                    let f = rel * (beta * dt);
                    fold[0] += f.x as f32;
                    fold[1] += f.y as f32;
                    fold[2] += f.z as f32;
                }
            }
            // Only ocean floor makes a trench (not oceanic specks stranded among continents);
            // with isostatic relief the trench is isostasy's (which reads `FrontPoints::trench`;
            // the paper's trench here keeps the active points, as the GPU kernel does).
            if !isostatic
                && sp != NONE
                && *ct == CrustType::Oceanic
                && (*z as f64) < z_r
                && fp.active[sp as usize]
            {
                let d = sd as f64 - fp.converged_km[sp as usize] as f64;
                if (0.0..wt).contains(&d) {
                    let target = z_t + (z_a - z_t) * (d / wt);
                    let zc = *z as f64;
                    if zc > target {
                        *z = (zc + (target - zc) * rate) as f32;
                    }
                }
            }
        });
}

/// Subduction uplift on overriding plates, fold directions, Andean orogeny, and trenches on
/// subducting plates (see the module documentation), on the GPU when a [`GpuContext`] is
/// installed, with [`subduction_uplift_cpu`] otherwise.
pub fn subduction_uplift(
    params: Res<Params>,
    fp: Res<FrontPoints>,
    field: Res<ConvergenceField>,
    mode: Res<ReliefMode>,
    mut crust: ResMut<Crust>,
    gpu: Option<ResMut<GpuContext>>,
) {
    if fp.is_empty() || field.overriding_point.len() != crust.len() {
        return;
    }
    let k = UpliftConstants::new(&params).with_isostasy(mode.isostatic);
    if let Some(mut gpu) = gpu {
        let (tick, field_tick) = (crust.last_changed(), field.last_changed());
        let done = run_or_record(&mut gpu, |g| {
            g.sync_crust(&crust, Some(tick))?;
            crate::gpu::subduction_uplift::subduction_uplift_dispatch(
                g,
                &k,
                &fp,
                &field,
                Some(field_tick),
            )?;
            // The host copy is pulled lazily, by the next CPU reader (see gpu::FieldMask).
            // Isostatic relief thickens the crust; the paper's raises the elevation.
            let relief = if k.isostatic {
                FieldMask::THICKNESS
            } else {
                FieldMask::ELEVATION
            };
            g.note_device_write(
                relief | FieldMask::OROGENY | FieldMask::OROGENY_AGE | FieldMask::FOLD_DIR,
                crust.bypass_change_detection(),
            )
        });
        if done {
            return;
        }
    }
    subduction_uplift_cpu(&k, &fp, &field, &mut crust);
}
