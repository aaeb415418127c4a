//! Exports: global and regional grids on one geographic lattice, streamed in bands of rows into
//! 16-bit PNG heightmaps and float32 GeoTIFFs (amplified elevation, every crust layer, flow
//! accumulation and drainage basins), and shaded previews.
//!
//! Every grid is a window of a lattice fixed by its pixel size alone: pixel (I, J) covers
//! longitudes `-180 + I·dx .. -180 + (I+1)·dx` and latitudes `90 − (J+1)·dy .. 90 − J·dy`, and
//! is sampled at its centre. Two regions exported at the same resolution therefore share the
//! same pixel centres, and neighbouring tiles fit together exactly.

use std::path::{Path, PathBuf};

use glam::DVec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::amplify::{Amplifier, AmplifyQuery, NoiseMemo};
use crate::geometry::SphereMesh;
use crate::gpu::GpuContext;
use crate::gpu::amplify::AmplifyGpu;
use crate::io::geotiff::{GeoBounds, GeoTiffError, GeoTiffWriter};
use crate::io::heightmap::{Heightmap16Writer, HeightmapError};
use crate::io::rivers::RiverNetwork;
use crate::resources::{Crust, Orogeny};

/// Largest grid side accepted, pixels.
pub const MAX_SIDE: u32 = 16384;
/// Rows computed per band when streaming (memory: band × width × 4 bytes per layer).
pub const BAND_ROWS: u32 = 64;
/// Width of the blocks of pixels whose valleys are carved together, km, and the most pixels a
/// side (see `Amplifier::carve_band`).
const VALLEY_BLOCK_KM: f64 = 0.8;
const MAX_VALLEY_BLOCK: usize = 8;

