//! Equirectangular map rendering of a sampled planet (elevation with hillshade, plates, crust age, crust type, 16-bit elevation) and PNG/JSON output.
//!
//! Conventions: unit sphere with +z the north pole; longitude λ in [-180°, 180°)
//! grows eastward from +x toward +y; direction = (cos φ cos λ, cos φ sin λ, sin φ).
//! Pixel (col, row) of a W×H image samples its centre:
//! λ = -180 + 360·(col+0.5)/W, φ = 90 − 180·(row+0.5)/H (row 0 is the north).

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma, RgbImage};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Largest raster width accepted by [`Raster::sample`].
pub const MAX_WIDTH: u32 = 16384;
/// Largest raster height accepted by [`Raster::sample`].
pub const MAX_HEIGHT: u32 = 8192;

/// Vertical exaggeration applied to slopes before hillshading.
const VERTICAL_EXAGGERATION: f64 = 20.0;
/// Sun azimuth in degrees clockwise from north (north-west).
const SUN_AZIMUTH_DEG: f64 = 315.0;
/// Sun altitude above the horizon in degrees.
const SUN_ALTITUDE_DEG: f64 = 45.0;
/// Hillshade strength on land (1 = full).
const LAND_SHADE_STRENGTH: f64 = 1.0;
/// Hillshade strength on the ocean floor.
const OCEAN_SHADE_STRENGTH: f64 = 0.35;

/// One sample of the planet at a point, what the maps need.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MapSample {
    /// Elevation relative to sea level, metres (negative below sea level).
    pub elevation_m: f32,
    /// Id of the tectonic plate at this point.
    pub plate: u32,
    /// Whether the crust here is continental (otherwise oceanic).
    pub continental: bool,
    /// Age of the crust in millions of years.
    pub age_my: f32,
}

/// Anything that can be sampled at a unit direction (x, y, z); must be callable from many threads.
pub trait SphereField: Sync {
    /// Returns the planet's properties at the unit direction `dir` (+z is the north pole).
    fn sample(&self, dir: [f64; 3]) -> MapSample;
}

/// Errors from sampling rasters and writing map files.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The requested raster size is zero or larger than the supported maximum.
    #[error("invalid raster size {width}x{height}: {reason}")]
    InvalidSize {
        /// Requested width in pixels.
        width: u32,
        /// Requested height in pixels.
        height: u32,
        /// Why the size was rejected.
        reason: String,
    },
    /// A raster's sample buffer does not match its declared size.
    #[error("malformed raster {width}x{height}: has {samples} samples, expected {expected}")]
    MalformedRaster {
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Number of samples actually present.
        samples: usize,
        /// Number of samples expected (width × height).
        expected: u64,
    },
    /// A file-system operation failed on `path`.
    #[error("I/O error at {}: {source}", path.display())]
    Io {
        /// The path that could not be created or written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// Encoding or writing an image to `path` failed.
    #[error("failed to write image {}: {source}", path.display())]
    Image {
        /// The image file being written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: image::ImageError,
    },
    /// Serialising the metadata for `path` failed.
    #[error("failed to serialise JSON for {}: {source}", path.display())]
    Json {
        /// The JSON file being written.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: serde_json::Error,
    },
}

/// Geographic bounds of a map, in degrees.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Western edge longitude (-180).
    pub west: f64,
    /// Southern edge latitude (-90).
    pub south: f64,
    /// Eastern edge longitude (180).
    pub east: f64,
    /// Northern edge latitude (90).
    pub north: f64,
}

/// Metadata describing how to read the 16-bit elevation image.
#[derive(Serialize, Deserialize, Debug, Clone, PartialEq)]
pub struct Elevation16Meta {
    /// Elevation in metres of grey value 0.
    pub min_elevation_m: f64,
    /// Elevation in metres of grey value 65535.
    pub max_elevation_m: f64,
    /// Map projection, always "equirectangular".
    pub projection: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Geographic bounds of the image (whole globe).
    pub bounds: Bounds,
    /// How to convert grey values to metres.
    pub note: String,
}

/// A rendered raster of samples (row-major, row 0 = north), kept so several images can be written from one sampling pass.
#[derive(Clone, Debug, PartialEq)]
pub struct Raster {
    /// Width in pixels (longitude).
    pub width: u32,
    /// Height in pixels (latitude).
    pub height: u32,
    /// Row-major samples, `width × height` of them, row 0 at the north.
    pub samples: Vec<MapSample>,
}

/// Checks that a raster size is non-zero and within the supported maximum.
fn check_size(width: u32, height: u32) -> Result<(), MapError> {
    let reason = if width == 0 || height == 0 {
        Some("width and height must be at least 1".to_string())
    } else if width > MAX_WIDTH || height > MAX_HEIGHT {
        Some(format!(
            "maximum supported size is {MAX_WIDTH}x{MAX_HEIGHT}"
        ))
    } else {
        None
    };
    match reason {
        Some(reason) => Err(MapError::InvalidSize {
            width,
            height,
            reason,
        }),
        None => Ok(()),
    }
}

/// Linear interpolation of an RGB colour ramp given as (value, colour) stops sorted by value.
fn ramp(stops: &[(f64, [f64; 3])], v: f64) -> [f64; 3] {
    let Some(first) = stops.first() else {
        return [0.0; 3];
    };
    if v.is_nan() || v <= first.0 {
        return first.1;
    }
    for w in stops.windows(2) {
        let (a, b) = (w[0], w[1]);
        if v <= b.0 {
            let t = if b.0 > a.0 {
                (v - a.0) / (b.0 - a.0)
            } else {
                1.0
            };
            return [
                a.1[0] + (b.1[0] - a.1[0]) * t,
                a.1[1] + (b.1[1] - a.1[1]) * t,
                a.1[2] + (b.1[2] - a.1[2]) * t,
            ];
        }
    }
    stops.last().map_or(first.1, |s| s.1)
}

