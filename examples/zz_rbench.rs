//! Throwaway relief pass timing (not committed).
use tectonic_planets::prelude::*;
use tectonic_planets::resources::CrustType;
use tectonic_planets::systems::relief::coast::{CoastScratch, coast_params, coastal_erosion};
use tectonic_planets::systems::relief::diffusion::{DiffusionScratch, diffuse_land};
use tectonic_planets::systems::relief::drainage::{Drainage, SeaMaskScratch, sea_mask_with};
use tectonic_planets::systems::relief::network::relief_graph;
use tectonic_planets::systems::relief::sediment::SedimentRouter;
use tectonic_planets::systems::relief::stream_power::{StreamPowerScratch, stream_power_erode};
use tectonic_planets::systems::relief::{sediment_params, stream_power_params};

fn cpu_ms() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 * 1e-6
}
struct Instant(f64);
impl Instant {
    fn now() -> Self {
        if std::env::var("CPU").is_ok() {
            Instant(cpu_ms())
        } else {
            Instant(
                std::time::Instant::now()
                    .duration_since(*START.get_or_init(std::time::Instant::now))
                    .as_secs_f64()
                    * 1e3,
            )
        }
    }
    fn elapsed(&self) -> std::time::Duration {
        let now = Instant::now().0;
        std::time::Duration::from_secs_f64(((now - self.0) * 1e-3).max(0.0))
    }
}
static START: std::sync::OnceLock<std::time::Instant> = std::sync::OnceLock::new();
fn med(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let samples: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(500_000);
    let my: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let mut params = Params::default();
    params.planet.samples = samples;
    let mut sim = Simulation::new(params.clone()).unwrap();
    let steps = sim.steps_for(my).unwrap();
    sim.run_steps(steps).unwrap();
    let mesh = sim.mesh().clone();
    let crust0 = sim.crust().clone();
    let g = relief_graph(&mesh);
    let oceanic: Vec<bool> = crust0
        .crust_type
        .iter()
        .map(|&t| t == CrustType::Oceanic)
        .collect();
    let mut sea = SeaMaskScratch::default();
    let mut ocean = Vec::new();
    let mut dr = Drainage::new();
    dr.lake_area_ratio = tectonic_planets::systems::relief::lake_area_ratio(&params);
    let mut spl = StreamPowerScratch::default();
    let mut dif = DiffusionScratch::default();
    let mut cs = CoastScratch::default();
    let mut router = SedimentRouter::new();
    let sp = stream_power_params(&params);
    let sedp = sediment_params(&params);
    let cp = coast_params(&params);
    let n = mesh.len();
    let reps: usize = std::env::var("REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(9);
    let (mut tm, mut td, mut ts, mut tdf, mut tc, mut tr) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut sub = vec![vec![]; 5];
    for _ in 0..reps {
        let mut c = crust0.clone();
        let t = Instant::now();
        sea_mask_with(
            &g,
            &c.elevation_km,
            &oceanic,
            params.rivers.min_sea_area_km2,
            &mut ocean,
            &mut sea,
        );
        tm.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        dr.compute(&g, &c.elevation_km, &ocean, None);
        td.push(t.elapsed().as_secs_f64() * 1e3);
        for k in 0..5 {
            sub[k].push(dr.timings_ms[k]);
        }
        let mut eroded = vec![0f32; n];
        let t = Instant::now();
        stream_power_erode(
            &g,
            &dr,
            &mut c.elevation_km,
            &mut eroded,
            None,
            &sp,
            2.0,
            &mut spl,
        );
        ts.push(t.elapsed().as_secs_f64() * 1e3);
        let mut delta = vec![0f32; n];
        let mut to_ocean = vec![0f64; n];
        let t = Instant::now();
        diffuse_land(
            &g,
            &mut c.elevation_km,
            &dr.ocean,
            params.rivers.hillslope_diffusivity_km2_per_my,
            2.0,
            &mut delta,
            &mut to_ocean,
            &mut dif,
        );
        tdf.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let mut th = c.thickness_km.clone();
        coastal_erosion(
            &g,
            &dr.ocean,
            &mut c.elevation_km,
            &mut th,
            &mut eroded,
            &cp,
            2.0,
            &mut cs,
        );
        tc.push(t.elapsed().as_secs_f64() * 1e3);
        let mut dep = vec![0f32; n];
        let t = Instant::now();
        router.route(
            &g,
            &dr,
            &c.elevation_km,
            &eroded,
            Some(&to_ocean),
            None,
            &sedp,
            &mut dep,
        );
        tr.push(t.elapsed().as_secs_f64() * 1e3);
    }
    println!(
        "n={n} pits={} region={} lakes={}",
        dr.pit_count, dr.region_count, dr.lake_sample_count
    );
    println!(
        "sea_mask {:.2}  drainage {:.2} [recv {:.2} basins {:.2} flood {:.2} stack {:.2} area {:.2}]",
        med(tm),
        med(td),
        med(sub[0].clone()),
        med(sub[1].clone()),
        med(sub[2].clone()),
        med(sub[3].clone()),
        med(sub[4].clone())
    );
    println!(
        "stream_power {:.2} diffusion {:.2} coasts {:.2} sediment {:.2}",
        med(ts),
        med(tdf),
        med(tc),
        med(tr)
    );
}
