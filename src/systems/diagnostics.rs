//! Diagnostics: area statistics of the crust (land and continental fractions, elevation range,
//! plate count) and the no-NaN check, every step. Sums are taken over fixed-size chunks in a
//! fixed order so the result does not depend on the number of threads.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::components::Plate;
use crate::geometry::SphereMesh;
use crate::gpu::crust_reduce::REDUCE_CHUNK;
use crate::gpu::{FieldMask, GpuContext};
use crate::resources::{Crust, CrustStats, CrustType, NonFinite};

/// Area-weighted land and continental fractions and the elevation range of a crust.
pub fn crust_stats(mesh: &SphereMesh, crust: &Crust) -> CrustStats {
    let partial: Vec<(f64, f64, f64, f32, f32)> = crust
        .elevation_km
        .par_chunks(REDUCE_CHUNK)
        .zip(crust.crust_type.par_chunks(REDUCE_CHUNK))
        .zip(mesh.area_km2.par_chunks(REDUCE_CHUNK))
        .map(|((z, t), a)| {
            let (mut total, mut land, mut cont) = (0.0, 0.0, 0.0);
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for k in 0..z.len() {
                total += a[k];
                if z[k] > 0.0 {
                    land += a[k];
                }
                if t[k] == CrustType::Continental {
                    cont += a[k];
                }
                lo = lo.min(z[k]);
                hi = hi.max(z[k]);
            }
            (total, land, cont, lo, hi)
        })
        .collect();
    let (mut total, mut land, mut cont) = (0.0, 0.0, 0.0);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for (t, l, c, a, b) in partial {
        total += t;
        land += l;
        cont += c;
        lo = lo.min(a);
        hi = hi.max(b);
    }
    CrustStats {
        land_fraction: land / total.max(f64::MIN_POSITIVE),
        continental_fraction: cont / total.max(f64::MIN_POSITIVE),
        plates: 0,
        elevation_range_km: (lo, hi),
    }
}

/// The first non-finite crust value found by the last diagnostics pass, if any.
#[derive(Resource, Clone, Debug, Default, PartialEq, Eq)]
pub struct CrustHealth(pub Option<NonFinite>);

/// The fields the diagnostics reduction kernel checks on the device.
const REDUCED: FieldMask = FieldMask(
    FieldMask::ELEVATION.0 | FieldMask::AGE.0 | FieldMask::OROGENY_AGE.0 | FieldMask::FOLD_DIR.0,
);

/// Refreshes [`CrustStats`] and [`CrustHealth`].
///
/// On the GPU backend, when the device holds fields newer than the host (lazy host sync), the
/// reduction kernel ([`crate::gpu::crust_reduce`]) computes the land bitmask, the elevation
/// range and the first non-finite index of the device-written fields on the device (N/8 bytes
/// read back instead of the elevation); the land area is summed on the host in the chunk order
/// of [`crust_stats`], so the results are the CPU path's. Thickness is pulled first when the
/// device thickened the crust; it, the ridge direction and any reduced field not newer on the
/// device are checked on the host. If the kernel fails, the error is recorded and the elevation is pulled instead.
pub fn update_diagnostics(
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    plates: Query<&Plate>,
    mut stats: ResMut<CrustStats>,
    mut health: ResMut<CrustHealth>,
    gpu: Option<ResMut<GpuContext>>,
) {
    let mut reduced = None;
    if let Some(mut gpu) = gpu {
        // Thickness is not reduced on the device: bring it over when a kernel thickened the
        // crust, so the host check below reads it current.
        crate::gpu::pull_or_record(&mut gpu, &mut crust, FieldMask::THICKNESS);
        let newer = gpu.device_newer().and(REDUCED);
        if !newer.is_empty() && gpu.failure.is_none() {
            match crate::gpu::crust_reduce::crust_reduce_gpu(&mut gpu) {
                Ok(r) => reduced = Some((r, newer)),
                Err(e) => gpu.record_failure(e),
            }
        }
        if reduced.is_none() {
            crate::gpu::pull_or_record(&mut gpu, &mut crust, REDUCED);
        }
    }
    let crust: &Crust = &crust;
    let mut s;
    match &reduced {
        Some((r, newer)) => {
            s = if newer.contains(FieldMask::ELEVATION) {
                crate::gpu::crust_reduce::stats_from_reduction(&mesh, &crust.crust_type, r)
            } else {
                crust_stats(&mesh, crust)
            };
            health.0 = check_finite_with(crust, r, *newer);
        }
        None => {
            s = crust_stats(&mesh, crust);
            health.0 = crust.check_finite().err();
        }
    }
    s.plates = plates.iter().count();
    *stats = s;
    // A non-finite value stops the simulation at the end of the step, which reports it.
}

/// `Crust::check_finite` with the fields of `newer` taken from the device reduction `r` (same
/// field order, so the same first error).
pub fn check_finite_with(
    crust: &Crust,
    r: &crate::gpu::crust_reduce::CrustReduction,
    newer: FieldMask,
) -> Option<NonFinite> {
    use crate::resources::crust::{first_non_finite as host, first_non_finite3 as host3};
    let pick = |m: FieldMask, k: usize, h: &dyn Fn() -> Option<usize>| {
        if newer.contains(m) {
            r.first_non_finite[k]
        } else {
            h()
        }
    };
    let order: [(&'static str, Option<usize>); 6] = [
        (
            "elevation_km",
            pick(FieldMask::ELEVATION, 0, &|| host(&crust.elevation_km)),
        ),
        ("thickness_km", host(&crust.thickness_km)),
        ("age_my", pick(FieldMask::AGE, 1, &|| host(&crust.age_my))),
        (
            "orogeny_age_my",
            pick(FieldMask::OROGENY_AGE, 2, &|| host(&crust.orogeny_age_my)),
        ),
        ("ridge_dir", host3(&crust.ridge_dir)),
        (
            "fold_dir",
            pick(FieldMask::FOLD_DIR, 3, &|| host3(&crust.fold_dir)),
        ),
    ];
    order
        .into_iter()
        .find_map(|(field, i)| i.map(|index| NonFinite { field, index }))
}
