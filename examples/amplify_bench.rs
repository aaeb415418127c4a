//! Times the parts of amplification on a saved planet: point location, the per-point relief,
//! and a streamed global export. `cargo run --release --example amplify_bench -- SAVE [WIDTH]`.

use std::time::Instant;

use tectonic_planets::amplify::{Amplifier, AmplifyOptions};
use tectonic_planets::io::export::GeoGrid;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| anyhow::anyhow!("usage: amplify_bench SAVE [WIDTH]"))?;
    let width: u32 = args.next().map_or(Ok(2048), |w| w.parse())?;
    let mut sim = tectonic_planets::io::save::load_from_file(std::path::Path::new(&path))?;
    let seed = sim.params().planet.seed;
    let view = sim.resampled_crust();
    let amp = Amplifier::new(sim.mesh(), &view, seed, AmplifyOptions::default());
    let grid = GeoGrid::global(width, width / 2)?;
    let n = f64::from(width) * f64::from(width / 2);
    for (name, f) in [
        (
            "locate only",
            &(|d| amp.query(d).w0) as &(dyn Fn(glam::DVec3) -> f32 + Sync),
        ),
        ("crust elevation", &|d| amp.crust_elevation_m(d)),
        ("amplified elevation", &|d| amp.elevation_m(d)),
    ] {
        let t = Instant::now();
        let v = grid.sample(&|d| f(d));
        let s = t.elapsed().as_secs_f64();
        println!(
            "{name:<22} {width}x{}: {s:.2} s ({:.0} ns/pixel on {} threads) checksum {}",
            width / 2,
            s * 1e9 / n,
            rayon::current_num_threads(),
            v.iter().map(|&x| f64::from(x)).sum::<f64>()
        );
    }
    for (name, f) in [
        (
            "locate, hinted",
            &(|d, h: &mut u32| amp.query_hinted(d, h).w0)
                as &(dyn Fn(glam::DVec3, &mut u32) -> f32 + Sync),
        ),
        ("amplified, hinted", &|d, h: &mut u32| {
            amp.elevation_m_hinted(d, h)
        }),
    ] {
        let t = Instant::now();
        let v = grid.sample_hinted(&|d, h| f(d, h));
        let s = t.elapsed().as_secs_f64();
        println!(
            "{name:<22} {width}x{}: {s:.2} s ({:.0} ns/pixel on {} threads) checksum {}",
            width / 2,
            s * 1e9 / n,
            rayon::current_num_threads(),
            v.iter().map(|&x| f64::from(x)).sum::<f64>()
        );
    }
    Ok(())
}
