//! Elevation exemplars from files (paper §5, Fig. 12): one file (a 16-bit grey PNG with an
//! optional JSON sidecar, or a GeoTIFF) or a folder of them sorted by terrain type, read into the
//! [`Exemplar`]s that `amplify::exemplar` places. The folder layout and the sidecar are described
//! there and in docs/amplification.md.

use std::path::{Path, PathBuf};

use crate::amplify::exemplar::{Exemplar, ExemplarError, ExemplarSet, TerrainType};

/// Largest exemplar file read, bytes (a 8192×8192 float32 GeoTIFF is 256 MiB).
pub const MAX_EXEMPLAR_BYTES: u64 = 512 << 20;
/// Largest sidecar read, bytes.
pub const MAX_SIDECAR_BYTES: u64 = 64 << 10;
/// Largest elevation magnitude a sidecar may give, metres (the Earth's span is about −11 km to
/// +9 km).
pub const MAX_SIDECAR_ELEVATION_M: f64 = 20_000.0;
/// Largest pixel size a sidecar may give, metres.
pub const MAX_SIDECAR_PIXEL_M: f64 = 100_000.0;

fn file_error(path: &Path, e: crate::resources::input::TextFileError) -> ExemplarError {
    use crate::resources::input::TextFileError;
    match e {
        TextFileError::Io(source) => ExemplarError::Io {
            path: path.to_path_buf(),
            source,
        },
        other => ExemplarError::Format {
            path: path.to_path_buf(),
            reason: format!("the file {other}"),
        },
    }
}

/// Reads and preprocesses one file (16-bit grey PNG with optional JSON sidecar, or GeoTIFF).
/// Only regular files are read; an 8-bit or colour PNG, a sidecar whose range is empty or
/// beyond ±20 km, or a file over 512 MiB is refused with the reason.
pub fn load_exemplar(path: &Path) -> Result<Exemplar, ExemplarError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "png" => load_png(path),
        "tif" | "tiff" => {
            let bytes = crate::resources::input::read_regular_capped(path, MAX_EXEMPLAR_BYTES)
                .map_err(|e| file_error(path, e))?;
            let t = super::geotiff::read_single_band(&bytes).map_err(|reason| {
                ExemplarError::Format {
                    path: path.to_path_buf(),
                    reason,
                }
            })?;
            let pixel_km = t.pixel_deg.map_or(0.09, |d| (d * 111.32) as f32);
            Exemplar::from_elevations(path.to_path_buf(), t.width, t.height, &t.values, pixel_km)
        }
        _ => Err(ExemplarError::Format {
            path: path.to_path_buf(),
            reason: "expected a .png or .tif file".into(),
        }),
    }
}

#[derive(serde::Deserialize)]
struct PngSidecar {
    min_elevation_m: Option<f64>,
    max_elevation_m: Option<f64>,
    pixel_size_m: Option<f64>,
}

/// The grey scale (metres of grey 0 and 65535) and pixel size (km) of a PNG exemplar, from its
/// sidecar `NAME.json` if there is one, checked.
fn read_sidecar(png: &Path) -> Result<((f64, f64), f32), ExemplarError> {
    use crate::resources::input::{TextFileError, num};
    let path = png.with_extension("json");
    let bad = |reason: String| ExemplarError::Format {
        path: path.clone(),
        reason,
    };
    let text = match crate::resources::input::read_regular_capped(&path, MAX_SIDECAR_BYTES) {
        Ok(b) => String::from_utf8(b).map_err(|_| bad("is not UTF-8 text".into()))?,
        Err(TextFileError::Missing) => return Ok(((0.0, 65535.0), 0.09)),
        Err(e) => return Err(file_error(&path, e)),
    };
    let s: PngSidecar = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let range = match (s.min_elevation_m, s.max_elevation_m) {
        (Some(lo), Some(hi)) => {
            for (key, v) in [("min_elevation_m", lo), ("max_elevation_m", hi)] {
                if !(v.is_finite() && v.abs() <= MAX_SIDECAR_ELEVATION_M) {
                    return Err(bad(format!(
                        "{key} = {} m is beyond ±{MAX_SIDECAR_ELEVATION_M} m (elevations on Earth lie within about −11,000 m and +9,000 m)",
                        num(v)
                    )));
                }
            }
            if lo >= hi {
                return Err(bad(format!(
                    "min_elevation_m = {} m must be below max_elevation_m = {} m",
                    num(lo),
                    num(hi)
                )));
            }
            (lo, hi)
        }
        (None, None) => (0.0, 65535.0),
        _ => {
            return Err(bad(
                "gives only one of min_elevation_m and max_elevation_m (give both, or neither to read greys as metres)".into(),
            ));
        }
    };
    let pixel_km = match s.pixel_size_m {
        Some(m) if m.is_finite() && m > 0.0 && m <= MAX_SIDECAR_PIXEL_M => (m / 1000.0) as f32,
        Some(m) => {
            return Err(bad(format!(
                "pixel_size_m = {} must be above 0 and at most {MAX_SIDECAR_PIXEL_M} m",
                num(m)
            )));
        }
        None => 0.09,
    };
    Ok((range, pixel_km))
}

