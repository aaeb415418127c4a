//! Float32 GeoTIFF (EPSG:4326, PixelIsArea) written row by row, so a 16384×8192 raster never
//! sits in memory; and a small reader for single-band uncompressed TIFFs (exemplars, tests).
//!
//! Layout: little-endian classic TIFF, header, one IFD right after it, the IFD's arrays, then
//! one strip per row. The georeferencing is ModelPixelScaleTag (degrees per pixel),
//! ModelTiepointTag (pixel (0,0)'s corner at the west/north bound) and a GeoKeyDirectoryTag
//! saying geographic WGS 84 (EPSG:4326), raster type PixelIsArea, angular unit degree.

use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};

/// Geographic bounds of a raster, degrees (edges of the outer pixels).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GeoBounds {
    /// Western edge, longitude.
    pub west: f64,
    /// Southern edge, latitude.
    pub south: f64,
    /// Eastern edge, longitude.
    pub east: f64,
    /// Northern edge, latitude.
    pub north: f64,
}

/// Errors while writing a GeoTIFF.
#[derive(Debug, thiserror::Error)]
pub enum GeoTiffError {
    /// Writing `path` failed.
    #[error("could not write GeoTIFF {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The raster is too large for a classic TIFF or empty.
    #[error("GeoTIFF {}: {reason}", path.display())]
    Size {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Fewer or more rows were written than declared.
    #[error("GeoTIFF {}: {written} rows written, {expected} declared", path.display())]
    Rows {
        /// The file.
        path: PathBuf,
        /// Rows written.
        written: u32,
        /// Rows declared.
        expected: u32,
    },
}

/// A float32 single-band GeoTIFF being written, one row at a time from the north.
pub struct GeoTiffWriter {
    path: PathBuf,
    file: crate::io::pending::PendingFile,
    out: BufWriter<std::fs::File>,
    width: u32,
    height: u32,
    rows: u32,
}

const TYPE_SHORT: u16 = 3;
const TYPE_LONG: u16 = 4;
const TYPE_ASCII: u16 = 2;
const TYPE_DOUBLE: u16 = 12;

impl GeoTiffWriter {
    /// Creates `path` and writes the header and georeferencing of a `width × height` raster
    /// covering `bounds`. `description` goes into ImageDescription.
    pub fn create(
        path: &Path,
        width: u32,
        height: u32,
        bounds: GeoBounds,
        description: &str,
    ) -> Result<Self, GeoTiffError> {
        let io = |source| GeoTiffError::Io {
            path: path.to_path_buf(),
            source,
        };
        let data_bytes = u64::from(width) * u64::from(height) * 4;
        if width == 0
            || height == 0
            || data_bytes + (1 << 20) + u64::from(height) * 8 > u32::MAX as u64
        {
            return Err(GeoTiffError::Size {
                path: path.to_path_buf(),
                reason: format!(
                    "{width}×{height} float32 is empty or too large for a classic TIFF"
                ),
            });
        }
        let (pending, file) = crate::io::pending::PendingFile::create(path).map_err(io)?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        let header = build_header(width, height, bounds, description);
        out.write_all(&header).map_err(io)?;
        Ok(Self {
            path: path.to_path_buf(),
            file: pending,
            out,
            width,
            height,
            rows: 0,
        })
    }

    /// Appends the next row (`width` values, west to east).
    pub fn write_row(&mut self, row: &[f32]) -> Result<(), GeoTiffError> {
        if row.len() != self.width as usize || self.rows >= self.height {
            return Err(GeoTiffError::Rows {
                path: self.path.clone(),
                written: self.rows + 1,
                expected: self.height,
            });
        }
        self.out
            .write_all(bytemuck::cast_slice(row))
            .map_err(|source| GeoTiffError::Io {
                path: self.path.clone(),
                source,
            })?;
        self.rows += 1;
        Ok(())
    }

