//! The command line of `planet`: the clap types shared by the commands, the dispatch, and the
//! helpers every command uses (parameters, threads, backend, phenomenon switches). One module
//! per command: [`run`](mod@run) (generate, resume), [`export`](mod@export), [`view`](mod@view), [`bench`](mod@bench).

pub(crate) mod bench;
pub(crate) mod export;
pub(crate) mod run;
pub(crate) mod table2;
#[cfg(feature = "viewer")]
pub(crate) mod view;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use tectonic_planets::Simulation;
use tectonic_planets::commands::Command as Cmd;
use tectonic_planets::gpu::{BackendChoice, ComputeBackend};
use tectonic_planets::resources::input::{clip, num};
use tectonic_planets::resources::params::{ParamValue, Params, read_param_file};
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
    /// Print the GPU adapters `--backend auto` would choose from, for a parent `planet` (see
    /// [`use_backend`]); not for users.
    #[command(hide = true)]
    ProbeAdapters,
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
    /// How the first plates are made: `voronoi` (warped Voronoi cells, continents from a noise
    /// field; the default) or `flood-fill` (plates grown from seed points, each wholly
    /// continental or oceanic). Sets `init.flood_fill`.
    #[arg(long)]
    pub(crate) init: Option<InitMethod>,
    /// Impact craters struck into the initial crust (a late heavy bombardment; radii 200 to
    /// 2,500 km by default). Sets `init.craters`.
    #[arg(long)]
    pub(crate) craters: Option<u64>,
    /// Build the climate and the drainage network on one step in K (1 to 16; 2 is the default),
    /// the sediment laying down with each new network what the rivers and coasts, which run
    /// every step on the last network, eroded since. 1 builds them every step, a little slower
    /// for the same relief (docs/relief.md). Sets `time.relief_interval_steps`.
    #[arg(long, value_name = "K")]
    pub(crate) relief_every: Option<u64>,
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

/// The start methods of `--init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum InitMethod {
    /// Warped Voronoi plates, continents from a noise field.
    Voronoi,
    /// Plates grown from seed points over the sample graph.
    FloodFill,
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
            let (params, plugins) = match &config {
                Some(p) => read_config(p)?,
                None => (Params::default(), PluginConfig::default()),
            };
            let mut registry = tiny_sim()?;
            registry
                .apply_plugin_config(&plugins)
                .with_context(|| config_context(config.as_deref()))?;
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
        Command::ProbeAdapters => {
            print!("{}", tectonic_planets::gpu::AdapterSurvey::take().to_text());
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
        bail!("phenomenon \"{}\" is both enabled and disabled", clip(n));
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

/// "config FILE", to say where a parameter error comes from.
pub(crate) fn config_context(path: Option<&Path>) -> String {
    match path {
        Some(p) => format!("config {}", p.display()),
        None => "plugin parameters".into(),
    }
}

/// The core parameters and the plugin parameter tables of a config file, from one read of it
/// (so that `--config <(...)` and `--config /dev/stdin` work).
pub(crate) fn read_config(path: &Path) -> Result<(Params, PluginConfig)> {
    let text = read_param_file(path)?;
    let ctx = || config_context(Some(path));
    let params = Params::from_toml_str(&text).with_context(ctx)?;
    let plugins = PluginConfig::from_toml_str(&text).with_context(ctx)?;
    Ok((params, plugins))
}

/// Parameters from the config file (already read, or the defaults) and the command line,
/// validated.
pub(crate) fn load_params(a: &PlanetArgs, base: Params) -> Result<Params> {
    let mut params = base;
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
    if let Some(m) = a.init {
        set(
            &mut params,
            "init.flood_fill",
            ParamValue::Bool(m == InitMethod::FloodFill),
        )?;
    }
    if let Some(c) = a.craters {
        set(&mut params, "init.craters", ParamValue::Int(c))?;
    }
    if let Some(k) = a.relief_every {
        set(
            &mut params,
            "time.relief_interval_steps",
            ParamValue::Int(k),
        )?;
    }
    params.validate()?;
    Ok(params)
}

/// The most worker threads `--threads` may ask for: 4 per core, and never more than 256
/// (more only adds switching: results do not depend on the thread count).
pub(crate) fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (4 * cores).clamp(4, 256)
}

pub(crate) fn setup_threads(threads: Option<usize>) -> Result<()> {
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        let max = max_threads();
        if n > max {
            bail!(
                "--threads {n} is more than this machine can use: at most {max} (4 per core, 256 at most); results do not depend on it"
            );
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("could not start the thread pool")?;
    }
    Ok(())
}

/// The parameters of a new planet (the config, read once, and the command line), checked, and
/// the thread pool; nothing is built yet.
pub(crate) fn planet_params(a: &PlanetArgs) -> Result<(Params, PluginConfig)> {
    setup_threads(a.threads)?;
    let (base, plugins) = match &a.config {
        Some(p) => read_config(p)?,
        None => (Params::default(), PluginConfig::default()),
    };
    Ok((load_params(a, base)?, plugins))
}

/// Steps of `my` million years at the time step of `params` (as `Simulation::steps_for`).
pub(crate) fn steps_of(params: &Params, my: f64) -> u64 {
    (my / params.time.time_step_my).round() as u64
}

/// Builds the planet of [`planet_params`]: the plugin parameters, the switches. The compute
/// backend is chosen by the caller ([`use_backend`]) once every other check has passed.
pub(crate) fn build_sim(
    a: &PlanetArgs,
    params: Params,
    plugins: PluginConfig,
    start: Option<&StartMaps>,
) -> Result<Simulation> {
    let mut sim = match start {
        Some(s) => s.build(params)?,
        None => Simulation::new(params)?,
    };
    sim.apply_plugin_config(&plugins)
        .with_context(|| config_context(a.config.as_deref()))?;
    apply_switches(&mut sim, &a.switches.enable, &a.switches.disable)?;
    Ok(sim)
}

