//! Maps a planet can start from (paper §7.1, Fig. 17): `planet generate --from-heightmap FILE`
//! (a global equirectangular 16-bit PNG with the JSON sidecar `generate` writes beside
//! `elevation16.png`, or a GeoTIFF in EPSG:4326), `--plates-map FILE` (one colour per plate),
//! `--motions FILE` (Euler poles per plate) and `--from-earth` (ETOPO1 bedrock relief, the PB2002
//! plates and their NNR-MORVEL56 motions; sources in `assets/earth/README.md`).
//!
//! Every loader checks what it reads and says what is wrong, naming the file: not global, not
//! 2:1, 8-bit, colour, no sidecar or georeferencing, a projected GeoTIFF, a motion for a plate
//! the map does not have.

use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::components::PlateMotion;
use crate::geometry::{from_lat_lon_deg, to_lat_lon_deg};
use crate::resources::input::{TextFileError, num, read_regular_capped};

/// Largest map file read, bytes (a 21600×10800 float32 GeoTIFF is 890 MiB: use a smaller one).
pub const MAX_MAP_BYTES: u64 = 1 << 30;
/// Largest sidecar or motions file read, bytes.
pub const MAX_TEXT_BYTES: u64 = 1 << 20;
/// Smallest map height, pixels.
pub const MIN_MAP_HEIGHT: usize = 8;

/// Why a start map could not be read.
#[derive(Debug, thiserror::Error)]
pub enum StartMapError {
    /// The file could not be read.
    #[error("could not read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a map we can start from.
    #[error("{path} {reason}")]
    Bad {
        /// The file.
        path: PathBuf,
        /// What is wrong, as a sentence starting with a verb.
        reason: String,
    },
}

