//! The command line of `planet`: the clap types shared by the commands, the dispatch, and the
//! helpers every command uses (parameters, threads, backend, phenomenon switches). One module
//! per command: [`run`] (generate, resume), [`export`], [`view`], [`bench`].

pub(crate) mod bench;
pub(crate) mod export;
pub(crate) mod run;
#[cfg(feature = "viewer")]
pub(crate) mod view;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use tectonic_planets::Simulation;
use tectonic_planets::commands::Command as Cmd;
use tectonic_planets::gpu::{BackendChoice, ComputeBackend};
use tectonic_planets::resources::params::{ParamValue, Params};
use tectonic_planets::resources::plugin_params::PluginConfig;

use bench::*;
use export::*;
use run::*;
#[cfg(feature = "viewer")]
use view::*;

#[derive(Parser)]
#[command(
    name = "planet",
    version,
    about = "Procedural tectonic planet generator"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
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
    /// Continue a saved planet for some more million years, then save it (and write maps).
    Resume(ResumeArgs),
    /// Write the maps and summary of a saved planet, as `generate` does.
    Export(ExportArgs),
    /// Open the viewer: watch, steer and toggle the stepped schedule live.
    #[cfg(feature = "viewer")]
    View(ViewArgs),
}

/// Options shared by every command that builds a planet.
#[derive(Args, Clone)]
pub(crate) struct PlanetArgs {
    /// TOML file with parameters (see `planet params`); command-line options override it.
    #[arg(long)]
    pub(crate) config: Option<PathBuf>,
    /// Random seed.
    #[arg(long)]
    pub(crate) seed: Option<u64>,
    /// Number of crust samples (1,000 to 4,000,000).
    #[arg(long)]
    pub(crate) samples: Option<u64>,
    /// Initial number of plates.
    #[arg(long)]
    pub(crate) plates: Option<u64>,
    /// Initial fraction of the surface covered by continental crust.
    #[arg(long)]
    pub(crate) continental_fraction: Option<f64>,
    #[command(flatten)]
    pub(crate) switches: SwitchArgs,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub(crate) threads: Option<usize>,
    /// Compute backend: auto (a hardware GPU if any, else the CPU), gpu (any wgpu adapter,
    /// software ones included), cpu.
    #[arg(long, default_value = "auto")]
    pub(crate) backend: BackendChoice,
}

/// Phenomena to switch on or off.
#[derive(Args, Clone)]
pub(crate) struct SwitchArgs {
    /// Phenomena to switch off, comma-separated (see `planet plugins`).
    #[arg(long, value_delimiter = ',')]
    pub(crate) disable: Vec<String>,
    /// Phenomena to switch on, comma-separated (e.g. `hotspots`, off by default).
    #[arg(long, value_delimiter = ',')]
    pub(crate) enable: Vec<String>,
}

/// Where and how often to save.
#[derive(Args, Clone)]
pub(crate) struct SaveArgs {
    /// Save the planet to this file at the end (a bare file name goes into `saves/`).
    #[arg(long)]
    pub(crate) save: Option<PathBuf>,
    /// Also save every this many million years while running (to the `--save` file, or to
    /// `saves/planet-<seed>.planet` when none is given).
    #[arg(long, value_name = "MY")]
    pub(crate) save_every: Option<f64>,
}

pub(crate) fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Generate(a) => generate(a),
        Command::Params { config } => {
            let params = match &config {
                Some(p) => Params::load(p)?,
                None => Params::default(),
            };
            let mut registry = tiny_sim()?;
            if let Some(p) = &config {
                registry.apply_plugin_config(&PluginConfig::load(p)?)?;
            }
            print!("{}", params.to_commented_toml());
            let plugin_toml = registry.plugin_params().to_commented_toml();
            if !plugin_toml.is_empty() {
                print!("\n# Parameters declared by plugins (see `planet plugins`).\n{plugin_toml}");
            }
            Ok(())
        }
        Command::Plugins => {
            let sim = tiny_sim()?;
            println!("{:<16} {:<12} {:<8} description", "name", "set", "default");
            for p in sim.phenomena() {
                println!(
                    "{:<16} {:<12} {:<8} {}",
                    p.name,
                    p.set.name(),
                    if p.default_enabled { "on" } else { "off" },
                    p.description
                );
            }
            Ok(())
        }
        Command::Bench(a) => bench(a),
        Command::Resume(a) => resume(a),
        Command::Export(a) => export(a),
        #[cfg(feature = "viewer")]
        Command::View(a) => view(a),
    }
}

