//! `planet export` and the opt-in exports shared with `generate`: amplified relief, GeoTIFFs,
//! regional tiles, glTF.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use tectonic_planets::Simulation;
use tectonic_planets::gpu::{BackendChoice, GpuContext};
use tectonic_planets::io::rivers::NetworkOptions;
use tectonic_planets::io::save::{self};

use super::*;

#[derive(Args)]
pub(crate) struct ExportArgs {
    /// The save to export.
    pub(crate) file: PathBuf,
    /// Output folder for the maps and summary.json.
    #[arg(long, default_value = "out")]
    pub(crate) out: PathBuf,
    /// Width of the equirectangular maps in pixels (height is half).
    #[arg(long, default_value_t = 2048)]
    pub(crate) width: u32,
    /// No listing of the files written.
    #[arg(long)]
    pub(crate) quiet: bool,
    /// Skip the standard maps and summary (write only the exports asked for below).
    #[arg(long)]
    pub(crate) no_maps: bool,
    /// Compute backend of the amplified export: auto (a hardware GPU if any, else the CPU), gpu
    /// (any wgpu adapter, software ones included), cpu (bit-reproducible everywhere).
    #[arg(long, default_value = "auto")]
    pub(crate) backend: BackendChoice,
    #[command(flatten)]
    pub(crate) extra: ExtraExports,
}

/// Opt-in exports: amplified relief, GeoTIFFs, regional tiles, glTF (see docs/exports.md).
#[derive(Args, Clone, Default)]
pub(crate) struct ExtraExports {
    /// Amplified elevation (paper §5): a 16-bit PNG heightmap with a JSON sidecar
    /// (`amplified16.png`, or `tile_amplified16.png` with --region), plus a GeoTIFF with
    /// --geotiff.
    #[arg(long)]
    pub(crate) amplified: bool,
    /// Width of the global amplified heightmap (height is half); default: --width.
    #[arg(long, value_name = "W")]
    pub(crate) amplified_width: Option<u32>,
    /// Float32 GeoTIFFs (EPSG:4326) of every crust layer, flow accumulation and drainage basins,
    /// and of the amplified elevation with --amplified.
    #[arg(long)]
    pub(crate) geotiff: bool,
    /// Export a region instead of the globe: LAT0,LON0,LAT1,LON1 in degrees, from the south-west
    /// corner to the north-east one (LON0 > LON1 crosses the antimeridian).
    #[arg(long, value_name = "LAT0,LON0,LAT1,LON1", allow_hyphen_values = true)]
    pub(crate) region: Option<String>,
    /// Pixel size of --region: 100m, 2km or 0.001deg (metres measured north-south) [default:
    /// 100m].
    #[arg(long)]
    pub(crate) resolution: Option<String>,
    /// Elevation exemplars for continental relief: a folder with andean/, himalayan/, old/,
    /// plain/ sub-folders of 16-bit PNG or GeoTIFF files.
    #[arg(long, value_name = "DIR")]
    pub(crate) exemplars: Option<PathBuf>,
    /// Multiplies the amplified relief (1 = the model's amplitudes).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub(crate) relief_scale: f32,
    /// Amplified relief without river valleys (by default the drainage network of the crust
    /// is carved into it: see docs/amplification.md).
    #[arg(long)]
    pub(crate) no_valleys: bool,
    /// Also write a shaded preview PNG of the amplified elevation (and of the crust alone).
    #[arg(long)]
    pub(crate) preview: bool,
    /// A glTF 2.0 binary mesh of the planet (`planet.glb`).
    #[arg(long)]
    pub(crate) gltf: bool,
    /// Longitude segments of the glTF mesh (latitude rings are half as many).
    #[arg(long, default_value_t = 1024)]
    pub(crate) gltf_segments: u32,
    /// Elevation exaggeration of the glTF mesh.
    #[arg(long, default_value_t = 20.0)]
    pub(crate) exaggeration: f64,
}

pub(crate) fn export(a: ExportArgs) -> Result<()> {
    check_width(a.width)?;
    let started = Instant::now();
    let mut sim = save::load_from_file(&a.file)?;
    let exports = plan_extra_exports(&a.extra, a.width, sim.params().planet.radius_km, &a.out)?;
    prepare_out_dir(&a.out)?;
    if !a.no_maps {
        check_output_files(&a.out, standard_output_names())?;
    }
    if a.extra.amplified {
        use_backend(&mut sim, a.backend)?;
    }
    let mut files = if a.no_maps {
        Vec::new()
    } else {
        write_outputs(&mut sim, &a.out, a.width)?
    };
    if let Some(exports) = exports {
        files.extend(write_extra_exports(&mut sim, &a.out, exports, a.quiet)?);
    }
    if !a.quiet {
        report(&sim, started, &files);
    }
    Ok(())
}

