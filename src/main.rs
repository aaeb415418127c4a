//! `planet`: the command-line interface of the tectonic planet generator.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use tectonic_planets::Simulation;
use tectonic_planets::io::maps::{Raster, write_all_maps};
use tectonic_planets::io::params::{ParamValue, Params};
use tectonic_planets::io::summary::{CrustSampler, summarize};
use tectonic_planets::plugins::TectonicSystems;

#[derive(Parser)]
#[command(
    name = "planet",
    version,
    about = "Procedural tectonic planet generator"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a planet and write its maps and summary.
    Generate(GenerateArgs),
    /// Print the default parameters as commented TOML (or the parameters a config file gives).
    Params {
        /// Start from this TOML file instead of the defaults.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// List the phenomena (plugins) and whether they are on by default.
    Plugins,
    /// Measure the time per step of each system set, one resampling, and memory.
    Bench(BenchArgs),
}

/// Options shared by every command that builds a planet.
#[derive(Args, Clone)]
struct PlanetArgs {
    /// TOML file with parameters (see `planet params`); command-line options override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Random seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Number of crust samples (1,000 to 4,000,000).
    #[arg(long)]
    samples: Option<u64>,
    /// Initial number of plates.
    #[arg(long)]
    plates: Option<u64>,
    /// Initial fraction of the surface covered by continental crust.
    #[arg(long)]
    continental_fraction: Option<f64>,
    /// Phenomena to switch off, comma-separated (see `planet plugins`).
    #[arg(long, value_delimiter = ',')]
    disable: Vec<String>,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
struct GenerateArgs {
    #[command(flatten)]
    planet: PlanetArgs,
    /// Simulated time in million years.
    #[arg(long, default_value_t = 250.0)]
    my: f64,
    /// Output folder for the maps and summary.json.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    width: u32,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct BenchArgs {
    #[command(flatten)]
    planet: PlanetArgs,
    /// Steps to time.
    #[arg(long, default_value_t = 60)]
    steps: u64,
    /// Extra forced resamplings to time after the steps.
    #[arg(long, default_value_t = 5)]
    resamplings: u64,
}

fn main() {
    let filter =
        tracing_subscriber::EnvFilter::try_from_env("PLANET_LOG").unwrap_or_else(|_| "warn".into());
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Generate(a) => generate(a),
        Command::Params { config } => {
            let params = match config {
                Some(p) => Params::load(&p)?,
                None => Params::default(),
            };
            print!("{}", params.to_commented_toml());
            Ok(())
        }
        Command::Plugins => {
            let mut params = Params::default();
            params.planet.samples = 1000;
            params.init.plates = 2;
            let sim = Simulation::new(params)?;
            println!("{:<16} {:<12} {:<4} description", "name", "set", "on");
            for p in sim.phenomena() {
                println!(
                    "{:<16} {:<12} {:<4} {}",
                    p.name,
                    p.set.name(),
                    if p.enabled { "yes" } else { "no" },
                    p.description
                );
            }
            Ok(())
        }
        Command::Bench(a) => bench(a),
    }
}

/// Parameters from the config file and the command line, validated.
fn load_params(a: &PlanetArgs) -> Result<Params> {
    let mut params = match &a.config {
        Some(p) => Params::load(p)?,
        None => Params::default(),
    };
    let set = |params: &mut Params, key: &str, v: ParamValue| {
        params.set(key, v).map_err(anyhow::Error::from)
    };
    if let Some(s) = a.seed {
        set(&mut params, "planet.seed", ParamValue::Int(s))?;
    }
    if let Some(n) = a.samples {
        set(&mut params, "planet.samples", ParamValue::Int(n))?;
    }
    if let Some(p) = a.plates {
        set(&mut params, "init.plates", ParamValue::Int(p))?;
    }
    if let Some(f) = a.continental_fraction {
        set(
            &mut params,
            "init.continental_fraction",
            ParamValue::Float(f),
        )?;
    }
    params.validate()?;
    Ok(params)
}