    /// Flushes the file and gives it its name (it is written under a temporary one until
    /// then); fails if not every row was written.
    pub fn finish(mut self) -> Result<PathBuf, GeoTiffError> {
        if self.rows != self.height {
            return Err(GeoTiffError::Rows {
                path: self.path,
                written: self.rows,
                expected: self.height,
            });
        }
        let io = |source| GeoTiffError::Io {
            path: self.path.clone(),
            source,
        };
        self.out.flush().map_err(io)?;
        let _ = self.out.stream_position();
        drop(self.out);
        self.file.commit().map_err(io)
    }
}

/// Little-endian only (bytemuck casts rows); every supported target is little-endian.
#[cfg(target_endian = "big")]
compile_error!("the GeoTIFF writer assumes a little-endian target");

/// Header + IFD + arrays, with strip offsets pointing past the header.
fn build_header(width: u32, height: u32, b: GeoBounds, description: &str) -> Vec<u8> {
    let dx = (b.east - b.west) / f64::from(width);
    let dy = (b.north - b.south) / f64::from(height);
    let mut desc = description.as_bytes().to_vec();
    desc.push(0);
    let geokeys: [u16; 20] = [
        1, 1, 0, 4, // version, revision, minor, number of keys
        1024, 0, 1, 2, // GTModelTypeGeoKey = ModelTypeGeographic
        1025, 0, 1, 1, // GTRasterTypeGeoKey = RasterPixelIsArea
        2048, 0, 1, 4326, // GeographicTypeGeoKey = EPSG:4326 (WGS 84)
        2054, 0, 1, 9102, // GeogAngularUnitsGeoKey = degree
    ];
    let pixel_scale = [dx, dy, 0.0];
    let tiepoint = [0.0, 0.0, 0.0, b.west, b.north, 0.0];
    // (tag, type, count, payload bytes)
    let mut entries: Vec<(u16, u16, u32, Vec<u8>)> = Vec::new();
    let short = |v: u16| v.to_le_bytes().to_vec();
    let long = |v: u32| v.to_le_bytes().to_vec();
    entries.push((256, TYPE_LONG, 1, long(width)));
    entries.push((257, TYPE_LONG, 1, long(height)));
    entries.push((258, TYPE_SHORT, 1, short(32)));
    entries.push((259, TYPE_SHORT, 1, short(1)));
    entries.push((262, TYPE_SHORT, 1, short(1)));
    entries.push((270, TYPE_ASCII, desc.len() as u32, desc));
    entries.push((273, TYPE_LONG, height, Vec::new())); // strip offsets, filled below
    entries.push((277, TYPE_SHORT, 1, short(1)));
    entries.push((278, TYPE_LONG, 1, long(1)));
    let counts: Vec<u8> = (0..height)
        .flat_map(|_| (width * 4).to_le_bytes())
        .collect();
    entries.push((279, TYPE_LONG, height, counts));
    entries.push((284, TYPE_SHORT, 1, short(1)));
    entries.push((339, TYPE_SHORT, 1, short(3)));
    entries.push((
        33550,
        TYPE_DOUBLE,
        3,
        pixel_scale.iter().flat_map(|v| v.to_le_bytes()).collect(),
    ));
    entries.push((
        33922,
        TYPE_DOUBLE,
        6,
        tiepoint.iter().flat_map(|v| v.to_le_bytes()).collect(),
    ));
    entries.push((
        34735,
        TYPE_SHORT,
        geokeys.len() as u32,
        geokeys.iter().flat_map(|v| v.to_le_bytes()).collect(),
    ));
    let ifd_start = 8u32;
    let ifd_len = 2 + 12 * entries.len() as u32 + 4;
    // Arrays that do not fit in 4 bytes go after the IFD, word aligned.
    let mut extra_len = 0u32;
    for (tag, _, count, payload) in &entries {
        let len = if *tag == 273 {
            count * 4
        } else {
            payload.len() as u32
        };
        if len > 4 {
            extra_len += len.div_ceil(4) * 4;
        }
    }
    let data_start = ifd_start + ifd_len + extra_len;
    let offsets: Vec<u8> = (0..height)
        .flat_map(|r| (data_start + r * width * 4).to_le_bytes())
        .collect();
    for e in entries.iter_mut() {
        if e.0 == 273 {
            e.3 = offsets.clone();
        }
    }
    let mut out = Vec::with_capacity(data_start as usize);
    out.extend_from_slice(b"II");
    out.extend_from_slice(&42u16.to_le_bytes());
    out.extend_from_slice(&ifd_start.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    let mut extra = Vec::new();
    let extra_start = ifd_start + ifd_len;
    for (tag, ty, count, payload) in &entries {
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&ty.to_le_bytes());
        out.extend_from_slice(&count.to_le_bytes());
        if payload.len() <= 4 {
            let mut v = payload.clone();
            v.resize(4, 0);
            out.extend_from_slice(&v);
        } else {
            out.extend_from_slice(&(extra_start + extra.len() as u32).to_le_bytes());
            extra.extend_from_slice(payload);
            while !extra.len().is_multiple_of(4) {
                extra.push(0);
            }
        }
    }
    out.extend_from_slice(&0u32.to_le_bytes());
    out.extend_from_slice(&extra);
    debug_assert_eq!(out.len() as u32, data_start);
    out
}

/// Writes a whole float32 raster (row-major, row 0 north) as a GeoTIFF.
pub fn write_geotiff(
    path: &Path,
    width: u32,
    height: u32,
    bounds: GeoBounds,
    description: &str,
    values: &[f32],
) -> Result<PathBuf, GeoTiffError> {
    let mut w = GeoTiffWriter::create(path, width, height, bounds, description)?;
    for row in values.chunks(width as usize) {
        w.write_row(row)?;
    }
    w.finish()
}

/// A single-band raster read back from a TIFF.
#[derive(Clone, Debug, PartialEq)]
pub struct TiffRaster {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Values as f32, row-major.
    pub values: Vec<f32>,
    /// Pixel size (x) in degrees from ModelPixelScaleTag, if present.
    pub pixel_deg: Option<f64>,
    /// ModelTiepointTag (i, j, k, x, y, z), if present.
    pub tiepoint: Option<[f64; 6]>,
    /// GeoKeyDirectoryTag, if present.
    pub geokeys: Vec<u16>,
}

/// Reads a single-band, uncompressed, strip-organised TIFF of 16-bit integers or 32-bit
/// floats (little- or big-endian). Anything else is refused with the reason.
pub fn read_single_band(bytes: &[u8]) -> Result<TiffRaster, String> {
    if bytes.len() < 8 {
        return Err("file too short for a TIFF".into());
    }
    let le = match &bytes[0..2] {
        b"II" => true,
        b"MM" => false,
        _ => return Err("not a TIFF (bad byte order mark)".into()),
    };
    let u16_at = |o: usize| -> Result<u16, String> {
        let b = bytes.get(o..o + 2).ok_or("truncated TIFF")?;
        Ok(if le {
            u16::from_le_bytes([b[0], b[1]])
        } else {
            u16::from_be_bytes([b[0], b[1]])
        })
    };
    let u32_at = |o: usize| -> Result<u32, String> {
        let b = bytes.get(o..o + 4).ok_or("truncated TIFF")?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if le {
            u32::from_le_bytes(a)
        } else {
            u32::from_be_bytes(a)
        })
    };
    let f64_at = |o: usize| -> Result<f64, String> {
        let b = bytes.get(o..o + 8).ok_or("truncated TIFF")?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(if le {
            f64::from_le_bytes(a)
        } else {
            f64::from_be_bytes(a)
        })
    };
    if u16_at(2)? != 42 {
        return Err("not a classic TIFF (BigTIFF is not supported)".into());
    }
    let ifd = u32_at(4)? as usize;
    let n = u16_at(ifd)? as usize;
    let mut width = 0usize;
    let mut height = 0usize;
    let mut bits = 0u16;
    let mut compression = 1u16;
    let mut sample_format = 1u16;
    let mut spp = 1u16;
    let mut offsets: Vec<u32> = Vec::new();
    let mut pixel_deg = None;
    let mut tiepoint = None;
    let mut geokeys = Vec::new();
    let mut tiled = false;
    for k in 0..n {
        let e = ifd + 2 + 12 * k;
        let tag = u16_at(e)?;
        let ty = u16_at(e + 2)?;
        let count = u32_at(e + 4)? as usize;
        let size = match ty {
            3 => 2,
            4 => 4,
            12 => 8,
            _ => 1,
        };
        let at = if size * count <= 4 {
            e + 8
        } else {
            u32_at(e + 8)? as usize
        };
        let int = |i: usize| -> Result<u32, String> {
            if ty == 3 {
                u16_at(at + 2 * i).map(u32::from)
            } else {
                u32_at(at + 4 * i)
            }
        };
        match tag {
            256 => width = int(0)? as usize,
            257 => height = int(0)? as usize,
            258 => bits = int(0)? as u16,
            259 => compression = int(0)? as u16,
            273 => offsets = (0..count).map(int).collect::<Result<_, _>>()?,
            277 => spp = int(0)? as u16,
            322..=324 => tiled = true,
            339 => sample_format = int(0)? as u16,
            33550 if ty == 12 => pixel_deg = Some(f64_at(at)?),
            33922 if ty == 12 && count >= 6 => {
                let mut t = [0.0; 6];
                for (i, v) in t.iter_mut().enumerate() {
                    *v = f64_at(at + 8 * i)?;
                }
                tiepoint = Some(t);
            }
            34735 if ty == 3 => {
                geokeys = (0..count)
                    .map(|i| u16_at(at + 2 * i))
                    .collect::<Result<_, _>>()?
            }
            _ => {}
        }
    }
    if compression != 1 {
        return Err(format!(
            "compressed TIFF (compression {compression}); convert it with \
             `gdal_translate -co COMPRESS=NONE -co TILED=NO in.tif out.tif`"
        ));
    }
    if tiled {
        return Err("tiled TIFFs are not supported; use gdal_translate -co TILED=NO".into());
    }
    if n == 0 {
        return Err("its image file directory is empty (no tags, so no image)".into());
    }
    if offsets.is_empty() {
        return Err("it has no StripOffsets tag, so no image data".into());
    }
    if spp != 1 {
        return Err(format!("{spp} samples per pixel; expected one band"));
    }
    if width == 0 || height == 0 || width.saturating_mul(height) > 1 << 28 {
        return Err(format!("unsupported size {width}×{height}"));
    }
    let bytes_per = match (bits, sample_format) {
        (16, 1) | (16, 2) => 2,
        (32, 3) => 4,
        _ => {
            return Err(format!(
                "{bits}-bit samples of format {sample_format}; expected int16, uint16 or float32"
            ));
        }
    };
    // Strips are contiguous rows; read them in order.
    let rows_per_strip = height.div_ceil(offsets.len());
    let mut values = Vec::with_capacity(width * height);
    for (s, &off) in offsets.iter().enumerate() {
        let rows = rows_per_strip.min(height - s * rows_per_strip);
        for i in 0..rows * width {
            let o = off as usize + i * bytes_per;
            let v = match (bytes_per, sample_format) {
                (2, 2) => u16_at(o)? as i16 as f32,
                (2, _) => u16_at(o)? as f32,
                _ => f32::from_bits(u32_at(o)?),
            };
            values.push(v);
        }
    }
    Ok(TiffRaster {
        width,
        height,
        values,
        pixel_deg,
        tiepoint,
        geokeys,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_values_and_georeferencing() {
        let dir = std::env::temp_dir().join(format!("geotiff-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.tif");
        let (w, h) = (7u32, 5u32);
        let vals: Vec<f32> = (0..w * h).map(|i| i as f32 * 1.5 - 3.0).collect();
        let b = GeoBounds {
            west: 10.0,
            south: -5.0,
            east: 17.0,
            north: 0.0,
        };
        write_geotiff(&path, w, h, b, "test", &vals).unwrap();
        let t = read_single_band(&std::fs::read(&path).unwrap()).unwrap();
        assert_eq!((t.width, t.height), (7, 5));
        assert_eq!(t.values, vals);
        assert_eq!(t.pixel_deg, Some(1.0));
        assert_eq!(t.tiepoint, Some([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]));
        assert!(t.geokeys.windows(4).any(|k| k == [2048, 0, 1, 4326]));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn short_rows_and_garbage_are_errors() {
        let dir = std::env::temp_dir().join(format!("geotiff-test2-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let b = GeoBounds {
            west: 0.0,
            south: 0.0,
            east: 1.0,
            north: 1.0,
        };
        let mut w = GeoTiffWriter::create(&dir.join("a.tif"), 4, 2, b, "").unwrap();
        w.write_row(&[0.0; 4]).unwrap();
        assert!(w.write_row(&[0.0; 3]).is_err());
        assert!(w.finish().is_err());
        assert!(read_single_band(b"not a tiff at all").is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
