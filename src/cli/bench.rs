//! `planet bench`: time per system set, resamplings, rifting, saves and memory, with the GPU
//! traffic per kind of step.

use std::time::{Duration, Instant};

use anyhow::{Result, bail};
use clap::Args;
use tectonic_planets::Simulation;
use tectonic_planets::commands::Command as Cmd;
use tectonic_planets::gpu::GpuContext;
use tectonic_planets::io::save::{self};
use tectonic_planets::plugins::TectonicSystems;

use super::*;

#[derive(Args)]
pub(crate) struct BenchArgs {
    #[command(flatten)]
    pub(crate) planet: PlanetArgs,
    /// Steps to time.
    #[arg(long, default_value_t = 60)]
    pub(crate) steps: u64,
    /// Time the steps of a saved planet (a `.planet` file) instead of a new one: a mature
    /// planet's relief passes cost more than a young one's. The planet's own parameters are
    /// used (the options that make a new planet are not); `--threads`, `--backend`, `--enable`,
    /// `--disable` and `--relief-every` still apply.
    #[arg(long, value_name = "SAVE")]
    pub(crate) from: Option<std::path::PathBuf>,
    /// Extra forced resamplings to time after the steps.
    #[arg(long, default_value_t = 5)]
    pub(crate) resamplings: u64,
    /// Print the layout of the paper's Table 2 instead (Cortial et al. 2019: subduction,
    /// collision, elevation, total per step, oceanic crust generation, rifting) at 60k, 100k,
    /// 250k and 500k samples, each from a 250 My run of its own (`--samples`, `--steps` and
    /// `--resamplings` are not used), with the paper's figures beside ours.
    #[arg(long)]
    pub(crate) table2: bool,
    /// Also print a row for each timed step: its wall time, its kind, and the time of each
    /// system set in it (ms), to see where the steps with and without a drainage network, and
    /// those around a resampling, spend theirs.
    #[arg(long)]
    pub(crate) per_step: bool,
    /// With `--table2`: divide the sample counts by this (a quick look; the tests use it).
    #[arg(long, default_value_t = 1, hide = true)]
    pub(crate) table2_divisor: u64,
}

/// Peak resident memory of this process (VmHWM), bytes, where the OS tells.
pub(crate) fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

pub(crate) fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Rifts the largest plate into two, `n` times (a step after each, which resamples), and returns
/// the wall time of each rift itself (partition, motions, plate geometry), ms.
pub(crate) fn bench_rifts(sim: &mut Simulation, n: usize) -> Result<Vec<f64>> {
    use tectonic_planets::components::{Plate, PlateStats};
    use tectonic_planets::systems::rifting::RiftLog;
    let mut out = Vec::new();
    for _ in 0..n {
        let world = sim.world_mut();
        let largest = world
            .query::<(&Plate, &PlateStats)>()
            .iter(world)
            .max_by(|a, b| {
                a.1.area_km2
                    .total_cmp(&b.1.area_km2)
                    .then(b.0.id.0.cmp(&a.0.id.0))
            })
            .map(|(p, _)| p.id.0);
        let Some(id) = largest else { break };
        let rift = Cmd::RiftAt {
            plate: tectonic_planets::commands::PlateRef::Id(id),
            fragments: 2,
        };
        if sim.apply(&rift).is_ok()
            && let Some(e) = sim.world().resource::<RiftLog>().events.last()
        {
            out.push(e.elapsed_ms);
        }
        sim.step()?;
    }
    Ok(out)
}

