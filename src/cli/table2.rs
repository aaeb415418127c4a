//! `planet bench --table2`: the layout of Table 2 of Cortial et al. (2019), "Procedural
//! Tectonic Planets", with their figures beside ours, and the time of a whole planet.
//!
//! Each resolution runs the planet of the command line (seed, plates, parameters) for 250 My
//! from scratch, as `generate` does, and reads the medians of its system sets off the run:
//!
//! | row | the paper | ours |
//! |---|---|---|
//! | subduction | subduction uplift, slab pull | sets `subduction` + `slab_pull` |
//! | continental collision | collision detection and surges | set `collision` |
//! | elevation | erosion, damping, aging of the crust | sets `erosion` + `aging` + the relief (`climate`, `drainage`, `rivers`, `coasts`, `sediment`, `isostasy`) |
//! | total | per step | every per-step set (the ones above, drift, rifting checks, diagnostics) |
//! | oceanic crust | crust generation (with the remeshing) | one global resampling + rebuilding the fronts and terranes after it |
//! | plate rifting | one rift | one rift of the largest plate into two (partition, motions, geometry) |
//!
//! The paper ran an "Intel Core i7" desktop with a GPU for the amplification; it does not give
//! a time for a whole planet. Its estimate here is 125 steps at its per-step total, plus a crust
//! generation and a rift every 20 to 120 My (the cadence its §7.4 gives): a range.

use std::time::Instant;

use anyhow::Result;
use tectonic_planets::Simulation;
use tectonic_planets::plugins::TectonicSystems;
use tectonic_planets::systems::rifting::RiftLog;

use super::bench::{BenchArgs, backend_name, bench_rifts, median};
use super::*;

/// Sample counts of the paper's Table 2.
pub(crate) const SAMPLES: [u64; 4] = [60_000, 100_000, 250_000, 500_000];

/// The paper's Table 2, seconds per time step, by column of [`SAMPLES`] (Cortial et al. 2019,
/// §7.4): subduction, continental collision, elevation, total, oceanic crust, plate rifting.
pub(crate) const PAPER: [(&str, [f64; 4]); 6] = [
    ("subduction", [0.08, 0.14, 0.26, 0.65]),
    ("continental collision", [0.02, 0.04, 0.69, 0.63]),
    ("elevation", [0.09, 0.10, 0.29, 0.62]),
    ("total", [0.19, 0.28, 1.24, 1.90]),
    ("oceanic crust", [0.58, 1.22, 3.58, 13.10]),
    ("plate rifting", [0.23, 0.21, 1.50, 7.70]),
];

/// The paper's resolution line, km.
const PAPER_KM: [f64; 4] = [102.0, 78.0, 50.0, 35.0];

/// Simulated time of the whole-planet run, My.
const RUN_MY: f64 = 250.0;

/// One column of our table.
struct Column {
    spacing_km: f64,
    rows: [f64; 6],
    whole_s: f64,
    steps: u64,
    resamplings: u64,
    backend: String,
}

fn set_ms(sim: &Simulation, set: TectonicSystems) -> f64 {
    sim.timings().median_ms(set.name()).unwrap_or(0.0)
}

/// Runs one resolution: a straight 250 My run (timed whole), then the medians.
fn column(a: &BenchArgs, samples: u64) -> Result<Column> {
    let mut planet = a.planet.clone();
    planet.samples = Some(samples);
    let (params, plugins) = planet_params(&planet)?;
    let steps = steps_of(&params, RUN_MY);
    let t0 = Instant::now();
    let mut sim = build_sim(&planet, params, plugins, None)?;
    use_backend(&mut sim, planet.backend)?;
    sim.run_steps(steps)?;
    let whole_s = t0.elapsed().as_secs_f64();
    let resamplings = sim.clock().resamplings;
    let mut rift_ms: Vec<f64> = sim
        .world()
        .resource::<RiftLog>()
        .events
        .iter()
        .map(|e| e.elapsed_ms)
        .collect();
    if rift_ms.len() < 3 {
        rift_ms.extend(bench_rifts(&mut sim, 3 - rift_ms.len())?);
    }
    use TectonicSystems as S;
    let subduction = set_ms(&sim, S::Subduction) + set_ms(&sim, S::SlabPull);
    let collision = set_ms(&sim, S::Collision);
    let elevation: f64 = [
        S::Erosion,
        S::Aging,
        S::Climate,
        S::Drainage,
        S::Rivers,
        S::Coasts,
        S::Sediment,
        S::Isostasy,
    ]
    .iter()
    .map(|&s| set_ms(&sim, s))
    .sum();
    let total: f64 = S::ALL
        .iter()
        .filter(|&&s| s != S::Resample)
        .map(|&s| set_ms(&sim, s))
        .sum();
    let timing = |name: &str| sim.timings().median_ms(name).unwrap_or(f64::NAN);
    let oceanic = timing("resampling") + timing("after_resample");
    let ms = [
        subduction,
        collision,
        elevation,
        total,
        oceanic,
        median(&rift_ms),
    ];
    Ok(Column {
        spacing_km: sim.mesh().mean_spacing_rad() * sim.mesh().radius_km,
        rows: ms.map(|m| m / 1e3),
        whole_s,
        steps,
        resamplings,
        backend: backend_name(&sim),
    })
}

