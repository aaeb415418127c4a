//! The sample graph every relief pass works on: CSR adjacency of the spherical Delaunay mesh,
//! the area each sample stands for, and per-edge geometry computed once per mesh.
//!
//! Units: lengths in km, areas in km². Built once per run (the mesh is fixed); 8 bytes per
//! directed edge of its own (length and weight), the adjacency and the areas shared with the
//! mesh: about 24 MB at 500k samples.

use std::sync::Arc;

use glam::DVec3;
use rayon::prelude::*;

/// Regular triangular-lattice value of the cotangent weight (Voronoi edge length / edge length
/// = 1/√3), used where no triangles are given.
pub const LATTICE_WEIGHT: f32 = 0.577_350_26;

/// 1 / `d` for an edge `d` km long, 0 for a degenerate one (see [`ReliefGraph::inv_edge_km`]).
#[inline]
pub fn inv_km(d: f32) -> f32 {
    if d > 0.0 { 1.0 / d } else { 0.0 }
}

/// The CSR offsets made monotone, in range (≤ `m`, the edge count), `n + 1` long and starting
/// at 0; `None` when `start` is so already.
fn repaired_starts(start: &[u32], n: usize, m: usize) -> Option<Vec<u32>> {
    let m = u32::try_from(m).unwrap_or(u32::MAX);
    let fine = start.len() == n + 1
        && start[0] == 0
        && start.windows(2).all(|w| w[0] <= w[1])
        && start[n] <= m;
    if fine {
        return None;
    }
    let mut out = start.to_vec();
    out.resize(n + 1, *start.last().unwrap_or(&0));
    let mut prev = 0u32;
    for s in out.iter_mut() {
        *s = (*s).clamp(prev, m);
        prev = *s;
    }
    if let Some(first) = out.first_mut() {
        *first = 0;
    }
    Some(out)
}

/// The neighbour lists with out-of-range neighbours made self-loops (length 0, weight 0,
/// skipped by every pass); `None` when every neighbour is in range.
fn repaired_neighbors(start: &[u32], neighbors: &[u32], n: usize) -> Option<Vec<u32>> {
    let listed = &neighbors[..(start[n] as usize).min(neighbors.len())];
    if listed.iter().all(|&j| (j as usize) < n) {
        return None;
    }
    let mut out = neighbors.to_vec();
    for i in 0..n {
        for nb in &mut out[start[i] as usize..start[i + 1] as usize] {
            if *nb as usize >= n {
                *nb = i as u32;
            }
        }
    }
    Some(out)
}

/// Sample graph with per-edge geometry. Edge arrays are aligned with `neighbors` (CSR).
#[derive(Clone, Debug)]
pub struct ReliefGraph {
    /// CSR offsets into `neighbors` (length = samples + 1); shared with the mesh (an `Arc`).
    pub neighbor_start: Arc<[u32]>,
    /// Neighbours of each sample (any order; the project sorts them ascending); shared with the
    /// mesh.
    pub neighbors: Arc<[u32]>,
    /// Area each sample stands for, km² (Voronoi/third-of-triangles; sums to 4πR²); shared
    /// with the mesh.
    pub area_km2: Arc<[f64]>,
    /// Great-circle length of each directed edge, km.
    pub edge_km: Vec<f32>,
    /// Cotangent weight of each edge: (Voronoi dual-edge length) / (edge length), ≥ 0,
    /// dimensionless; symmetric (w_ij = w_ji), so finite-volume fluxes conserve mass exactly.
    pub edge_weight: Vec<f32>,
    /// Planet radius, km.
    pub radius_km: f64,
    /// Mean edge length, km.
    pub mean_spacing_km: f64,
    /// True when every edge i → j (j ≠ i) has its reverse j → i, as in a Delaunay mesh. Passes
    /// that treat the graph as undirected (connected components) rely on it and fall back to
    /// directed searches otherwise. Computed by [`ReliefGraph::new`]; editing `neighbors`
    /// afterwards does not update it.
    symmetric: bool,
}

impl ReliefGraph {
    /// Builds the graph from the project's mesh arrays: unit `positions`, CSR adjacency, the
    /// triangles (for cotangent weights; `None` falls back to [`LATTICE_WEIGHT`]) and the
    /// per-sample areas in km² (`None`: equal areas 4πR²/N).
    ///
    /// Malformed input (offsets out of range, indices ≥ N) is tolerated: such edges get zero
    /// length and weight and are skipped by every pass.
    pub fn new(
        positions: &[DVec3],
        neighbor_start: &[u32],
        neighbors: &[u32],
        triangles: Option<&[[u32; 3]]>,
        area_km2: Option<&[f64]>,
        radius_km: f64,
    ) -> Self {
        let area: Option<Arc<[f64]>> = area_km2.map(Arc::from);
        Self::from_shared(
            positions,
            &Arc::from(neighbor_start),
            &Arc::from(neighbors),
            triangles,
            area.as_ref(),
            radius_km,
        )
    }

