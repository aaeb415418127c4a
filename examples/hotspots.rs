//! Generates a planet with hotspots on and writes its maps, then lists the hotspots and the
//! chains of edifices they left (position in pixels of the maps, age, height).
//!
//! `cargo run --release --example hotspots -- [samples] [my] [out] [width]` (defaults: 500000,
//! 250, `out/hotspots`, 2048). Also writes `elevation_chain.png`, the part of the elevation map
//! around the hotspot with the longest chain.

use std::path::PathBuf;

use tectonic_planets::geometry::to_lat_lon_deg;
use tectonic_planets::io::maps::{Raster, write_all_maps};
use tectonic_planets::io::summary::CrustSampler;
use tectonic_planets::plugins::hotspots::{Edifice, Hotspot};
use tectonic_planets::prelude::*;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let samples: u64 = args.first().map_or(Ok(500_000), |s| s.parse())?;
    let my: f64 = args.get(1).map_or(Ok(250.0), |s| s.parse())?;
    let out = PathBuf::from(args.get(2).map_or("out/hotspots", |s| s.as_str()));
    let mut params = Params::default();
    params.planet.samples = samples;
    let mut sim = Simulation::new(params)?;
    sim.set_enabled("hotspots", true)?;
    sim.run_for(my)?;
    let width: u32 = args.get(3).map_or(Ok(2048), |s| s.parse())?;
    let px = |p: DVec3| {
        let (lat, lon) = to_lat_lon_deg(p);
        (
            ((lon + 180.0) / 360.0 * width as f64) as i64,
            ((90.0 - lat) / 180.0 * (width / 2) as f64) as i64,
        )
    };
    let world = sim.world_mut();
    let frames: Vec<(u32, DQuat)> = world
        .query::<(&Plate, &PlateFrame)>()
        .iter(world)
        .map(|(p, f)| (p.id.0, f.world_from_plate))
        .collect();
    let mut spots: Vec<Hotspot> = world.query::<&Hotspot>().iter(world).copied().collect();
    spots.sort_by_key(|h| h.index);
    let mut edifices: Vec<Edifice> = world.query::<&Edifice>().iter(world).copied().collect();
    edifices.sort_by_key(|e| (e.hotspot, e.age_my.to_bits()));
    for h in &spots {
        let chain: Vec<&Edifice> = edifices.iter().filter(|e| e.hotspot == h.index).collect();
        println!(
            "hotspot {} at pixel {:?}: {} edifices",
            h.index,
            px(h.position),
            chain.len()
        );
        for e in chain.iter().step_by(5) {
            let f = frames
                .iter()
                .find(|f| f.0 == e.plate.0)
                .map_or(DQuat::IDENTITY, |f| f.1);
            println!(
                "  age {:>5.0} My  height {:>4.1} km  at pixel {:?}",
                e.age_my,
                e.height_km,
                px(e.world_position(f))
            );
        }
    }
    let view = sim.resampled_crust();
    let raster = Raster::sample(
        &CrustSampler {
            mesh: sim.mesh(),
            crust: &view,
        },
        width,
        width / 2,
    )?;
    std::fs::create_dir_all(&out)?;
    for f in write_all_maps(&raster, &out, sim.params().planet.radius_km)? {
        println!("wrote {}", f.display());
    }
    let longest = spots
        .iter()
        .max_by_key(|h| edifices.iter().filter(|e| e.hotspot == h.index).count());
    if let Some(h) = longest {
        let map = image::open(out.join("elevation.png"))?;
        let (cw, ch) = (width / 4, width / 8);
        let (x, y) = px(h.position);
        let x0 = (x - i64::from(cw) / 2).clamp(0, i64::from(width - cw)) as u32;
        let y0 = (y - i64::from(ch) / 2).clamp(0, i64::from(width / 2 - ch)) as u32;
        let path = out.join("elevation_chain.png");
        map.crop_imm(x0, y0, cw, ch).save(&path)?;
        println!(
            "wrote {} (hotspot {} at the centre)",
            path.display(),
            h.index
        );
    }
    Ok(())
}
