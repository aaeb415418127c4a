//! Exemplar-based amplification (paper §5, Fig. 12): elevation exemplars (16-bit PNG or
//! uncompressed GeoTIFF) sorted by terrain type, preprocessed once (mean fold direction and
//! elevation range), then placed as primitives over the continental samples of the matching
//! type, shifted by a random offset, rotated to the local fold direction and blended.
//!
//! Folder layout: `DIR/andean/`, `DIR/himalayan/`, `DIR/old/`, `DIR/plain/`, each holding any
//! number of `*.png` (16-bit grey) or `*.tif`/`*.tiff` files. A PNG may have a sidecar
//! `NAME.json` with `min_elevation_m`, `max_elevation_m` (the metres of grey 0 and 65535, as
//! this project's own heightmaps write) and `pixel_size_m`; without one, grey values are read
//! as metres and pixels as 90 m (SRTM 3″). GeoTIFFs give their pixel size in degrees
//! (converted at 111.32 km per degree) and their values in metres.

use std::path::PathBuf;

use super::procedural::{AmplifyUniform, AmplifyVertex, KIND_ANDEAN, KIND_HIMALAYAN, KIND_PLAIN};
use crate::random::{hash3, unit_f64};

/// Terrain types an exemplar can stand for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TerrainType {
    /// Young ranges raised by subduction.
    Andean = 0,
    /// Young ranges raised by collision.
    Himalayan = 1,
    /// Ranges older than the old-orogeny threshold.
    Old = 2,
    /// Continental crust outside any orogeny.
    Plain = 3,
}

impl TerrainType {
    /// All types, in folder order.
    pub const ALL: [TerrainType; 4] = [
        TerrainType::Andean,
        TerrainType::Himalayan,
        TerrainType::Old,
        TerrainType::Plain,
    ];

    /// The sub-folder holding this type's exemplars.
    pub fn folder(self) -> &'static str {
        match self {
            TerrainType::Andean => "andean",
            TerrainType::Himalayan => "himalayan",
            TerrainType::Old => "old",
            TerrainType::Plain => "plain",
        }
    }
}

/// Why exemplars could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ExemplarError {
    /// The folder or a file could not be read.
    #[error("could not read exemplar {}: {source}", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A file is not a usable elevation image.
    #[error("exemplar {} is not usable: {reason}", path.display())]
    Format {
        /// The path.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The folder holds no exemplar at all.
    #[error(
        "no exemplars in {} (expected *.png or *.tif files in andean/, himalayan/, old/ or plain/)",
        path.display()
    )]
    Empty {
        /// The folder.
        path: PathBuf,
    },
}

/// One preprocessed exemplar.
#[derive(Clone, Debug, PartialEq)]
pub struct Exemplar {
    /// Where it came from.
    pub path: PathBuf,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Elevation minus its mean, metres, row-major.
    pub relief_m: Vec<f32>,
    /// Lowest and highest elevation, metres.
    pub range_m: (f32, f32),
    /// Mean fold direction: the angle (radians, from the +column axis toward +row) along which
    /// its ridges run, from the structure tensor of its gradients.
    pub fold_angle_rad: f32,
    /// Pixel size, km.
    pub pixel_km: f32,
}