/// Errors of the exports.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A region, resolution or size that cannot be exported.
    #[error("{0}")]
    Invalid(String),
    /// Writing a GeoTIFF failed.
    #[error(transparent)]
    GeoTiff(#[from] GeoTiffError),
    /// Writing a heightmap failed.
    #[error(transparent)]
    Heightmap(#[from] HeightmapError),
    /// The GPU amplification failed.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    /// Writing a preview image failed.
    #[error("could not write {}: {reason}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// A window of the geographic lattice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoGrid {
    /// Pixel width, degrees of longitude.
    pub dx_deg: f64,
    /// Pixel height, degrees of latitude.
    pub dy_deg: f64,
    /// Lattice column of the window's first column.
    pub i0: i64,
    /// Lattice row of the window's first row (0 at the north pole).
    pub j0: i64,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl GeoGrid {
    /// The whole globe, `width × height` pixels.
    pub fn global(width: u32, height: u32) -> Result<Self, ExportError> {
        check_side(width, height)?;
        Ok(Self {
            dx_deg: 360.0 / f64::from(width),
            dy_deg: 180.0 / f64::from(height),
            i0: 0,
            j0: 0,
            width,
            height,
        })
    }

    /// The smallest window covering latitudes `lat0..lat1` and longitudes `lon0..lon1`
    /// (degrees) on the lattice of square pixels of `pixel_deg` degrees. `lat0` must be south of
    /// `lat1`; `lon0 > lon1` is a window across the antimeridian (its eastern bound is then
    /// `lon1 + 360`).
    pub fn region(
        lat0: f64,
        lon0: f64,
        lat1: f64,
        lon1: f64,
        pixel_deg: f64,
    ) -> Result<Self, ExportError> {
        use crate::resources::input::num;
        for (name, v) in [
            ("LAT0", lat0),
            ("LON0", lon0),
            ("LAT1", lat1),
            ("LON1", lon1),
        ] {
            if !v.is_finite() {
                return Err(ExportError::Invalid(format!(
                    "region {name} = {} is not a finite number",
                    num(v)
                )));
            }
        }
        let corners = format!("{},{},{},{}", num(lat0), num(lon0), num(lat1), num(lon1));
        if [lat0, lat1].iter().any(|l| l.abs() > 90.0)
            || [lon0, lon1].iter().any(|l| l.abs() > 180.0)
        {
            return Err(ExportError::Invalid(format!(
                "region {corners} is outside latitudes -90..90 and longitudes -180..180"
            )));
        }
        if lat0 >= lat1 {
            return Err(ExportError::Invalid(format!(
                "region {corners}: LAT0 must be south of LAT1 (the region runs from its south-west corner LAT0,LON0 to its north-east corner LAT1,LON1)"
            )));
        }
        if lon0 == lon1 {
            return Err(ExportError::Invalid(format!(
                "region {corners} is empty: LON0 = LON1"
            )));
        }
        let (south, north, west) = (lat0, lat1, lon0);
        let east = if lon1 > lon0 { lon1 } else { lon1 + 360.0 };
        if !(pixel_deg.is_finite() && pixel_deg > 1e-7 && pixel_deg <= 10.0) {
            return Err(ExportError::Invalid(format!(
                "pixel size {}° is out of range (1e-7° to 10°, about 1 cm to 1,100 km on the Earth)",
                num(pixel_deg)
            )));
        }
        let i0 = ((west + 180.0) / pixel_deg + 1e-9).floor() as i64;
        let i1 = ((east + 180.0) / pixel_deg - 1e-9).ceil() as i64;
        let j0 = ((90.0 - north) / pixel_deg + 1e-9).floor() as i64;
        let j1 = ((90.0 - south) / pixel_deg - 1e-9).ceil() as i64;
        let (w, h) = ((i1 - i0).max(1), (j1 - j0).max(1));
        if w > i64::from(MAX_SIDE) || h > i64::from(MAX_SIDE) {
            return Err(ExportError::Invalid(format!(
                "region needs {w}×{h} pixels at {}°; at most {MAX_SIDE} a side (split it into tiles)",
                num(pixel_deg)
            )));
        }
        Ok(Self {
            dx_deg: pixel_deg,
            dy_deg: pixel_deg,
            i0,
            j0,
            width: w as u32,
            height: h as u32,
        })
    }

    /// Outer edges of the window, degrees.
    pub fn bounds(&self) -> GeoBounds {
        GeoBounds {
            west: -180.0 + self.i0 as f64 * self.dx_deg,
            east: -180.0 + (self.i0 + i64::from(self.width)) as f64 * self.dx_deg,
            north: 90.0 - self.j0 as f64 * self.dy_deg,
            south: 90.0 - (self.j0 + i64::from(self.height)) as f64 * self.dy_deg,
        }
    }

    /// Unit direction of the centre of pixel (`col`, `row`) of the window.
    pub fn direction(&self, col: u32, row: u32) -> DVec3 {
        dir_from_trig(self.lat_trig(row), self.lon_trig(col))
    }

    /// (cos, sin) of the latitude of row `row`'s centres.
    fn lat_trig(&self, row: u32) -> (f64, f64) {
        let lat = 90.0 - ((self.j0 + i64::from(row)) as f64 + 0.5) * self.dy_deg;
        let r = lat.clamp(-90.0, 90.0).to_radians();
        (r.cos(), r.sin())
    }

    /// (cos, sin) of the longitude of column `col`'s centres.
    fn lon_trig(&self, col: u32) -> (f64, f64) {
        let lon = -180.0 + ((self.i0 + i64::from(col)) as f64 + 0.5) * self.dx_deg;
        let r = lon.to_radians();
        (r.cos(), r.sin())
    }

    /// Computes `f` at every pixel of rows `row0..row0+rows`, in parallel, row-major.
    pub fn band<T: Send + Default + Clone>(
        &self,
        row0: u32,
        rows: u32,
        f: &(impl Fn(DVec3) -> T + Sync),
        out: &mut Vec<T>,
    ) {
        self.band_hinted(row0, rows, &|d, _| f(d), out);
    }

    /// [`Self::band`] for functions that carry a hint from one pixel to the next along a run
    /// of 256 pixels (e.g. the previous pixel's triangle); `f` must give the same value
    /// whatever the hint, so results do not depend on how pixels are split into runs.
    pub fn band_hinted<T: Send + Default + Clone>(
        &self,
        row0: u32,
        rows: u32,
        f: &(impl Fn(DVec3, &mut u32) -> T + Sync),
        out: &mut Vec<T>,
    ) {
        const RUN: usize = 256;
        let w = self.width as usize;
        out.clear();
        out.resize(w * rows as usize, T::default());
        // The same trigonometry as `direction`, computed once per column and per row.
        let lons: Vec<(f64, f64)> = (0..self.width).map(|c| self.lon_trig(c)).collect();
        let lats: Vec<(f64, f64)> = (0..rows).map(|r| self.lat_trig(row0 + r)).collect();
        out.par_chunks_mut(RUN).enumerate().for_each(|(k, chunk)| {
            let mut hint = u32::MAX;
            for (i, v) in chunk.iter_mut().enumerate() {
                let idx = k * RUN + i;
                let (row, col) = (idx / w, idx % w);
                *v = f(dir_from_trig(lats[row], lons[col]), &mut hint);
            }
        });
    }

    /// [`Self::sample`] with a hint (see [`Self::band_hinted`]).
    pub fn sample_hinted<T: Send + Default + Clone>(
        &self,
        f: &(impl Fn(DVec3, &mut u32) -> T + Sync),
    ) -> Vec<T> {
        let mut out = Vec::new();
        self.band_hinted(0, self.height, f, &mut out);
        out
    }

    /// Computes `f` over the whole window (small windows: tests and previews).
    pub fn sample<T: Send + Default + Clone>(&self, f: &(impl Fn(DVec3) -> T + Sync)) -> Vec<T> {
        let mut out = Vec::new();
        self.band(0, self.height, f, &mut out);
        out
    }
}

/// Unit vector from (cos, sin) of latitude and longitude (as `from_lat_lon_deg`).
#[inline]
fn dir_from_trig((clat, slat): (f64, f64), (clon, slon): (f64, f64)) -> DVec3 {
    DVec3::new(clat * clon, clat * slon, slat)
}

fn check_side(width: u32, height: u32) -> Result<(), ExportError> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(ExportError::Invalid(format!(
            "grid {width}×{height} must be between 1 and {MAX_SIDE} pixels a side"
        )));
    }
    Ok(())
}

