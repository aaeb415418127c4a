//! A glTF 2.0 binary (`.glb`) mesh of the planet: a latitude–longitude sphere of radius 1
//! displaced by elevation (with an exaggeration factor), with normals and vertex colours, that
//! Blender and other engines import as is.

use std::path::{Path, PathBuf};

use glam::DVec3;
use rayon::prelude::*;

/// Options of the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfOptions {
    /// Longitude segments (rings have this many vertices).
    pub segments: u32,
    /// Multiplies elevations before displacing the sphere (1 = true scale).
    pub exaggeration: f64,
    /// Planet radius, km (the mesh has radius 1; elevations are divided by it).
    pub radius_km: f64,
}

/// Errors while writing a glTF file.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    /// Bad options.
    #[error("glTF export: {0}")]
    Invalid(String),
    /// Writing failed.
    #[error("could not write {}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
}

/// Checks the mesh options before any work: 8 to 8192 segments, an exaggeration between 0 and
/// 1000.
pub fn check_options(segments: u32, exaggeration: f64) -> Result<(), GltfError> {
    if !(8..=8192).contains(&segments) {
        return Err(GltfError::Invalid(format!(
            "segments must be between 8 and 8192, got {segments}"
        )));
    }
    if !(exaggeration.is_finite() && (0.0..=1000.0).contains(&exaggeration)) {
        return Err(GltfError::Invalid(format!(
            "exaggeration must be between 0 and 1000, got {}",
            crate::resources::input::num(exaggeration)
        )));
    }
    Ok(())
}