/// Ocean part of the hypsometric palette (metres, sRGB 0..255).
const OCEAN_STOPS: [(f64, [f64; 3]); 7] = [
    (-8000.0, [6.0, 12.0, 40.0]),
    (-6000.0, [12.0, 26.0, 78.0]),
    (-4500.0, [22.0, 52.0, 120.0]),
    (-3000.0, [36.0, 84.0, 158.0]),
    (-1500.0, [62.0, 126.0, 194.0]),
    (-300.0, [118.0, 182.0, 222.0]),
    (0.0, [176.0, 226.0, 238.0]),
];

/// Land part of the hypsometric palette (metres, sRGB 0..255).
const LAND_STOPS: [(f64, [f64; 3]); 9] = [
    (0.0, [64.0, 128.0, 72.0]),
    (300.0, [104.0, 156.0, 84.0]),
    (800.0, [168.0, 180.0, 108.0]),
    (1500.0, [206.0, 188.0, 128.0]),
    (2200.0, [190.0, 150.0, 100.0]),
    (3000.0, [150.0, 108.0, 76.0]),
    (4000.0, [128.0, 106.0, 96.0]),
    (5000.0, [190.0, 188.0, 186.0]),
    (6500.0, [250.0, 250.0, 252.0]),
];

/// Hypsometric tint for an elevation in metres (sea level at 0; 0 and above is land).
pub(crate) fn hypsometric(elev: f64) -> [f64; 3] {
    if elev < 0.0 {
        ramp(&OCEAN_STOPS, elev)
    } else {
        ramp(&LAND_STOPS, elev)
    }
}

/// Crust age ramp, RdYlBu from young (red) to old (blue) over 0..=200 My.
const AGE_STOPS: [(f64, [f64; 3]); 11] = [
    (0.0, [165.0, 0.0, 38.0]),
    (20.0, [215.0, 48.0, 39.0]),
    (40.0, [244.0, 109.0, 67.0]),
    (60.0, [253.0, 174.0, 97.0]),
    (80.0, [254.0, 224.0, 144.0]),
    (100.0, [255.0, 255.0, 191.0]),
    (120.0, [224.0, 243.0, 248.0]),
    (140.0, [171.0, 217.0, 233.0]),
    (160.0, [116.0, 173.0, 209.0]),
    (180.0, [69.0, 117.0, 180.0]),
    (200.0, [49.0, 54.0, 149.0]),
];

/// Colour of continental crust on the crust-age map.
const AGE_CONTINENTAL: [u8; 3] = [128, 128, 128];
/// Colour of continental crust on the crust-type map.
const TYPE_CONTINENTAL: [u8; 3] = [200, 164, 110];
/// Colour of oceanic crust on the crust-type map.
const TYPE_OCEANIC: [u8; 3] = [44, 88, 156];
/// Colour of the coastline on the crust-type map.
const TYPE_COAST: [u8; 3] = [16, 16, 16];
/// Colour of plate borders on the plates map.
const PLATE_BORDER: [u8; 3] = [24, 24, 28];

/// Colour for crust of the given age in millions of years (clamped to 0..=200).
fn age_colour(age_my: f64) -> [u8; 3] {
    let a = if age_my.is_finite() {
        age_my.clamp(0.0, 200.0)
    } else {
        0.0
    };
    to_u8(ramp(&AGE_STOPS, a))
}

/// Rounds and clamps a floating colour to 8-bit channels.
fn to_u8(c: [f64; 3]) -> [u8; 3] {
    [
        c[0].round().clamp(0.0, 255.0) as u8,
        c[1].round().clamp(0.0, 255.0) as u8,
        c[2].round().clamp(0.0, 255.0) as u8,
    ]
}

/// A 64-bit mixing hash (SplitMix64 finaliser); fixed, so colours are stable across runs and platforms.
fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Converts HSV (h in turns 0..1, s and v in 0..1) to RGB 0..255.
fn hsv_to_rgb(h: f64, s: f64, v: f64) -> [f64; 3] {
    let h6 = (h - h.floor()) * 6.0;
    let i = h6.floor();
    let f = h6 - i;
    let p = v * (1.0 - s);
    let q = v * (1.0 - s * f);
    let t = v * (1.0 - s * (1.0 - f));
    let (r, g, b) = match i as i32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r * 255.0, g * 255.0, b * 255.0]
}

/// Stable colour of a plate id: the hue steps by the golden ratio between consecutive ids
/// (so neighbouring ids are far apart in hue) and a fixed hash varies saturation and value.
pub fn plate_colour(id: u32) -> [u8; 3] {
    const GOLDEN: f64 = 0.618_033_988_749_894_8;
    let h = mix64(u64::from(id));
    let hue = (f64::from(id) * GOLDEN + 0.07).fract();
    let s = 0.42 + 0.30 * ((h & 0xFFFF) as f64 / 65535.0);
    let v = 0.78 + 0.18 * (((h >> 16) & 0xFFFF) as f64 / 65535.0);
    to_u8(hsv_to_rgb(hue, s, v))
}

/// Builds an RGB image from a raw buffer of the right size (falls back to black if sizes disagree).
fn rgb_from_raw(width: u32, height: u32, buf: Vec<u8>) -> RgbImage {
    RgbImage::from_raw(width, height, buf).unwrap_or_else(|| RgbImage::new(width, height))
}

