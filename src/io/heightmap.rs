//! 16-bit greyscale PNG heightmaps written row by row, with the JSON sidecar engines expect
//! (the metres of grey 0 and 65535, the projection and the bounds).

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::io::geotiff::GeoBounds;
use crate::io::maps::{Bounds, Elevation16Meta};

/// Errors while writing a heightmap.
#[derive(Debug, thiserror::Error)]
pub enum HeightmapError {
    /// Creating or writing `path` failed.
    #[error("could not write heightmap {}: {reason}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The grey scale is empty or not finite.
    #[error("heightmap {}: invalid elevation range {min_m}..{max_m} m", path.display())]
    Range {
        /// The file.
        path: PathBuf,
        /// Metres of grey 0.
        min_m: f64,
        /// Metres of grey 65535.
        max_m: f64,
    },
}

/// A 16-bit PNG heightmap being written from the north, one row at a time, with a fixed grey
/// scale: grey g is `min_m + g/65535·(max_m − min_m)` metres.
pub struct Heightmap16Writer {
    path: PathBuf,
    file: crate::io::pending::PendingFile,
    stream: png::StreamWriter<'static, BufWriter<std::fs::File>>,
    meta: Elevation16Meta,
    row_bytes: Vec<u8>,
    rows: u32,
}

impl Heightmap16Writer {
    /// Creates `path` (under a temporary name until `finish`; then `path` with extension
    /// `.json`).
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        bounds: GeoBounds,
        range_m: (f64, f64),
    ) -> Result<Self, HeightmapError> {
        let (min_m, max_m) = (range_m.0.floor(), range_m.1.ceil());
        if !(min_m.is_finite() && max_m.is_finite() && max_m > min_m) {
            return Err(HeightmapError::Range {
                path: path.to_path_buf(),
                min_m,
                max_m,
            });
        }
        let err = |e: &dyn std::fmt::Display| HeightmapError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        };
        let (pending, file) = crate::io::pending::PendingFile::create(path).map_err(|e| err(&e))?;
        let mut enc = png::Encoder::new(BufWriter::with_capacity(1 << 20, file), width, height);
        enc.set_color(png::ColorType::Grayscale);
        enc.set_depth(png::BitDepth::Sixteen);
        enc.set_compression(png::Compression::Fast);
        let writer = enc.write_header().map_err(|e| err(&e))?;
        let stream = writer.into_stream_writer().map_err(|e| err(&e))?;
        let span = max_m - min_m;
        let meta = Elevation16Meta {
            min_elevation_m: min_m,
            max_elevation_m: max_m,
            projection: "equirectangular".to_string(),
            width,
            height,
            bounds: Bounds {
                west: bounds.west,
                south: bounds.south,
                east: bounds.east,
                north: bounds.north,
            },
            note: format!(
                "16-bit grey g maps linearly to elevation: metres = min_elevation_m + g / 65535 * \
                 (max_elevation_m - min_elevation_m) = {min_m} + g * {}; row 0 is the north edge, \
                 column 0 the west edge; pixels are areas (the bounds are their outer edges), \
                 sampled at their centres; EPSG:4326 coordinates",
                span / 65535.0
            ),
        };
        Ok(Self {
            path: path.to_path_buf(),
            file: pending,
            stream,
            meta,
            row_bytes: Vec::with_capacity(width as usize * 2),
            rows: 0,
        })
    }

    /// The grey of `metres` on this heightmap's scale.
    pub fn grey(&self, metres: f32) -> u16 {
        let (lo, hi) = (self.meta.min_elevation_m, self.meta.max_elevation_m);
        let g = (f64::from(metres) - lo) / (hi - lo) * 65535.0;
        if g.is_finite() {
            g.round().clamp(0.0, 65535.0) as u16
        } else {
            0
        }
    }

    /// Appends the next row (`width` elevations in metres, west to east).
    pub fn write_row(&mut self, row_m: &[f32]) -> Result<(), HeightmapError> {
        if row_m.len() != self.meta.width as usize || self.rows >= self.meta.height {
            return Err(HeightmapError::Write {
                path: self.path.clone(),
                reason: format!(
                    "row {} of {} values, expected {} rows of {}",
                    self.rows,
                    row_m.len(),
                    self.meta.height,
                    self.meta.width
                ),
            });
        }
        self.row_bytes.clear();
        for &m in row_m {
            let g = self.grey(m);
            self.row_bytes.extend_from_slice(&g.to_be_bytes());
        }
        self.stream
            .write_all(&self.row_bytes)
            .map_err(|e| HeightmapError::Write {
                path: self.path.clone(),
                reason: e.to_string(),
            })?;
        self.rows += 1;
        Ok(())
    }

    /// Finishes the PNG and writes the JSON sidecar; returns both paths.
    pub fn finish(self) -> Result<(PathBuf, PathBuf), HeightmapError> {
        let err = |e: &dyn std::fmt::Display, p: &Path| HeightmapError::Write {
            path: p.to_path_buf(),
            reason: e.to_string(),
        };
        if self.rows != self.meta.height {
            return Err(err(
                &format!("{} of {} rows written", self.rows, self.meta.height),
                &self.path,
            ));
        }
        self.stream.finish().map_err(|e| err(&e, &self.path))?;
        let json_path = self.path.with_extension("json");
        let json = serde_json::to_string_pretty(&self.meta).map_err(|e| err(&e, &json_path))?;
        // The PNG is written under a temporary name: it gets its own once whole.
        let png = self.file.commit().map_err(|e| err(&e, &self.path))?;
        std::fs::write(&json_path, json).map_err(|e| err(&e, &json_path))?;
        Ok((png, json_path))
    }
}