/// The opt-in exports of one command, checked before anything is computed or written: the
/// grid, the exemplars (read), the files and their size against the limit and the free space.
pub(crate) struct ExportPlan {
    /// The options.
    pub(crate) e: ExtraExports,
    /// The grid of the amplified heightmap and the GeoTIFFs.
    pub(crate) grid: tectonic_planets::io::export::GeoGrid,
    /// `tile_` for a region, empty for the globe.
    pub(crate) prefix: &'static str,
    /// The exemplars, read.
    pub(crate) exemplars: Option<tectonic_planets::amplify::exemplar::ExemplarSet>,
}

impl ExportPlan {
    /// Whether the amplifier is needed.
    fn wants_amp(&self) -> bool {
        self.e.amplified || self.e.preview || self.e.gltf
    }

    /// The files this plan writes in the output folder.
    pub(crate) fn file_names(&self) -> Vec<String> {
        use tectonic_planets::io::export::CRUST_LAYERS;
        let p = self.prefix;
        let mut names = Vec::new();
        if self.e.geotiff {
            names.extend(
                CRUST_LAYERS
                    .iter()
                    .map(|(stem, _)| format!("{p}{stem}.tif")),
            );
        }
        if self.e.amplified {
            names.push(format!("{p}amplified16.png"));
            names.push(format!("{p}amplified16.json"));
            if self.e.geotiff {
                names.push(format!("{p}amplified.tif"));
            }
        }
        if self.e.preview {
            names.push(format!("{p}amplified_preview.png"));
            names.push(format!("{p}crust_preview.png"));
        }
        if self.e.gltf {
            names.push("planet.glb".into());
        }
        names
    }

    /// Bytes the GeoTIFFs and the 16-bit heightmap will take (their size is known before
    /// they are computed; previews and the glTF mesh are small beside them).
    pub(crate) fn known_bytes(&self) -> u64 {
        use tectonic_planets::io::export::{CRUST_LAYERS, geotiff_bytes, heightmap16_bytes};
        let (w, h) = (self.grid.width, self.grid.height);
        let mut tiffs = 0;
        if self.e.geotiff {
            tiffs += CRUST_LAYERS.len() as u64;
            if self.e.amplified {
                tiffs += 1;
            }
        }
        let png = if self.e.amplified {
            heightmap16_bytes(w, h)
        } else {
            0
        };
        tiffs * geotiff_bytes(w, h) + png
    }
}

/// Checks the opt-in exports of `e` before any work: flags that need others, the region and
/// resolution, the relief scale and glTF options, the exemplars (read now), the total size of
/// the files (at most [`MAX_EXPORT_BYTES`](tectonic_planets::io::export::MAX_EXPORT_BYTES)) and
/// the free space where they go. `None` when no opt-in export is asked for.
pub(crate) fn plan_extra_exports(
    e: &ExtraExports,
    width: u32,
    radius_km: f64,
    out: &Path,
) -> Result<Option<ExportPlan>> {
    use tectonic_planets::io::export::{self, GeoGrid};
    let wants_amp = e.amplified || e.preview || e.gltf;
    if let (Some(res), None) = (&e.resolution, &e.region) {
        bail!(
            "--resolution {} is the pixel size of --region, which is not given (global exports are sized by --width or --amplified-width)",
            clip(res)
        );
    }
    if !(wants_amp || e.geotiff) {
        if e.region.is_some() || e.exemplars.is_some() {
            bail!("--region and --exemplars need --amplified, --geotiff, --preview or --gltf");
        }
        if e.amplified_width.is_some() {
            bail!("--amplified-width needs --amplified, --geotiff, --preview or --gltf");
        }
        return Ok(None);
    }
    if !(e.relief_scale.is_finite() && (0.0..=10.0).contains(&e.relief_scale)) {
        bail!(
            "--relief-scale must be between 0 and 10, got {}",
            num(f64::from(e.relief_scale))
        );
    }
    if e.gltf {
        tectonic_planets::io::gltf::check_options(e.gltf_segments, e.exaggeration)?;
    }
    let (grid, prefix) = match &e.region {
        Some(r) => {
            if e.amplified_width.is_some() {
                bail!(
                    "--amplified-width sets the size of the global heightmap; with --region, the size follows --resolution"
                );
            }
            let [lat0, lon0, lat1, lon1] = export::parse_region(r)?;
            let res = e.resolution.as_deref().unwrap_or("100m");
            let px = export::parse_resolution(res, radius_km)?;
            let grid = GeoGrid::region(lat0, lon0, lat1, lon1, px)
                .with_context(|| format!("--region {} at --resolution {}", clip(r), clip(res)))?;
            (grid, "tile_")
        }
        None => {
            let w = e.amplified_width.unwrap_or(width);
            check_width(w).context("--amplified-width")?;
            (GeoGrid::global(w, w / 2)?, "")
        }
    };
    let exemplars = match &e.exemplars {
        Some(dir) if wants_amp => Some(tectonic_planets::io::exemplars::load_exemplar_dir(dir)?),
        Some(_) => {
            bail!("--exemplars shape the amplified relief: add --amplified, --preview or --gltf")
        }
        None => None,
    };
    let plan = ExportPlan {
        e: e.clone(),
        grid,
        prefix,
        exemplars,
    };
    let needed = plan.known_bytes();
    export::check_export_size(needed, out).with_context(|| {
        format!(
            "the exports of {}×{} pixels",
            plan.grid.width, plan.grid.height
        )
    })?;
    let names = plan.file_names();
    check_output_files(out, names.iter().map(String::as_str))?;
    Ok(Some(plan))
}

