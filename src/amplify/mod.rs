//! Amplification of the coarse crust to detailed relief (paper §5): flat per-sample tables
//! built once from a crust, and an [`Amplifier`] that gives the detailed elevation at any
//! point of the sphere, procedurally ([`procedural`]) or from elevation exemplars
//! ([`exemplar`]).

pub mod exemplar;
pub mod procedural;
pub mod valleys;

use glam::DVec3;

use crate::geometry::SphereMesh;
use crate::random::{hash3, mix64, unit_f64};
use crate::resources::{Crust, CrustType, Orogeny};

pub use exemplar::{ExemplarError, ExemplarSet, TerrainType};
pub use procedural::{
    AmplifyQuery, AmplifyUniform, AmplifyVertex, KIND_ANDEAN, KIND_HIMALAYAN, KIND_OCEAN,
    KIND_PLAIN, MAX_RELIEF_M, NoiseMemo, amplify_cpu, amplify_point,
};
pub use valleys::{PitShare, Valleys, pit_depths, pit_depths_with_outlets, pit_share};

/// Random stream of the primitives' offsets.
const STREAM_OFFSET: u64 = 900;

/// Options of the amplification.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmplifyOptions {
    /// Multiplies all relief (1 = the model's amplitudes); 0 gives the crust back.
    pub relief_scale: f32,
    /// Orogeny age above which a range counts as *old mountains* for exemplars, My.
    pub old_orogeny_my: f32,
}

impl Default for AmplifyOptions {
    fn default() -> Self {
        Self {
            relief_scale: 1.0,
            old_orogeny_my: 100.0,
        }
    }
}

/// Noise octaves shorter than this many output pixels are left out (see
/// [`Amplifier::with_pixel_km`]). One pixel: a pixel's average keeps a fair share of a
/// wavelength of two pixels, so cutting there would move values away from the average
/// (tests/amplify.rs, `hundred_metre_tile_averaged_down_matches_the_global_map`).
pub const NOISE_LOD_PIXELS: f64 = 1.0;

/// 32 noise-seed bits from a 64-bit planet seed.
pub fn noise_seed(seed: u64) -> u32 {
    let h = mix64(seed ^ 0x616d_706c_6966_7921);
    (h ^ (h >> 32)) as u32
}

/// A unit tangent at `p` along `dir` (projected), or a fixed eastward tangent where `dir` is
/// zero or radial.
fn tangent_along(p: DVec3, dir: [f32; 3]) -> DVec3 {
    let d = DVec3::new(dir[0] as f64, dir[1] as f64, dir[2] as f64);
    let t = d - p * p.dot(d);
    if t.length_squared() > 1e-12 {
        return t.normalize();
    }
    let east = DVec3::Z.cross(p);
    if east.length_squared() > 1e-12 {
        east.normalize()
    } else {
        DVec3::X
    }
}

/// The amplification tables of a crust: one [`AmplifyVertex`] per sample.
pub fn build_vertices(mesh: &SphereMesh, crust: &Crust, seed: u64) -> Vec<AmplifyVertex> {
    use rayon::prelude::*;
    (0..mesh.len())
        .into_par_iter()
        .map(|i| {
            let p = mesh.positions[i];
            // Land relief on continents and on oceanic crust above the sea (arcs, basins filled
            // to above it); abyssal hills only on the sea floor.
            let land = crust.crust_type[i] == CrustType::Continental || crust.elevation_km[i] > 0.0;
            let (kind, dir, age) = if land {
                let kind = match crust.orogeny[i] {
                    Orogeny::None => KIND_PLAIN,
                    Orogeny::Andean => KIND_ANDEAN,
                    Orogeny::Himalayan => KIND_HIMALAYAN,
                };
                (kind, crust.fold_dir[i], crust.orogeny_age_my[i])
            } else {
                (KIND_OCEAN, crust.ridge_dir[i], crust.age_my[i])
            };
            let a = tangent_along(p, dir);
            // Offsets are drawn from the position's bits, not the sample index.
            let key = p.x.to_bits() ^ p.y.to_bits().rotate_left(21) ^ p.z.to_bits().rotate_left(42);
            let ox = unit_f64(hash3(seed, STREAM_OFFSET, key)) * 1000.0;
            let oy = unit_f64(hash3(seed, STREAM_OFFSET + 1, key)) * 1000.0;
            AmplifyVertex {
                px: p.x as f32,
                py: p.y as f32,
                pz: p.z as f32,
                ax: a.x as f32,
                ay: a.y as f32,
                az: a.z as f32,
                elevation_m: crust.elevation_km[i] * 1000.0,
                age_my: if age.is_finite() { age.max(0.0) } else { 0.0 },
                offset_x_km: ox as f32,
                offset_y_km: oy as f32,
                kind,
                exemplar: 0,
            }
        })
        .collect()
}

