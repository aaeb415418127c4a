//! `planet`: the command-line interface of the tectonic planet generator.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use tectonic_planets::Simulation;
use tectonic_planets::io::maps::{Raster, write_all_maps};
use tectonic_planets::io::params::{ParamValue, Params};
use tectonic_planets::io::save::{self, CommandHistory};
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
    /// Continue a saved planet for some more million years, then save it (and write maps).
    Resume(ResumeArgs),
    /// Write the maps and summary of a saved planet, as `generate` does.
    Export(ExportArgs),
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
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
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
    #[command(flatten)]
    saving: SaveArgs,
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
        Command::Resume(a) => resume(a),
        Command::Export(a) => export(a),
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

/// Runs `steps` steps with a progress bar, saving every `plan.1` steps (when non-zero).
fn run_steps_with_progress(
    sim: &mut Simulation,
    steps: u64,
    quiet: bool,
    plan: Option<&(PathBuf, u64)>,
) -> Result<()> {
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
        sim.step()?;
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
    run_steps_with_progress(&mut sim, steps, a.quiet, plan.as_ref())?;
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
    let step = sim.clock().step;
    sim.world_mut()
        .resource_mut::<CommandHistory>()
        .record(step, command_line());
    let plan = save_plan(&sim, &a.saving, Some(&a.file))?;
    let steps = sim.steps_for(a.my)?;
    run_steps_with_progress(&mut sim, steps, a.quiet, plan.as_ref())?;
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

/// Writes the opt-in exports of `e` into `out`; returns the files written.
fn write_extra_exports(
    sim: &mut Simulation,
    out: &Path,
    width: u32,
    e: &ExtraExports,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    use tectonic_planets::amplify::{Amplifier, AmplifyOptions, ExemplarSet};
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
        let set = ExemplarSet::load_dir(dir)?;
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
        files.extend(export::export_amplified(&amp, &grid, &outputs)?);
        say(&format!("amplified {}x{}", grid.width, grid.height), t);
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
    println!(
        "{:<28} {:>10.1} ms",
        "  + fronts, terranes (median)",
        sim.timings()
            .median_ms("after_resample")
            .unwrap_or(f64::NAN)
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
    bench_saves(&mut sim)
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
