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
use tectonic_planets::io::save::{self, CommandHistory, SaveError};
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
    #[command(flatten)]
    pub(crate) start: StartArgs,
}

/// Where a planet starts, when not from the parameters alone.
#[derive(Args, Default)]
pub(crate) struct StartArgs {
    /// Start from this heightmap: a global equirectangular 16-bit grey PNG with its JSON sidecar
    /// (as `generate` writes elevation16.png), or a GeoTIFF in EPSG:4326. Crust above
    /// `init.map_continental_above_m` (−1,000 m) is continental.
    #[arg(long, value_name = "FILE", conflicts_with = "from_earth")]
    pub(crate) from_heightmap: Option<PathBuf>,
    /// Start from today's Earth: ETOPO1 bedrock relief, Bird's PB2002 plates (the 27 larger
    /// than 0.1% of the globe; smaller ones join a neighbour), NNR-MORVEL56 motions.
    #[arg(long)]
    pub(crate) from_earth: bool,
    /// With --from-heightmap or --from-earth: the plates from this map (a global equirectangular
    /// PNG, one flat colour per plate; plates are numbered in the order of their colours'
    /// #rrggbb).
    #[arg(long, value_name = "FILE")]
    pub(crate) plates_map: Option<PathBuf>,
    /// With --from-heightmap or --from-earth: Euler poles of some plates (TOML `[[plate]]`
    /// tables: `plate` = number or `colour` = "#rrggbb", `pole_lat_deg`, `pole_lon_deg`,
    /// `rate_deg_per_my`); the others move at random.
    #[arg(long, value_name = "FILE")]
    pub(crate) motions: Option<PathBuf>,
}

/// Plates of today's Earth smaller than this fraction of the globe join a neighbour in
/// `--from-earth` (they would be a few samples wide).
pub(crate) const EARTH_MIN_PLATE_FRACTION: f64 = 0.001;

/// The maps of [`StartArgs`], read and checked (before the planet is built).
pub(crate) struct StartMaps {
    elevation: Elevation,
    plates: Option<tectonic_planets::io::start::PlateGrid>,
    motions: Vec<(u32, tectonic_planets::components::PlateMotion)>,
    min_plate_fraction: f64,
}

enum Elevation {
    Grid(tectonic_planets::io::start::ElevationGrid),
    Earth,
}

impl StartArgs {
    /// Reads the maps; None for a planet from the parameters alone.
    pub(crate) fn load(&self) -> Result<Option<StartMaps>> {
        use tectonic_planets::io::start::{
            earth_plates, load_heightmap, load_motions, load_plates_map,
        };
        let elevation = match (&self.from_heightmap, self.from_earth) {
            (Some(p), _) => Elevation::Grid(load_heightmap(p)?),
            (None, true) => Elevation::Earth,
            (None, false) => {
                if self.plates_map.is_some() || self.motions.is_some() {
                    bail!("--plates-map and --motions go with --from-heightmap or --from-earth");
                }
                return Ok(None);
            }
        };
        let (plates, mut motions, min_plate_fraction) = match &self.plates_map {
            Some(p) => (Some(load_plates_map(p)?), Vec::new(), 0.0),
            None if self.from_earth => {
                let (grid, plates) = earth_plates();
                let motions = plates
                    .iter()
                    .enumerate()
                    .map(|(k, p)| (k as u32, p.motion))
                    .collect();
                (Some(grid), motions, EARTH_MIN_PLATE_FRACTION)
            }
            None => (None, Vec::new(), 0.0),
        };
        if let Some(m) = &self.motions {
            let colours = plates.as_ref().map_or(&[][..], |p| &p.colours[..]);
            for (k, motion) in load_motions(m, colours)? {
                motions.retain(|(p, _)| *p != k);
                motions.push((k, motion));
            }
        }
        Ok(Some(StartMaps {
            elevation,
            plates,
            motions,
            min_plate_fraction,
        }))
    }
}

impl StartMaps {
    /// The options of `planet` that a start from a map does not use, in words.
    pub(crate) fn ignored(&self, a: &PlanetArgs) -> Vec<String> {
        let mut out = Vec::new();
        if a.continental_fraction.is_some() {
            out.push(
                "--continental-fraction is ignored: the map decides where the continents are"
                    .into(),
            );
        }
        if self.plates.is_some() {
            if a.plates.is_some() {
                out.push("--plates is ignored: the plates come from the plates map".into());
            }
            if a.init.is_some() {
                out.push("--init is ignored: the plates come from the plates map".into());
            }
        }
        out
    }