/// Locates `q` in triangle `hint` when it lies strictly inside it (the locator's formula and
/// early-exit threshold, so the result is bit-identical to `mesh.locate(q)`), else asks the
/// mesh's locator.
pub fn hinted_locate(mesh: &SphereMesh, q: DVec3, hint: u32) -> crate::geometry::Location {
    if let Some(tri) = mesh.triangles.get(hint as usize) {
        let (a, b, c) = (
            mesh.positions[tri[0] as usize],
            mesh.positions[tri[1] as usize],
            mesh.positions[tri[2] as usize],
        );
        let wa = q.dot(b.cross(c));
        if wa > 0.0 {
            let wb = q.dot(c.cross(a));
            let wc = q.dot(a.cross(b));
            let s = wa + wb + wc;
            if s > 0.0 {
                let w = [wa / s, wb / s, wc / s];
                if w[0].min(w[1]).min(w[2]) > 1e-9 {
                    return crate::geometry::Location {
                        triangle: hint,
                        weights: w,
                    };
                }
            }
        }
    }
    mesh.locate(q)
}

/// Amplified elevation anywhere on the sphere, from a crust on its mesh.
pub struct Amplifier<'a> {
    /// The reference mesh.
    pub mesh: &'a SphereMesh,
    /// One entry per sample (read them; the amplifier keeps terms derived from them, so they
    /// change only through its builder methods).
    pub vertices: Vec<AmplifyVertex>,
    /// Global constants.
    pub uniform: AmplifyUniform,
    /// Exemplars, when amplifying from real or user elevation data.
    pub exemplars: Option<ExemplarSet>,
    /// Crust elevation range, metres (min, max).
    pub crust_range_m: (f32, f32),
    /// River valleys carved into the relief, when a drainage network was given
    /// ([`Self::with_valleys`]).
    pub valleys: Option<Valleys>,
    /// The per-vertex terms of the procedural primitives, one per vertex (built with them).
    terms: Vec<procedural::VertexTerms>,
}