pub(crate) fn bench(a: BenchArgs) -> Result<()> {
    if a.table2 {
        return super::table2::table2(&a);
    }
    let t0 = Instant::now();
    let check_length = |samples: usize| {
        check_run_length(
            &format!("--steps {} and --resamplings {}", a.steps, a.resamplings),
            a.steps.saturating_add(a.resamplings),
            samples,
            false,
        )
    };
    let mut sim = match &a.from {
        Some(path) => {
            setup_threads(a.planet.threads)?;
            let mut sim = save::load_from_file(path)?;
            apply_switches(
                &mut sim,
                &a.planet.switches.enable,
                &a.planet.switches.disable,
            )?;
            check_length(sim.mesh().len())?;
            if let Some(k) = a.planet.relief_every {
                let mut p = sim.params().clone();
                p.set("time.relief_interval_steps", ParamValue::Int(k))?;
                p.validate()?;
                *sim.world_mut()
                    .resource_mut::<tectonic_planets::resources::Params>() = p;
            }
            sim
        }
        None => {
            let (params, plugins) = planet_params(&a.planet)?;
            check_length(params.planet.samples as usize)?;
            build_sim(&a.planet, params, plugins, None)?
        }
    };
    use_backend(&mut sim, a.planet.backend)?;
    let build = t0.elapsed();
    let n = sim.mesh().len();
    println!(
        "planet bench: {} samples, {} plates, {} steps, {} threads, backend {}",
        n,
        sim.stats().plates,
        a.steps,
        rayon::current_num_threads(),
        backend_name(&sim)
    );
    let ms = |d: Option<Duration>| d.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
    if let Some(path) = &a.from {
        println!(
            "{:<28} {:>10.1} ms  ({}, at {} My)",
            "loading the save",
            build.as_secs_f64() * 1e3,
            path.display(),
            num(sim.clock().time_my)
        );
    } else {
        println!("{:<28} {:>10.1} ms", "mesh", ms(sim.timings().last("mesh")));
        println!(
            "{:<28} {:>10.1} ms",
            "initial planet",
            ms(sim.timings().last("initial_planet"))
        );
        println!(
            "{:<28} {:>10.1} ms",
            "mesh + initial planet",
            build.as_secs_f64() * 1e3
        );
    }
    // Each step: wall time, what kind of step it was, and its GPU traffic.
    let mut steps: Vec<BenchStep> = Vec::new();
    let traffic0 = gpu_traffic(&sim);
    // The relief sets' means skip the first step (it builds the sample graph and tables once).
    let relief_sets = [
        TectonicSystems::Climate,
        TectonicSystems::Drainage,
        TectonicSystems::Rivers,
        TectonicSystems::Coasts,
        TectonicSystems::Sediment,
        TectonicSystems::Isostasy,
    ];
    let mut relief_from: Vec<usize> = Vec::new();
    // With `--per-step`: each step's time in each set and in the resampling, None where it did
    // not run.
    let per_step_names: Vec<&str> = if a.per_step {
        TectonicSystems::ALL
            .iter()
            .map(|s| s.name())
            .chain(["resampling", "after_resample"])
            .collect()
    } else {
        Vec::new()
    };
    let mut per_step: Vec<Vec<Option<f64>>> = Vec::new();
    for k in 0..a.steps {
        if k == 1 {
            relief_from = relief_sets
                .iter()
                .map(|s| sim.timings().count(s.name()))
                .collect();
        }
        let before = (sim.clock().resamplings, gpu_traffic(&sim));
        let counts: Vec<u64> = per_step_names
            .iter()
            .map(|name| sim.timings().recorded(name))
            .collect();
        let s = Instant::now();
        sim.step()?;
        let ms = s.elapsed().as_secs_f64() * 1e3;
        if a.per_step {
            per_step.push(
                per_step_names
                    .iter()
                    .zip(&counts)
                    .map(|(name, &c)| {
                        let t = sim.timings();
                        (t.recorded(name) > c)
                            .then(|| t.last(name).map_or(0.0, |d| d.as_secs_f64() * 1e3))
                    })
                    .collect(),
            );
        }
        let after = gpu_traffic(&sim);
        steps.push(BenchStep {
            ms,
            kind: if sim.clock().resamplings != before.0 {
                StepKind::Resampling
            } else if steps.last().is_some_and(|s| s.kind == StepKind::Resampling) {
                StepKind::AfterResampling
            } else {
                StepKind::Steady
            },
            traffic: before.1.zip(after).map(|(b, a)| {
                (
                    a.uploaded_bytes - b.uploaded_bytes,
                    a.downloaded_bytes - b.downloaded_bytes,
                )
            }),
        });
    }
    let relief_to: Vec<usize> = relief_sets
        .iter()
        .map(|s| sim.timings().count(s.name()))
        .collect();
    let traffic1 = gpu_traffic(&sim);
    let step_ms: Vec<f64> = steps.iter().map(|s| s.ms).collect();
    for _ in 0..a.resamplings {
        sim.request_resample();
        sim.step()?;
    }
    let rift_ms = bench_rifts(&mut sim, 3)?;
    if a.per_step {
        print_per_step(&per_step_names, &per_step, &steps);
    }
    println!("median per step, by system set:");
    let mut per_step_sum = 0.0;
    for set in TectonicSystems::ALL {
        let m = sim.timings().median_ms(set.name()).unwrap_or(f64::NAN);
        if set != TectonicSystems::Resample {
            per_step_sum += m;
        }
        println!("  {:<26} {:>10.3} ms", set.name(), m);
    }
    // The relief issue's budget is for the relief's sets together (40 ms a step at 500k). With
    // the surface processes on one step in several, the medians say nothing: the means do.
    let timings = sim.timings();
    let relief_median: f64 = relief_sets
        .iter()
        .filter_map(|set| timings.median_ms(set.name()))
        .sum();
    println!("  {:<26} {:>10.3} ms", "relief sets (sum)", relief_median);
    // With a single step there is no step but the first to average over.
    let relief_mean: f64 = if relief_from.is_empty() {
        f64::NAN
    } else {
        relief_sets
            .iter()
            .zip(relief_from.iter().zip(&relief_to))
            .filter_map(|(set, (&from, &to))| timings.mean_ms(set.name(), from, to))
            .sum()
    };
    println!(
        "  {:<26} {:>10.3} ms  (their means over the steps but the first; a drainage network \
         every {} steps)",
        "relief sets (mean a step)",
        relief_mean,
        sim.params().time.relief_interval_steps
    );
    if let Some(m) = timings.median_ms("climate_search") {
        println!(
            "  {:<26} {m:>10.3} ms  (on the steps it runs, on its own thread beside the \
             drainage)",
            "climate's search"
        );
    }
    let by_stage: [(&str, &[(&str, &str)]); 2] = [
        (
            "drainage, by pass (median):",
            &[
                ("sea mask", "drainage_sea_mask"),
                ("receivers", "drainage_receivers"),
                ("pit basins", "drainage_pit_basins"),
                ("priority flood", "drainage_flood"),
                ("stack", "drainage_stack"),
                ("waiting for the climate", "drainage_climate_wait"),
                ("areas", "drainage_areas"),
                ("lakes' water balance", "drainage_lake_balance"),
            ],
        ),
        (
            "sediment, by phase (median):",
            &[
                ("setup", "sediment_setup"),
                ("land (rivers and lakes)", "sediment_land"),
                ("sea", "sediment_sea"),
                ("safety net and write-out", "sediment_safety_net"),
            ],
        ),
    ];
    for (title, stages) in by_stage {
        println!("{title}");
        for (label, name) in stages {
            if let Some(m) = sim.timings().median_ms(name) {
                println!("  {label:<26} {m:>10.3} ms");
            }
        }
    }
    println!("{:<28} {:>10.3} ms", "all sets but resample", per_step_sum);
    println!(
        "{:<28} {:>10.3} ms",
        "whole step (median)",
        median(&step_ms)
    );
    println!(
        "{:<28} {:>10.3} ms",
        "whole step (mean)",
        step_ms.iter().sum::<f64>() / step_ms.len().max(1) as f64
    );
    for kind in StepKind::ALL {
        let ms: Vec<f64> = steps
            .iter()
            .filter(|s| s.kind == kind)
            .map(|s| s.ms)
            .collect();
        println!(
            "{:<30} {:>8.3} ms  ({} of {} steps)",
            format!("  {} (median)", kind.label()),
            median(&ms),
            ms.len(),
            steps.len()
        );
    }
    println!(
        "{:<28} {:>10.1} ms",
        "one resampling (median)",
        sim.timings().median_ms("resampling").unwrap_or(f64::NAN)
    );
    println!(
        "{:<28} {:>10.1} ms",
        "  + fronts, terranes (median)",
        sim.timings()
            .median_ms("after_resample")
            .unwrap_or(f64::NAN)
    );
    println!(
        "{:<28} {:>10.1} ms",
        "  of which locate (median)",
        sim.timings()
            .median_ms("resample_locate")
            .unwrap_or(f64::NAN)
    );
    println!(
        "{:<28} {:>10.1} ms",
        "  of which interp (median)",
        sim.timings()
            .median_ms("resample_interpolate")
            .unwrap_or(f64::NAN)
    );
    if let Some(t) = gpu_traffic(&sim) {
        println!(
            "{:<28} {:>10} on the GPU, {} samples left to the CPU",
            "point locations", t.locations, t.rechecked_samples
        );
        println!(
            "{:<28} {:>10} on the GPU",
            "collision surges", t.collision_surges
        );
        println!(
            "{:<28} {:>10} on the GPU",
            "interpolations", t.interpolations
        );
        println!(
            "{:<28} {:>10} isostasy, {} diffusion passes on the GPU",
            "relief", t.isostasy_passes, t.diffusion_passes
        );
    }
    println!(
        "{:<28} {:>10.1} ms  ({} rifts of the largest plate into 2)",
        "one rift (median)",
        median(&rift_ms),
        rift_ms.len()
    );
    if let (Some(t0), Some(t1)) = (traffic0, traffic1) {
        let steps = a.steps.max(1) as f64;
        println!(
            "{:<28} {:>10.2} MB up, {:.2} MB down, {:.1} dispatches, {} full crust uploads in {} steps",
            "GPU traffic, mean per step",
            (t1.uploaded_bytes - t0.uploaded_bytes) as f64 / steps / 1e6,
            (t1.downloaded_bytes - t0.downloaded_bytes) as f64 / steps / 1e6,
            (t1.dispatches - t0.dispatches) as f64 / steps,
            t1.crust_uploads - t0.crust_uploads,
            a.steps
        );
    }
    print_step_traffic(&steps, n);
    let state = sim.state_bytes();
    println!(
        "{:<28} {:>10.1} MB  ({:.0} bytes/sample)",
        "simulation state",
        state as f64 / 1e6,
        state as f64 / n as f64
    );
    if let Some(peak) = peak_rss_bytes() {
        println!(
            "{:<28} {:>10.1} MB  ({:.0} bytes/sample)",
            "peak memory (VmHWM)",
            peak as f64 / 1e6,
            peak as f64 / n as f64
        );
    }
    bench_saves(&mut sim)
}