fn bad(path: &Path, reason: impl Into<String>) -> StartMapError {
    StartMapError::Bad {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn read(path: &Path, limit: u64) -> Result<Vec<u8>, StartMapError> {
    read_regular_capped(path, limit).map_err(|e| match e {
        TextFileError::Io(source) => StartMapError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => bad(path, other.to_string()),
    })
}

/// A global equirectangular elevation grid: row 0 along the north edge, column 0 along 180° W,
/// values at pixel centres, metres.
#[derive(Clone, Debug)]
pub struct ElevationGrid {
    /// Width, pixels (twice the height).
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Elevations, m, row-major.
    pub metres: Vec<f32>,
}

impl ElevationGrid {
    /// Bilinear elevation (m) at world unit direction `dir` (longitudes wrap around).
    pub fn at(&self, dir: DVec3) -> f64 {
        let (lat, lon) = to_lat_lon_deg(dir);
        let (w, h) = (self.width, self.height);
        let x = (lon + 180.0) / 360.0 * w as f64 - 0.5;
        let y = ((90.0 - lat) / 180.0 * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let col = |c: f64| (c as i64).rem_euclid(w as i64) as usize;
        let (c0, c1) = (col(x0), col(x0 + 1.0));
        let (r0, r1) = (y0 as usize, (y0 as usize + 1).min(h - 1));
        let v = |r: usize, c: usize| self.metres[r * w + c] as f64;
        (v(r0, c0) * (1.0 - fx) + v(r0, c1) * fx) * (1.0 - fy)
            + (v(r1, c0) * (1.0 - fx) + v(r1, c1) * fx) * fy
    }
}

fn check_shape(path: &Path, width: usize, height: usize) -> Result<(), StartMapError> {
    if width != 2 * height || height < MIN_MAP_HEIGHT {
        return Err(bad(
            path,
            format!(
                "is {width}×{height} pixels; a global equirectangular map is twice as wide as it is high, at least {}×{MIN_MAP_HEIGHT}",
                2 * MIN_MAP_HEIGHT
            ),
        ));
    }
    Ok(())
}

/// Reads a heightmap to start from: `.png` (16-bit grey with its JSON sidecar `NAME.json`, as
/// `generate` writes `elevation16.png`) or `.tif`/`.tiff` (single-band GeoTIFF in geographic
/// coordinates, EPSG:4326). Both must cover the whole globe.
pub fn load_heightmap(path: &Path) -> Result<ElevationGrid, StartMapError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let grid = match ext.as_str() {
        "png" => load_png16(path)?,
        "tif" | "tiff" => load_geotiff(path)?,
        _ => {
            return Err(bad(
                path,
                "is not a .png (16-bit, with its .json sidecar) or a .tif/.tiff (GeoTIFF) file",
            ));
        }
    };
    if let Some(k) = grid.metres.iter().position(|v| !v.is_finite()) {
        return Err(bad(
            path,
            format!(
                "holds a value that is not a number (pixel {} of row {})",
                k % grid.width,
                k / grid.width
            ),
        ));
    }
    Ok(grid)
}

#[derive(serde::Deserialize)]
struct Bounds {
    west: f64,
    south: f64,
    east: f64,
    north: f64,
}

#[derive(serde::Deserialize)]
struct Sidecar {
    min_elevation_m: f64,
    max_elevation_m: f64,
    projection: Option<String>,
    width: Option<usize>,
    height: Option<usize>,
    bounds: Option<Bounds>,
}

fn is_global(west: f64, south: f64, east: f64, north: f64) -> bool {
    let near = |a: f64, b: f64| (a - b).abs() <= 1e-3;
    near(west, -180.0) && near(east, 180.0) && near(south, -90.0) && near(north, 90.0)
}

fn load_png16(path: &Path) -> Result<ElevationGrid, StartMapError> {
    use image::ImageDecoder;
    let bytes = read(path, MAX_MAP_BYTES)?;
    let decoder = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|source| StartMapError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .into_decoder()
        .map_err(|e| bad(path, format!("is not a readable PNG: {e}")))?;
    match decoder.color_type() {
        image::ColorType::L16 => {}
        image::ColorType::L8 => {
            return Err(bad(
                path,
                "is an 8-bit PNG: 256 grey levels cannot hold a planet's relief; give a 16-bit grey PNG (as `generate` writes elevation16.png) or a GeoTIFF",
            ));
        }
        other => {
            return Err(bad(
                path,
                format!("is a {other:?} PNG; a heightmap must be 16-bit greyscale"),
            ));
        }
    }
    let img = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| bad(path, format!("could not be decoded: {e}")))?
        .to_luma16();
    let (w, h) = (img.width() as usize, img.height() as usize);
    check_shape(path, w, h)?;
    let side = path.with_extension("json");
    let text = match read_regular_capped(&side, MAX_TEXT_BYTES) {
        Ok(b) => String::from_utf8(b).map_err(|_| bad(&side, "is not UTF-8 text"))?,
        Err(TextFileError::Missing) => {
            return Err(bad(
                path,
                format!(
                    "has no sidecar {}: without it the grey levels have no elevations and the image no place on the globe (`generate` writes one beside elevation16.png)",
                    side.display()
                ),
            ));
        }
        Err(TextFileError::Io(source)) => return Err(StartMapError::Io { path: side, source }),
        Err(e) => return Err(bad(&side, e.to_string())),
    };
    let s: Sidecar = serde_json::from_str(&text)
        .map_err(|e| bad(&side, format!("is not a heightmap sidecar: {e}")))?;
    let (lo, hi) = (s.min_elevation_m, s.max_elevation_m);
    if !(lo.is_finite()
        && hi.is_finite()
        && lo < hi
        && lo.abs() <= 20_000.0
        && hi.abs() <= 20_000.0)
    {
        return Err(bad(
            &side,
            format!(
                "gives min_elevation_m = {} and max_elevation_m = {}; they must be finite, within ±20,000 m, the first below the second",
                num(lo),
                num(hi)
            ),
        ));
    }
    if let Some(p) = &s.projection
        && p != "equirectangular"
    {
        return Err(bad(
            &side,
            format!("gives projection \"{p}\"; a start needs an equirectangular map"),
        ));
    }
    if s.width.is_some_and(|sw| sw != w) || s.height.is_some_and(|sh| sh != h) {
        return Err(bad(
            &side,
            format!(
                "describes a {}×{} image, but {} is {w}×{h}",
                s.width.unwrap_or(w),
                s.height.unwrap_or(h),
                path.display()
            ),
        ));
    }
    match &s.bounds {
        Some(b) if is_global(b.west, b.south, b.east, b.north) => {}
        Some(b) => {
            return Err(bad(
                &side,
                format!(
                    "gives bounds west {} south {} east {} north {}; a start needs the whole globe (−180, −90, 180, 90)",
                    num(b.west),
                    num(b.south),
                    num(b.east),
                    num(b.north)
                ),
            ));
        }
        None => {
            return Err(bad(
                &side,
                "gives no bounds: the map is not georeferenced (add \"bounds\": {\"west\": -180, \"south\": -90, \"east\": 180, \"north\": 90})",
            ));
        }
    }
    let metres = img
        .as_raw()
        .iter()
        .map(|&g| (lo + (hi - lo) * g as f64 / 65535.0) as f32)
        .collect();
    Ok(ElevationGrid {
        width: w,
        height: h,
        metres,
    })
}

fn load_geotiff(path: &Path) -> Result<ElevationGrid, StartMapError> {
    let bytes = read(path, MAX_MAP_BYTES)?;
    let t = super::geotiff::read_single_band(&bytes)
        .map_err(|e| bad(path, format!("is not a GeoTIFF we can read: {e}")))?;
    let (Some(dx), Some(tie)) = (t.pixel_deg, t.tiepoint) else {
        return Err(bad(
            path,
            "is not georeferenced (no ModelPixelScale or ModelTiepoint tag): its pixels have no place on the globe",
        ));
    };
    // GeoKey directory: header of 4 shorts, then (key, location, count, value) entries.
    let key = |k: u16| -> Option<u16> {
        t.geokeys
            .get(4..)?
            .chunks_exact(4)
            .find(|e| e[0] == k && e[1] == 0)
            .map(|e| e[3])
    };
    match (key(1024), key(2048)) {
        (Some(1), _) => {
            return Err(bad(
                path,
                "is in projected coordinates; a start needs geographic ones (EPSG:4326): reproject it with `gdalwarp -t_srs EPSG:4326`",
            ));
        }
        (_, Some(code)) if code != 4326 && code != 32767 => {
            return Err(bad(
                path,
                format!("is in geographic system EPSG:{code}; a start needs EPSG:4326 (WGS 84)"),
            ));
        }
        _ => {}
    }
    check_shape(path, t.width, t.height)?;
    let (west, north) = (tie[3] - tie[0] * dx, tie[4] + tie[1] * dx);
    let (east, south) = (west + t.width as f64 * dx, north - t.height as f64 * dx);
    if !is_global(west, south, east, north) {
        return Err(bad(
            path,
            format!(
                "covers west {} south {} east {} north {}; a start needs the whole globe (−180, −90, 180, 90)",
                num(west),
                num(south),
                num(east),
                num(north)
            ),
        ));
    }
    Ok(ElevationGrid {
        width: t.width,
        height: t.height,
        metres: t.values,
    })
}

/// A global equirectangular map of plate indices (row 0 north, column 0 at 180° W).
#[derive(Clone, Debug)]
pub struct PlateGrid {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Plate index per pixel, row-major.
    pub index: Vec<u32>,
    /// Number of plates.
    pub count: usize,
    /// The colour of each plate (for a map read from colours), `#rrggbb`.
    pub colours: Vec<String>,
}

impl PlateGrid {
    /// The plate of the pixel holding world unit direction `dir`.
    pub fn at(&self, dir: DVec3) -> u32 {
        let (lat, lon) = to_lat_lon_deg(dir);
        let x = ((lon + 180.0) / 360.0 * self.width as f64).floor() as i64;
        let y = ((90.0 - lat) / 180.0 * self.height as f64).floor() as i64;
        let c = x.rem_euclid(self.width as i64) as usize;
        let r = y.clamp(0, self.height as i64 - 1) as usize;
        self.index[r * self.width + c]
    }
}

/// Reads a plates map: an equirectangular PNG of the whole globe, one colour per plate. Plates
/// are numbered in the order of their colours as `#rrggbb` hex (`--motions` names them by that
/// number or by colour).
pub fn load_plates_map(path: &Path) -> Result<PlateGrid, StartMapError> {
    let bytes = read(path, MAX_MAP_BYTES)?;
    let img = image::load_from_memory(&bytes)
        .map_err(|e| bad(path, format!("is not a readable image: {e}")))?
        .to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    check_shape(path, w, h)?;
    let key = |p: &image::Rgb<u8>| ((p[0] as u32) << 16) | ((p[1] as u32) << 8) | p[2] as u32;
    let mut colours: Vec<u32> = img.pixels().map(key).collect();
    colours.sort_unstable();
    colours.dedup();
    if colours.len() < 2 {
        return Err(bad(
            path,
            "has a single colour: a plates map needs at least two plates",
        ));
    }
    if colours.len() > 4096 {
        return Err(bad(
            path,
            format!(
                "has {} colours; a plates map has one flat colour per plate (no smoothing or antialiasing)",
                colours.len()
            ),
        ));
    }
    let index = img
        .pixels()
        .map(|p| colours.binary_search(&key(p)).unwrap_or(0) as u32)
        .collect();
    Ok(PlateGrid {
        width: w,
        height: h,
        index,
        count: colours.len(),
        colours: colours.iter().map(|c| format!("#{c:06x}")).collect(),
    })
}

/// One entry of a motions file.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct MotionEntry {
    plate: Option<u32>,
    colour: Option<String>,
    pole_lat_deg: f64,
    pole_lon_deg: f64,
    rate_deg_per_my: f64,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct MotionsFile {
    plate: Vec<MotionEntry>,
}

/// The motion of an Euler pole at (`lat`, `lon`) degrees turning `rate` degrees per My
/// (counter-clockwise positive).
pub fn euler_motion(lat_deg: f64, lon_deg: f64, rate_deg_per_my: f64) -> PlateMotion {
    PlateMotion {
        euler_pole: from_lat_lon_deg(lat_deg, lon_deg),
        angular_speed_rad_per_my: rate_deg_per_my.to_radians(),
    }
}

/// Reads a motions file (TOML): `[[plate]]` tables with `plate` (the number) or `colour`
/// (`"#rrggbb"`, for a plates map), `pole_lat_deg`, `pole_lon_deg` and `rate_deg_per_my`
/// (counter-clockwise positive). `colours` are the plates map's, if any.
pub fn load_motions(
    path: &Path,
    colours: &[String],
) -> Result<Vec<(u32, PlateMotion)>, StartMapError> {
    let bytes = read(path, MAX_TEXT_BYTES)?;
    let text = String::from_utf8(bytes).map_err(|_| bad(path, "is not UTF-8 text"))?;
    let f: MotionsFile =
        toml::from_str(&text).map_err(|e| bad(path, format!("is not a motions file: {e}")))?;
    let mut out = Vec::with_capacity(f.plate.len());
    for (k, e) in f.plate.iter().enumerate() {
        let which = |what: String| bad(path, format!("entry {}: {what}", k + 1));
        let plate =
            match (&e.plate, &e.colour) {
                (Some(p), None) => *p,
                (None, Some(c)) => {
                    let c = c.to_ascii_lowercase();
                    colours.iter().position(|x| *x == c).ok_or_else(|| {
                        which(format!("no plate of the plates map has colour {c}"))
                    })? as u32
                }
                _ => return Err(which("give either `plate` (a number) or `colour`".into())),
            };
        if !(e.pole_lat_deg.abs() <= 90.0
            && e.pole_lon_deg.abs() <= 360.0
            && e.rate_deg_per_my.abs() <= 10.0)
        {
            return Err(which(format!(
                "pole ({}, {}) turning {} °/My is out of range (latitude ±90°, longitude ±360°, rate within ±10 °/My)",
                num(e.pole_lat_deg),
                num(e.pole_lon_deg),
                num(e.rate_deg_per_my)
            )));
        }
        if out.iter().any(|(p, _)| *p == plate) {
            return Err(which(format!("plate {plate} is given twice")));
        }
        out.push((
            plate,
            euler_motion(e.pole_lat_deg, e.pole_lon_deg, e.rate_deg_per_my),
        ));
    }
    Ok(out)
}

/// Today's Earth: ETOPO1 bedrock elevation (m) at world unit direction `dir`, from the
/// `elevation-mini` crate (10′ grid, bilinear).
pub fn earth_elevation_m(dir: DVec3) -> f64 {
    let (lat, lon) = to_lat_lon_deg(dir);
    elevation_mini::elevation(lat.clamp(-90.0, 90.0), lon.clamp(-180.0, 180.0))
}

/// One of Earth's plates in the built-in map.
#[derive(Clone, Debug)]
pub struct EarthPlate {
    /// PB2002 code (e.g. `PA`).
    pub code: String,
    /// Name.
    pub name: String,
    /// Present motion (NNR-MORVEL56).
    pub motion: PlateMotion,
}

const EARTH_PLATES_PNG: &[u8] = include_bytes!("../../assets/earth/pb2002_plates_720x360.png");
const EARTH_PLATES_CSV: &str = include_str!("../../assets/earth/earth_plates.csv");

/// Today's plates: Bird's PB2002 outlines (52 plates) rasterised to 0.5°, each with its
/// NNR-MORVEL56 motion (Argus, Gordon & DeMets 2011). Sources and licences in
/// `assets/earth/README.md`.
pub fn earth_plates() -> (PlateGrid, Vec<EarthPlate>) {
    let img = image::load_from_memory(EARTH_PLATES_PNG)
        .expect("the built-in plate map is a PNG")
        .to_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let index: Vec<u32> = img.as_raw().iter().map(|&g| g as u32).collect();
    let mut plates = Vec::new();
    for line in EARTH_PLATES_CSV.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f.len() < 7 {
            continue;
        }
        let p = |k: usize| {
            f[k].trim()
                .parse::<f64>()
                .expect("a number in earth_plates.csv")
        };
        plates.push(EarthPlate {
            code: f[1].to_string(),
            name: f[2].to_string(),
            motion: euler_motion(p(4), p(5), p(6)),
        });
    }
    let grid = PlateGrid {
        width: w,
        height: h,
        count: plates.len(),
        colours: Vec::new(),
        index,
    };
    (grid, plates)
}