impl Exemplar {
    /// Preprocesses an elevation grid (metres, row-major).
    pub fn from_elevations(
        path: PathBuf,
        width: usize,
        height: usize,
        elevation_m: &[f32],
        pixel_km: f32,
    ) -> Result<Self, ExemplarError> {
        let bad = |reason: String| ExemplarError::Format {
            path: path.clone(),
            reason,
        };
        if width < 4 || height < 4 || elevation_m.len() != width * height {
            return Err(bad(format!(
                "needs at least 4×4 pixels, got {width}×{height}"
            )));
        }
        if !(pixel_km.is_finite() && pixel_km > 0.0) {
            return Err(bad(format!("pixel size {pixel_km} km is not positive")));
        }
        if elevation_m.iter().any(|z| !z.is_finite()) {
            return Err(bad("holds non-finite elevations".into()));
        }
        let n = elevation_m.len() as f64;
        let mean = elevation_m.iter().map(|&z| z as f64).sum::<f64>() / n;
        let (lo, hi) = elevation_m
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |a, &z| {
                (a.0.min(z), a.1.max(z))
            });
        // Structure tensor of the gradients; ridges run across the dominant gradient.
        let (mut jxx, mut jyy, mut jxy) = (0.0f64, 0.0f64, 0.0f64);
        for r in 1..height - 1 {
            for c in 1..width - 1 {
                let gx = (elevation_m[r * width + c + 1] - elevation_m[r * width + c - 1]) as f64;
                let gy =
                    (elevation_m[(r + 1) * width + c] - elevation_m[(r - 1) * width + c]) as f64;
                jxx += gx * gx;
                jyy += gy * gy;
                jxy += gx * gy;
            }
        }
        let gradient_angle = 0.5 * (2.0 * jxy).atan2(jxx - jyy);
        let fold = gradient_angle + std::f64::consts::FRAC_PI_2;
        Ok(Self {
            path,
            width,
            height,
            relief_m: elevation_m
                .iter()
                .map(|&z| (z as f64 - mean) as f32)
                .collect(),
            range_m: (lo, hi),
            fold_angle_rad: fold as f32,
            pixel_km,
        })
    }

    /// Bilinear relief (metres) at continuous pixel coordinates, mirrored at the borders so the
    /// exemplar repeats without a seam.
    pub fn relief_at(&self, col: f32, row: f32) -> f32 {
        let mirror = |t: f32, n: usize| -> f32 {
            let period = 2.0 * (n - 1) as f32;
            let m = t.rem_euclid(period);
            if m > (n - 1) as f32 { period - m } else { m }
        };
        let x = mirror(col, self.width);
        let y = mirror(row, self.height);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = (x - x0 as f32, y - y0 as f32);
        let at = |c: usize, r: usize| self.relief_m[r * self.width + c];
        let top = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * tx;
        let bottom = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * tx;
        top + (bottom - top) * ty
    }
}

/// Exemplars by terrain type.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExemplarSet {
    /// All exemplars; `by_type` indexes into it.
    pub exemplars: Vec<Exemplar>,
    /// Indices into `exemplars` for each [`TerrainType`] (in `TerrainType::ALL` order).
    pub by_type: [Vec<usize>; 4],
}

impl ExemplarSet {
    /// Adds an exemplar of type `ty`.
    pub fn push(&mut self, ty: TerrainType, e: Exemplar) {
        self.by_type[ty as usize].push(self.exemplars.len());
        self.exemplars.push(e);
    }

    /// The terrain type of a continental vertex, or `None` for oceanic crust.
    pub fn terrain_type(v: &AmplifyVertex, old_orogeny_my: f32) -> Option<TerrainType> {
        match v.kind {
            KIND_PLAIN => Some(TerrainType::Plain),
            KIND_ANDEAN | KIND_HIMALAYAN if v.age_my > old_orogeny_my => Some(TerrainType::Old),
            KIND_ANDEAN => Some(TerrainType::Andean),
            KIND_HIMALAYAN => Some(TerrainType::Himalayan),
            _ => None,
        }
    }

    /// Gives every continental vertex whose type has exemplars one of them (drawn from the
    /// seed and the vertex position); the others keep procedural relief.
    pub fn assign(&self, vertices: &mut [AmplifyVertex], seed: u64, old_orogeny_my: f32) {
        for v in vertices.iter_mut() {
            v.exemplar = 0;
            let Some(ty) = Self::terrain_type(v, old_orogeny_my) else {
                continue;
            };
            let list = &self.by_type[ty as usize];
            if list.is_empty() {
                continue;
            }
            let key = (v.px.to_bits() as u64) | ((v.py.to_bits() as u64) << 32);
            let key = key ^ (v.pz.to_bits() as u64).rotate_left(17);
            let k = (unit_f64(hash3(seed, 910, key)) * list.len() as f64) as usize;
            v.exemplar = list[k.min(list.len() - 1)] as u32 + 1;
        }
    }

