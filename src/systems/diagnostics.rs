//! Diagnostics: area statistics of the crust (land and continental fractions, elevation range,
//! plate count) and the no-NaN check, every step. Sums are taken over fixed-size chunks in a
//! fixed order so the result does not depend on the number of threads.

use bevy_ecs::prelude::*;
use rayon::prelude::*;

use crate::components::Plate;
use crate::geometry::SphereMesh;
use crate::gpu::{FieldMask, GpuContext};
use crate::resources::{Crust, CrustStats, CrustType, NonFinite};

/// Chunk size of deterministic reductions.
pub const REDUCE_CHUNK: usize = 8192;

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

/// Refreshes [`CrustStats`] and [`CrustHealth`].
///
/// On the GPU backend the elevation is pulled from the device first (lazy host sync; 4 bytes a
/// sample). The other device-written fields (ages, fold direction) are checked as of their last
/// pull, at the latest the last resampling, until a reduction kernel does the check on the
/// device (docs/gpu-residency.md, stage 1).
pub fn update_diagnostics(
    mesh: Res<SphereMesh>,
    mut crust: ResMut<Crust>,
    plates: Query<&Plate>,
    mut stats: ResMut<CrustStats>,
    mut health: ResMut<CrustHealth>,
    gpu: Option<ResMut<GpuContext>>,
) {
    if let Some(mut gpu) = gpu {
        crate::gpu::pull_or_record(&mut gpu, &mut crust, FieldMask::ELEVATION);
    }
    let crust: &Crust = &crust;
    let mut s = crust_stats(&mesh, crust);
    s.plates = plates.iter().count();
    *stats = s;
    health.0 = crust.check_finite().err();
    if let Some(e) = &health.0 {
        tracing::error!("{e}");
    }
}
