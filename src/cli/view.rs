//! `planet view`: the egui viewer on a new or saved planet.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use tectonic_planets::Simulation;
use tectonic_planets::io::save::{self};
use tectonic_planets::resources::plugin_params::PluginConfig;

use super::*;

#[cfg(feature = "viewer")]
#[derive(Args)]
pub(crate) struct ViewArgs {
    /// A saved planet to open (otherwise a new planet from the options).
    pub(crate) file: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) planet: PlanetArgs,
    /// Take this many steps, then exit (with --screenshot: after writing it).
    #[arg(long, value_name = "N")]
    pub(crate) exit_after_steps: Option<u64>,
    /// Write a PNG screenshot of the window before exiting (needs --exit-after-steps).
    #[arg(long, value_name = "FILE", requires = "exit_after_steps")]
    pub(crate) screenshot: Option<PathBuf>,
    /// Measure the frame rate: run the simulation, exit after N frames drawn while it steps,
    /// and print the median and 90th-percentile frame times.
    #[arg(long, value_name = "N", conflicts_with = "exit_after_steps")]
    pub(crate) fps_report: Option<u64>,
    /// Window width and height in pixels.
    #[arg(long, value_name = "WxH", default_value = "1280x800")]
    pub(crate) window: String,
    /// Start in the 3D globe view (instead of the 2D map).
    #[arg(long)]
    pub(crate) globe: bool,
    /// Steps per second while running (default: as fast as possible).
    #[arg(long, value_name = "STEPS")]
    pub(crate) speed: Option<f64>,
    /// Map colouring at start: elevation, plates, crust_type, oceanic_age, orogeny_type,
    /// orogeny_age, laplacian, rivers, basins, thickness, rain, pelagic_rain.
    #[arg(long, default_value = "elevation")]
    pub(crate) overlay: String,
    /// Vector layers drawn at start, comma-separated: folds, ridges, velocity, fronts, terranes.
    #[arg(long, value_delimiter = ',')]
    pub(crate) draw: Vec<String>,
    #[command(flatten)]
    pub(crate) start: StartArgs,
}

#[cfg(feature = "viewer")]
pub(crate) fn view(a: ViewArgs) -> Result<()> {
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
    let start = a.start.load()?;
    if start.is_some() && a.file.is_some() {
        bail!(
            "a saved planet is opened as it was saved: --from-heightmap and --from-earth start a new one"
        );
    }
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
            let (base, plugins) = match &planet.config {
                Some(p) => read_config(p)?,
                None => (Params::default(), PluginConfig::default()),
            };
            Ok((load_params(&planet, base)?, plugins))
        }
    };
    let switches = a.planet.switches.clone();
    let backend = a.planet.backend;
    let build = move || -> std::result::Result<Simulation, String> {
        let mut sim = match source {
            Err(path) => save::load_from_file(&path).map_err(|e| e.to_string())?,
            Ok((params, plugins)) => {
                let mut sim = match &start {
                    Some(s) => s.build(params).map_err(|e| format!("{e:#}"))?,
                    None => Simulation::new(params).map_err(|e| e.to_string())?,
                };
                sim.apply_plugin_config(&plugins)
                    .map_err(|e| e.to_string())?;
                sim
            }
        };
        apply_switches(&mut sim, &switches.enable, &switches.disable)
            .map_err(|e| format!("{e:#}"))?;
        // The viewer steps on the backend --backend picks (auto: a hardware GPU when there is
        // one), as generate does.
        let note = sim
            .set_backend(backend)
            .map_err(|e| format!("could not start the GPU compute backend: {e}"))?;
        tracing::info!("{note}");
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
