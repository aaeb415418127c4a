//! The long run of the convergence work: the default planet over 1000 My, printing continental
//! area, land fraction, highest elevation and plate count every 100 My.
//! `cargo run --release --example long_run -- [samples] [seeds...]` (environment: `PLANET_LOG`
//! for logs, `INTERPENETRATION` and `TRAPPED` to try other collision thresholds, in km and km²).
use tectonic_planets::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    if let Ok(f) = tracing_subscriber::EnvFilter::try_from_env("PLANET_LOG") {
        tracing_subscriber::fmt()
            .with_env_filter(f)
            .with_writer(std::io::stderr)
            .init();
    }
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let samples = args.first().copied().unwrap_or(100_000);
    let seeds: Vec<u64> = if args.len() > 1 {
        args[1..].to_vec()
    } else {
        vec![1, 2, 3, 4, 5]
    };
    for seed in seeds {
        let mut p = Params::default();
        p.planet.samples = samples;
        p.planet.seed = seed;
        if let Ok(v) = std::env::var("INTERPENETRATION") {
            p.collision.interpenetration_km = v.parse()?;
        }
        if let Ok(v) = std::env::var("TRAPPED") {
            p.collision.trapped_ocean_km2 = v.parse()?;
        }
        let mut sim = Simulation::new(p)?;
        let c0 = sim.stats().continental_fraction;
        let t = std::time::Instant::now();
        let (mut lo, mut hi, mut zmax, mut worst) = (1.0f64, 0.0f64, f32::MIN, 0.0f64);
        for step in 1..=500 {
            sim.step()?;
            let s = sim.stats().clone();
            lo = lo.min(s.land_fraction);
            hi = hi.max(s.land_fraction);
            zmax = zmax.max(s.elevation_range_km.1);
            worst = worst.max((s.continental_fraction - c0).abs() / c0);
            if step % 50 == 0 {
                let lost = sim
                    .world()
                    .resource::<tectonic_planets::systems::resample::ResampleWork>()
                    .continental_subducted_total_km2;
                let total = sim.mesh().total_area_km2();
                println!(
                    "   subducted continental so far: {:.3} of the surface; collisions {}",
                    lost / total,
                    sim.world()
                        .resource::<tectonic_planets::resources::Sutures>()
                        .total
                );
                println!(
                    "seed {seed} {:>5.0} My: continental {:.3} ({:+.1}%), land {:.3}, max {:.2} km, plates {}",
                    sim.time_my(),
                    s.continental_fraction,
                    100.0 * (s.continental_fraction - c0) / c0,
                    s.land_fraction,
                    s.elevation_range_km.1,
                    s.plates
                );
            }
        }
        println!(
            "seed {seed}: land {lo:.3}..{hi:.3}, highest {zmax:.2} km, worst continental change {:.1}%, {:.1} s",
            100.0 * worst,
            t.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