/// Writes the opt-in exports of `plan` into `out`; returns the files written. On the GPU
/// backend the amplified heightmap is amplified on the device (procedural relief only).
pub(crate) fn write_extra_exports(
    sim: &mut Simulation,
    out: &Path,
    plan: ExportPlan,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    // The context leaves the world while the mesh is borrowed, and goes back afterwards.
    let mut gpu = sim.world_mut().remove_resource::<GpuContext>();
    let r = write_extra_exports_on(sim, gpu.as_mut(), out, plan, quiet);
    if let Some(ctx) = gpu {
        sim.world_mut().insert_resource(ctx);
    }
    r
}

/// [`write_extra_exports`] with the GPU context, if any.
pub(crate) fn write_extra_exports_on(
    sim: &mut Simulation,
    gpu: Option<&mut GpuContext>,
    out: &Path,
    plan: ExportPlan,
    quiet: bool,
) -> Result<Vec<PathBuf>> {
    use tectonic_planets::amplify::{Amplifier, AmplifyOptions};
    use tectonic_planets::io::export::{self, ElevationOutputs, GeoGrid};
    use tectonic_planets::io::gltf;
    let wants_amp = plan.wants_amp();
    let ExportPlan {
        e,
        grid,
        prefix,
        exemplars,
    } = plan;
    use tectonic_planets::io::rivers::RiverNetwork;
    let say = |what: &str, t: Instant| {
        if !quiet {
            eprintln!("  {what} in {:.2} s", t.elapsed().as_secs_f64());
        }
    };
    let radius_km = sim.params().planet.radius_km;
    let seed = sim.params().planet.seed;
    let network_opts = NetworkOptions::of(sim.params());
    let view = sim.resampled_crust();
    let mesh = sim.mesh();
    let mut files = Vec::new();
    let mut rivers = None;
    if e.geotiff {
        let t = Instant::now();
        files.extend(export::export_crust_layers(
            mesh, &view, &grid, out, prefix,
        )?);
        say(&format!("crust GeoTIFFs {}x{}", grid.width, grid.height), t);
        let t = Instant::now();
        let rivers = rivers.insert(RiverNetwork::of(mesh, &view, network_opts));
        files.extend(export::export_drainage_layers(
            mesh, rivers, &grid, out, prefix,
        )?);
        say(
            &format!("drainage GeoTIFFs {}x{}", grid.width, grid.height),
            t,
        );
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
    if let Some(set) = exemplars {
        amp = amp.with_exemplars(set, seed, options);
    }
    if !e.no_valleys && e.relief_scale != 0.0 {
        // The valleys keep what they need of the network; it goes before the rows are made.
        let rivers = rivers
            .take()
            .unwrap_or_else(|| RiverNetwork::of(mesh, &view, network_opts));
        amp = amp.with_valleys(rivers.valley_network());
    }
    // Only the detail the output's pixels resolve (its north-south pixel size).
    amp = amp.with_pixel_km(grid.dy_deg.to_radians() * radius_km);
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
        let after = export::amplified_values(&amp, &pgrid);
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