impl Raster {
    /// Samples `field` at the centre of every pixel of a `width × height` equirectangular
    /// grid, in parallel over rows. Rejects zero sizes and sizes above 16384×8192.
    pub fn sample(field: &impl SphereField, width: u32, height: u32) -> Result<Raster, MapError> {
        check_size(width, height)?;
        let w = width as usize;
        let mut samples = vec![MapSample::default(); w * height as usize];
        samples
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(row, out)| {
                for (col, s) in out.iter_mut().enumerate() {
                    *s = field.sample(Raster::pixel_direction(
                        width, height, col as u32, row as u32,
                    ));
                }
            });
        Ok(Raster {
            width,
            height,
            samples,
        })
    }

    /// Unit direction of the centre of pixel (`col`, `row`) in a `width × height`
    /// equirectangular image (row 0 north, col 0 at λ = -180°). Zero sizes are treated as 1.
    pub fn pixel_direction(width: u32, height: u32, col: u32, row: u32) -> [f64; 3] {
        let lon = (-180.0 + 360.0 * (f64::from(col) + 0.5) / f64::from(width.max(1))).to_radians();
        let lat = (90.0 - 180.0 * (f64::from(row) + 0.5) / f64::from(height.max(1))).to_radians();
        let (slat, clat) = lat.sin_cos();
        let (slon, clon) = lon.sin_cos();
        [clat * clon, clat * slon, slat]
    }

    /// Checks that the sample buffer matches the declared size and the size is valid.
    pub fn validate(&self) -> Result<(), MapError> {
        check_size(self.width, self.height)?;
        let expected = u64::from(self.width) * u64::from(self.height);
        if self.samples.len() as u64 != expected {
            return Err(MapError::MalformedRaster {
                width: self.width,
                height: self.height,
                samples: self.samples.len(),
                expected,
            });
        }
        Ok(())
    }

    /// Sample at (col, row), or the default sample if out of range (never panics).
    #[inline]
    fn at(&self, col: usize, row: usize) -> MapSample {
        self.samples
            .get(row * self.width as usize + col)
            .copied()
            .unwrap_or_default()
    }

    /// Finite elevation at (col, row) in metres (non-finite values read as 0).
    #[inline]
    fn elev(&self, col: usize, row: usize) -> f64 {
        let e = f64::from(self.at(col, row).elevation_m);
        if e.is_finite() { e } else { 0.0 }
    }

    /// Renders one RGB image in parallel over rows; `f(col, row)` gives each pixel.
    fn render<F>(&self, f: F) -> RgbImage
    where
        F: Fn(usize, usize) -> [u8; 3] + Sync,
    {
        let w = self.width as usize;
        let h = self.height as usize;
        let mut buf = vec![0u8; w * h * 3];
        if w > 0 {
            buf.par_chunks_mut(w * 3)
                .enumerate()
                .for_each(|(row, out)| {
                    for (col, px) in out.chunks_exact_mut(3).enumerate() {
                        px.copy_from_slice(&f(col, row));
                    }
                });
        }
        rgb_from_raw(self.width, self.height, buf)
    }

    /// Column to the east of `col`, wrapping around in longitude.
    #[inline]
    fn east(&self, col: usize) -> usize {
        if col + 1 >= self.width as usize {
            0
        } else {
            col + 1
        }
    }

    /// Column to the west of `col`, wrapping around in longitude.
    #[inline]
    fn west(&self, col: usize) -> usize {
        if col == 0 {
            (self.width as usize).saturating_sub(1)
        } else {
            col - 1
        }
    }

    /// Hypsometric tint (deep navy ocean to pale cyan shelf; green lowlands, tan, brown, grey-white peaks)
    /// multiplied by a hillshade from the north-west at 45° altitude, with slopes computed in metres per
    /// metre on a sphere of radius `planet_radius_km` and exaggerated 20×; the shading is weaker on the ocean.
    pub fn elevation_image(&self, planet_radius_km: f64) -> RgbImage {
        let w = self.width as usize;
        let h = self.height as usize;
        let radius_m = if planet_radius_km.is_finite() && planet_radius_km > 0.0 {
            planet_radius_km * 1000.0
        } else {
            6_371_000.0
        };
        // Pixel size north-south, metres.
        let dy = std::f64::consts::PI * radius_m / h.max(1) as f64;
        let dx_equator = 2.0 * std::f64::consts::PI * radius_m / w.max(1) as f64;
        let az = SUN_AZIMUTH_DEG.to_radians();
        let alt = SUN_ALTITUDE_DEG.to_radians();
        // Light vector in (east, north, up).
        let light = [alt.cos() * az.sin(), alt.cos() * az.cos(), alt.sin()];
        let flat = light[2];
        self.render(|col, row| {
            let e = self.elev(col, row);
            let lat = (90.0 - 180.0 * (row as f64 + 0.5) / h as f64).to_radians();
            let dx = dx_equator * lat.cos().max(1e-6);
            let gx = (self.elev(self.east(col), row) - self.elev(self.west(col), row)) / (2.0 * dx);
            let rn = row.saturating_sub(1);
            let rs = (row + 1).min(h.saturating_sub(1));
            let steps = (rs - rn).max(1) as f64;
            // Gradient toward the north: north value minus south value.
            let gy = (self.elev(col, rn) - self.elev(col, rs)) / (steps * dy);
            let nx = -VERTICAL_EXAGGERATION * gx;
            let ny = -VERTICAL_EXAGGERATION * gy;
            let norm = (nx * nx + ny * ny + 1.0).sqrt();
            let lit = ((nx * light[0] + ny * light[1] + light[2]) / norm).max(0.0);
            let rel = lit / flat; // 1 on flat ground
            let strength = if e < 0.0 {
                OCEAN_SHADE_STRENGTH
            } else {
                LAND_SHADE_STRENGTH
            };
            let factor = (1.0 + strength * (rel - 1.0)).clamp(0.25, 1.35);
            let c = hypsometric(e);
            to_u8([c[0] * factor, c[1] * factor, c[2] * factor])
        })
    }

    /// Whether (col, row) differs from its east or south neighbour according to `key`
    /// (a one-pixel line along the boundary; wraps in longitude).
    #[inline]
    fn is_edge<K: PartialEq>(&self, col: usize, row: usize, key: impl Fn(MapSample) -> K) -> bool {
        let here = key(self.at(col, row));
        let h = self.height as usize;
        key(self.at(self.east(col), row)) != here
            || (row + 1 < h && key(self.at(col, row + 1)) != here)
    }

    /// Distinct colour per plate id (a stable hash of the id, see [`plate_colour`]), ocean slightly
    /// darker than land, thin dark lines at plate borders and faint coastlines.
    pub fn plates_image(&self) -> RgbImage {
        self.render(|col, row| {
            if self.is_edge(col, row, |s| s.plate) {
                return PLATE_BORDER;
            }
            let s = self.at(col, row);
            let base = plate_colour(s.plate);
            let mut k = if s.elevation_m < 0.0 { 0.8 } else { 1.0 };
            if self.is_edge(col, row, |s| s.elevation_m < 0.0) {
                k *= 0.62;
            }
            to_u8([
                f64::from(base[0]) * k,
                f64::from(base[1]) * k,
                f64::from(base[2]) * k,
            ])
        })
    }

    /// Oceanic crust coloured by age (red young → pale yellow → blue old over 0..=200 My, clamped);
    /// continental crust in neutral grey.
    pub fn crust_age_image(&self) -> RgbImage {
        self.render(|col, row| {
            let s = self.at(col, row);
            if s.continental {
                AGE_CONTINENTAL
            } else {
                age_colour(f64::from(s.age_my))
            }
        })
    }

    /// Continental crust in tan, oceanic crust in blue, and the coastline (elevation 0) as a dark line.
    pub fn crust_type_image(&self) -> RgbImage {
        self.render(|col, row| {
            if self.is_edge(col, row, |s| s.elevation_m < 0.0) {
                TYPE_COAST
            } else if self.at(col, row).continental {
                TYPE_CONTINENTAL
            } else {
                TYPE_OCEANIC
            }
        })
    }

    /// 16-bit grey image linear in metres between the raster's minimum and maximum elevation
    /// (rounded outward to whole metres; widened by 1 m if flat), with metadata describing the mapping.
    /// Non-finite elevations are written as grey 0.
    pub fn elevation16(&self) -> (ImageBuffer<Luma<u16>, Vec<u16>>, Elevation16Meta) {
        let (lo, hi) = self
            .samples
            .par_iter()
            .map(|s| f64::from(s.elevation_m))
            .filter(|e| e.is_finite())
            .fold(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |(lo, hi), e| (lo.min(e), hi.max(e)),
            )
            .reduce(
                || (f64::INFINITY, f64::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let (mut min, mut max) = if lo.is_finite() && hi.is_finite() {
            (lo.floor(), hi.ceil())
        } else {
            (0.0, 0.0)
        };
        if max <= min {
            max = min + 1.0;
        }
        if !min.is_finite() {
            min = 0.0;
            max = 1.0;
        }
        let span = max - min;
        let w = self.width as usize;
        let h = self.height as usize;
        let mut buf = vec![0u16; w * h];
        if w > 0 {
            buf.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
                for (col, g) in out.iter_mut().enumerate() {
                    let e = f64::from(self.at(col, row).elevation_m);
                    *g = if e.is_finite() {
                        ((e - min) / span * 65535.0).round().clamp(0.0, 65535.0) as u16
                    } else {
                        0
                    };
                }
            });
        }
        let img = ImageBuffer::from_raw(self.width, self.height, buf)
            .unwrap_or_else(|| ImageBuffer::new(self.width, self.height));
        let meta = Elevation16Meta {
            min_elevation_m: min,
            max_elevation_m: max,
            projection: "equirectangular".to_string(),
            width: self.width,
            height: self.height,
            bounds: Bounds {
                west: -180.0,
                south: -90.0,
                east: 180.0,
                north: 90.0,
            },
            note: format!(
                "16-bit grey g maps linearly to elevation: metres = min_elevation_m + g / 65535 * \
                 (max_elevation_m - min_elevation_m) = {min} + g * {}; row 0 is the north edge (latitude 90), \
                 column 0 the west edge (longitude -180); pixels sample their centres",
                span / 65535.0
            ),
        };
        (img, meta)
    }
}