/// The table of `--per-step`: a row a step (its number, kind and wall time, then each set's
/// time, `-` where it did not run), with the columns of the sets that took at least 0.05 ms in
/// some step.
fn print_per_step(names: &[&str], rows: &[Vec<Option<f64>>], steps: &[BenchStep]) {
    let shown: Vec<usize> = (0..names.len())
        .filter(|&c| rows.iter().any(|r| r[c].is_some_and(|ms| ms >= 0.05)))
        .collect();
    println!("per step, ms (the sets in the order they run; `-`: did not run):");
    let mut header = format!("  {:>4} {:<16} {:>8}", "step", "kind", "step");
    for &c in &shown {
        header += &format!(" {:>w$}", names[c], w = names[c].len().max(6));
    }
    println!("{header}");
    for (k, (row, step)) in rows.iter().zip(steps).enumerate() {
        let mut line = format!("  {k:>4} {:<16} {:>8.1}", step.kind.label(), step.ms);
        for &c in &shown {
            let w = names[c].len().max(6);
            match row[c] {
                Some(ms) => line += &format!(" {ms:>w$.1}"),
                None => line += &format!(" {:>w$}", "-"),
            }
        }
        println!("{line}");
    }
}

/// One timed step of the bench.
pub(crate) struct BenchStep {
    /// Wall time, ms.
    pub(crate) ms: f64,
    /// Steady, resampling, or the step right after a resampling.
    pub(crate) kind: StepKind,
    /// Bytes uploaded and downloaded during the step (GPU backend only).
    pub(crate) traffic: Option<(u64, u64)>,
}