/// Parses `LAT0,LON0,LAT1,LON1` (degrees); each must be a finite number.
pub fn parse_region(s: &str) -> Result<[f64; 4], ExportError> {
    use crate::resources::input::clip;
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 4 {
        return Err(ExportError::Invalid(format!(
            "--region expects LAT0,LON0,LAT1,LON1 in degrees, got `{}`",
            clip(s)
        )));
    }
    let mut v = [0.0; 4];
    for ((o, p), name) in v
        .iter_mut()
        .zip(parts)
        .zip(["LAT0", "LON0", "LAT1", "LON1"])
    {
        *o = match p.parse::<f64>() {
            Ok(x) if x.is_finite() => x,
            _ => {
                return Err(ExportError::Invalid(format!(
                    "--region {name} = `{}` is not a finite number of degrees (--region expects LAT0,LON0,LAT1,LON1)",
                    clip(p)
                )));
            }
        };
    }
    Ok(v)
}

/// Parses a resolution (`100m`, `2.5km`, `0.001deg`, or a bare number of metres) into degrees
/// per pixel on a planet of `radius_km` (metres are measured north–south).
pub fn parse_resolution(s: &str, radius_km: f64) -> Result<f64, ExportError> {
    let t = s.trim().to_ascii_lowercase();
    let bad = || {
        ExportError::Invalid(format!(
            "--resolution expects e.g. 100m, 2km or 0.001deg, got `{}`",
            crate::resources::input::clip(s)
        ))
    };
    let (num, unit_deg) = if let Some(n) = t.strip_suffix("deg") {
        (n, 1.0)
    } else if let Some(n) = t.strip_suffix("km") {
        (n, 1.0 / (radius_km * std::f64::consts::PI / 180.0))
    } else {
        let n = t.strip_suffix('m').unwrap_or(&t);
        (n, 1.0 / (radius_km * 1000.0 * std::f64::consts::PI / 180.0))
    };
    let v: f64 = num.trim().parse().map_err(|_| bad())?;
    if !(v.is_finite() && v > 0.0) {
        return Err(bad());
    }
    Ok(v * unit_deg)
}

/// Bytes of a float32 GeoTIFF of `width × height` pixels as [`GeoTiffWriter`] writes it.
pub fn geotiff_bytes(width: u32, height: u32) -> u64 {
    u64::from(width) * u64::from(height) * 4 + u64::from(height) * 8 + 4096
}

/// An upper bound of the bytes of a 16-bit PNG heightmap of `width × height` pixels and its
/// sidecar (incompressible rows, plus the deflate framing).
pub fn heightmap16_bytes(width: u32, height: u32) -> u64 {
    let raw = (u64::from(width) * 2 + 1) * u64::from(height);
    raw + raw / 100 + 8192
}