/// The smallest simulation, to list what the plugins register.
pub(crate) fn tiny_sim() -> Result<Simulation> {
    let mut params = Params::default();
    params.planet.samples = 1000;
    params.init.plates = 2;
    Ok(Simulation::new(params)?)
}

/// Switches phenomena on (`enable`) and off (`disable`); a name in both is refused.
pub(crate) fn apply_switches(
    sim: &mut Simulation,
    enable: &[String],
    disable: &[String],
) -> Result<()> {
    let names = |v: &[String]| -> Vec<String> {
        v.iter()
            .map(|n| n.trim().to_string())
            .filter(|n| !n.is_empty())
            .collect()
    };
    let (on, off) = (names(enable), names(disable));
    if let Some(n) = on.iter().find(|n| off.contains(n)) {
        bail!("phenomenon \"{n}\" is both enabled and disabled");
    }
    // Through the command API, so that the switches are in the history and replay.
    for (names, enabled) in [(&on, true), (&off, false)] {
        for n in names {
            sim.apply(&Cmd::SetPhenomenon {
                name: n.clone(),
                enabled,
            })?;
        }
    }
    Ok(())
}

/// Parameters from the config file and the command line, validated.
pub(crate) fn load_params(a: &PlanetArgs) -> Result<Params> {
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

pub(crate) fn setup_threads(threads: Option<usize>) -> Result<()> {
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

pub(crate) fn build_sim(a: &PlanetArgs) -> Result<Simulation> {
    setup_threads(a.threads)?;
    let params = load_params(a)?;
    let mut sim = Simulation::new(params)?;
    use_backend(&mut sim, a.backend)?;
    if let Some(path) = &a.config {
        sim.apply_plugin_config(&PluginConfig::load(path)?)?;
    }
    apply_switches(&mut sim, &a.switches.enable, &a.switches.disable)?;
    Ok(sim)
}

/// Installs the compute backend; says which one when it is not the one asked for.
pub(crate) fn use_backend(sim: &mut Simulation, choice: BackendChoice) -> Result<()> {
    let note = sim
        .set_backend(choice)
        .context("could not start the GPU compute backend")?;
    // Falling back for want of any adapter is worth a warning; a machine with only a software
    // adapter (lavapipe) is the ordinary CPU case.
    if choice == BackendChoice::Auto
        && sim.backend() == ComputeBackend::Cpu
        && !note.starts_with(tectonic_planets::gpu::SOFTWARE_ONLY)
    {
        tracing::warn!("{note}");
    } else {
        tracing::info!("{note}");
    }
    Ok(())
}

/// The command line as typed, for the command history of saves.
pub(crate) fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!("planet {}", args.join(" "))
}

pub(crate) fn check_width(width: u32) -> Result<()> {
    if !(2..=16384).contains(&width) || !width.is_multiple_of(2) {
        bail!("--width must be an even number between 2 and 16384, got {width}");
    }
    Ok(())
}

pub(crate) fn check_my(flag: &str, my: f64) -> Result<()> {
    if !my.is_finite() || my < 0.0 {
        bail!("{flag} must be a finite, non-negative number of million years, got {my}");
    }
    Ok(())
}

pub(crate) fn prepare_out_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("output path {} exists and is not a folder", dir.display());
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("could not create output folder {}", dir.display()))
}
