//! `planet`: the command-line interface of the tectonic planet generator.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use tectonic_planets::Simulation;
use tectonic_planets::commands::{Command as Cmd, Outcome, Script};
use tectonic_planets::gpu::{BackendChoice, ComputeBackend, GpuContext};
use tectonic_planets::io::maps::{Raster, write_all_maps};
use tectonic_planets::io::save::{self, CommandHistory};
use tectonic_planets::io::summary::{CrustSampler, summarize};
use tectonic_planets::plugins::TectonicSystems;
use tectonic_planets::resources::params::{ParamValue, Params};
use tectonic_planets::resources::plugin_params::PluginConfig;

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
    /// Continue a saved planet for some more million years, then save it (and write maps).
    Resume(ResumeArgs),
    /// Write the maps and summary of a saved planet, as `generate` does.
    Export(ExportArgs),
    /// Open the viewer: watch, steer and toggle the stepped schedule live.
    #[cfg(feature = "viewer")]
    View(ViewArgs),
}

#[cfg(feature = "viewer")]
#[derive(Args)]
struct ViewArgs {
    /// A saved planet to open (otherwise a new planet from the options).
    file: Option<PathBuf>,
    #[command(flatten)]
    planet: PlanetArgs,
    /// Take this many steps, then exit (with --screenshot: after writing it).
    #[arg(long, value_name = "N")]
    exit_after_steps: Option<u64>,
    /// Write a PNG screenshot of the window before exiting (needs --exit-after-steps).
    #[arg(long, value_name = "FILE", requires = "exit_after_steps")]
    screenshot: Option<PathBuf>,
    /// Measure the frame rate: run the simulation, exit after N frames drawn while it steps,
    /// and print the median and 90th-percentile frame times.
    #[arg(long, value_name = "N", conflicts_with = "exit_after_steps")]
    fps_report: Option<u64>,
    /// Window width and height in pixels.
    #[arg(long, value_name = "WxH", default_value = "1280x800")]
    window: String,
    /// Start in the 3D globe view (instead of the 2D map).
    #[arg(long)]
    globe: bool,
    /// Steps per second while running (default: as fast as possible).
    #[arg(long, value_name = "STEPS")]
    speed: Option<f64>,
    /// Map colouring at start: elevation, plates, crust_type, oceanic_age, orogeny_type,
    /// orogeny_age, laplacian.
    #[arg(long, default_value = "elevation")]
    overlay: String,
    /// Vector layers drawn at start, comma-separated: folds, ridges, velocity, fronts, terranes.
    #[arg(long, value_delimiter = ',')]
    draw: Vec<String>,
}

/// Where and how often to save.
#[derive(Args, Clone)]
struct SaveArgs {
    /// Save the planet to this file at the end (a bare file name goes into `saves/`).
    #[arg(long)]
    save: Option<PathBuf>,
    /// Also save every this many million years while running (to the `--save` file, or to
    /// `saves/planet-<seed>.planet` when none is given).
    #[arg(long, value_name = "MY")]
    save_every: Option<f64>,
}

#[derive(Args)]
struct ResumeArgs {
    /// The save to continue.
    file: PathBuf,
    /// Simulated time to add, million years.
    #[arg(long)]
    my: f64,
    /// Also write maps and summary.json into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    saving: SaveArgs,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    width: u32,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Compute backend: auto, gpu or cpu (see `generate --help`).
    #[arg(long, default_value = "auto")]
    backend: BackendChoice,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Phenomena to switch on or off from now on (the save keeps the switches otherwise).
    #[command(flatten)]
    switches: SwitchArgs,
}

#[derive(Args)]
struct ExportArgs {
    /// The save to export.
    file: PathBuf,
    /// Output folder for the maps and summary.json.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    width: u32,
    /// No listing of the files written.
    #[arg(long)]
    quiet: bool,
    /// Skip the standard maps and summary (write only the exports asked for below).
    #[arg(long)]
    no_maps: bool,
    /// Compute backend of the amplified export: auto (a hardware GPU if any, else the CPU), gpu
    /// (any wgpu adapter, software ones included), cpu (bit-reproducible everywhere).
    #[arg(long, default_value = "auto")]
    backend: BackendChoice,
    #[command(flatten)]
    extra: ExtraExports,
}