impl<'a> Amplifier<'a> {
    /// Procedural amplification of `crust` (world frame, on `mesh`) with noise seeded by `seed`.
    pub fn new(mesh: &'a SphereMesh, crust: &Crust, seed: u64, options: AmplifyOptions) -> Self {
        let vertices = build_vertices(mesh, crust, seed);
        let terms = {
            use rayon::prelude::*;
            vertices
                .par_iter()
                .with_min_len(4096)
                .map(procedural::VertexTerms::of)
                .collect()
        };
        let (lo, hi) = crust
            .elevation_km
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &z| {
                (lo.min(z), hi.max(z))
            });
        let crust_range_m = if lo.is_finite() {
            (lo * 1000.0, hi * 1000.0)
        } else {
            (0.0, 0.0)
        };
        Self {
            mesh,
            vertices,
            uniform: AmplifyUniform {
                radius_km: mesh.radius_km as f32,
                seed: noise_seed(seed),
                relief_scale: options.relief_scale,
                count: 0,
                min_wavelength_km: 0.0,
                pad: [0; 3],
            },
            exemplars: None,
            crust_range_m,
            valleys: None,
            terms,
        }
    }

    /// Switches continental primitives to exemplars: every continental sample whose terrain
    /// type has exemplars gets one, drawn from the seed and its position.
    pub fn with_exemplars(mut self, set: ExemplarSet, seed: u64, options: AmplifyOptions) -> Self {
        set.assign(&mut self.vertices, seed, options.old_orogeny_my);
        self.exemplars = Some(set);
        self
    }

    /// Carves the river valleys of `network` (the drainage network of the crust this amplifier
    /// was built from, on the same mesh) into the relief: see [`valleys`]. Their incision and
    /// walls follow the amplitude of each sample's primitive: an exemplar's relief where one is
    /// assigned (call [`Self::with_exemplars`] first), the procedural one elsewhere.
    pub fn with_valleys(mut self, network: valleys::Network<'_>) -> Self {
        let scale = self.uniform.relief_scale;
        // Each sample's amplitude, and the floor its crests must clear on the divides' cap
        // (higher for exemplars, whose blocks of crests ring more hollows: see
        // [`Valleys::new`]).
        let (amp_m, crest_floor_m): (Vec<f32>, Vec<f32>) = self
            .vertices
            .iter()
            .map(|v| {
                let exemplar = self
                    .exemplars
                    .as_ref()
                    .and_then(|s| s.relief_amplitude_m(v));
                let floor = if exemplar.is_some() {
                    valleys::EXEMPLAR_CREST_FLOOR_AMPS
                } else {
                    valleys::CREST_FLOOR_AMPS
                };
                let amp = exemplar.unwrap_or_else(|| procedural::relief_amplitude_m(v)) * scale;
                (amp, floor * amp)
            })
            .unzip();
        self.valleys = Some(Valleys::new(
            self.mesh,
            network,
            amp_m,
            crest_floor_m,
            self.uniform.seed,
        ));
        self
    }

    /// Leaves out the detail an output of `pixel_km` pixels cannot resolve: noise octaves whose
    /// wavelength is under [`NOISE_LOD_PIXELS`] pixel (averaged over a pixel, they vanish) and
    /// tributary levels whose junctions lie under [`valleys::LOD_PIXELS`] pixels apart (see
    /// [`Valleys::set_pixel_km`]; sampled, they alias into a maze). Nothing changes at 100 m
    /// pixels or finer. Call it after [`Self::with_valleys`].
    pub fn with_pixel_km(mut self, pixel_km: f64) -> Self {
        self.uniform.min_wavelength_km = (NOISE_LOD_PIXELS * pixel_km) as f32;
        if let Some(v) = self.valleys.as_mut() {
            v.set_pixel_km(pixel_km);
        }
        self
    }

    /// Elevation range (metres) that every amplified value lies in: the crust's range widened
    /// by the largest relief (and above by the valleys' cap, when carved).
    pub fn range_m(&self) -> (f32, f32) {
        let r = if self.uniform.relief_scale == 0.0 {
            0.0
        } else {
            MAX_RELIEF_M
        };
        let rise = self.valleys.as_ref().map_or(0.0, Valleys::max_rise_m);
        (self.crust_range_m.0 - r, self.crust_range_m.1 + r + rise)
    }

    /// The query (triangle and weights) of unit direction `dir`.
    pub fn query(&self, dir: DVec3) -> AmplifyQuery {
        let mut hint = u32::MAX;
        self.query_hinted(dir, &mut hint)
    }

    /// [`Self::query`], trying triangle `hint` first (the previous pixel's, usually) and
    /// leaving the triangle found in it. The answer is the same bits as without a hint: a point
    /// strictly inside the hint triangle (smallest weight above 1e-9, the locator's own
    /// early-exit rule, same formula) is strictly inside no other triangle.
    pub fn query_hinted(&self, dir: DVec3, hint: &mut u32) -> AmplifyQuery {
        let loc = hinted_locate(self.mesh, dir, *hint);
        *hint = loc.triangle;
        let t = self.mesh.triangles[loc.triangle as usize];
        let w = loc.weights;
        AmplifyQuery {
            dx: dir.x as f32,
            dy: dir.y as f32,
            dz: dir.z as f32,
            c0: t[0],
            c1: t[1],
            c2: t[2],
            w0: w[0] as f32,
            w1: w[1] as f32,
            w2: w[2] as f32,
        }
    }

    /// Amplified elevation at unit direction `dir`, metres.
    pub fn elevation_m(&self, dir: DVec3) -> f32 {
        let q = self.query(dir);
        self.elevation_of(&q)
    }

    /// [`Self::elevation_m`] with a triangle hint (see [`Self::query_hinted`]); same bits.
    pub fn elevation_m_hinted(&self, dir: DVec3, hint: &mut u32) -> f32 {
        let q = self.query_hinted(dir, hint);
        self.elevation_of(&q)
    }

    /// Amplified elevation of a query, metres.
    pub fn elevation_of(&self, q: &AmplifyQuery) -> f32 {
        let z = self.primitives_of(q);
        self.carve(q, z)
    }

    /// `z`, the primitives' amplified elevation at query `q` (on the CPU or the GPU), with the
    /// river valleys carved (unchanged without valleys).
    pub fn carve(&self, q: &AmplifyQuery, z: f32) -> f32 {
        match &self.valleys {
            None => z,
            Some(v) => v.carve(self.mesh, q, self.base_of(q), z),
        }
    }

    /// [`Self::carve`] over a band of rows `width` pixels wide (`queries` and `z` row-major,
    /// whole rows), in parallel, by blocks of `block` × `block` pixels that share the search
    /// for the valleys near them: the same bits as [`Self::carve`] pixel by pixel, whatever the
    /// block size (blocks about a kilometre wide are the fastest; see docs/amplification.md).
    pub fn carve_band(&self, queries: &[AmplifyQuery], z: &mut [f32], width: usize, block: usize) {
        use rayon::prelude::*;
        let Some(valleys) = &self.valleys else {
            return;
        };
        let (width, block) = (width.max(1), block.max(1));
        z.par_chunks_mut(width * block)
            .zip(queries.par_chunks(width * block))
            .for_each(|(zs, qs)| {
                let rows = zs.len() / width;
                let mut plan = valleys::Plan::default();
                let (mut bq, mut bb, mut bz, mut idx) =
                    (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                for col0 in (0..width).step_by(block) {
                    let col1 = (col0 + block).min(width);
                    bq.clear();
                    bb.clear();
                    bz.clear();
                    idx.clear();
                    for r in 0..rows {
                        for k in r * width + col0..r * width + col1 {
                            bq.push(qs[k]);
                            bb.push(self.base_of(&qs[k]));
                            bz.push(zs[k]);
                            idx.push(k);
                        }
                    }
                    valleys.carve_points(self.mesh, &bq, &bb, &mut bz, &mut plan);
                    for (&k, &v) in idx.iter().zip(&bz) {
                        zs[k] = v;
                    }
                }
            });
    }

    /// Crust elevation (barycentric) of a query, metres.
    fn base_of(&self, q: &AmplifyQuery) -> f32 {
        let v = &self.vertices;
        q.w0 * v[q.c0 as usize].elevation_m
            + q.w1 * v[q.c1 as usize].elevation_m
            + q.w2 * v[q.c2 as usize].elevation_m
    }

    /// Amplified elevation of a query from the primitives alone (no valleys), metres.
    pub fn primitives_of(&self, q: &AmplifyQuery) -> f32 {
        self.primitives_of_memo(q, &mut NoiseMemo::default())
    }

    /// [`Self::primitives_of`], with the noise cells of the queries before it in `memo` (one
    /// per thread, over a run of nearby queries: the same bits, faster).
    pub fn primitives_of_memo(&self, q: &AmplifyQuery, memo: &mut NoiseMemo) -> f32 {
        match &self.exemplars {
            None => {
                procedural::amplify_point_terms(&self.uniform, &self.vertices, &self.terms, q, memo)
            }
            Some(set) => procedural::amplify_point_with(
                &self.uniform,
                &self.vertices,
                q,
                memo,
                |c, v, p, m| {
                    set.primitive(&self.uniform, v, p).unwrap_or_else(|| {
                        procedural::procedural_primitive(&self.uniform, v, &self.terms[c], p, m)
                    })
                },
            ),
        }
    }

    /// Crust elevation (no relief) at unit direction `dir`, metres, for before/after pictures.
    pub fn crust_elevation_m(&self, dir: DVec3) -> f32 {
        let q = self.query(dir);
        self.base_of(&q)
    }
}
