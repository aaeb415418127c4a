//! The run summary (`summary.json`) and the crust sampler that maps and exports read.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::geometry::SphereMesh;
use crate::io::hypsometry::Hypsometry;
use crate::io::maps::{MapSample, SphereField};
use crate::resources::{Crust, CrustType};
use crate::simulation::Simulation;

/// Elevation percentiles by area, metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ElevationSummary {
    /// Lowest elevation.
    pub min: f64,
    /// 1st percentile by area.
    pub p01: f64,
    /// Median by area.
    pub p50: f64,
    /// 99th percentile by area.
    pub p99: f64,
    /// Highest elevation.
    pub max: f64,
}

/// What `summary.json` holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Random seed.
    pub seed: u64,
    /// Number of samples.
    pub samples: usize,
    /// Number of plates at the end.
    pub plates: usize,
    /// Steps taken.
    pub steps: u64,
    /// Simulated time, My.
    pub time_my: f64,
    /// Fraction of the area above sea level.
    pub land_fraction: f64,
    /// Fraction of the area of continental crust.
    pub continental_fraction: f64,
    /// Elevation percentiles, metres.
    pub elevation_m: ElevationSummary,
    /// Median wall time per system set and for one resampling, milliseconds.
    pub timings_ms: BTreeMap<String, f64>,
    /// Global resamplings performed.
    pub resamplings: u64,
    /// The relief against Earth's: bands, means, the ocean mode, the W1 gap.
    pub hypsometry: Hypsometry,
    /// Lakes and basins of the final surface (written by `generate`; absent from summaries
    /// made without a drainage network).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drainage: Option<crate::io::rivers::DrainageSummary>,
}

/// Area-weighted elevation percentiles of a crust, metres.
pub fn elevation_summary(mesh: &SphereMesh, crust: &Crust) -> ElevationSummary {
    let mut pairs: Vec<(f32, f64)> = crust
        .elevation_km
        .iter()
        .copied()
        .zip(mesh.area_km2.iter().copied())
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum();
    let quantile = |q: f64| -> f64 {
        let target = q * total;
        let mut acc = 0.0;
        for &(z, a) in &pairs {
            acc += a;
            if acc >= target {
                return z as f64 * 1000.0;
            }
        }
        pairs.last().map_or(0.0, |p| p.0 as f64 * 1000.0)
    };
    ElevationSummary {
        min: pairs.first().map_or(0.0, |p| p.0 as f64 * 1000.0),
        p01: quantile(0.01),
        p50: quantile(0.5),
        p99: quantile(0.99),
        max: pairs.last().map_or(0.0, |p| p.0 as f64 * 1000.0),
    }
}

/// Builds the summary of `sim` from its resampled crust `view`.
pub fn summarize(sim: &Simulation, view: &Crust) -> Summary {
    let mesh = sim.mesh();
    let stats = crate::systems::diagnostics::crust_stats(mesh, view);
    let mut plates: Vec<u32> = view.plate.clone();
    plates.sort_unstable();
    plates.dedup();
    let timings = sim.timings();
    let timings_ms = timings
        .names()
        .filter_map(|n| timings.median_ms(n).map(|m| (n.to_string(), m)))
        .collect();
    Summary {
        seed: sim.params().planet.seed,
        samples: mesh.len(),
        plates: plates.len(),
        steps: sim.clock().step,
        time_my: sim.clock().time_my,
        land_fraction: stats.land_fraction,
        continental_fraction: stats.continental_fraction,
        elevation_m: elevation_summary(mesh, view),
        timings_ms,
        resamplings: sim.clock().resamplings,
        hypsometry: Hypsometry {
            ocean_age_depth_r_normal_floor: normal_floor_age_depth_r(sim),
            sea_level_m: sea_level_m(sim),
            ..crate::io::hypsometry::hypsometry(mesh, view)
        },
        drainage: None,
    }
}

/// [`Hypsometry::sea_level_m`] of the live isostasy: None with the sea fixed at the datum.
fn sea_level_m(sim: &Simulation) -> Option<f64> {
    if sim.params().isostasy.ocean_volume_layer_km <= 0.0 {
        return None;
    }
    let state = sim
        .world()
        .get_resource::<crate::systems::relief::ReliefState>()?;
    Some(state.sea_level_km * 1000.0)
}

/// [`Hypsometry::ocean_age_depth_r_normal_floor`] of the live crust: its samples outside the
/// trenches the isostasy cut this step, with at most
/// [`crate::io::hypsometry::normal_floor_max_load_km`] over the normal oceanic thickness. None
/// without the isostasy's trench field.
fn normal_floor_age_depth_r(sim: &Simulation) -> Option<f64> {
    let crust = sim.crust();
    let state = sim
        .world()
        .get_resource::<crate::systems::relief::ReliefState>()?;
    let trench = &state.trench_km;
    if trench.len() != crust.len() {
        return None;
    }
    let p = sim.params();
    let max_t =
        (p.init.oceanic_thickness_km + crate::io::hypsometry::normal_floor_max_load_km(p)) as f32;
    crate::io::hypsometry::age_depth_r_where(sim.mesh(), crust, |i| {
        trench[i] <= 0.0 && crust.thickness_km[i] <= max_t
    })
}

/// Samples a crust on the reference mesh at any direction (barycentric for scalars, nearest
/// vertex for categories), for maps.
pub struct CrustSampler<'a> {
    /// The mesh.
    pub mesh: &'a SphereMesh,
    /// A crust in the reference (world) frame, e.g. from `Simulation::resampled_crust`.
    pub crust: &'a Crust,
}

impl SphereField for CrustSampler<'_> {
    fn sample(&self, dir: [f64; 3]) -> MapSample {
        let q = glam::DVec3::from_array(dir).normalize();
        let loc = self.mesh.locate(q);
        let t = self.mesh.triangles[loc.triangle as usize];
        let w = loc.weights;
        let lerp = |f: &[f32]| {
            (w[0] * f[t[0] as usize] as f64
                + w[1] * f[t[1] as usize] as f64
                + w[2] * f[t[2] as usize] as f64) as f32
        };
        let d = t[loc.dominant_corner()] as usize;
        MapSample {
            elevation_m: lerp(&self.crust.elevation_km) * 1000.0,
            plate: self.crust.plate[d],
            continental: self.crust.crust_type[d] == CrustType::Continental,
            age_my: lerp(&self.crust.age_my),
        }
    }
}