/// Most bytes one command may export: the largest global export (16384 × 8192 pixels: the six
/// crust GeoTIFFs, the amplified one and its 16-bit heightmap) fits; a larger region must be
/// split into tiles (regions on one lattice fit together exactly).
pub const MAX_EXPORT_BYTES: u64 = 4 << 30;

/// Bytes free for this process on the file system holding `dir` (or its nearest existing
/// parent); `None` where the OS does not tell.
pub fn free_bytes(dir: &Path) -> Option<u64> {
    let mut d = dir;
    while std::fs::metadata(d).is_err() {
        d = d.parent().filter(|p| !p.as_os_str().is_empty())?;
    }
    free_bytes_at(d)
}

#[cfg(unix)]
fn free_bytes_at(dir: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st = std::mem::MaybeUninit::<libc::statvfs>::uninit();
    // SAFETY: `path` is a NUL-terminated string that outlives the call, and `st` is a buffer of
    // the type statvfs fills; it is read only when the call succeeds.
    let st = unsafe {
        if libc::statvfs(path.as_ptr(), st.as_mut_ptr()) != 0 {
            return None;
        }
        st.assume_init()
    };
    #[allow(clippy::unnecessary_cast)]
    Some((st.f_bavail as u64).saturating_mul(st.f_frsize as u64))
}

#[cfg(not(unix))]
fn free_bytes_at(_dir: &Path) -> Option<u64> {
    None
}

/// Refuses an export of `needed` bytes into `dir` before it starts: more than
/// [`MAX_EXPORT_BYTES`], or more than the free space there (with a margin of 1%).
pub fn check_export_size(needed: u64, dir: &Path) -> Result<(), ExportError> {
    check_export_size_with(needed, free_bytes(dir), dir)
}

/// [`check_export_size`] with the free space given (`None`: unknown, not checked).
pub fn check_export_size_with(
    needed: u64,
    free: Option<u64>,
    dir: &Path,
) -> Result<(), ExportError> {
    use crate::resources::input::bytes_in_words;
    if needed > MAX_EXPORT_BYTES {
        return Err(ExportError::Invalid(format!(
            "would write {} of GeoTIFF and heightmap files, more than the {} one command may write (the largest global export); split the region into tiles or lower the resolution",
            bytes_in_words(needed),
            bytes_in_words(MAX_EXPORT_BYTES)
        )));
    }
    if let Some(free) = free
        && needed.saturating_add(needed / 100) > free
    {
        return Err(ExportError::Invalid(format!(
            "would write {} of GeoTIFF and heightmap files, but only {} are free on the file system of {}",
            bytes_in_words(needed),
            bytes_in_words(free),
            dir.display()
        )));
    }
    Ok(())
}

/// What to write for the amplified elevation of a grid.
#[derive(Clone, Debug, Default)]
pub struct ElevationOutputs {
    /// 16-bit PNG heightmap (+ JSON sidecar).
    pub png16: Option<PathBuf>,
    /// Float32 GeoTIFF.
    pub geotiff: Option<PathBuf>,
}

/// Streams the amplified elevation of `grid` into the requested files, `BAND_ROWS` rows at a
/// time (memory stays at one band whatever the size). The PNG's grey scale is the amplifier's
/// whole-planet range, so tiles of one planet share it. Returns the files written.
pub fn export_amplified(
    amp: &Amplifier,
    grid: &GeoGrid,
    outputs: &ElevationOutputs,
) -> Result<Vec<PathBuf>, ExportError> {
    export_amplified_on(amp, grid, outputs, None)
}