/// Opt-in exports: amplified relief, GeoTIFFs, regional tiles, glTF (see docs/exports.md).
#[derive(Args, Clone, Default)]
struct ExtraExports {
    /// Amplified elevation (paper §5): a 16-bit PNG heightmap with a JSON sidecar
    /// (`amplified16.png`, or `tile16.png` with --region), plus a GeoTIFF with --geotiff.
    #[arg(long)]
    amplified: bool,
    /// Width of the global amplified heightmap (height is half); default: --width.
    #[arg(long, value_name = "W")]
    amplified_width: Option<u32>,
    /// Float32 GeoTIFFs (EPSG:4326) of every crust layer, and of the amplified elevation with
    /// --amplified.
    #[arg(long)]
    geotiff: bool,
    /// Export a region instead of the globe: LAT0,LON0,LAT1,LON1 in degrees.
    #[arg(long, value_name = "LAT0,LON0,LAT1,LON1", allow_hyphen_values = true)]
    region: Option<String>,
    /// Pixel size of --region: 100m, 2km or 0.001deg (metres measured north-south).
    #[arg(long, default_value = "100m")]
    resolution: String,
    /// Elevation exemplars for continental relief: a folder with andean/, himalayan/, old/,
    /// plain/ sub-folders of 16-bit PNG or GeoTIFF files.
    #[arg(long, value_name = "DIR")]
    exemplars: Option<PathBuf>,
    /// Multiplies the amplified relief (1 = the model's amplitudes).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    relief_scale: f32,
    /// Also write a shaded preview PNG of the amplified elevation (and of the crust alone).
    #[arg(long)]
    preview: bool,
    /// A glTF 2.0 binary mesh of the planet (`planet.glb`).
    #[arg(long)]
    gltf: bool,
    /// Longitude segments of the glTF mesh (latitude rings are half as many).
    #[arg(long, default_value_t = 1024)]
    gltf_segments: u32,
    /// Elevation exaggeration of the glTF mesh.
    #[arg(long, default_value_t = 20.0)]
    exaggeration: f64,
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
    #[command(flatten)]
    switches: SwitchArgs,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// Compute backend: auto (a hardware GPU if any, else the CPU), gpu (any wgpu adapter,
    /// software ones included), cpu.
    #[arg(long, default_value = "auto")]
    backend: BackendChoice,
}