    /// [`Self::new`] on arrays held in `Arc`s, as the mesh holds them: arrays that need no
    /// repair are shared, not copied (at 500,000 samples the adjacency and the areas are 18 MB,
    /// held once for the mesh and all its graphs).
    pub fn from_shared(
        positions: &[DVec3],
        neighbor_start: &Arc<[u32]>,
        neighbors: &Arc<[u32]>,
        triangles: Option<&[[u32; 3]]>,
        area_km2: Option<&Arc<[f64]>>,
        radius_km: f64,
    ) -> Self {
        let n = positions.len();
        let start: Arc<[u32]> = repaired_starts(neighbor_start, n, neighbors.len())
            .map_or_else(|| neighbor_start.clone(), Arc::from);
        let nbrs: Arc<[u32]> =
            repaired_neighbors(&start, neighbors, n).map_or_else(|| neighbors.clone(), Arc::from);
        let radius = if radius_km.is_finite() && radius_km > 0.0 {
            radius_km
        } else {
            1.0
        };
        let area: Arc<[f64]> = match area_km2 {
            Some(a) if a.len() == n => {
                // Negative, NaN and infinite areas read as 0 (−0 too, as +0).
                let bad = |x: f64| !(x.is_finite() && x > 0.0) && x.to_bits() != 0;
                if a.iter().any(|&x| bad(x)) {
                    a.iter()
                        .map(|&x| if x.is_finite() && x > 0.0 { x } else { 0.0 })
                        .collect()
                } else {
                    a.clone()
                }
            }
            _ => vec![4.0 * std::f64::consts::PI * radius * radius / n.max(1) as f64; n].into(),
        };
        let edge_km: Vec<f32> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .flat_map_iter(|i| {
                let (a, b) = (start[i] as usize, start[i + 1] as usize);
                let p = positions[i];
                nbrs[a..b].iter().map(move |&j| {
                    let q = positions[j as usize];
                    (p.cross(q).length().atan2(p.dot(q)) * radius) as f32
                })
            })
            .collect();
        let mut edge_weight = vec![
            if triangles.is_some() {
                0.0
            } else {
                LATTICE_WEIGHT
            };
            nbrs.len()
        ];
        if let Some(tris) = triangles {
            let find = |i: usize, j: u32| -> Option<usize> {
                let (a, b) = (start[i] as usize, start[i + 1] as usize);
                nbrs[a..b].iter().position(|&x| x == j).map(|k| a + k)
            };
            for t in tris {
                if t.iter().any(|&v| v as usize >= n) {
                    continue;
                }
                for k in 0..3 {
                    let (a, b, c) = (t[k] as usize, t[(k + 1) % 3] as usize, t[(k + 2) % 3]);
                    let (pa, pb, pc) = (positions[a], positions[b], positions[c as usize]);
                    let (u, v) = (pa - pc, pb - pc);
                    let cross = u.cross(v).length();
                    if cross <= 0.0 {
                        continue;
                    }
                    let half_cot = (0.5 * u.dot(v) / cross) as f32;
                    if let Some(e) = find(a, b as u32) {
                        edge_weight[e] += half_cot;
                    }
                    if let Some(e) = find(b, a as u32) {
                        edge_weight[e] += half_cot;
                    }
                }
            }
            for w in &mut edge_weight {
                if !(w.is_finite() && *w > 0.0) {
                    *w = 0.0;
                }
            }
        }
        for (e, w) in edge_weight.iter_mut().enumerate() {
            if edge_km[e] <= 0.0 {
                *w = 0.0;
            }
        }
        let total: f64 = edge_km.iter().map(|&d| d as f64).sum();
        let mean_spacing_km = if edge_km.is_empty() {
            0.0
        } else {
            total / edge_km.len() as f64
        };
        let list = |i: usize| &nbrs[start[i] as usize..start[i + 1] as usize];
        let symmetric = (0..n).into_par_iter().with_min_len(4096).all(|i| {
            list(i)
                .iter()
                .all(|&j| j as usize == i || list(j as usize).contains(&(i as u32)))
        });
        Self {
            symmetric,
            neighbor_start: start,
            neighbors: nbrs,
            area_km2: area,
            edge_km,
            edge_weight,
            radius_km: radius,
            mean_spacing_km,
        }
    }

    /// Number of samples.
    #[inline]
    pub fn len(&self) -> usize {
        self.area_km2.len()
    }

    /// True without samples.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.area_km2.is_empty()
    }

    /// CSR index range of sample `i`'s edges.
    #[inline]
    pub fn edges(&self, i: usize) -> std::ops::Range<usize> {
        self.neighbor_start[i] as usize..self.neighbor_start[i + 1] as usize
    }

    /// Neighbours of sample `i`.
    #[inline]
    pub fn neighbors_of(&self, i: usize) -> &[u32] {
        &self.neighbors[self.edges(i)]
    }

    /// True when the adjacency is symmetric (every edge i → j, j ≠ i, has its reverse).
    #[inline]
    pub fn is_symmetric(&self) -> bool {
        self.symmetric
    }

    /// Total area, km².
    pub fn total_area_km2(&self) -> f64 {
        self.area_km2.iter().sum()
    }

    /// 1 / the length of edge `e` (0 for a degenerate edge), 1/km: slopes by multiplication.
    /// Computed at each use (a division) rather than stored: 12 MB less at 500,000 samples.
    #[inline]
    pub fn inv_edge_km(&self, e: usize) -> f32 {
        inv_km(self.edge_km[e])
    }
}