/// [`export_amplified`], amplifying each band on the GPU when `gpu` is given (the kernel of
/// `shaders/amplify.wgsl`; point location stays on the CPU). The values then differ from the
/// CPU's within the tolerance of docs/amplification.md. Without `gpu`, or with exemplars (the
/// shader has none), the bands are computed on the CPU: the same bits as [`export_amplified`].
pub fn export_amplified_on(
    amp: &Amplifier,
    grid: &GeoGrid,
    outputs: &ElevationOutputs,
    gpu: Option<&mut GpuContext>,
) -> Result<Vec<PathBuf>, ExportError> {
    let mut device = match gpu {
        Some(ctx) if amp.exemplars.is_none() => {
            let kernel = AmplifyGpu::new(ctx, &amp.vertices, &amp.uniform)?;
            Some((kernel, ctx))
        }
        _ => None,
    };
    let bounds = grid.bounds();
    let (lo, hi) = amp.range_m();
    let mut png = match &outputs.png16 {
        Some(p) => Some(Heightmap16Writer::create(
            p,
            grid.width,
            grid.height,
            bounds,
            (f64::from(lo), f64::from(hi)),
        )?),
        None => None,
    };
    let mut tiff = match &outputs.geotiff {
        Some(p) => Some(GeoTiffWriter::create(
            p,
            grid.width,
            grid.height,
            bounds,
            "amplified elevation, metres",
        )?),
        None => None,
    };
    // The bands are written on a thread of their own while the next one is computed: encoding
    // and compressing a band is serial, and would otherwise leave a core idle (a band's
    // buffer comes back for reuse). A file is finished only once every row came.
    let width = grid.width as usize;
    std::thread::scope(|scope| {
        let (to_writer, bands) = std::sync::mpsc::sync_channel::<Vec<f32>>(1);
        let (give_back, spare) = std::sync::mpsc::channel::<Vec<f32>>();
        let writer = scope.spawn(move || -> Result<Vec<PathBuf>, ExportError> {
            let mut rows = 0u32;
            for band in bands {
                for row in band.chunks(width) {
                    if let Some(w) = png.as_mut() {
                        w.write_row(row)?;
                    }
                    if let Some(w) = tiff.as_mut() {
                        w.write_row(row)?;
                    }
                    rows += 1;
                }
                let _ = give_back.send(band);
            }
            let mut files = Vec::new();
            if rows < grid.height {
                // The rows stopped coming (an error, returned by the computing side): the
                // unfinished files are dropped, which removes them.
                return Ok(files);
            }
            if let Some(w) = png {
                let (a, b) = w.finish()?;
                files.push(a);
                files.push(b);
            }
            if let Some(w) = tiff {
                files.push(w.finish()?);
            }
            Ok(files)
        });
        let mut queries = Vec::new();
        let mut row0 = 0;
        let locate = |d: DVec3, hint: &mut u32| amp.query_hinted(d, hint);
        let computed = (|| -> Result<(), ExportError> {
            while row0 < grid.height {
                let rows = BAND_ROWS.min(grid.height - row0);
                let mut band = spare.try_recv().unwrap_or_default();
                match device.as_mut() {
                    Some((kernel, ctx)) => {
                        grid.band_hinted(row0, rows, &locate, &mut queries);
                        band.clear();
                        band.resize(queries.len(), f32::NAN);
                        kernel.run(ctx, &queries, &mut band)?;
                        // The valleys are carved on the CPU, after the kernel.
                        amp.carve_band(&queries, &mut band, width, valley_block(grid, amp));
                    }
                    None => amplify_band_cpu(amp, grid, row0, rows, &mut queries, &mut band),
                }
                if to_writer.send(band).is_err() {
                    break; // the writer stopped on an error, which its result gives
                }
                row0 += rows;
            }
            Ok(())
        })();
        drop(to_writer);
        let written = writer
            .join()
            .unwrap_or_else(|e| std::panic::resume_unwind(e));
        computed?;
        written
    })
}

/// Pixels a side of the blocks whose valleys `amp` carves together on `grid` (about
/// [`VALLEY_BLOCK_KM`] wide).
fn valley_block(grid: &GeoGrid, amp: &Amplifier) -> usize {
    let pixel_km = grid.dy_deg.to_radians() * amp.mesh.radius_km;
    ((VALLEY_BLOCK_KM / pixel_km).round() as usize).clamp(1, MAX_VALLEY_BLOCK)
}

/// The amplified elevation of rows `row0..row0 + rows` of `grid` on the CPU, into `band`
/// (`queries`: scratch): the primitives pixel by pixel, then the valleys (if any) block by
/// block (the same bits as pixel by pixel, faster).
fn amplify_band_cpu(
    amp: &Amplifier,
    grid: &GeoGrid,
    row0: u32,
    rows: u32,
    queries: &mut Vec<AmplifyQuery>,
    band: &mut Vec<f32>,
) {
    let locate = |d: DVec3, hint: &mut u32| amp.query_hinted(d, hint);
    grid.band_hinted(row0, rows, &locate, queries);
    band.clear();
    // One noise memo per run of nearby pixels (a row's neighbours share noise cells).
    band.par_extend(
        queries
            .par_iter()
            .with_min_len(1024)
            .map_init(NoiseMemo::default, |m, q| amp.primitives_of_memo(q, m)),
    );
    amp.carve_band(queries, band, grid.width as usize, valley_block(grid, amp));
}