    /// How far the relief of the exemplar assigned to `v` reaches above or below the crust,
    /// metres: half its elevation range, scaled as [`Self::primitive`] scales it (`None`: no
    /// exemplar).
    pub fn relief_amplitude_m(&self, v: &AmplifyVertex) -> Option<f32> {
        let e = self.exemplars.get((v.exemplar as usize).checked_sub(1)?)?;
        let span = (e.range_m.1 - e.range_m.0).max(1.0);
        Some(0.5 * span * exemplar_scale(v, span))
    }

    /// The exemplar primitive of vertex `v` at unit direction `p`: (relief m, detail amplitude
    /// m), or `None` when the vertex has no exemplar. The exemplar is rotated so its mean fold
    /// direction lies along the vertex's fold direction, shifted by the vertex's random offset,
    /// and scaled down where the crust is lower than the exemplar's relief.
    pub fn primitive(
        &self,
        u: &AmplifyUniform,
        v: &AmplifyVertex,
        p: [f32; 3],
    ) -> Option<(f32, f32)> {
        let e = self.exemplars.get((v.exemplar as usize).checked_sub(1)?)?;
        let r = u.radius_km;
        let d = [(p[0] - v.px) * r, (p[1] - v.py) * r, (p[2] - v.pz) * r];
        let b = [
            v.py * v.az - v.pz * v.ay,
            v.pz * v.ax - v.px * v.az,
            v.px * v.ay - v.py * v.ax,
        ];
        let x = d[0] * v.ax + d[1] * v.ay + d[2] * v.az + v.offset_x_km;
        let y = d[0] * b[0] + d[1] * b[1] + d[2] * b[2] + v.offset_y_km;
        // x runs along the local fold direction, which is the direction of compression, and y
        // along the range axis (perpendicular to it). The exemplar's ridges run at
        // `fold_angle_rad`: map the range axis onto them, and the compression direction onto
        // the exemplar's across-ridge axis.
        let (compression_dir, range_axis) = (x, y);
        let (s, c) = e.fold_angle_rad.sin_cos();
        let col = (range_axis * c + compression_dir * s) / e.pixel_km;
        let row = (range_axis * s - compression_dir * c) / e.pixel_km;
        let span = (e.range_m.1 - e.range_m.0).max(1.0);
        Some((e.relief_at(col, row) * exemplar_scale(v, span), 5.0))
    }
}

/// The scale of an exemplar's relief (elevation range `span`, metres) at vertex `v`: the
/// crust's height over the range on mountains, at most 1, at least 0.1; 1 on plains.
fn exemplar_scale(v: &AmplifyVertex, span: f32) -> f32 {
    if v.kind == KIND_PLAIN {
        1.0
    } else {
        (v.elevation_m / span).clamp(0.1, 1.0)
    }
}

/// A synthetic exemplar (metres, row-major `size × size`): ridged noise whose ridges run at
/// `fold_angle_rad` from the column axis, `relief_m` high, for tests and the shipped samples.
pub fn synthetic_exemplar(
    size: usize,
    fold_angle_rad: f32,
    wavelength_px: f32,
    relief_m: f32,
    seed: u32,
) -> Vec<f32> {
    let (s, c) = fold_angle_rad.sin_cos();
    let mut out = Vec::with_capacity(size * size);
    for r in 0..size {
        for col in 0..size {
            let (x, y) = (col as f32, r as f32);
            let along = x * c + y * s;
            let across = -x * s + y * c;
            let mut h = 0.0;
            let mut amp = 1.0;
            let mut f = 1.0 / wavelength_px;
            for o in 0..4u32 {
                let n =
                    super::procedural::noise2(seed.wrapping_add(o), along * f / 4.0, across * f);
                let ridge = 1.0 - n.abs() * 1.4;
                h += amp * ridge * ridge;
                amp *= 0.5;
                f *= 2.0;
            }
            out.push(h / 1.875 * relief_m);
        }
    }
    out
}