fn setup_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("could not start the thread pool")?;
    }
    Ok(())
}

fn build_sim(a: &PlanetArgs) -> Result<Simulation> {
    setup_threads(a.threads)?;
    let params = load_params(a)?;
    let mut sim = Simulation::new(params)?;
    for name in &a.disable {
        let name = name.trim();
        if !name.is_empty() {
            sim.set_enabled(name, false)?;
        }
    }
    Ok(sim)
}

fn generate(a: GenerateArgs) -> Result<()> {
    if !a.my.is_finite() || a.my < 0.0 {
        bail!(
            "--my must be a finite, non-negative number of million years, got {}",
            a.my
        );
    }
    if a.width < 2 || a.width > 16384 || !a.width.is_multiple_of(2) {
        bail!(
            "--width must be an even number between 2 and 16384, got {}",
            a.width
        );
    }
    prepare_out_dir(&a.out)?;
    let started = Instant::now();
    let mut sim = build_sim(&a.planet)?;
    let steps = sim.steps_for(a.my)?;
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(steps)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{bar:40}] {pos}/{len} steps  {msg}  {per_sec}  left {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let dt = sim.params().time.time_step_my;
    for k in 0..steps {
        sim.step()?;
        bar.set_message(format!(
            "{:.0}/{:.0} My",
            (k + 1) as f64 * dt,
            steps as f64 * dt
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let view = sim.resampled_crust();
    let raster = Raster::sample(
        &CrustSampler {
            mesh: sim.mesh(),
            crust: &view,
        },
        a.width,
        a.width / 2,
    )?;
    let files = write_all_maps(&raster, &a.out, sim.params().planet.radius_km)?;
    let summary = summarize(&sim, &view);
    let summary_path = a.out.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("could not write {}", summary_path.display()))?;
    if !a.quiet {
        eprintln!(
            "{} samples, {} plates, {:.0} My in {:.1} s: land {:.1}%, continental crust {:.1}%",
            summary.samples,
            summary.plates,
            summary.time_my,
            started.elapsed().as_secs_f64(),
            100.0 * summary.land_fraction,
            100.0 * summary.continental_fraction
        );
        for f in files.iter().chain(std::iter::once(&summary_path)) {
            eprintln!("  wrote {}", f.display());
        }
    }
    Ok(())
}

fn prepare_out_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("output path {} exists and is not a folder", dir.display());
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("could not create output folder {}", dir.display()))
}

/// Peak resident memory of this process (VmHWM), bytes, where the OS tells.
fn peak_rss_bytes() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn bench(a: BenchArgs) -> Result<()> {
    let t0 = Instant::now();
    let mut sim = build_sim(&a.planet)?;
    let build = t0.elapsed();
    let n = sim.mesh().len();
    println!(
        "planet bench: {} samples, {} plates, {} steps, {} threads",
        n,
        sim.stats().plates,
        a.steps,
        rayon::current_num_threads()
    );
    let ms = |d: Option<Duration>| d.map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
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
    let mut step_ms = Vec::new();
    for _ in 0..a.steps {
        let s = Instant::now();
        sim.step()?;
        step_ms.push(s.elapsed().as_secs_f64() * 1e3);
    }
    for _ in 0..a.resamplings {
        sim.request_resample();
        sim.step()?;
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
    println!("{:<28} {:>10.3} ms", "all sets but resample", per_step_sum);
    step_ms.sort_by(f64::total_cmp);
    println!(
        "{:<28} {:>10.3} ms",
        "whole step (median)",
        step_ms.get(step_ms.len() / 2).copied().unwrap_or(f64::NAN)
    );
    println!(
        "{:<28} {:>10.1} ms",
        "one resampling (median)",
        sim.timings().median_ms("resampling").unwrap_or(f64::NAN)
    );
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
    Ok(())
}
