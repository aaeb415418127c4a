//! Helpers shared by the integration tests.
#![allow(dead_code)]

use tectonic_planets::geometry::SphereMesh;
use tectonic_planets::prelude::*;

/// Default parameters at a given resolution and seed.
pub fn params(samples: u64, seed: u64) -> Params {
    let mut p = Params::default();
    p.planet.samples = samples;
    p.planet.seed = seed;
    p
}

/// Runs `f` inside a pool of `threads` worker threads (for results that must not depend on the
/// thread count).
pub fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("thread pool")
        .install(f)
}

/// A small, busy planet: 12 plates, resampled every 4 to 9 steps (collisions, lakes and
/// resamplings come within a few tens of steps).
pub fn small_params(samples: u64, seed: u64) -> Params {
    let mut p = params(samples, seed);
    p.init.plates = 12;
    p.resample.min_interval_steps = 4;
    p.resample.max_interval_steps = 9;
    p
}

/// The surface processes of the relief (isostasy, drainage, rivers, coasts, sediment): tests of moving,
/// resampling or the paper's kernels switch them off.
pub const RELIEF: [&str; 5] = ["isostasy", "drainage", "rivers", "coasts", "sediment"];

/// Switches the relief phenomena off and the paper's erosion law on: the relief as the paper
/// makes it (uplift raises the elevation, trenches are cut into it), for tests of those kernels.
pub fn paper_relief(sim: &mut Simulation) {
    for name in RELIEF {
        sim.set_enabled(name, false).unwrap();
    }
    sim.set_enabled("erosion", true).unwrap();
}

/// Area of the samples selected by `pick`, km².
pub fn area_where(mesh: &SphereMesh, pick: impl Fn(usize) -> bool) -> f64 {
    (0..mesh.len())
        .filter(|&i| pick(i))
        .map(|i| mesh.area_km2[i])
        .sum()
}

/// Continental area of a crust, km².
pub fn continental_area(mesh: &SphereMesh, crust: &Crust) -> f64 {
    area_where(mesh, |i| crust.crust_type[i] == CrustType::Continental)
}

/// Spearman rank correlation of two equally long samples.
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    fn ranks(v: &[f64]) -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        let mut k = 0;
        while k < idx.len() {
            let mut e = k;
            while e + 1 < idx.len() && v[idx[e + 1]] == v[idx[k]] {
                e += 1;
            }
            let avg = (k + e) as f64 / 2.0;
            for &i in &idx[k..=e] {
                r[i] = avg;
            }
            k = e + 1;
        }
        r
    }
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let cov: f64 = ra.iter().zip(&rb).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = ra.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = rb.iter().map(|y| (y - mb).powi(2)).sum();
    cov / (va * vb).sqrt()
}

/// Connected pieces of the samples with `same(i, j)`, as lists of sample indices.
pub fn components(
    mesh: &SphereMesh,
    member: impl Fn(usize) -> bool,
    same: impl Fn(usize, usize) -> bool,
) -> Vec<Vec<usize>> {
    let n = mesh.len();
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    for s in 0..n {
        if seen[s] || !member(s) {
            continue;
        }
        let mut comp = vec![s];
        seen[s] = true;
        let mut k = 0;
        while k < comp.len() {
            let u = comp[k];
            k += 1;
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                if !seen[v] && member(v) && same(u, v) {
                    seen[v] = true;
                    comp.push(v);
                }
            }
        }
        out.push(comp);
    }
    out
}

/// A GPU adapter (lavapipe on CI), or None with a message when there is none outside CI; on CI
/// (`CI=true`) a missing adapter is a failure.
pub fn gpu_or_skip(test: &str) -> Option<tectonic_planets::gpu::GpuContext> {
    use tectonic_planets::gpu::{BackendChoice, select_backend};
    match select_backend(BackendChoice::Gpu) {
        Ok(s) => s.context,
        Err(e) => {
            if std::env::var("CI").is_ok_and(|v| v == "true") {
                panic!("{test}: no GPU adapter on CI (is mesa-vulkan-drivers installed?): {e}");
            }
            eprintln!("{test}: SKIPPED, no GPU adapter: {e}");
            None
        }
    }
}

/// A fresh seed each run (from the clock), or the value of the environment variable `replay`
/// to replay one.
pub fn fresh_seed(replay: &str) -> u64 {
    if let Some(s) = std::env::var(replay).ok().and_then(|s| s.parse().ok()) {
        return s;
    }
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(1)
}

/// A random crust of `n` samples for kernel parity tests: elevations uniform in `elevation_km`,
/// half continental, a third of it in each orogeny (none, Andean, Himalayan), ages up to 300 My,
/// orogeny ages up to `orogeny_age_max_my`, random fold and ridge directions.
pub fn random_crust(
    n: usize,
    rng: &mut tectonic_planets::random::SimRng,
    elevation_km: (f64, f64),
    orogeny_age_max_my: f64,
) -> Crust {
    let mut c = Crust::with_len(n);
    let v = |rng: &mut tectonic_planets::random::SimRng| {
        [
            (rng.next_f64() - 0.5) as f32,
            (rng.next_f64() - 0.5) as f32,
            (rng.next_f64() - 0.5) as f32,
        ]
    };
    let (lo, hi) = elevation_km;
    for i in 0..n {
        c.elevation_km[i] = (lo + rng.next_f64() * (hi - lo)) as f32;
        c.crust_type[i] = if rng.next_f64() < 0.5 {
            CrustType::Continental
        } else {
            CrustType::Oceanic
        };
        c.age_my[i] = (rng.next_f64() * 300.0) as f32;
        c.orogeny[i] = match (rng.next_f64() * 3.0) as u32 {
            0 => Orogeny::None,
            1 => Orogeny::Andean,
            _ => Orogeny::Himalayan,
        };
        c.orogeny_age_my[i] = (rng.next_f64() * orogeny_age_max_my) as f32;
        c.fold_dir[i] = v(rng);
        c.ridge_dir[i] = v(rng);
    }
    c
}

/// The water below sea level on `sim`'s surface, as the depth of a layer over the whole globe
/// (km): Σ a·max(0, −z) / Σ a.
pub fn water_layer_km(sim: &Simulation) -> f64 {
    let mesh = sim.mesh();
    tectonic_planets::systems::relief::sea_level::ocean_volume_km3(
        &sim.crust().elevation_km,
        &mesh.area_km2,
    ) / mesh.total_area_km2()
}