    /// The planet of these maps.
    pub(crate) fn build(&self, params: Params) -> Result<Simulation> {
        use tectonic_planets::io::start::earth_elevation_m;
        use tectonic_planets::systems::init::MapStart;
        let grid_elev;
        let elevation: &(dyn Fn(glam::DVec3) -> f64 + Sync) = match &self.elevation {
            Elevation::Grid(g) => {
                grid_elev = move |d: glam::DVec3| g.at(d);
                &grid_elev
            }
            Elevation::Earth => &earth_elevation_m,
        };
        let plate_fn;
        let plates: Option<&(dyn Fn(glam::DVec3) -> u32 + Sync)> = match &self.plates {
            Some(p) => {
                plate_fn = move |d: glam::DVec3| p.at(d);
                Some(&plate_fn)
            }
            None => None,
        };
        let r = params.planet.radius_km;
        let start = MapStart {
            elevation_m: elevation,
            plates,
            motions: &self.motions,
            min_plate_area_km2: self.min_plate_fraction * 4.0 * std::f64::consts::PI * r * r,
        };
        Ok(Simulation::from_map(params, &start)?)
    }
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

/// Where and how often a run saves, and what it last saw of that file (to notice another
/// writer).
pub(crate) struct SavePlan {
    /// The save file.
    pub(crate) path: PathBuf,
    /// Steps between saves (0: only at the end).
    pub(crate) every: u64,
    /// The file as this run last read or wrote it (`None`: it did not exist).
    pub(crate) last_seen: Option<save::FileStamp>,
    /// The path the user asked for, when another program replaced that file during the run
    /// and this run's saves went to `path` instead.
    pub(crate) diverted_from: Option<PathBuf>,
}

/// The save file and the number of steps between saves, from the options; checked before the
/// run (a folder, a FIFO, a device or a link to one is refused, and the folder must take
/// files), so that a run never ends unable to save.
pub(crate) fn save_plan(
    sim: &Simulation,
    s: &SaveArgs,
    default: Option<&Path>,
) -> Result<Option<SavePlan>> {
    let every = match s.save_every {
        Some(my) => {
            if !my.is_finite() || my <= 0.0 {
                bail!(
                    "--save-every must be a finite, positive number of million years, got {}",
                    num(my)
                );
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
    let Some(path) = path else {
        return Ok(None);
    };
    if path.is_dir() {
        bail!("save path {} is a folder, not a file", path.display());
    }
    let target = save::check_save_target(&path)?;
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("cannot create the folder of save {}", path.display()))?;
    probe_writable(&dir)
        .with_context(|| format!("cannot write save {} in {}", path.display(), dir.display()))?;
    Ok(Some(SavePlan {
        last_seen: save::FileStamp::of(&path),
        path,
        every,
        diverted_from: None,
    }))
}

/// Saves to the plan's file. If another program replaced that file since this run last saw
/// it, the file is left alone and this run's save goes beside it (`NAME.PID.planet`) from now
/// on; the run says so at the end.
pub(crate) fn save_now(sim: &mut Simulation, plan: &mut SavePlan) -> Result<()> {
    let t = Instant::now();
    let info = match save::save_to_file_checked(sim, &plan.path, &mut plan.last_seen) {
        Err(SaveError::Replaced { .. }) if plan.diverted_from.is_none() => {
            let stem = plan
                .path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "planet".into());
            let aside = plan.path.with_file_name(format!(
                "{stem}.{}.{}",
                std::process::id(),
                save::EXTENSION
            ));
            eprintln!(
                "warning: save {} was replaced by another program during this run; it is left as it is, and this run saves to {} instead",
                plan.path.display(),
                aside.display()
            );
            let asked = std::mem::replace(&mut plan.path, aside);
            plan.diverted_from = Some(asked);
            plan.last_seen = save::FileStamp::of(&plan.path);
            save::save_to_file_checked(sim, &plan.path, &mut plan.last_seen)?
        }
        r => r?,
    };
    tracing::info!(
        path = %plan.path.display(),
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
    pub(crate) plan: Option<&'a mut SavePlan>,
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
        mut plan,
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
        if let Some(plan) = plan.as_deref_mut()
            && plan.every > 0
            && (k + 1) % plan.every == 0
            && k + 1 < steps
        {
            save_now(sim, plan)?;
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
/// The land and continental fractions of the surface the maps of a step show (the crust
/// resampled onto the mesh, as `summary.json` gives them), for the closing line of the run:
/// the live crust's own figures count its plates' overlaps and leave out their gaps.
#[derive(bevy_ecs::prelude::Resource)]
struct MapFigures {
    step: u64,
    land_fraction: f64,
    continental_fraction: f64,
}

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
    // On the graph the run's relief passes used (shared, not built again).
    let rivers = RiverNetwork::on_graph(
        &sim.relief_graph(),
        &sim.mesh().positions,
        &view,
        sim.network_options(),
    );
    files.extend(write_rivers(&raster, sim.mesh(), &rivers, out, radius_km)?);
    // With a pelagic rain that varies from place to place (and the sediment that lays it on),
    // its map.
    if let Some(rate) = sim.pelagic_rate()
        && let Some(p) =
            tectonic_planets::io::maps::write_pelagic_rate(&raster, sim.mesh(), &rate, out)?
    {
        files.push(p);
    }
    let mut summary = summarize(sim, &view);
    summary.drainage = Some(rivers.summary(sim.mesh()));
    let step = sim.clock().step;
    sim.world_mut().insert_resource(MapFigures {
        step,
        land_fraction: summary.land_fraction,
        continental_fraction: summary.continental_fraction,
    });
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
    // The figures of the maps just written (those of summary.json) when there are any.
    let (land, continental) = sim
        .world()
        .get_resource::<MapFigures>()
        .filter(|m| m.step == sim.clock().step)
        .map_or((s.land_fraction, s.continental_fraction), |m| {
            (m.land_fraction, m.continental_fraction)
        });
    eprintln!(
        "{} samples, {} plates, {:.0} My in {:.1} s: land {:.1}%, continental crust {:.1}%",
        sim.mesh().len(),
        s.plates,
        sim.time_my(),
        started.elapsed().as_secs_f64(),
        100.0 * land,
        100.0 * continental
    );
    for f in files {
        eprintln!("  wrote {}", f.display());
    }
}

pub(crate) fn generate(a: GenerateArgs) -> Result<()> {
    check_my("--my", a.my)?;
    check_width(a.width)?;
    let started = Instant::now();
    // Everything that can be checked is checked before the run starts.
    let (params, plugins) = planet_params(&a.planet)?;
    check_run_length(
        &format!("--my {}", num(a.my)),
        steps_of(&params, a.my),
        params.planet.samples as usize,
        a.quiet,
    )?;
    // The script's syntax and values before the planet is built, the rest against it.
    let script = match &a.script {
        Some(path) => {
            let script = Script::load(path)?;
            script.validate(&params)?;
            Some(script)
        }
        None => None,
    };
    let start = a.start.load()?;
    if let Some(s) = &start
        && !a.quiet
    {
        for note in s.ignored(&a.planet) {
            eprintln!("note: {note}");
        }
    }
    let mut sim = build_sim(&a.planet, params, plugins, start.as_ref())?;
    sim.world_mut()
        .resource_mut::<CommandHistory>()
        .record(0, command_line());
    let mut plan = save_plan(&sim, &a.saving, None)?;
    let steps = sim.steps_for(a.my)?;
    let script = match script {
        Some(script) => {
            let notes = script.validate_for(&mut sim)?;
            let late = script.events.iter().filter(|e| e.at_my > a.my).count();
            if !a.quiet {
                for n in notes {
                    eprintln!("note: {n}");
                }
                if late > 0 {
                    eprintln!(
                        "note: {late} script event(s) come after the end of the run ({} My) and will not happen",
                        num(a.my)
                    );
                }
            }
            Some(script)
        }
        None => None,
    };
    let maps = match a.maps_every {
        Some(my) => {
            if !my.is_finite() || my <= 0.0 {
                bail!(
                    "--maps-every must be a finite, positive number of million years, got {}",
                    num(my)
                );
            }
            Some((a.out.clone(), sim.steps_for(my)?.max(1), a.width))
        }
        None => None,
    };
    let exports = plan_extra_exports(&a.extra, a.width, sim.params().planet.radius_km, &a.out)?;
    prepare_out_dir(&a.out)?;
    check_output_files(&a.out, standard_output_names())?;
    use_backend(&mut sim, a.planet.backend)?;
    let extras = RunExtras {
        plan: plan.as_mut(),
        script,
        maps,
    };
    let run = run_steps_with_progress(&mut sim, steps, a.quiet, extras);
    if let Err(e) = run {
        return Err(stopped_early(
            &mut sim,
            e,
            plan.as_mut(),
            Some(&a.out),
            a.width,
        ));
    }
    // The run is over: its work areas go before the maps are made (the peak of memory).
    sim.release_scratch();
    // The maps, then the exports, then the save: a failure of one still leaves the others.
    let mut failures: Vec<anyhow::Error> = Vec::new();
    let mut files = write_outputs(&mut sim, &a.out, a.width).unwrap_or_else(|e| {
        failures.push(e);
        Vec::new()
    });
    if let Some(exports) = exports {
        match write_extra_exports(&mut sim, &a.out, exports, a.quiet) {
            Ok(f) => files.extend(f),
            Err(e) => failures.push(e),
        }
    }
    finish_run(&mut sim, plan.as_mut(), files, failures, a.quiet, started)
}

/// The files `write_outputs` writes in the output folder.
pub(crate) fn standard_output_names() -> impl IntoIterator<Item = &'static str> {
    [
        "elevation.png",
        "plates.png",
        "crust_age.png",
        "crust_type.png",
        "elevation16.png",
        "elevation16.json",
        "summary.json",
    ]
}

/// The error of a run that stopped before its end (a script event that failed, a step that
/// failed): the planet as it was is still saved and its maps written, and the message says at
/// what time and where they are.
pub(crate) fn stopped_early(
    sim: &mut Simulation,
    error: anyhow::Error,
    plan: Option<&mut SavePlan>,
    out: Option<&Path>,
    width: u32,
) -> anyhow::Error {
    let at = sim.time_my();
    let mut kept = Vec::new();
    if let Some(plan) = plan {
        match save_now(sim, plan) {
            Ok(()) => kept.push(format!("saved to {}", plan.path.display())),
            Err(e) => kept.push(format!("could not be saved ({e:#})")),
        }
    }
    if let Some(out) = out {
        match write_outputs(sim, out, width) {
            Ok(_) => kept.push(format!("its maps written to {}", out.display())),
            Err(e) => kept.push(format!("its maps could not be written ({e:#})")),
        }
    }
    let what = if kept.is_empty() {
        String::new()
    } else {
        format!("; the planet as it was then was {}", kept.join(" and "))
    };
    error.context(format!("the run stopped at {} My{what}", num(at)))
}

/// The end of `generate` and `resume`: the final save (if any), whatever failed before it, then
/// the report. `failures` are the outputs that could not be written; the save is still made and
/// the error names each failure and the save.
pub(crate) fn finish_run(
    sim: &mut Simulation,
    plan: Option<&mut SavePlan>,
    mut files: Vec<PathBuf>,
    failures: Vec<anyhow::Error>,
    quiet: bool,
    started: Instant,
) -> Result<()> {
    let mut saved = None;
    let mut diverted = None;
    if let Some(plan) = plan {
        match save_now(sim, plan) {
            Ok(()) => {
                files.push(plan.path.clone());
                saved = Some(plan.path.clone());
            }
            Err(e) if failures.is_empty() => return Err(e),
            Err(e) => {
                let list: Vec<String> = failures.iter().map(|f| format!("{f:#}")).collect();
                return Err(e.context(format!(
                    "{}; and the planet could not be saved",
                    list.join("; ")
                )));
            }
        }
        diverted = plan
            .diverted_from
            .clone()
            .map(|asked| (asked, plan.path.clone()));
    }
    if !quiet {
        report(sim, started, &files);
    }
    if let Some(first) = failures
        .into_iter()
        .reduce(|a, b| a.context(format!("{b:#}")))
    {
        let kept = match &saved {
            Some(p) => format!("the planet was saved to {}", p.display()),
            None => "nothing was saved (no --save)".into(),
        };
        return Err(first.context(format!(
            "the run finished but not every output was written ({kept})"
        )));
    }
    if let Some((asked, path)) = diverted {
        bail!(
            "save {} was replaced by another program during this run and left as it is; this run's planet was saved to {}",
            asked.display(),
            path.display()
        );
    }
    Ok(())
}

pub(crate) fn resume(a: ResumeArgs) -> Result<()> {
    check_my("--my", a.my)?;
    check_width(a.width)?;
    setup_threads(a.threads)?;
    let started = Instant::now();
    let mut sim = save::load_from_file(&a.file)?;
    apply_switches(&mut sim, &a.switches.enable, &a.switches.disable)?;
    let step = sim.clock().step;
    sim.world_mut()
        .resource_mut::<CommandHistory>()
        .record(step, command_line());
    let mut plan = save_plan(&sim, &a.saving, Some(&a.file))?;
    let steps = sim.steps_for(a.my)?;
    check_run_length(
        &format!("--my {}", num(a.my)),
        steps,
        sim.mesh().len(),
        a.quiet,
    )?;
    if let Some(out) = &a.out {
        prepare_out_dir(out)?;
        check_output_files(out, standard_output_names())?;
    }
    use_backend(&mut sim, a.backend)?;
    let extras = RunExtras {
        plan: plan.as_mut(),
        ..Default::default()
    };
    if let Err(e) = run_steps_with_progress(&mut sim, steps, a.quiet, extras) {
        return Err(stopped_early(
            &mut sim,
            e,
            plan.as_mut(),
            a.out.as_deref(),
            a.width,
        ));
    }
    let mut failures = Vec::new();
    let files = match &a.out {
        Some(out) => write_outputs(&mut sim, out, a.width).unwrap_or_else(|e| {
            failures.push(e);
            Vec::new()
        }),
        None => Vec::new(),
    };
    finish_run(&mut sim, plan.as_mut(), files, failures, a.quiet, started)
}
