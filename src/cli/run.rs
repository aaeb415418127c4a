//! `planet generate` and `planet resume`: build or load a planet, run it with a progress bar
//! (scripted commands, periodic maps and saves), then write the maps, the summary and the save.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tectonic_planets::Simulation;
use tectonic_planets::commands::{Outcome, Script};
use tectonic_planets::gpu::BackendChoice;
use tectonic_planets::io::maps::{Raster, write_all_maps};
use tectonic_planets::io::rivers::{RiverNetwork, write_rivers};
use tectonic_planets::io::save::{self, CommandHistory};
use tectonic_planets::io::summary::{CrustSampler, summarize};

use super::*;

#[derive(Args)]
pub(crate) struct GenerateArgs {
    #[command(flatten)]
    pub(crate) planet: PlanetArgs,
    /// Simulated time in million years.
    #[arg(long, default_value_t = 250.0)]
    pub(crate) my: f64,
    /// Output folder for the maps and summary.json.
    #[arg(long, default_value = "out")]
    pub(crate) out: PathBuf,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    pub(crate) width: u32,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
    #[command(flatten)]
    pub(crate) saving: SaveArgs,
    /// A script of timed authoring commands (TOML; see examples/scripts/ and docs/authoring.md).
    #[arg(long)]
    pub(crate) script: Option<PathBuf>,
    /// Also write the maps every this many million years, into `<out>/t<time>My/`.
    #[arg(long, value_name = "MY")]
    pub(crate) maps_every: Option<f64>,
    #[command(flatten)]
    pub(crate) extra: ExtraExports,
}

#[derive(Args)]
pub(crate) struct ResumeArgs {
    /// The save to continue.
    pub(crate) file: PathBuf,
    /// Simulated time to add, million years.
    #[arg(long)]
    pub(crate) my: f64,
    /// Also write maps and summary.json into this folder.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) saving: SaveArgs,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    pub(crate) width: u32,
    /// Worker threads (default: all cores). Results do not depend on it.
    #[arg(long)]
    pub(crate) threads: Option<usize>,
    /// Compute backend: auto, gpu or cpu (see `generate --help`).
    #[arg(long, default_value = "auto")]
    pub(crate) backend: BackendChoice,
    /// No progress bar.
    #[arg(long)]
    pub(crate) quiet: bool,
    /// Phenomena to switch on or off from now on (the save keeps the switches otherwise).
    #[command(flatten)]
    pub(crate) switches: SwitchArgs,
}

/// The save file and the number of steps between saves, from the options.
pub(crate) fn save_plan(
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

pub(crate) fn save_now(sim: &mut Simulation, path: &Path) -> Result<()> {
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
pub(crate) struct RunExtras<'a> {
    /// Save file and steps between saves (0: only at the end, by the caller).
    pub(crate) plan: Option<&'a (PathBuf, u64)>,
    /// Timed commands.
    pub(crate) script: Option<Script>,
    /// Map snapshots: folder, steps between snapshots and map width.
    pub(crate) maps: Option<(PathBuf, u64, u32)>,
}

pub(crate) fn describe(o: &Outcome) -> String {
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
pub(crate) fn run_steps_with_progress(
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

/// Writes the maps, rivers (rivers.png, rivers.geojson), hypsometry.png and summary of `sim`
/// into `out`; returns the files written.
pub(crate) fn write_outputs(sim: &mut Simulation, out: &Path, width: u32) -> Result<Vec<PathBuf>> {
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
    let radius_km = sim.params().planet.radius_km;
    let mut files = write_all_maps(&raster, out, radius_km)?;
    let rivers = RiverNetwork::of(sim.mesh(), &view, sim.params().rivers.min_sea_area_km2);
    files.extend(write_rivers(&raster, sim.mesh(), &rivers, out, radius_km)?);
    let summary = summarize(sim, &view);
    let hyps_path = out.join("hypsometry.png");
    tectonic_planets::io::hypsometry::write_hypsometry_png(&summary.hypsometry, &hyps_path, 900)?;
    files.push(hyps_path);
    let summary_path = out.join("summary.json");
    std::fs::write(&summary_path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("could not write {}", summary_path.display()))?;
    files.push(summary_path);
    Ok(files)
}

pub(crate) fn report(sim: &Simulation, started: Instant, files: &[PathBuf]) {
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

pub(crate) fn generate(a: GenerateArgs) -> Result<()> {
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
pub(crate) fn finish_run(
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

pub(crate) fn resume(a: ResumeArgs) -> Result<()> {
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