/// The amplified elevation of every pixel of `grid`, row-major, on the CPU (band by band, as
/// the exports compute it: the same bits as [`Amplifier::elevation_m`] pixel by pixel).
pub fn amplified_values(amp: &Amplifier, grid: &GeoGrid) -> Vec<f32> {
    let (mut out, mut band, mut queries) = (Vec::new(), Vec::new(), Vec::new());
    let mut row0 = 0;
    while row0 < grid.height {
        let rows = BAND_ROWS.min(grid.height - row0);
        amplify_band_cpu(amp, grid, row0, rows, &mut queries, &mut band);
        out.extend_from_slice(&band);
        row0 += rows;
    }
    out
}

/// The crust layers exported as GeoTIFFs, with their file stems and descriptions.
pub const CRUST_LAYERS: [(&str, &str); 6] = [
    ("crust_elevation", "crust elevation, metres"),
    ("crust_age", "crust age (oceanic age on oceanic crust), My"),
    ("plate", "plate id"),
    ("crust_type", "crust type: 0 oceanic, 1 continental"),
    (
        "orogeny_type",
        "orogeny type: 0 none, 1 Andean, 2 Himalayan",
    ),
    ("orogeny_age", "time since the last orogeny, My"),
];

/// The six crust layers at unit direction `q`: scalars interpolated, categories from the
/// dominant corner.
pub fn crust_layers_at(mesh: &SphereMesh, crust: &Crust, q: DVec3, hint: &mut u32) -> [f32; 6] {
    let loc = crate::amplify::hinted_locate(mesh, q, *hint);
    *hint = loc.triangle;
    let t = mesh.triangles[loc.triangle as usize];
    let w = loc.weights;
    let lerp = |f: &[f32]| {
        (w[0] * f64::from(f[t[0] as usize])
            + w[1] * f64::from(f[t[1] as usize])
            + w[2] * f64::from(f[t[2] as usize])) as f32
    };
    let d = t[loc.dominant_corner()] as usize;
    let orogeny = match crust.orogeny[d] {
        Orogeny::None => 0.0,
        Orogeny::Andean => 1.0,
        Orogeny::Himalayan => 2.0,
    };
    [
        lerp(&crust.elevation_km) * 1000.0,
        lerp(&crust.age_my),
        crust.plate[d] as f32,
        crust.crust_type[d] as u8 as f32,
        orogeny,
        lerp(&crust.orogeny_age_my),
    ]
}

/// Streams the six crust layers of `grid` into `dir/<prefix><layer>.tif`. Returns the files.
pub fn export_crust_layers(
    mesh: &SphereMesh,
    crust: &Crust,
    grid: &GeoGrid,
    dir: &Path,
    prefix: &str,
) -> Result<Vec<PathBuf>, ExportError> {
    let f = |q: DVec3, hint: &mut u32| crust_layers_at(mesh, crust, q, hint);
    export_layers(&CRUST_LAYERS, &f, grid, dir, prefix)
}

/// The drainage layers exported as GeoTIFFs, with their file stems and descriptions.
pub const DRAINAGE_LAYERS: [(&str, &str); 2] = [
    (
        "flow_accumulation",
        "drainage area (flow accumulation), km2; 0 on the sea",
    ),
    (
        "drainage_basin",
        "drainage basin: index of the outlet sample (sea sample or endorheic sink) the water drains to; -1 on the sea",
    ),
];

/// The drainage layers at unit direction `q`, from the nearest sample (the dominant corner):
/// its drainage area in km² (0 on the sea) and its basin, the index of its outlet sample (−1 on
/// the sea; exact as float32 up to 16,777,216 samples).
pub fn drainage_layers_at(
    mesh: &SphereMesh,
    net: &RiverNetwork,
    q: DVec3,
    hint: &mut u32,
) -> [f32; 2] {
    let loc = crate::amplify::hinted_locate(mesh, q, *hint);
    *hint = loc.triangle;
    let t = mesh.triangles[loc.triangle as usize];
    let s = t[loc.dominant_corner()] as usize;
    let d = &net.drainage;
    match (d.ocean.get(s), d.area_km2.get(s), net.outlets.get(s)) {
        (Some(false), Some(&a), Some(&o)) => [a as f32, o as f32],
        _ => [0.0, -1.0],
    }
}