fn load_png(path: &Path) -> Result<Exemplar, ExemplarError> {
    use image::ImageDecoder;
    let format = |e: &dyn std::fmt::Display| ExemplarError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let meta = std::fs::metadata(path).map_err(|source| ExemplarError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    if !meta.is_file() {
        return Err(format(&format!(
            "it is {}, not a regular file",
            crate::resources::input::kind_in_words(meta.file_type())
        )));
    }
    if meta.len() > MAX_EXEMPLAR_BYTES {
        return Err(format(&format!(
            "it is larger than {}",
            crate::resources::input::bytes_in_words(MAX_EXEMPLAR_BYTES)
        )));
    }
    let decoder = image::ImageReader::open(path)
        .map_err(|source| ExemplarError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| ExemplarError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .into_decoder()
        .map_err(|e| format(&e))?;
    let colour = decoder.color_type();
    if colour != image::ColorType::L16 {
        let (bits, what) = match colour {
            image::ColorType::L8 => ("8-bit", "grey"),
            image::ColorType::La8 => ("8-bit", "grey with alpha"),
            image::ColorType::La16 => ("16-bit", "grey with alpha"),
            image::ColorType::Rgb8 => ("8-bit", "RGB"),
            image::ColorType::Rgba8 => ("8-bit", "RGBA"),
            image::ColorType::Rgb16 => ("16-bit", "RGB"),
            image::ColorType::Rgba16 => ("16-bit", "RGBA"),
            _ => ("other", "colour"),
        };
        return Err(format(&format!(
            "it is a {bits} {what} image; exemplar PNGs must be 16-bit greyscale (see docs/amplification.md)"
        )));
    }
    let img = image::DynamicImage::from_decoder(decoder).map_err(|e| format(&e))?;
    let grey = img.to_luma16();
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    let ((lo, hi), pixel_km) = read_sidecar(path)?;
    let elev: Vec<f32> = grey
        .as_raw()
        .iter()
        .map(|&g| (lo + (hi - lo) * g as f64 / 65535.0) as f32)
        .collect();
    Exemplar::from_elevations(path.to_path_buf(), w, h, &elev, pixel_km)
}

/// Loads every exemplar under `dir` (files sorted by name, so the set is reproducible).
pub fn load_exemplar_dir(dir: &Path) -> Result<ExemplarSet, ExemplarError> {
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(m) => {
            return Err(ExemplarError::Format {
                path: dir.to_path_buf(),
                reason: format!(
                    "--exemplars must name a folder; this is {}",
                    crate::resources::input::kind_in_words(m.file_type())
                ),
            });
        }
        Err(source) => {
            return Err(ExemplarError::Io {
                path: dir.to_path_buf(),
                source,
            });
        }
    }
    let mut set = ExemplarSet::default();
    for ty in TerrainType::ALL {
        let sub = dir.join(ty.folder());
        if !sub.is_dir() {
            continue;
        }
        let mut files: Vec<PathBuf> = std::fs::read_dir(&sub)
            .map_err(|source| ExemplarError::Io {
                path: sub.clone(),
                source,
            })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                matches!(
                    p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()),
                    Some(ref e) if e == "png" || e == "tif" || e == "tiff"
                )
            })
            .collect();
        files.sort();
        for f in files {
            set.push(ty, load_exemplar(&f)?);
        }
    }
    if set.exemplars.is_empty() {
        return Err(ExemplarError::Empty {
            path: dir.to_path_buf(),
        });
    }
    Ok(set)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_folder_is_named() {
        let err = load_exemplar_dir(Path::new("/nonexistent/exemplars")).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/exemplars"), "{err}");
    }
}
