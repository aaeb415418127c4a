//! Debug probe: finds deep pits surrounded by land and prints what they are.
use tectonic_planets::prelude::*;
use tectonic_planets::resources::{ConvergenceField, FrontPoints};
fn main() {
    let mut p = Params::default();
    p.planet.samples = 200_000;
    let mut sim = Simulation::new(p).unwrap();
    sim.run_for(250.0).unwrap();
    let mesh = sim.mesh().clone();
    let c = sim.crust().clone();
    let f = sim.world().resource::<ConvergenceField>().clone();
    let fp = sim.world().resource::<FrontPoints>().clone();
    let mut n = 0;
    for i in 0..mesh.len() {
        let nb = mesh.neighbors_of(i);
        let land = nb
            .iter()
            .filter(|&&v| c.elevation_km[v as usize] > 0.5)
            .count();
        if c.elevation_km[i] < -3.0 && land * 2 > nb.len() {
            n += 1;
            if n < 12 {
                let sp = f.subducting_point[i];
                println!(
                    "i={i} z={:.2} type={:?} plate={} age={:.0} over_d={:.0} sub_d={:.0} conv={:?} nb_plates={:?} nb_z={:?}",
                    c.elevation_km[i],
                    c.crust_type[i],
                    c.plate[i],
                    c.age_my[i],
                    f.overriding_distance_km[i],
                    f.subducting_distance_km[i],
                    if sp != u32::MAX {
                        Some(fp.converged_km[sp as usize])
                    } else {
                        None
                    },
                    nb.iter().map(|&v| c.plate[v as usize]).collect::<Vec<_>>(),
                    nb.iter()
                        .map(|&v| (c.elevation_km[v as usize] * 10.0).round() / 10.0)
                        .collect::<Vec<_>>()
                );
            }
        }
    }
    println!(
        "{n} pits; steps since resample {}",
        sim.clock().steps_since_resample
    );
}