/// Streams the drainage layers of `net` (on `mesh`, world frame) over `grid` into
/// `dir/<prefix><layer>.tif` (see [`DRAINAGE_LAYERS`]). Returns the files.
pub fn export_drainage_layers(
    mesh: &SphereMesh,
    net: &RiverNetwork,
    grid: &GeoGrid,
    dir: &Path,
    prefix: &str,
) -> Result<Vec<PathBuf>, ExportError> {
    if net.len() != mesh.len() {
        return Err(ExportError::Invalid(format!(
            "drainage network of {} samples on a mesh of {}",
            net.len(),
            mesh.len()
        )));
    }
    let f = |q: DVec3, hint: &mut u32| drainage_layers_at(mesh, net, q, hint);
    export_layers(&DRAINAGE_LAYERS, &f, grid, dir, prefix)
}

/// Streams `K` layers computed together by `f` over `grid` into `dir/<prefix><stem>.tif`, one
/// float32 GeoTIFF per (stem, description) of `layers`. Returns the files.
fn export_layers<const K: usize>(
    layers: &[(&str, &str); K],
    f: &(impl Fn(DVec3, &mut u32) -> [f32; K] + Sync),
    grid: &GeoGrid,
    dir: &Path,
    prefix: &str,
) -> Result<Vec<PathBuf>, ExportError> {
    let bounds = grid.bounds();
    let mut writers = layers
        .iter()
        .map(|(stem, desc)| {
            GeoTiffWriter::create(
                &dir.join(format!("{prefix}{stem}.tif")),
                grid.width,
                grid.height,
                bounds,
                desc,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    /// One pixel's layers (arrays of any length have no `Default`).
    #[derive(Clone)]
    struct Px<const K: usize>([f32; K]);
    impl<const K: usize> Default for Px<K> {
        fn default() -> Self {
            Self([0.0; K])
        }
    }
    let g = |q: DVec3, hint: &mut u32| Px(f(q, hint));
    let mut band = Vec::new();
    let mut row = vec![0.0f32; grid.width as usize];
    let mut row0 = 0;
    while row0 < grid.height {
        let rows = BAND_ROWS.min(grid.height - row0);
        grid.band_hinted(row0, rows, &g, &mut band);
        for px in band.chunks(grid.width as usize) {
            for (k, w) in writers.iter_mut().enumerate() {
                for (o, v) in row.iter_mut().zip(px) {
                    *o = v.0[k];
                }
                w.write_row(&row)?;
            }
        }
        row0 += rows;
    }
    writers
        .into_iter()
        .map(|w| w.finish().map_err(ExportError::from))
        .collect()
}

/// A shaded-relief preview of elevations (metres, row-major over `grid`): hypsometric colours
/// lit from the north-west, slopes from the true pixel size on a planet of `radius_km`.
pub fn shaded_preview(grid: &GeoGrid, elevation_m: &[f32], radius_km: f64) -> RgbImage {
    let (w, h) = (grid.width as usize, grid.height as usize);
    let m_per_deg = radius_km * 1000.0 * std::f64::consts::PI / 180.0;
    let dy = grid.dy_deg * m_per_deg;
    let at = |c: usize, r: usize| f64::from(elevation_m[r.min(h - 1) * w + c.min(w - 1)]);
    let mut img = RgbImage::new(grid.width, grid.height);
    for r in 0..h {
        let lat = (90.0 - (grid.j0 as f64 + r as f64 + 0.5) * grid.dy_deg).to_radians();
        let dx = (grid.dx_deg * m_per_deg * lat.cos()).max(1e-3);
        for c in 0..w {
            let gx = (at(c + 1, r) - at(c.saturating_sub(1), r)) / (2.0 * dx);
            let gy = (at(c, r.saturating_sub(1)) - at(c, r + 1)) / (2.0 * dy);
            let (nx, ny) = (-gx * 2.0, -gy * 2.0);
            let l = [-0.5f64, 0.5, std::f64::consts::FRAC_1_SQRT_2];
            let lit = ((nx * l[0] + ny * l[1] + l[2]) / (nx * nx + ny * ny + 1.0).sqrt()).max(0.0);
            let f = (lit / l[2]).clamp(0.3, 1.4);
            let e = at(c, r);
            let f = if e < 0.0 { 1.0 + 0.4 * (f - 1.0) } else { f };
            let col = crate::io::maps::hypsometric(e);
            let px = [col[0] * f / 255.0, col[1] * f / 255.0, col[2] * f / 255.0];
            img.put_pixel(
                c as u32,
                r as u32,
                image::Rgb(px.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)),
            );
        }
    }
    img
}

/// Saves an RGB image as PNG, naming the path on failure.
pub fn save_rgb(img: &RgbImage, path: &Path) -> Result<PathBuf, ExportError> {
    img.save(path).map_err(|e| ExportError::Image {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    Ok(path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_snap_to_one_lattice() {
        let px = 0.01;
        let a = GeoGrid::region(10.0, 20.0, 11.0, 21.0, px).unwrap();
        let b = GeoGrid::region(10.0, 21.0, 11.0, 22.0, px).unwrap();
        assert_eq!(a.width, 100);
        assert_eq!(a.height, 100);
        assert_eq!(a.i0 + i64::from(a.width), b.i0);
        let (ba, bb) = (a.bounds(), b.bounds());
        assert!((ba.east - bb.west).abs() < 1e-9);
        assert!((ba.west - 20.0).abs() < 1e-9 && (ba.north - 11.0).abs() < 1e-9);
        // Same lattice pixel, same direction bits.
        assert_eq!(a.direction(a.width, 5), b.direction(0, 5));
    }

    #[test]
    fn bad_regions_and_resolutions_are_named() {
        assert!(GeoGrid::region(0.0, 0.0, 0.0, 1.0, 0.1).is_err());
        assert!(GeoGrid::region(-95.0, 0.0, 0.0, 1.0, 0.1).is_err());
        let e = GeoGrid::region(0.0, 0.0, 80.0, 170.0, 0.0001).unwrap_err();
        assert!(e.to_string().contains("16384"), "{e}");
        assert!(parse_region("1,2,3").is_err());
        let e = parse_region("NaN,0,1,1").unwrap_err().to_string();
        assert!(
            e.contains("LAT0") && e.contains("not a finite number"),
            "{e}"
        );
        let e = GeoGrid::region(10.0, 0.0, 5.0, 1.0, 0.1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("south of"), "{e}");
        // Across the antimeridian: 170°E to 170°W is 20° wide.
        let g = GeoGrid::region(0.0, 170.0, 1.0, -170.0, 0.1).unwrap();
        assert_eq!(g.width, 200);
        assert!((g.bounds().east - 190.0).abs() < 1e-9);
        let e = GeoGrid::region(0.0, 0.0, 1.0, 1.0, 1e-300)
            .unwrap_err()
            .to_string();
        assert!(e.len() < 200 && e.contains("1e-300"), "{e}");
        assert!(parse_resolution("fast", 6371.0).is_err());
        assert!(parse_resolution("-3m", 6371.0).is_err());
        let d = parse_resolution("100m", 6371.0).unwrap();
        assert!((d * 6371.0 * 1000.0 * std::f64::consts::PI / 180.0 - 100.0).abs() < 1e-6);
        let k = parse_resolution("2km", 6371.0).unwrap();
        assert!((k / d - 20.0).abs() < 1e-9);
        assert_eq!(parse_resolution("0.5deg", 6371.0).unwrap(), 0.5);
    }

    #[test]
    fn oversized_exports_and_full_disks_are_refused_up_front() {
        let dir = Path::new("/out");
        // 14.5° × 14.5° at 100 m: 16120 pixels a side, six crust layers and the amplified one.
        let big = 7 * geotiff_bytes(16_120, 16_120) + heightmap16_bytes(16_120, 16_120);
        let e = check_export_size_with(big, None, dir)
            .unwrap_err()
            .to_string();
        assert!(e.contains("split the region"), "{e}");
        // The largest global export fits.
        let global = 7 * geotiff_bytes(16_384, 8_192) + heightmap16_bytes(16_384, 8_192);
        check_export_size_with(global, None, dir).unwrap();
        let e = check_export_size_with(1 << 30, Some(1 << 20), dir)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("only 1 MiB are free") && e.contains("/out"),
            "{e}"
        );
        check_export_size_with(1 << 20, Some(1 << 30), dir).unwrap();
    }
}