/// Saves an image to `path` as PNG, naming the path on failure.
fn save_png<P, C>(img: &ImageBuffer<P, C>, path: &Path) -> Result<(), MapError>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let file = std::fs::File::create(path).map_err(|source| MapError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut w = std::io::BufWriter::new(file);
    img.write_to(&mut w, image::ImageFormat::Png)
        .map_err(|source| MapError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    std::io::Write::flush(&mut w).map_err(|source| MapError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Colour of pelagic rain `m` times the globe's mean (`pelagic_rate.png`), log scale: pale sand
/// where a fifth of the mean or less settles (red clay under the gyres), pale blue at the mean,
/// deep teal where five times the mean or more does (ooze under upwelling).
pub fn pelagic_colour(m: f64) -> [u8; 3] {
    const STOPS: [(f64, [f64; 3]); 4] = [
        (-2.32, [236.0, 222.0, 190.0]),
        (0.0, [150.0, 200.0, 220.0]),
        (1.2, [40.0, 130.0, 160.0]),
        (2.32, [10.0, 60.0, 90.0]),
    ];
    let x = if m > 0.0 { m.log2() } else { f64::NEG_INFINITY };
    to_u8(ramp(&STOPS, x))
}

/// Colour of the land on the pelagic rain's map (the viewer's too).
pub const PELAGIC_LAND: [u8; 3] = [120, 120, 120];

/// A map of `field` (one value per sample of `mesh`, interpolated in the triangle under each
/// pixel) in `colour`, except where `fixed` gives a pixel its colour from the raster's sample
/// there (`None` past the raster's samples): the land of a sea-floor map, the sea of a land map.
/// Rows in parallel, each walking its triangles from the last one found. `field` must cover
/// the mesh (the callers check).
pub(crate) fn field_image(
    raster: &Raster,
    mesh: &crate::geometry::SphereMesh,
    field: &[f32],
    fixed: impl Fn(Option<&MapSample>) -> Option<[u8; 3]> + Sync,
    colour: impl Fn(f64) -> [u8; 3] + Sync,
) -> RgbImage {
    let (w, h) = (raster.width, raster.height);
    let mut px = vec![[0u8; 3]; w as usize * h as usize];
    px.par_chunks_mut((w as usize).max(1))
        .enumerate()
        .for_each(|(row, line)| {
            let mut hint = u32::MAX;
            for (col, o) in line.iter_mut().enumerate() {
                let k = row * w as usize + col;
                if let Some(c) = fixed(raster.samples.get(k)) {
                    *o = c;
                    continue;
                }
                let d =
                    glam::DVec3::from_array(Raster::pixel_direction(w, h, col as u32, row as u32));
                let loc = crate::amplify::hinted_locate(mesh, d, hint);
                hint = loc.triangle;
                let v: f64 = mesh
                    .triangles
                    .get(loc.triangle as usize)
                    .map(|t| {
                        t.iter()
                            .zip(loc.weights)
                            .map(|(&s, wt)| wt * f64::from(field[s as usize]))
                            .sum()
                    })
                    .unwrap_or(1.0);
                *o = colour(v);
            }
        });
    RgbImage::from_fn(w, h, |c, r| image::Rgb(px[(r * w + c) as usize]))
}

/// The map of a pelagic rain that varies from place to place (`pelagic_rate.png`, see
/// `sediment.pelagic_variability`): the rain's multiplier `rate` (one per sample of `mesh`) in
/// [`pelagic_colour`] over the sea of `raster` (see [`field_image`]), the land grey. `None`
/// when `rate` does not cover the mesh (the same rain everywhere).
pub fn pelagic_rate_image(
    raster: &Raster,
    mesh: &crate::geometry::SphereMesh,
    rate: &[f32],
) -> Option<RgbImage> {
    if rate.is_empty() || rate.len() != mesh.len() {
        return None;
    }
    Some(field_image(
        raster,
        mesh,
        rate,
        |s| {
            s.is_none_or(|s| s.elevation_m > 0.0)
                .then_some(PELAGIC_LAND)
        },
        pelagic_colour,
    ))
}

/// Writes `pelagic_rate.png` ([`pelagic_rate_image`]) into `dir` and returns its path; `None`
/// (nothing written) with the same rain everywhere.
pub fn write_pelagic_rate(
    raster: &Raster,
    mesh: &crate::geometry::SphereMesh,
    rate: &[f32],
    dir: &Path,
) -> Result<Option<PathBuf>, MapError> {
    let Some(img) = pelagic_rate_image(raster, mesh, rate) else {
        return Ok(None);
    };
    let path = dir.join("pelagic_rate.png");
    save_png(&img, &path)?;
    Ok(Some(path))
}

/// Writes elevation.png, plates.png, crust_age.png, crust_type.png, elevation16.png and elevation16.json into `dir` (created if missing).
/// Returns the paths written, in that order. Images are rendered in parallel.
pub fn write_all_maps(
    raster: &Raster,
    dir: &Path,
    planet_radius_km: f64,
) -> Result<Vec<PathBuf>, MapError> {
    raster.validate()?;
    std::fs::create_dir_all(dir).map_err(|source| MapError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let ((elev, plates), (age, ty)) = rayon::join(
        || {
            rayon::join(
                || raster.elevation_image(planet_radius_km),
                || raster.plates_image(),
            )
        },
        || rayon::join(|| raster.crust_age_image(), || raster.crust_type_image()),
    );
    let (e16, meta) = raster.elevation16();
    let rgb: [(&str, RgbImage); 4] = [
        ("elevation.png", elev),
        ("plates.png", plates),
        ("crust_age.png", age),
        ("crust_type.png", ty),
    ];
    let e16_path = dir.join("elevation16.png");
    let (rgb_results, e16_result) = rayon::join(
        || {
            rgb.par_iter()
                .map(|(name, img)| {
                    let p = dir.join(name);
                    save_png(img, &p).map(|()| p)
                })
                .collect::<Vec<Result<PathBuf, MapError>>>()
        },
        || save_png(&e16, &e16_path),
    );
    let mut written = rgb_results
        .into_iter()
        .collect::<Result<Vec<PathBuf>, MapError>>()?;
    e16_result?;
    written.push(e16_path);
    let json_path = dir.join("elevation16.json");
    let json = serde_json::to_string_pretty(&meta).map_err(|source| MapError::Json {
        path: json_path.clone(),
        source,
    })?;
    std::fs::write(&json_path, json).map_err(|source| MapError::Io {
        path: json_path.clone(),
        source,
    })?;
    written.push(json_path);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    fn unique_temp_dir(tag: &str) -> PathBuf {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!(
            "maps_test_{tag}_{}_{nanos}_{n}",
            std::process::id()
        ))
    }

    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    fn normalize(a: [f64; 3]) -> [f64; 3] {
        let n = dot(a, a).sqrt();
        [a[0] / n, a[1] / n, a[2] / n]
    }

    fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
        let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    }

    /// A fixed pseudo-random plane wave on the sphere: direction, frequency, phase, amplitude.
    type Wave = ([f64; 3], f64, f64, f64);

    /// Builds `n` plane waves with frequencies spread log-uniformly over `fmin..fmax`
    /// and amplitudes ∝ 1/frequency (a cheap fractal noise on the sphere).
    fn waves(seed: u64, n: usize, fmin: f64, fmax: f64) -> Vec<Wave> {
        let u = |k: u64| {
            (mix64(seed.wrapping_mul(1000).wrapping_add(k)) >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n as u64)
            .map(|i| {
                let z = 2.0 * u(4 * i) - 1.0;
                let t = 2.0 * std::f64::consts::PI * u(4 * i + 1);
                let r = (1.0 - z * z).sqrt();
                let f = fmin * (fmax / fmin).powf(u(4 * i + 2));
                (
                    [r * t.cos(), r * t.sin(), z],
                    f,
                    2.0 * std::f64::consts::PI * u(4 * i + 3),
                    f.powf(-0.6),
                )
            })
            .collect()
    }

    fn noise(ws: &[Wave], d: [f64; 3]) -> f64 {
        let norm: f64 = (ws.iter().map(|w| w.3 * w.3).sum::<f64>() / 2.0)
            .sqrt()
            .max(1e-12);
        ws.iter()
            .map(|(v, f, p, a)| a * (f * dot(d, *v) + p).sin())
            .sum::<f64>()
            / norm
    }

    /// Synthetic planet: noise continents, a mountain belt on a great circle,
    /// ocean deepening away from a ridge, plates = nearest of 12 centres, age = distance to ridge.
    struct Synthetic {
        centres: Vec<[f64; 3]>,
        ridge_normal: [f64; 3],
        belt_normal: [f64; 3],
        continents: Vec<Wave>,
        rough: Vec<Wave>,
    }

    impl Synthetic {
        fn new() -> Self {
            let phi = (1.0 + 5f64.sqrt()) / 2.0;
            let mut centres = Vec::new();
            for &(a, b) in &[(1.0, phi), (-1.0, phi), (1.0, -phi), (-1.0, -phi)] {
                centres.push(normalize([0.1 * a, a, b]));
                centres.push(normalize([a, b, 0.15 * b]));
                centres.push(normalize([b, 0.05, a]));
            }
            Synthetic {
                centres,
                ridge_normal: normalize([0.3, 1.0, 0.25]),
                belt_normal: normalize([0.8, -0.3, 0.55]),
                continents: waves(7, 14, 1.2, 4.0),
                rough: waves(2, 40, 8.0, 220.0),
            }
        }
    }

    impl SphereField for Synthetic {
        fn sample(&self, d: [f64; 3]) -> MapSample {
            let thr = 0.45;
            let rough = noise(&self.rough, d);
            let f = noise(&self.continents, d) + 0.06 * rough;
            let ridge_ang = dot(d, self.ridge_normal).clamp(-1.0, 1.0).asin().abs();
            let belt_ang = dot(d, self.belt_normal).clamp(-1.0, 1.0).asin().abs();
            let ocean =
                -2600.0 - 3400.0 * (ridge_ang / std::f64::consts::FRAC_PI_2).sqrt() + 250.0 * rough;
            let elev = if f > thr {
                let base = 60.0
                    + 1500.0 * (f - thr)
                    + 600.0 * (rough + 1.0).max(0.0) * smoothstep(0.0, 0.15, f - thr);
                let belt = 5600.0 * (-(belt_ang / 0.05).powi(2)).exp() * (0.8 + 0.35 * rough);
                base + belt
            } else {
                let t = smoothstep(0.0, 0.12, thr - f);
                -120.0 * (1.0 - t) + ocean * t
            };
            let plate = self
                .centres
                .iter()
                .enumerate()
                .map(|(i, c)| (i, dot(d, *c)))
                .fold(
                    (0usize, f64::NEG_INFINITY),
                    |a, b| if b.1 > a.1 { b } else { a },
                )
                .0 as u32;
            MapSample {
                elevation_m: elev as f32,
                plate,
                continental: f > thr - 0.05,
                age_my: (ridge_ang / std::f64::consts::FRAC_PI_2 * 230.0) as f32,
            }
        }
    }

    /// Land where x > 0 (flat 500 m), ocean elsewhere (flat -3000 m).
    struct HalfLand;
    impl SphereField for HalfLand {
        fn sample(&self, d: [f64; 3]) -> MapSample {
            let land = d[0] > 0.0;
            MapSample {
                elevation_m: if land { 500.0 } else { -3000.0 },
                plate: if d[2] > 0.0 { 1 } else { 2 },
                continental: land,
                age_my: if land { 0.0 } else { 10.0 },
            }
        }
    }

    /// The pelagic rain's map: land grey, the sea coloured by the rain's multiplier there
    /// (darker where more settles), nothing without a field. Seen to fail with the colour read
    /// from the wrong end of the ramp.
    #[test]
    fn the_pelagic_rate_map_colours_the_sea_by_its_rain() {
        let mesh = crate::geometry::SphereMesh::fibonacci(2_000, 0.0, 0, 6371.0).expect("mesh");
        let r = Raster::sample(&HalfLand, 64, 32).expect("sample");
        assert!(pelagic_rate_image(&r, &mesh, &[]).is_none());
        // Five times the mean in the north, a fifth in the south.
        let rate: Vec<f32> = mesh
            .positions
            .iter()
            .map(|p| if p.z > 0.0 { 5.0 } else { 0.2 })
            .collect();
        let img = pelagic_rate_image(&r, &mesh, &rate).expect("a map");
        let brightness = |c: u32, row: u32| {
            img.get_pixel(c, row)
                .0
                .iter()
                .map(|&v| u32::from(v))
                .sum::<u32>()
        };
        // Pixel columns 0..16 and 48..64 lie at x < 0 (sea), 16..48 at x > 0 (land).
        let land = img.get_pixel(32, 16).0;
        assert_eq!(land, [120, 120, 120]);
        let (north, south) = (brightness(2, 4), brightness(2, 27));
        assert_eq!(img.get_pixel(2, 4).0, pelagic_colour(5.0));
        assert_eq!(img.get_pixel(2, 27).0, pelagic_colour(0.2));
        assert!(
            north < south,
            "north {north}, south {south}: more rain is darker"
        );
        assert!(pelagic_colour(1.0) != pelagic_colour(5.0));
    }

    fn raster_of(elevs: &[f32]) -> Raster {
        Raster {
            width: elevs.len() as u32,
            height: 1,
            samples: elevs
                .iter()
                .map(|&e| MapSample {
                    elevation_m: e,
                    ..Default::default()
                })
                .collect(),
        }
    }

    #[test]
    fn pixel_direction_corners_and_centre() {
        // North row is near the pole.
        let d = Raster::pixel_direction(2048, 1024, 0, 0);
        assert!(d[2] > 0.9999, "north row z = {}", d[2]);
        let d = Raster::pixel_direction(2048, 1024, 0, 1023);
        assert!(d[2] < -0.9999, "south row z = {}", d[2]);
        // Column 0 is near λ = -180 (x ≈ -1, y slightly negative) on the equator row pair.
        let d = Raster::pixel_direction(3600, 1800, 0, 899);
        assert!(d[0] < -0.9999 && d[1] < 0.0 && d[1] > -0.001, "{d:?}");
        let lon = d[1].atan2(d[0]).to_degrees();
        assert!(
            (lon - (-179.95)).abs() < 1e-6 || (lon - 180.05).abs() < 1e-6,
            "lon {lon}"
        );
        // 4×2: pixel (1, 0) is λ = -45°, φ = 45°; (2, 1) is λ = 45°, φ = -45°.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let d = Raster::pixel_direction(4, 2, 1, 0);
        for (a, b) in d.iter().zip([0.5, -0.5, h]) {
            assert!((a - b).abs() < 1e-12, "{d:?}");
        }
        let d = Raster::pixel_direction(4, 2, 2, 1);
        for (a, b) in d.iter().zip([0.5, 0.5, -h]) {
            assert!((a - b).abs() < 1e-12, "{d:?}");
        }
        // East of centre is toward +y (eastward from +x toward +y).
        let d = Raster::pixel_direction(360, 180, 270, 90);
        assert!(d[1] > 0.999, "{d:?}");
        for row in 0..5 {
            for col in 0..7 {
                let d = Raster::pixel_direction(7, 5, col, row);
                assert!((dot(d, d) - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn elevation16_maps_range_and_json_round_trips() {
        let r = raster_of(&[-100.0, 50.0, 200.0]);
        let (img, meta) = r.elevation16();
        assert_eq!(meta.min_elevation_m, -100.0);
        assert_eq!(meta.max_elevation_m, 200.0);
        assert_eq!(img.get_pixel(0, 0).0[0], 0);
        assert_eq!(img.get_pixel(2, 0).0[0], 65535);
        let mid = img.get_pixel(1, 0).0[0];
        assert!((i32::from(mid) - 32768).abs() <= 1, "mid {mid}");
        // Converting back with the documented formula gives metres within a few mm.
        let back = meta.min_elevation_m
            + f64::from(mid) / 65535.0 * (meta.max_elevation_m - meta.min_elevation_m);
        assert!((back - 50.0).abs() < 0.01, "{back}");
        assert_eq!(meta.projection, "equirectangular");
        assert_eq!(
            meta.bounds,
            Bounds {
                west: -180.0,
                south: -90.0,
                east: 180.0,
                north: 90.0
            }
        );
        assert_eq!((meta.width, meta.height), (3, 1));
        let json = serde_json::to_string(&meta).expect("serialise");
        let back: Elevation16Meta = serde_json::from_str(&json).expect("deserialise");
        assert_eq!(back, meta);

        // Rounded outward to whole metres.
        let (_, m) = raster_of(&[-100.4, 20.0, 199.2]).elevation16();
        assert_eq!((m.min_elevation_m, m.max_elevation_m), (-101.0, 200.0));
        // Flat rasters are widened by 1 m.
        let (img, m) = raster_of(&[5.0, 5.0]).elevation16();
        assert_eq!((m.min_elevation_m, m.max_elevation_m), (5.0, 6.0));
        assert_eq!(img.get_pixel(0, 0).0[0], 0);
    }

    #[test]
    fn elevation_image_land_green_ocean_blue() {
        let r = Raster::sample(&HalfLand, 64, 32).expect("sample");
        let img = r.elevation_image(6371.0);
        // λ = 0 (x > 0) is column 32, λ = 180 (x < 0) is column 0; equator rows 15/16.
        let land = img.get_pixel(30, 10).0;
        let ocean = img.get_pixel(2, 10).0;
        assert!(land[1] > land[0] && land[1] > land[2], "land {land:?}");
        assert!(
            ocean[2] > ocean[0] && ocean[2] > ocean[1],
            "ocean {ocean:?}"
        );
        // Flat ground is not darkened by hillshade.
        let flat = to_u8(hypsometric(500.0));
        assert_eq!(land, flat);
    }

    #[test]
    fn hillshade_lights_north_west_slopes() {
        // A ridge running north-south: west-facing flank is lit, east-facing flank is darker.
        let w = 64u32;
        let h = 32u32;
        let mut samples = Vec::new();
        for _row in 0..h {
            for col in 0..w {
                let dist = (col as f64 - 32.0).abs();
                samples.push(MapSample {
                    elevation_m: (2000.0 - 150.0 * dist).max(100.0) as f32,
                    ..Default::default()
                });
            }
        }
        let r = Raster {
            width: w,
            height: h,
            samples,
        };
        // Small planet (~10 km pixels) so the 150 m per pixel flanks are steep.
        let img = r.elevation_image(100.0);
        let west_flank = img.get_pixel(28, 16).0;
        let east_flank = img.get_pixel(36, 16).0;
        let sum = |p: [u8; 3]| p.iter().map(|&v| u32::from(v)).sum::<u32>();
        assert!(
            sum(west_flank) > sum(east_flank) + 30,
            "{west_flank:?} vs {east_flank:?}"
        );
    }

    #[test]
    fn plate_colours_stable_and_distinct() {
        assert_eq!(plate_colour(7), plate_colour(7));
        // Fixed values: a plate keeps its colour across runs and versions.
        assert_eq!(plate_colour(0), plate_colour_expected(0));
        assert_eq!(plate_colour(1), plate_colour_expected(1));
        for id in 0..200u32 {
            let a = plate_colour(id);
            let b = plate_colour(id + 1);
            let d: i32 = a
                .iter()
                .zip(b)
                .map(|(&x, y)| (i32::from(x) - i32::from(y)).abs())
                .sum();
            assert!(d > 60, "ids {id} and {} too similar: {a:?} {b:?}", id + 1);
        }
    }

    fn plate_colour_expected(id: u32) -> [u8; 3] {
        match id {
            0 => PLATE0,
            _ => PLATE1,
        }
    }
    const PLATE0: [u8; 3] = [221, 136, 75];
    const PLATE1: [u8; 3] = [120, 105, 223];

    #[test]
    fn plates_image_draws_borders() {
        let r = Raster::sample(&HalfLand, 64, 32).expect("sample");
        let img = r.plates_image();
        // Plate 1 north of the equator, 2 south: row 15 borders row 16.
        assert_eq!(img.get_pixel(40, 15).0, PLATE_BORDER);
        assert_ne!(img.get_pixel(40, 5).0, PLATE_BORDER);
        assert_eq!(img.get_pixel(40, 5).0, plate_colour(1));
    }

    #[test]
    fn crust_images_colours() {
        let samples = vec![
            MapSample {
                elevation_m: -2500.0,
                age_my: 0.0,
                ..Default::default()
            },
            MapSample {
                elevation_m: -5000.0,
                age_my: 250.0,
                ..Default::default()
            },
            MapSample {
                elevation_m: 300.0,
                continental: true,
                ..Default::default()
            },
            MapSample {
                elevation_m: 300.0,
                continental: true,
                ..Default::default()
            },
        ];
        let r = Raster {
            width: 4,
            height: 1,
            samples,
        };
        let age = r.crust_age_image();
        let young = age.get_pixel(0, 0).0;
        let old = age.get_pixel(1, 0).0;
        assert!(young[0] > young[2] + 80, "{young:?}");
        assert!(old[2] > old[0] + 80, "{old:?}");
        assert_eq!(age.get_pixel(2, 0).0, AGE_CONTINENTAL);
        let ty = r.crust_type_image();
        assert_eq!(ty.get_pixel(0, 0).0, TYPE_OCEANIC);
        assert_eq!(ty.get_pixel(1, 0).0, TYPE_COAST); // ocean next to land to the east
        assert_eq!(ty.get_pixel(2, 0).0, TYPE_CONTINENTAL);
        assert_eq!(ty.get_pixel(3, 0).0, TYPE_COAST); // wraps to ocean at column 0
    }

    #[test]
    fn write_all_maps_writes_six_files() {
        let dir = unique_temp_dir("write").join("nested");
        let r = Raster::sample(&Synthetic::new(), 96, 48).expect("sample");
        let files = write_all_maps(&r, &dir, 6371.0).expect("write");
        let names: Vec<String> = files
            .iter()
            .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .collect();
        for name in [
            "elevation.png",
            "plates.png",
            "crust_age.png",
            "crust_type.png",
            "elevation16.png",
            "elevation16.json",
        ] {
            assert!(
                names.iter().any(|n| n == name),
                "missing {name} in {names:?}"
            );
            let p = dir.join(name);
            assert!(
                std::fs::metadata(&p).map(|m| m.len() > 0).unwrap_or(false),
                "{p:?}"
            );
        }
        let e16 = image::open(dir.join("elevation16.png"))
            .expect("open")
            .into_luma16();
        assert_eq!(e16.dimensions(), (96, 48));
        let meta: Elevation16Meta = serde_json::from_str(
            &std::fs::read_to_string(dir.join("elevation16.json")).expect("read"),
        )
        .expect("json");
        assert_eq!(meta, r.elevation16().1);
        let _ = std::fs::remove_dir_all(dir.parent().unwrap_or(&dir));
    }

    #[test]
    fn write_all_maps_unwritable_path_names_it() {
        let base = unique_temp_dir("unwritable");
        std::fs::create_dir_all(&base).expect("mkdir");
        let file = base.join("a_file");
        std::fs::write(&file, b"x").expect("write");
        let target = file.join("maps");
        let r = raster_of(&[1.0, -1.0]);
        let err = write_all_maps(&r, &target, 6371.0).expect_err("must fail");
        let msg = err.to_string();
        assert!(msg.contains(&*file.to_string_lossy()), "{msg}");
        assert!(matches!(err, MapError::Io { .. }));
        let _ = std::fs::remove_dir_all(&base);
    }

    #[test]
    fn bad_sizes_error_without_panic() {
        for (w, h) in [
            (0, 10),
            (10, 0),
            (0, 0),
            (16385, 10),
            (10, 8193),
            (u32::MAX, u32::MAX),
        ] {
            let err = Raster::sample(&HalfLand, w, h).expect_err("bad size");
            assert!(matches!(err, MapError::InvalidSize { .. }), "{err}");
            assert!(err.to_string().contains(&format!("{w}x{h}")), "{err}");
        }
        // A malformed raster renders without panicking and refuses to be written.
        let bad = Raster {
            width: 4,
            height: 3,
            samples: vec![MapSample::default(); 5],
        };
        let _ = bad.elevation_image(6371.0);
        let _ = bad.plates_image();
        let _ = bad.crust_age_image();
        let _ = bad.crust_type_image();
        let _ = bad.elevation16();
        let empty = Raster {
            width: 0,
            height: 0,
            samples: Vec::new(),
        };
        let _ = empty.elevation_image(6371.0);
        let _ = empty.elevation16();
        let dir = unique_temp_dir("bad");
        assert!(matches!(
            write_all_maps(&bad, &dir, 6371.0),
            Err(MapError::MalformedRaster { .. })
        ));
        assert!(matches!(
            write_all_maps(&empty, &dir, 6371.0),
            Err(MapError::InvalidSize { .. })
        ));
        // NaN elevations do not panic either.
        let nan = raster_of(&[f32::NAN, 1.0, f32::INFINITY]);
        let (img, meta) = nan.elevation16();
        assert_eq!((meta.min_elevation_m, meta.max_elevation_m), (1.0, 2.0));
        assert_eq!(img.get_pixel(0, 0).0[0], 0);
        let _ = nan.elevation_image(6371.0);
    }

    /// Renders the synthetic planet at 2048×1024, prints timings and writes the maps to
    /// `$MAPS_PREVIEW_DIR` (or a temp dir). Run with `cargo test --release -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn preview_synthetic_maps() {
        let field = Synthetic::new();
        let t0 = std::time::Instant::now();
        let r = Raster::sample(&field, 2048, 1024).expect("sample");
        let t_sample = t0.elapsed();
        let t1 = std::time::Instant::now();
        let e = r.elevation_image(6371.0);
        let t_elev = t1.elapsed();
        let t2 = std::time::Instant::now();
        let p = r.plates_image();
        let a = r.crust_age_image();
        let c = r.crust_type_image();
        let (g, _) = r.elevation16();
        let t_rest = t2.elapsed();
        std::hint::black_box((&e, &p, &a, &c, &g));
        let dir = std::env::var_os("MAPS_PREVIEW_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|| unique_temp_dir("preview"));
        let t3 = std::time::Instant::now();
        let files = write_all_maps(&r, &dir, 6371.0).expect("write");
        let t_write = t3.elapsed();
        let land = r.samples.iter().filter(|s| s.elevation_m >= 0.0).count() as f64
            / r.samples.len() as f64;
        println!("land fraction {land:.3}");
        let crop = image::imageops::crop_imm(&e, 1400, 150, 600, 400).to_image();
        crop.save(dir.join("elevation_crop.png")).expect("crop");
        println!(
            "sample {t_sample:?}; elevation_image {t_elev:?}; other 4 images {t_rest:?}; write_all_maps (render+encode+write) {t_write:?}; {files:?}"
        );
    }
}