/// Grows a drainage network into a grid of relief (`size × size`, row-major): a small
/// landscape-evolution run in which the grid's own relief, normalised, sets the rate of uplift
/// (never below `uplift_floor` of the highest), the first and last rows are base level, and
/// rivers cut by
/// stream power (`E = K·A^0.5·S`, solved implicitly along a priority-flood routing, so closed
/// hollows fill and spill) for `steps` steps. Returns elevations spanning the input's range.
///
/// The ridged noise of [`synthetic_exemplar`] is a third hollows ringed by crests (closed pits
/// deeper than 10 m under D8 routing); real terrain, which rivers shaped, has almost none (the
/// shipped SRTM tile: 0.8%). After this the ridges still run along the input's grain, and the
/// valleys between them branch and reach the base level.
///
/// Why only two rows: the lookup mirrors an exemplar at its borders ([`Exemplar::relief_at`]),
/// and the mirror image of a drained grid drains too, except where water leaves it. Out through
/// a base-level row, it lands on the row's own flat line, and flows on along it; out through a
/// side, it would meet the valley's mirror image coming back up, a closed pit on every seam.
/// With base level all round, the two other sides would show as straight valleys across the
/// range every `size` pixels; along the first and last rows, with ridges along the rows, they
/// are longitudinal valleys between ridges.
pub fn eroded_exemplar(z: &[f32], size: usize, steps: usize, uplift_floor: f32) -> Vec<f32> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let n = size * size;
    assert_eq!(z.len(), n, "exemplar size");
    let (lo, hi) = z.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |a, &v| {
        (a.0.min(v), a.1.max(v))
    });
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let uplift: Vec<f32> = z
        .iter()
        .map(|&v| uplift_floor + (1.0 - uplift_floor) * (v - lo) / span)
        .collect();
    // Erodibility × time step, for areas counted in pixels and lengths in pixels.
    const K_DT: f32 = 0.05;
    let border = |i: usize| {
        let y = i / size;
        y == 0 || y + 1 == size
    };
    let key = crate::geometry::order_bits;
    let mut h = vec![0.0f32; n];
    let mut receiver = vec![u32::MAX; n];
    let mut order = Vec::with_capacity(n);
    let mut area = vec![0.0f32; n];
    let mut done = vec![false; n];
    let mut heap = BinaryHeap::new();
    for _ in 0..steps {
        for i in 0..n {
            h[i] = if border(i) { 0.0 } else { h[i] + uplift[i] };
        }
        // Routing: each pixel drains to the one that flooded it.
        order.clear();
        done.fill(false);
        receiver.fill(u32::MAX);
        for i in (0..n).filter(|&i| border(i)) {
            done[i] = true;
            heap.push(Reverse((key(h[i]), i as u32)));
        }
        while let Some(Reverse((k, i))) = heap.pop() {
            let i = i as usize;
            order.push(i);
            let (x, y) = ((i % size) as isize, (i / size) as isize);
            for (dx, dy) in NEIGHBOURS_8 {
                let (nx, ny) = (x + dx, y + dy);
                if nx < 0 || ny < 0 || nx >= size as isize || ny >= size as isize {
                    continue;
                }
                let j = ny as usize * size + nx as usize;
                if !done[j] {
                    done[j] = true;
                    receiver[j] = i as u32;
                    heap.push(Reverse((key(h[j]).max(k), j as u32)));
                }
            }
        }
        area.fill(1.0);
        for &i in order.iter().rev() {
            let r = receiver[i];
            if r != u32::MAX {
                area[r as usize] += area[i];
            }
        }
        // Implicit incision, receivers first.
        for &i in &order {
            let r = receiver[i];
            if r == u32::MAX {
                continue;
            }
            let r = r as usize;
            let diagonal = i % size != r % size && i / size != r / size;
            let dist = if diagonal {
                std::f32::consts::SQRT_2
            } else {
                1.0
            };
            let f = K_DT * area[i].sqrt() / dist;
            h[i] = (h[i] + f * h[r]) / (1.0 + f);
        }
    }
    let (hl, hh) = h.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |a, &v| {
        (a.0.min(v), a.1.max(v))
    });
    let hs = (hh - hl).max(f32::MIN_POSITIVE);
    h.iter().map(|&v| lo + (v - hl) / hs * span).collect()
}

