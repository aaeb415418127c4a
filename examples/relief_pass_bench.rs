//! Times the relief passes one by one on a saved planet (the fastest of repeated calls on the same
//! input), for comparing variants of a pass: `cargo run --release --example relief_pass_bench
//! -- SAVE [REPS]`. The planet is stepped once first, so that the network and the flux are
//! those of a real step.

use std::time::Instant;

use tectonic_planets::resources::Params;
use tectonic_planets::resources::{Crust, CrustType};
use tectonic_planets::systems::relief::climate::{ClimateScratch, precipitation};
use tectonic_planets::systems::relief::coast::{CoastScratch, shallow_width_km};
use tectonic_planets::systems::relief::diffusion::{DiffusionScratch, diffuse_land};
use tectonic_planets::systems::relief::drainage::{Drainage, SeaMaskScratch, sea_mask_with};
use tectonic_planets::systems::relief::sediment::SedimentRouter;
use tectonic_planets::systems::relief::stream_power::{StreamPowerScratch, stream_power_erode};
use tectonic_planets::systems::relief::{
    Precipitation, ReliefState, SurfaceFlux, climate_params, lake_area_ratio, sediment_params,
    stream_power_params,
};

/// The fastest of `reps` calls, ms (the least disturbed by the rest of a shared machine).
fn fastest_ms(mut f: impl FnMut() -> f64, reps: usize) -> f64 {
    (0..reps).map(|_| f()).fold(f64::INFINITY, f64::min)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).expect("usage: relief_pass_bench SAVE [REPS]");
    let reps: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(9);
    let mut sim = tectonic_planets::io::save::load_from_file(std::path::Path::new(path))
        .expect("load the save");
    sim.step().expect("one step");
    let w = sim.world();
    let params = w.resource::<Params>().clone();
    let crust = w.resource::<Crust>();
    let g = w
        .resource::<ReliefState>()
        .graph
        .clone()
        .expect("the graph");
    let flux = w.resource::<SurfaceFlux>();
    let rain = w.get_resource::<Precipitation>().map(|r| r.0.clone());
    let elev = crust.elevation_km.clone();
    let oceanic: Vec<bool> = crust
        .crust_type
        .iter()
        .map(|&t| t == CrustType::Oceanic)
        .collect();
    let n = g.len();
    println!("{n} samples, {reps} repetitions, fastest:");

    let mut ocean = Vec::new();
    let mut sea = SeaMaskScratch::default();
    let t = fastest_ms(
        || {
            let c = Instant::now();
            sea_mask_with(
                &g,
                &elev,
                &oceanic,
                params.rivers.min_sea_area_km2,
                &mut ocean,
                &mut sea,
            );
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!("  sea mask          {t:8.3} ms");

    let mesh = w.resource::<tectonic_planets::geometry::SphereMesh>();
    let cp = climate_params(&params);
    let mut cs = ClimateScratch::default();
    let mut out = Vec::new();
    let t = fastest_ms(
        || {
            let c = Instant::now();
            precipitation(&g, &mesh.positions, &elev, &cp, &mut out, &mut cs);
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!("  climate           {t:8.3} ms");

    let mut d = Drainage::default();
    d.lake_area_ratio = lake_area_ratio(&params);
    let t = fastest_ms(
        || {
            let c = Instant::now();
            d.compute_routes(&g, &elev, &ocean);
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!(
        "  routes            {t:8.3} ms  (receivers {:.3}, pit basins {:.3}, flood {:.3}, stack {:.3})",
        d.timings_ms[0], d.timings_ms[1], d.timings_ms[2], d.timings_ms[3]
    );
    let r = rain.as_deref().filter(|r| r.len() == n);
    let t = fastest_ms(
        || {
            let c = Instant::now();
            d.compute_areas(&g, r);
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!(
        "  areas + lakes     {t:8.3} ms  (areas {:.3}, lakes {:.3}); land {}, region {}, sinks {}",
        d.timings_ms[4],
        d.timings_ms[5],
        ocean.iter().filter(|o| !**o).count(),
        d.region_count,
        d.sinks.len()
    );

    let spl = stream_power_params(&params);
    let mut sp = StreamPowerScratch::default();
    let mut z = elev.clone();
    let mut e = vec![0.0f32; n];
    let t = fastest_ms(
        || {
            z.copy_from_slice(&elev);
            let c = Instant::now();
            stream_power_erode(
                &g,
                &d,
                &mut z,
                &mut e,
                None,
                &spl,
                params.time.time_step_my,
                &mut sp,
            );
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!("  stream power      {t:8.3} ms");

    let mut dz = vec![0.0f32; n];
    let mut to_sea = vec![0.0f64; n];
    let mut ds = DiffusionScratch::default();
    let mut substeps = 0;
    let t = fastest_ms(
        || {
            z.copy_from_slice(&elev);
            let c = Instant::now();
            substeps = diffuse_land(
                &g,
                &mut z,
                &ocean,
                params.rivers.hillslope_diffusivity_km2_per_my,
                params.time.time_step_my,
                &mut dz,
                &mut to_sea,
                &mut ds,
            )
            .substeps;
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!("  diffusion         {t:8.3} ms  ({substeps} substeps)");

    let mut cs = CoastScratch::default();
    let t = fastest_ms(
        || {
            let c = Instant::now();
            shallow_width_km(
                &g,
                &ocean,
                &elev,
                params.coasts.open_water_depth_m * 1e-3,
                &mut cs,
            );
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!("  shallow widths    {t:8.3} ms");

    let sp = sediment_params(&params);
    let (fill, passages) = w.resource::<ReliefState>().sediment_inputs();
    let fill = (fill.len() == n).then_some(fill);
    let mut router = SedimentRouter::new();
    router.passages_mut().extend_from_slice(passages);
    let mut dep = vec![0.0f32; n];
    let t = fastest_ms(
        || {
            let c = Instant::now();
            router.route(
                &g,
                &d,
                &elev,
                &flux.eroded_km,
                Some(&flux.to_ocean_km3),
                fill,
                &sp,
                &mut dep,
            );
            c.elapsed().as_secs_f64() * 1e3
        },
        reps,
    );
    println!(
        "  sediment route    {t:8.3} ms  (setup {:.3}, land {:.3}, sea {:.3}, net and write {:.3}; last call)",
        router.timings_ms[0], router.timings_ms[1], router.timings_ms[2], router.timings_ms[3]
    );
}
