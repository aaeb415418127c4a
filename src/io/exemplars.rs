//! Elevation exemplars from files (paper §5, Fig. 12): one file (a 16-bit grey PNG with an
//! optional JSON sidecar, or a GeoTIFF) or a folder of them sorted by terrain type, read into the
//! [`Exemplar`]s that `amplify::exemplar` places. The folder layout and the sidecar are described
//! there and in docs/amplification.md.

use std::path::{Path, PathBuf};

use crate::amplify::exemplar::{Exemplar, ExemplarError, ExemplarSet, TerrainType};

/// Reads and preprocesses one file (16-bit PNG with optional JSON sidecar, or GeoTIFF).
pub fn load_exemplar(path: &Path) -> Result<Exemplar, ExemplarError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match ext.as_str() {
        "png" => load_png(path),
        "tif" | "tiff" => {
            let bytes = std::fs::read(path).map_err(|source| ExemplarError::Io {
                path: path.to_path_buf(),
                source,
            })?;
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

fn load_png(path: &Path) -> Result<Exemplar, ExemplarError> {
    let img = image::open(path).map_err(|e| ExemplarError::Format {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let grey = img.to_luma16();
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    let sidecar_path = path.with_extension("json");
    let sidecar: Option<PngSidecar> = match std::fs::read_to_string(&sidecar_path) {
        Ok(s) => Some(serde_json::from_str(&s).map_err(|e| ExemplarError::Format {
            path: sidecar_path.clone(),
            reason: e.to_string(),
        })?),
        Err(_) => None,
    };
    let (lo, hi) = match &sidecar {
        Some(PngSidecar {
            min_elevation_m: Some(lo),
            max_elevation_m: Some(hi),
            ..
        }) => (*lo, *hi),
        _ => (0.0, 65535.0),
    };
    let pixel_km = sidecar
        .as_ref()
        .and_then(|s| s.pixel_size_m)
        .map_or(0.09, |m| (m / 1000.0) as f32);
    let elev: Vec<f32> = grey
        .as_raw()
        .iter()
        .map(|&g| (lo + (hi - lo) * g as f64 / 65535.0) as f32)
        .collect();
    Exemplar::from_elevations(path.to_path_buf(), w, h, &elev, pixel_km)
}

/// Loads every exemplar under `dir` (files sorted by name, so the set is reproducible).
pub fn load_exemplar_dir(dir: &Path) -> Result<ExemplarSet, ExemplarError> {
    if !dir.is_dir() {
        return Err(ExemplarError::Io {
            path: dir.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "not a folder"),
        });
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