const NEIGHBOURS_8: [(isize, isize); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preprocessing_finds_the_fold_direction() {
        for deg in [0.0f32, 30.0, 75.0, 120.0] {
            let a = deg.to_radians();
            let z = synthetic_exemplar(128, a, 10.0, 1000.0, 3);
            let e = Exemplar::from_elevations("t".into(), 128, 128, &z, 0.09).unwrap();
            // Angles are directions (mod 180°).
            let diff = (e.fold_angle_rad - a).rem_euclid(std::f32::consts::PI);
            let diff = diff.min(std::f32::consts::PI - diff).to_degrees();
            assert!(
                diff < 12.0,
                "fold {deg}°: found {}°",
                e.fold_angle_rad.to_degrees()
            );
            assert!(e.range_m.1 > e.range_m.0 + 100.0);
        }
    }

    #[test]
    fn mirrored_lookup_is_continuous() {
        let z = synthetic_exemplar(32, 0.3, 6.0, 500.0, 1);
        let e = Exemplar::from_elevations("t".into(), 32, 32, &z, 0.09).unwrap();
        for k in 0..400 {
            let t = k as f32 * 0.37 - 40.0;
            let a = e.relief_at(t, 0.5 * t);
            let b = e.relief_at(t + 1e-3, 0.5 * t);
            assert!((a - b).abs() < 5.0, "jump at {t}: {a} vs {b}");
        }
    }

    /// Ridged noise is full of hollows ringed by crests; grown drainage leaves next to none,
    /// and the ridges keep their direction.
    #[test]
    fn eroded_exemplars_drain_and_keep_their_grain() {
        let pits = |z: &[f32]| {
            // Lifted onto land: the measure counts land only.
            let land: Vec<f32> = z.iter().map(|v| v + 10_000.0).collect();
            let s = crate::amplify::valleys::pit_share(&land, 128, 128, 10.0, None);
            s.pit_cells as f64 / s.land_cells as f64
        };
        for deg in [0.0f32, 30.0, 120.0] {
            let a = deg.to_radians();
            let raw = synthetic_exemplar(128, a, 14.0, 3000.0, 7);
            let z = eroded_exemplar(&raw, 128, 150, 0.2);
            let (before, after) = (pits(&raw), pits(&z));
            assert!(before > 0.2, "the raw noise has {before:.3} in pits");
            assert!(
                after < 0.005,
                "{deg}°: {after:.4} of the eroded exemplar in pits"
            );
            let lo = z.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = z.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let raw_lo = raw.iter().copied().fold(f32::INFINITY, f32::min);
            let raw_hi = raw.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            assert!((lo - raw_lo).abs() < 1.0 && (hi - raw_hi).abs() < 1.0);
            let e = Exemplar::from_elevations("t".into(), 128, 128, &z, 0.2).unwrap();
            let diff = (e.fold_angle_rad - a).rem_euclid(std::f32::consts::PI);
            let diff = diff.min(std::f32::consts::PI - diff).to_degrees();
            // The lookup mirrors the exemplar at its borders: the seams add no pit either.
            let tiled: Vec<f32> = (0..256)
                .flat_map(|r| (0..256).map(move |c| (c as f32 - 64.0, r as f32 - 64.0)))
                .map(|(c, r)| e.relief_at(c, r) + 10_000.0)
                .collect();
            let s = crate::amplify::valleys::pit_share(&tiled, 256, 256, 10.0, None);
            let mirrored = s.pit_cells as f64 / s.land_cells as f64;
            println!(
                "{deg}°: pits {before:.3} -> {after:.4}, mirrored {mirrored:.4}, fold found \
                 {diff:.1}° off"
            );
            assert!(
                mirrored < 0.005,
                "{deg}°: {mirrored:.4} of the mirrored tiling in pits"
            );
            assert!(
                diff < 15.0,
                "fold {deg}°: found {}°",
                e.fold_angle_rad.to_degrees()
            );
        }
    }

    #[test]
    fn bad_exemplars_are_refused() {
        let err = Exemplar::from_elevations("x".into(), 2, 2, &[0.0; 4], 0.09).unwrap_err();
        assert!(err.to_string().contains("4×4"), "{err}");
    }
}