/// Installs the compute backend; says which one when it is not the one asked for.
///
/// Under `auto` the adapters are first surveyed in a child process (this program, `planet
/// probe-adapters`): with no hardware GPU the CPU runs, and no Vulkan driver (Mesa's lavapipe
/// and its LLVM, about 55 MB resident) is ever loaded here. With one, or when the child cannot
/// tell, the search runs here as before.
pub(crate) fn use_backend(sim: &mut Simulation, choice: BackendChoice) -> Result<()> {
    let surveyed = (choice == BackendChoice::Auto)
        .then(survey_in_child)
        .flatten()
        .filter(|s| s.hardware.is_none());
    let note = match surveyed {
        Some(survey) => {
            tracing::debug!("adapters surveyed in a child process: no hardware GPU");
            sim.set_backend(BackendChoice::Cpu)
                .context("could not start the CPU compute backend")?;
            survey.cpu_note()
        }
        None => sim
            .set_backend(choice)
            .context("could not start the GPU compute backend")?,
    };
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

/// The adapters as `planet probe-adapters` (this executable, in a child process) finds them;
/// `None` when the child could not be run or said something else.
fn survey_in_child() -> Option<tectonic_planets::gpu::AdapterSurvey> {
    let exe = std::env::current_exe().ok()?;
    let out = std::process::Command::new(exe)
        .arg("probe-adapters")
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    tectonic_planets::gpu::AdapterSurvey::from_text(&String::from_utf8_lossy(&out.stdout))
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
        bail!(
            "{flag} must be a finite, non-negative number of million years, got {}",
            num(my)
        );
    }
    Ok(())
}

/// Work (samples × steps) above which a run is refused: about two weeks on the CPU of the
/// 2-core machine of the README.
pub(crate) const MAX_SAMPLE_STEPS: f64 = 1e13;
/// Work above which the estimated time is printed first: about an hour there.
pub(crate) const WARN_SAMPLE_STEPS: f64 = 3e10;
/// Seconds per sample and step on that machine's CPU (`planet bench`: about 60 ms a step at
/// 500,000 samples); a GPU is faster, so the estimate is an upper bound there.
pub(crate) const SECONDS_PER_SAMPLE_STEP: f64 = 1.2e-7;

/// A duration in words: `40 s`, `12 min`, `3.5 h`, `9 days`, `2e9 years`.
pub(crate) fn duration_in_words(secs: f64) -> String {
    let (v, unit) = if secs < 120.0 {
        (secs, "s")
    } else if secs < 7200.0 {
        (secs / 60.0, "min")
    } else if secs < 3.0 * 86400.0 {
        (secs / 3600.0, "h")
    } else if secs < 3.0 * 365.25 * 86400.0 {
        (secs / 86400.0, "days")
    } else {
        (secs / (365.25 * 86400.0), "years")
    };
    if v < 1e6 {
        format!("{v:.0} {unit}")
    } else {
        format!("{v:.1e} {unit}")
    }
}

/// Refuses a run of `steps` steps on `samples` samples that would take weeks or more (a typo
/// like `--my 1e12`), and says how long a long one will take before it starts. `what` names the
/// option that asked for it.
pub(crate) fn check_run_length(what: &str, steps: u64, samples: usize, quiet: bool) -> Result<()> {
    let work = steps as f64 * samples as f64;
    let estimate = duration_in_words(work * SECONDS_PER_SAMPLE_STEP);
    if work > MAX_SAMPLE_STEPS {
        bail!(
            "{what} means {steps} steps of {samples} samples, about {estimate} of computing (estimated at {:.0} µs per 1,000 samples a step on a 2-core CPU); at most {MAX_SAMPLE_STEPS:.0e} samples × steps are run: ask for less time or fewer samples",
            SECONDS_PER_SAMPLE_STEP * 1e9
        );
    }
    if work > WARN_SAMPLE_STEPS && !quiet {
        eprintln!(
            "note: {what} means {steps} steps of {samples} samples: about {estimate} on a 2-core CPU (less on a GPU)"
        );
    }
    Ok(())
}

/// Creates the output folder (after every other check, so that a refused command leaves no
/// empty folder) and makes sure files can be written in it, before any work is done.
pub(crate) fn prepare_out_dir(dir: &Path) -> Result<()> {
    if let Ok(m) = std::fs::metadata(dir)
        && !m.is_dir()
    {
        bail!(
            "output path {} is {}, not a folder",
            dir.display(),
            tectonic_planets::resources::input::kind_in_words(m.file_type())
        );
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("could not create output folder {}", dir.display()))?;
    probe_writable(dir).with_context(|| format!("cannot write in output folder {}", dir.display()))
}

/// Creates and removes a file in `dir`: the check that it takes files, before a long run.
pub(crate) fn probe_writable(dir: &Path) -> Result<()> {
    let probe = dir.join(format!(".planet-write-test.{}", std::process::id()));
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&probe)?;
    std::fs::remove_file(&probe)?;
    Ok(())
}

/// Refuses output files (in `dir`) that exist and are not regular files: a map written onto a
/// FIFO would block, onto a device would be lost.
pub(crate) fn check_output_files<'a>(
    dir: &Path,
    names: impl IntoIterator<Item = &'a str>,
) -> Result<()> {
    for name in names {
        let p = dir.join(name);
        if let Ok(m) = std::fs::metadata(&p)
            && !m.is_file()
        {
            bail!(
                "output file {} is {}; outputs only replace regular files (remove it or choose another --out)",
                p.display(),
                tectonic_planets::resources::input::kind_in_words(m.file_type())
            );
        }
    }
    Ok(())
}