/// Prints the table (runs every resolution; about a minute on two cores).
pub(crate) fn table2(a: &BenchArgs) -> Result<()> {
    let mut cols = Vec::new();
    let divisor = a.table2_divisor.max(1);
    for &n in &SAMPLES {
        let n = n / divisor;
        eprintln!("planet bench --table2: {n} samples, {RUN_MY} My ...");
        cols.push(column(a, n)?);
    }
    let threads = rayon::current_num_threads();
    let backend = &cols[0].backend;
    println!(
        "planet bench --table2: {} My from scratch at each resolution, {} threads, backend {}",
        RUN_MY, threads, backend
    );
    println!(
        "seconds per time step; ours on the left, the paper's Table 2 (Cortial et al. 2019) on the right"
    );
    let row = |label: &str, ours: [String; 4], paper: [String; 4]| {
        println!(
            "{:<24} {:>9} {:>9} {:>9} {:>9}   | {:>7} {:>7} {:>7} {:>7}",
            label, ours[0], ours[1], ours[2], ours[3], paper[0], paper[1], paper[2], paper[3]
        );
    };
    row(
        "resolution (km)",
        std::array::from_fn(|k| format!("{:.0}", cols[k].spacing_km)),
        PAPER_KM.map(|k| format!("{k:.0}")),
    );
    row(
        "sample points",
        std::array::from_fn(|k| {
            let n = SAMPLES[k] / divisor;
            if n.is_multiple_of(1000) {
                format!("{}k", n / 1000)
            } else {
                format!("{:.1}k", n as f64 / 1000.0)
            }
        }),
        SAMPLES.map(|n| format!("{}k", n / 1000)),
    );
    for (r, (label, paper)) in PAPER.iter().enumerate() {
        row(
            label,
            std::array::from_fn(|k| format!("{:.4}", cols[k].rows[r])),
            paper.map(|s| format!("{s:.2}")),
        );
    }
    // The paper's whole planet, estimated: 125 steps at its total, and one crust generation and
    // one rift every 120 (fewest) to 20 My (most).
    let steps = cols[0].steps as f64;
    let paper_whole = |k: usize, every_my: f64| {
        steps * PAPER[3].1[k] + (RUN_MY / every_my) * (PAPER[4].1[k] + PAPER[5].1[k])
    };
    row(
        "whole planet, 250 My (s)",
        std::array::from_fn(|k| format!("{:.2}", cols[k].whole_s)),
        std::array::from_fn(|k| {
            format!("{:.0}-{:.0}", paper_whole(k, 120.0), paper_whole(k, 20.0))
        }),
    );
    row(
        "resamplings in 250 My",
        std::array::from_fn(|k| format!("{}", cols[k].resamplings)),
        std::array::from_fn(|_| "2-12".to_string()),
    );
    println!(
        "ours: subduction = subduction + slab_pull; elevation = erosion + aging + climate + drainage + rivers + coasts + sediment + isostasy (the paper had no climate, rivers, sediment or isostasy); total = every per-step set; oceanic crust = one global resampling + the fronts and terranes after it; the paper's whole planet is estimated from its table (a crust generation and a rift every 120 to 20 My)"
    );
    Ok(())
}