/// Phenomena to switch on or off.
#[derive(Args, Clone)]
struct SwitchArgs {
    /// Phenomena to switch off, comma-separated (see `planet plugins`).
    #[arg(long, value_delimiter = ',')]
    disable: Vec<String>,
    /// Phenomena to switch on, comma-separated (e.g. `hotspots`, off by default).
    #[arg(long, value_delimiter = ',')]
    enable: Vec<String>,
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
    #[command(flatten)]
    saving: SaveArgs,
    /// A script of timed authoring commands (TOML; see examples/scripts/ and docs/authoring.md).
    #[arg(long)]
    script: Option<PathBuf>,
    /// Also write the maps every this many million years, into `<out>/t<time>My/`.
    #[arg(long, value_name = "MY")]
    maps_every: Option<f64>,
    #[command(flatten)]
    extra: ExtraExports,
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

/// Mesa's Vulkan drivers (probed by `--backend auto`) print an error on every adapter request
/// when `XDG_RUNTIME_DIR` is unset, as on servers and in containers. Give them a private
/// directory, before any thread starts.
fn ensure_runtime_dir() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    let user = std::env::var("USER").unwrap_or_default();
    let dir = std::env::temp_dir().join(format!("planet-runtime-{user}"));
    if std::fs::create_dir_all(&dir).is_ok() {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
        }
        // SAFETY: called first thing in `main`, before any other thread exists.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

fn main() {
    ensure_runtime_dir();
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
fn tiny_sim() -> Result<Simulation> {
    let mut params = Params::default();
    params.planet.samples = 1000;
    params.init.plates = 2;
    Ok(Simulation::new(params)?)
}

/// Switches phenomena on (`enable`) and off (`disable`); a name in both is refused.
fn apply_switches(sim: &mut Simulation, enable: &[String], disable: &[String]) -> Result<()> {
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
    use_backend(&mut sim, a.backend)?;
    if let Some(path) = &a.config {
        sim.apply_plugin_config(&PluginConfig::load(path)?)?;
    }
    apply_switches(&mut sim, &a.switches.enable, &a.switches.disable)?;
    Ok(sim)
}

/// Installs the compute backend; says which one when it is not the one asked for.
fn use_backend(sim: &mut Simulation, choice: BackendChoice) -> Result<()> {
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
fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!("planet {}", args.join(" "))
}

fn check_width(width: u32) -> Result<()> {
    if !(2..=16384).contains(&width) || !width.is_multiple_of(2) {
        bail!("--width must be an even number between 2 and 16384, got {width}");
    }
    Ok(())
}

fn check_my(flag: &str, my: f64) -> Result<()> {
    if !my.is_finite() || my < 0.0 {
        bail!("{flag} must be a finite, non-negative number of million years, got {my}");
    }
    Ok(())
}

/// The save file and the number of steps between saves, from the options.
fn save_plan(
    sim: &Simulation,
    s: &SaveArgs,
    default: Option<&Path>,
) -> Result<Option<(PathBuf, u64)>> {
    let every = match s.save_every {
        Some(my) => {
            if !my.is_finite() || my <= 0.0 {
                bail!("--save-every must be a finite, positive number of million years, got {my}");
            }
            sim.steps_for(my)?.max(1)
        }
        None => 0,
    };
    let path = match (&s.save, default) {
        (Some(p), _) => Some(save::resolve_save_path(p)),
        (None, Some(d)) => Some(d.to_path_buf()),
        (None, None) if every > 0 => Some(Path::new(save::DEFAULT_DIR).join(format!(
            "planet-{}.{}",
            sim.params().planet.seed,
            save::EXTENSION
        ))),
        (None, None) => None,
    };
    if let Some(p) = &path
        && p.is_dir()
    {
        bail!("save path {} is a folder, not a file", p.display());
    }
    Ok(path.map(|p| (p, every)))
}

fn save_now(sim: &mut Simulation, path: &Path) -> Result<()> {
    let t = Instant::now();
    let info = save::save_to_file(sim, path)?;
    tracing::info!(
        path = %path.display(),
        bytes = info.file_bytes,
        ms = t.elapsed().as_secs_f64() * 1e3,
        "saved"
    );
    Ok(())
}

/// What happens along a run besides stepping: saves, script events, map snapshots.
#[derive(Default)]
struct RunExtras<'a> {
    /// Save file and steps between saves (0: only at the end, by the caller).
    plan: Option<&'a (PathBuf, u64)>,
    /// Timed commands.
    script: Option<Script>,
    /// Map snapshots: folder, steps between snapshots and map width.
    maps: Option<(PathBuf, u64, u32)>,
}

fn describe(o: &Outcome) -> String {
    match o {
        Outcome::Motion { plate } => format!("plate {plate} has a new motion"),
        Outcome::CrustType { samples } => format!("{samples} samples changed crust type"),
        Outcome::Rift { fragments } => format!("rift into plates {fragments:?}"),
        Outcome::Uplift { samples } => format!("{samples} samples raised or lowered"),
        Outcome::Phenomenon => "phenomenon switched".into(),
        Outcome::Param { key } => format!("{key} set"),
    }
}

/// Runs `steps` steps with a progress bar, applying script events when due, saving every
/// `plan.1` steps (when non-zero) and writing map snapshots.
fn run_steps_with_progress(
    sim: &mut Simulation,
    steps: u64,
    quiet: bool,
    extras: RunExtras,
) -> Result<()> {
    let RunExtras {
        plan,
        mut script,
        maps,
    } = extras;
    let bar = if quiet {
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
        if let Some(script) = script.as_mut() {
            for (event, outcome) in script.apply_due(sim)? {
                if !quiet {
                    bar.suspend(|| {
                        eprintln!(
                            "{:>7.1} My  {}{}",
                            sim.time_my(),
                            event
                                .note
                                .as_deref()
                                .map(|n| format!("{n}: "))
                                .unwrap_or_default(),
                            describe(&outcome)
                        )
                    });
                }
            }
        }
        sim.step()?;
        if let Some((dir, every, width)) = &maps
            && (k + 1) % every == 0
        {
            let sub = dir.join(format!("t{:04.0}My", sim.time_my()));
            write_outputs(sim, &sub, *width)?;
        }
        if let Some((path, every)) = plan
            && *every > 0
            && (k + 1) % every == 0
            && k + 1 < steps
        {
            save_now(sim, path)?;
        }
        bar.set_message(format!(
            "{:.0}/{:.0} My",
            (k + 1) as f64 * dt,
            steps as f64 * dt
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}

/// Writes the maps and summary of `sim` into `out`; returns the files written.
fn write_outputs(sim: &mut Simulation, out: &Path, width: u32) -> Result<Vec<PathBuf>> {
    prepare_out_dir(out)?;
    let view = sim.resampled_crust();
    let raster = Raster::sample(
        &CrustSampler {
            mesh: sim.mesh(),
            crust: &view,
        },
        width,
        width / 2,
    )?;
    let mut files = write_all_maps(&raster, out, sim.params().planet.radius_km)?;
    let summary = summarize(sim, &view);
    let summary_path = out.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("could not write {}", summary_path.display()))?;
    files.push(summary_path);
    Ok(files)
}

fn report(sim: &Simulation, started: Instant, files: &[PathBuf]) {
    let s = sim.stats();
    eprintln!(
        "{} samples, {} plates, {:.0} My in {:.1} s: land {:.1}%, continental crust {:.1}%",
        sim.mesh().len(),
        s.plates,
        sim.time_my(),
        started.elapsed().as_secs_f64(),
        100.0 * s.land_fraction,
        100.0 * s.continental_fraction
    );
    for f in files {
        eprintln!("  wrote {}", f.display());
    }
}

fn generate(a: GenerateArgs) -> Result<()> {
    check_my("--my", a.my)?;
    check_width(a.width)?;
    prepare_out_dir(&a.out)?;
    let started = Instant::now();
    let mut sim = build_sim(&a.planet)?;
    sim.world_mut()
        .resource_mut::<CommandHistory>()
        .record(0, command_line());
    let plan = save_plan(&sim, &a.saving, None)?;
    let steps = sim.steps_for(a.my)?;
    let script = match &a.script {
        Some(path) => {
            let script = Script::load(path)?;
            script.validate(sim.params())?;
            let late = script.events.iter().filter(|e| e.at_my > a.my).count();
            if late > 0 && !a.quiet {
                eprintln!(
                    "note: {late} script event(s) come after the end of the run ({} My) and will not happen",
                    a.my
                );
            }
            Some(script)
        }
        None => None,
    };
    let maps = match a.maps_every {
        Some(my) => {
            if !my.is_finite() || my <= 0.0 {
                bail!("--maps-every must be a finite, positive number of million years, got {my}");
            }
            Some((a.out.clone(), sim.steps_for(my)?.max(1), a.width))
        }
        None => None,
    };
    let extras = RunExtras {
        plan: plan.as_ref(),
        script,
        maps,
    };
    run_steps_with_progress(&mut sim, steps, a.quiet, extras)?;
    let mut files = write_outputs(&mut sim, &a.out, a.width)?;
    files.extend(write_extra_exports(
        &mut sim, &a.out, a.width, &a.extra, a.quiet,
    )?);
    finish_run(&mut sim, plan.as_ref(), files, a.quiet, started)
}

/// The end of `generate` and `resume`: the final save (if any), then the report.
fn finish_run(
    sim: &mut Simulation,
    plan: Option<&(PathBuf, u64)>,
    mut files: Vec<PathBuf>,
    quiet: bool,
    started: Instant,
) -> Result<()> {
    if let Some((path, _)) = plan {
        save_now(sim, path)?;
        files.push(path.clone());
    }
    if !quiet {
        report(sim, started, &files);
    }
    Ok(())
}

fn resume(a: ResumeArgs) -> Result<()> {
    check_my("--my", a.my)?;
    check_width(a.width)?;
    setup_threads(a.threads)?;
    if let Some(out) = &a.out {
        prepare_out_dir(out)?;
    }
    let started = Instant::now();
    let mut sim = save::load_from_file(&a.file)?;
    apply_switches(&mut sim, &a.switches.enable, &a.switches.disable)?;
    use_backend(&mut sim, a.backend)?;
    let step = sim.clock().step;
    sim.world_mut()
        .resource_mut::<CommandHistory>()
        .record(step, command_line());
    let plan = save_plan(&sim, &a.saving, Some(&a.file))?;
    let steps = sim.steps_for(a.my)?;
    let extras = RunExtras {
        plan: plan.as_ref(),
        ..Default::default()
    };
    run_steps_with_progress(&mut sim, steps, a.quiet, extras)?;
    let files = match &a.out {
        Some(out) => write_outputs(&mut sim, out, a.width)?,
        None => Vec::new(),
    };
    finish_run(&mut sim, plan.as_ref(), files, a.quiet, started)
}

fn export(a: ExportArgs) -> Result<()> {
    check_width(a.width)?;
    let started = Instant::now();
    let mut sim = save::load_from_file(&a.file)?;
    if a.extra.amplified {
        use_backend(&mut sim, a.backend)?;
    }
    let mut files = if a.no_maps {
        prepare_out_dir(&a.out)?;
        Vec::new()
    } else {
        write_outputs(&mut sim, &a.out, a.width)?
    };
    files.extend(write_extra_exports(
        &mut sim, &a.out, a.width, &a.extra, a.quiet,
    )?);
    if !a.quiet {
        report(&sim, started, &files);
    }
    Ok(())
}

/// Writes the opt-in exports of `e` into `out`; returns the files written. On the GPU backend
/// the amplified heightmap is amplified on the device (procedural relief only).
fn write_extra_exports(
    sim: &mut Simulation,
    out: &Path,
    width: u32,
    e: &ExtraExports,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    // The context leaves the world while the mesh is borrowed, and goes back afterwards.
    let mut gpu = sim.world_mut().remove_resource::<GpuContext>();
    let r = write_extra_exports_on(sim, gpu.as_mut(), out, width, e, quiet);
    if let Some(ctx) = gpu {
        sim.world_mut().insert_resource(ctx);
    }
    r
}

/// [`write_extra_exports`] with the GPU context, if any.
fn write_extra_exports_on(
    sim: &mut Simulation,
    gpu: Option<&mut GpuContext>,
    out: &Path,
    width: u32,
    e: &ExtraExports,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    use tectonic_planets::amplify::{Amplifier, AmplifyOptions};
    use tectonic_planets::io::export::{self, ElevationOutputs, GeoGrid};
    use tectonic_planets::io::gltf;
    let wants_amp = e.amplified || e.preview || e.gltf;
    if !(wants_amp || e.geotiff) {
        if e.region.is_some() || e.exemplars.is_some() {
            bail!("--region and --exemplars need --amplified, --geotiff, --preview or --gltf");
        }
        return Ok(Vec::new());
    }
    if !(e.relief_scale.is_finite() && (0.0..=10.0).contains(&e.relief_scale)) {
        bail!(
            "--relief-scale must be between 0 and 10, got {}",
            e.relief_scale
        );
    }
    let say = |what: &str, t: Instant| {
        if !quiet {
            eprintln!("  {what} in {:.2} s", t.elapsed().as_secs_f64());
        }
    };
    let radius_km = sim.params().planet.radius_km;
    let seed = sim.params().planet.seed;
    let view = sim.resampled_crust();
    let mesh = sim.mesh();
    let (grid, prefix) = match &e.region {
        Some(r) => {
            let [lat0, lon0, lat1, lon1] = export::parse_region(r)?;
            let px = export::parse_resolution(&e.resolution, radius_km)?;
            (GeoGrid::region(lat0, lon0, lat1, lon1, px)?, "tile_")
        }
        None => {
            let w = e.amplified_width.unwrap_or(width);
            check_width(w).context("--amplified-width")?;
            (GeoGrid::global(w, w / 2)?, "")
        }
    };
    let mut files = Vec::new();
    if e.geotiff {
        let t = Instant::now();
        files.extend(export::export_crust_layers(
            mesh, &view, &grid, out, prefix,
        )?);
        say(&format!("crust GeoTIFFs {}x{}", grid.width, grid.height), t);
    }
    if !wants_amp {
        return Ok(files);
    }
    let t = Instant::now();
    let options = AmplifyOptions {
        relief_scale: e.relief_scale,
        ..Default::default()
    };
    let mut amp = Amplifier::new(mesh, &view, seed, options);
    if let Some(dir) = &e.exemplars {
        let set = tectonic_planets::io::exemplars::load_exemplar_dir(dir)?;
        amp = amp.with_exemplars(set, seed, options);
    }
    say("amplification tables", t);
    if e.amplified {
        let t = Instant::now();
        let outputs = ElevationOutputs {
            png16: Some(out.join(format!("{prefix}amplified16.png"))),
            geotiff: e
                .geotiff
                .then(|| out.join(format!("{prefix}amplified.tif"))),
        };
        let on = match (&gpu, &amp.exemplars) {
            (Some(ctx), None) => format!("gpu: {}", ctx.adapter.name),
            (Some(_), Some(_)) => "cpu: the GPU kernel has no exemplars".to_string(),
            (None, _) => "cpu".to_string(),
        };
        files.extend(export::export_amplified_on(&amp, &grid, &outputs, gpu)?);
        say(
            &format!("amplified {}x{} ({on})", grid.width, grid.height),
            t,
        );
    }
    if e.preview {
        let t = Instant::now();
        // Previews are capped at 4096 pixels wide (sampled on a coarser lattice if needed).
        let k = grid.width.div_ceil(4096).max(grid.height.div_ceil(4096));
        let pgrid = GeoGrid {
            dx_deg: grid.dx_deg * f64::from(k),
            dy_deg: grid.dy_deg * f64::from(k),
            i0: grid.i0 / i64::from(k),
            j0: grid.j0 / i64::from(k),
            width: grid.width / k,
            height: grid.height / k,
        };
        let after = pgrid.sample(&|d| amp.elevation_m(d));
        let before = pgrid.sample(&|d| amp.crust_elevation_m(d));
        for (name, z) in [
            ("amplified_preview.png", after),
            ("crust_preview.png", before),
        ] {
            let img = export::shaded_preview(&pgrid, &z, radius_km);
            files.push(export::save_rgb(
                &img,
                &out.join(format!("{prefix}{name}")),
            )?);
        }
        say("previews", t);
    }
    if e.gltf {
        let t = Instant::now();
        let opts = gltf::GltfOptions {
            segments: e.gltf_segments,
            exaggeration: e.exaggeration,
            radius_km,
        };
        files.push(gltf::write_planet_glb(
            &out.join("planet.glb"),
            &opts,
            &|d| amp.elevation_m(d),
            &gltf::elevation_colour,
        )?);
        say("glTF mesh", t);
    }
    Ok(files)
}

#[cfg(feature = "viewer")]
fn view(a: ViewArgs) -> Result<()> {
    let (w, h) = a
        .window
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .filter(|(w, h)| (320..=8192).contains(w) && (200..=8192).contains(h))
        .with_context(|| {
            format!(
                "--window must be WIDTHxHEIGHT within 320x200..8192x8192, got \"{}\"",
                a.window
            )
        })?;
    setup_threads(a.planet.threads)?;
    // Parameters are checked here, before any window; the planet is built on the viewer's
    // simulation thread.
    let source = match &a.file {
        Some(path) => {
            if !path.is_file() {
                bail!(
                    "save file {} does not exist or is not a file",
                    path.display()
                );
            }
            Err(path.clone())
        }
        None => {
            let mut planet = a.planet.clone();
            if planet.samples.is_none() && planet.config.is_none() {
                // A planet that steps briskly on a laptop; --samples asks for more.
                planet.samples = Some(100_000);
            }
            Ok((load_params(&planet)?, planet))
        }
    };
    let switches = a.planet.switches.clone();
    let build = move || -> std::result::Result<Simulation, String> {
        let mut sim = match source {
            Err(path) => save::load_from_file(&path).map_err(|e| e.to_string())?,
            Ok((params, planet)) => {
                let mut sim = Simulation::new(params).map_err(|e| e.to_string())?;
                if let Some(path) = &planet.config {
                    let config = PluginConfig::load(path).map_err(|e| e.to_string())?;
                    sim.apply_plugin_config(&config)
                        .map_err(|e| e.to_string())?;
                }
                sim
            }
        };
        apply_switches(&mut sim, &switches.enable, &switches.disable)
            .map_err(|e| format!("{e:#}"))?;
        Ok(sim)
    };
    let opts = tectonic_planets::viewer::ViewerOptions {
        window_size: [w as f32, h as f32],
        exit_after_steps: a.exit_after_steps,
        screenshot: a.screenshot.clone(),
        globe: a.globe,
        fps_report: match a.fps_report {
            Some(0) => bail!("--fps-report needs at least 1 frame"),
            n => n,
        },
        steps_per_second: match a.speed {
            Some(s) if !s.is_finite() || s <= 0.0 => {
                bail!("--speed must be a positive number of steps per second, got {s}")
            }
            Some(s) => s,
            None => 0.0,
        },
        base: a.overlay.parse().map_err(anyhow::Error::msg)?,
        layers: tectonic_planets::viewer::map::VectorLayers::from_names(&a.draw)
            .map_err(anyhow::Error::msg)?,
    };
    let report = tectonic_planets::viewer::run(build, opts)?;
    if a.fps_report.is_some() {
        let show = |p: Option<tectonic_planets::viewer::Percentiles>| {
            p.map_or("–".to_string(), |p| {
                format!("median {:.1} ms, p90 {:.1} ms", p.median, p.p90)
            })
        };
        println!(
            "fps report: {} samples, window {}x{}, {} frames while stepping, {} steps, {} snapshots",
            report.samples, w, h, report.running_frames, report.steps, report.snapshots
        );
        println!("  frame interval: {}", show(report.frame_ms));
        if let Some(p) = report.frame_ms {
            println!("  fps (1 / median interval): {:.1}", 1e3 / p.median);
        }
        if let Some(f) = report.running_fps {
            println!("  fps (frames / seconds):    {f:.1}");
        }
        println!("  app UI code:    {}", show(report.ui_ms));
        println!("  eframe CPU:     {}", show(report.cpu_ms));
    }
    if a.exit_after_steps.is_some() {
        eprintln!(
            "viewer: {} samples, {} steps, {} frames while stepping ({})",
            report.samples,
            report.steps,
            report.running_frames,
            report
                .running_fps
                .map_or("no fps figure".into(), |f| format!("{f:.1} fps"))
        );
        if let Some(p) = &a.screenshot {
            eprintln!("  wrote {}", p.display());
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

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Rifts the largest plate into two, `n` times (a step after each, which resamples), and returns
/// the wall time of each rift itself (partition, motions, plate geometry), ms.
fn bench_rifts(sim: &mut Simulation, n: usize) -> Result<Vec<f64>> {
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

fn bench(a: BenchArgs) -> Result<()> {
    let t0 = Instant::now();
    let mut sim = build_sim(&a.planet)?;
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
    // Each step: wall time, what kind of step it was, and its GPU traffic.
    let mut steps: Vec<BenchStep> = Vec::new();
    let traffic0 = gpu_traffic(&sim);
    for _ in 0..a.steps {
        let before = (sim.clock().resamplings, gpu_traffic(&sim));
        let s = Instant::now();
        sim.step()?;
        let ms = s.elapsed().as_secs_f64() * 1e3;
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
    let traffic1 = gpu_traffic(&sim);
    let step_ms: Vec<f64> = steps.iter().map(|s| s.ms).collect();
    for _ in 0..a.resamplings {
        sim.request_resample();
        sim.step()?;
    }
    let rift_ms = bench_rifts(&mut sim, 3)?;
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
    println!(
        "{:<28} {:>10.3} ms",
        "whole step (median)",
        median(&step_ms)
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

/// One timed step of the bench.
struct BenchStep {
    /// Wall time, ms.
    ms: f64,
    /// Steady, resampling, or the step right after a resampling.
    kind: StepKind,
    /// Bytes uploaded and downloaded during the step (GPU backend only).
    traffic: Option<(u64, u64)>,
}

/// The kinds of step the bench reports apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StepKind {
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
fn print_step_traffic(steps: &[BenchStep], samples: usize) {
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
fn backend_name(sim: &Simulation) -> String {
    match sim.world().get_resource::<GpuContext>() {
        Some(g) => format!("gpu ({}, {:?})", g.adapter.name, g.adapter.device_type),
        None => "cpu".into(),
    }
}

/// The GPU traffic counters, on the GPU backend.
fn gpu_traffic(sim: &Simulation) -> Option<tectonic_planets::gpu::GpuTraffic> {
    sim.world().get_resource::<GpuContext>().map(|g| g.traffic)
}

/// Times a save (encode, compress, write, sync) and a load (read, check, decompress, rebuild the
/// mesh, restore) of the benchmark planet, and gives the file size.
fn bench_saves(sim: &mut Simulation) -> Result<()> {
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