/// The kinds of step the bench reports apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum StepKind {
    /// Neither a resampling nor the step right after one.
    Steady,
    /// A step that ended in a global resampling.
    Resampling,
    /// The step right after a resampling: on the GPU backend it uploads the crust that the CPU
    /// rebuilt, so its traffic belongs to the resampling.
    AfterResampling,
}

impl StepKind {
    const ALL: [StepKind; 3] = [
        StepKind::Steady,
        StepKind::Resampling,
        StepKind::AfterResampling,
    ];
    fn label(self) -> &'static str {
        match self {
            StepKind::Steady => "steady step",
            StepKind::Resampling => "resampling step",
            StepKind::AfterResampling => "after resampling",
        }
    }
}

/// The GPU traffic of each kind of step: median and largest bytes up and down per step, and per
/// sample. Steady steps are what residency is judged by.
pub(crate) fn print_step_traffic(steps: &[BenchStep], samples: usize) {
    for kind in StepKind::ALL {
        let t: Vec<(u64, u64)> = steps
            .iter()
            .filter(|s| s.kind == kind)
            .filter_map(|s| s.traffic)
            .collect();
        if t.is_empty() {
            continue;
        }
        let up: Vec<f64> = t.iter().map(|x| x.0 as f64).collect();
        let down: Vec<f64> = t.iter().map(|x| x.1 as f64).collect();
        let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
        let per = |b: f64| b / samples.max(1) as f64;
        println!(
            "{:<30} {:>8.3} MB up ({:.2} B/sample), {:.3} MB down ({:.2} B/sample); largest {:.2} MB up, {:.2} MB down ({} steps)",
            format!("GPU traffic, {}", kind.label()),
            median(&up) / 1e6,
            per(median(&up)),
            median(&down) / 1e6,
            per(median(&down)),
            max(&up) / 1e6,
            max(&down) / 1e6,
            t.len()
        );
    }
}