/// Builds the `.glb` bytes of a sphere whose elevation (metres) at a unit direction is given
/// by `elevation_m`, coloured by `colour` (linear RGB in 0..1).
pub fn planet_glb(
    options: &GltfOptions,
    elevation_m: &(impl Fn(DVec3) -> f32 + Sync),
    colour: &(impl Fn(f32) -> [f32; 3] + Sync),
) -> Result<Vec<u8>, GltfError> {
    let seg = options.segments;
    check_options(seg, options.exaggeration)?;
    if !(options.radius_km.is_finite() && options.radius_km > 0.0) {
        return Err(GltfError::Invalid("planet radius must be positive".into()));
    }
    let rings = seg / 2 - 1; // latitude rings between the poles
    // Vertices: north pole, rings (seg each), south pole.
    let mut dirs = Vec::with_capacity((rings * seg + 2) as usize);
    dirs.push(DVec3::Z);
    for r in 0..rings {
        let lat = 90.0 - 180.0 * f64::from(r + 1) / f64::from(rings + 1);
        for c in 0..seg {
            let lon = -180.0 + 360.0 * f64::from(c) / f64::from(seg);
            dirs.push(crate::geometry::from_lat_lon_deg(lat, lon));
        }
    }
    dirs.push(-DVec3::Z);
    let elev: Vec<f32> = dirs.par_iter().map(|&d| elevation_m(d)).collect();
    let scale = options.exaggeration / (options.radius_km * 1000.0);
    let pos: Vec<[f32; 3]> = dirs
        .iter()
        .zip(&elev)
        .map(|(d, &e)| {
            let e = if e.is_finite() { f64::from(e) } else { 0.0 };
            let p = *d * (1.0 + e * scale).max(0.01);
            [p.x as f32, p.y as f32, p.z as f32]
        })
        .collect();
    let ring = |r: u32, c: u32| 1 + r * seg + (c % seg);
    let south = 1 + rings * seg;
    let mut idx: Vec<u32> = Vec::with_capacity((seg * rings * 6) as usize);
    for c in 0..seg {
        // Counter-clockwise seen from outside.
        idx.extend_from_slice(&[0, ring(0, c), ring(0, c + 1)]);
    }
    for r in 0..rings.saturating_sub(1) {
        for c in 0..seg {
            let (a, b, cc, d) = (
                ring(r, c),
                ring(r, c + 1),
                ring(r + 1, c),
                ring(r + 1, c + 1),
            );
            idx.extend_from_slice(&[a, cc, d, a, d, b]);
        }
    }
    for c in 0..seg {
        idx.extend_from_slice(&[ring(rings - 1, c), south, ring(rings - 1, c + 1)]);
    }
    // Normals: area-weighted face normals.
    let mut nrm = vec![DVec3::ZERO; pos.len()];
    let v = |i: u32| {
        let p = pos[i as usize];
        DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
    };
    for t in idx.chunks_exact(3) {
        let n = (v(t[1]) - v(t[0])).cross(v(t[2]) - v(t[0]));
        for &k in t {
            nrm[k as usize] += n;
        }
    }
    let normals: Vec<[f32; 3]> = nrm
        .iter()
        .zip(&dirs)
        .map(|(n, d)| {
            let n = if n.length_squared() > 0.0 {
                n.normalize()
            } else {
                *d
            };
            [n.x as f32, n.y as f32, n.z as f32]
        })
        .collect();
    let colours: Vec<[f32; 4]> = elev
        .iter()
        .map(|&e| {
            let c = colour(e);
            [c[0], c[1], c[2], 1.0]
        })
        .collect();
    let (mut min, mut max) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in &pos {
        for k in 0..3 {
            min[k] = min[k].min(p[k]);
            max[k] = max[k].max(p[k]);
        }
    }
    // Binary chunk: positions, normals, colours, indices.
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut push = |bytes: &[u8], target: u32| {
        let offset = bin.len();
        bin.extend_from_slice(bytes);
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(serde_json::json!({
            "buffer": 0, "byteOffset": offset, "byteLength": bytes.len(), "target": target
        }));
    };
    push(bytemuck::cast_slice(&pos), 34962);
    push(bytemuck::cast_slice(&normals), 34962);
    push(bytemuck::cast_slice(&colours), 34962);
    push(bytemuck::cast_slice(&idx), 34963);
    let n = pos.len();
    let json = serde_json::json!({
        "asset": { "version": "2.0", "generator": "tectonic-planets" },
        "scene": 0,
        "scenes": [ { "nodes": [0] } ],
        "nodes": [ { "mesh": 0, "name": "planet" } ],
        "meshes": [ { "name": "planet", "primitives": [ {
            "attributes": { "POSITION": 0, "NORMAL": 1, "COLOR_0": 2 },
            "indices": 3, "mode": 4, "material": 0 } ] } ],
        "materials": [ { "name": "terrain", "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.9 } } ],
        "buffers": [ { "byteLength": bin.len() } ],
        "bufferViews": views,
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": n, "type": "VEC3", "min": min, "max": max },
            { "bufferView": 1, "componentType": 5126, "count": n, "type": "VEC3" },
            { "bufferView": 2, "componentType": 5126, "count": n, "type": "VEC4" },
            { "bufferView": 3, "componentType": 5125, "count": idx.len(), "type": "SCALAR" }
        ],
        "extras": { "radius_km": options.radius_km, "exaggeration": options.exaggeration,
                    "units": "planet radius = 1; +z is the north pole" }
    });
    let mut json_bytes = serde_json::to_vec(&json)
        .map_err(|e| GltfError::Invalid(format!("could not encode the glTF JSON: {e}")))?;
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

/// Writes [`planet_glb`] to `path`.
pub fn write_planet_glb(
    path: &Path,
    options: &GltfOptions,
    elevation_m: &(impl Fn(DVec3) -> f32 + Sync),
    colour: &(impl Fn(f32) -> [f32; 3] + Sync),
) -> Result<PathBuf, GltfError> {
    let bytes = planet_glb(options, elevation_m, colour)?;
    std::fs::write(path, bytes).map_err(|source| GltfError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(path.to_path_buf())
}

/// Hypsometric vertex colour of an elevation in metres, linear RGB.
pub fn elevation_colour(elevation_m: f32) -> [f32; 3] {
    let c = crate::io::maps::hypsometric(f64::from(elevation_m));
    // glTF vertex colours are linear; the map palette is sRGB 0..255.
    c.map(|v| ((v / 255.0).clamp(0.0, 1.0) as f32).powf(2.2))
}