/// The backend's name for the bench header: `cpu`, or `gpu (adapter, type)`.
pub(crate) fn backend_name(sim: &Simulation) -> String {
    match sim.world().get_resource::<GpuContext>() {
        Some(g) => format!("gpu ({}, {:?})", g.adapter.name, g.adapter.device_type),
        None => "cpu".into(),
    }
}

/// The GPU traffic counters, on the GPU backend.
pub(crate) fn gpu_traffic(sim: &Simulation) -> Option<tectonic_planets::gpu::GpuTraffic> {
    sim.world().get_resource::<GpuContext>().map(|g| g.traffic)
}

/// Times a save (encode, compress, write, sync) and a load (read, check, decompress, rebuild the
/// mesh, restore) of the benchmark planet, and gives the file size.
pub(crate) fn bench_saves(sim: &mut Simulation) -> Result<()> {
    let path = std::env::temp_dir().join(format!(
        "planet-bench-{}.{}",
        std::process::id(),
        save::EXTENSION
    ));
    let t = Instant::now();
    let info = save::save_to_file(sim, &path)?;
    let save_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let mut loaded = save::load_from_file(&path)?;
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    let _ = std::fs::remove_file(&path);
    if loaded.state_hash() != sim.state_hash() {
        bail!("the loaded planet differs from the saved one");
    }
    println!("{:<28} {:>10.1} ms", "save to file", save_ms);
    println!("{:<28} {:>10.1} ms", "load from file", load_ms);
    println!(
        "{:<28} {:>10.1} MB  ({:.1} MB before compression)",
        "save file size",
        info.file_bytes as f64 / 1e6,
        info.raw_bytes as f64 / 1e6
    );
    Ok(())
}
