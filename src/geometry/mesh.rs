//! The fixed reference mesh: sample positions, their spherical Delaunay triangles, vertex
//! adjacency, per-sample areas and the point locator. Built once per run; plates are subsets of
//! it in their own frames, and resampling maps data back onto it.

use std::sync::Arc;

use bevy_ecs::resource::Resource;
use glam::DVec3;
use rayon::prelude::*;

use super::delaunay::spherical_delaunay;
use super::locator::{Location, MeshLocator};
use super::sampling::{fibonacci_points, mean_spacing_rad};
use super::spherical::{angle_between, spherical_triangle_area, triple};

/// Smallest and largest sample counts the mesh supports.
pub const MIN_SAMPLES: usize = 1_000;
/// See [`MIN_SAMPLES`].
pub const MAX_SAMPLES: usize = 4_000_000;

/// Why a mesh could not be built.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// Sample count outside the supported range.
    #[error("sample count {0} is out of range: allowed {MIN_SAMPLES}..={MAX_SAMPLES}")]
    SampleCount(usize),
    /// The triangulation failed or came out inconsistent (a bug, reported rather than hidden).
    #[error("spherical triangulation failed: {0}")]
    Triangulation(String),
}

/// The reference mesh (a resource). Positions are unit vectors; areas are in km². Its data
/// ([`MeshData`], read through `Deref`) sits behind an `Arc`: a clone is cheap and shares it,
/// so work handed to a task off the schedule (the isostasy's trench) can read the mesh.
#[derive(Resource, Clone, Debug)]
pub struct SphereMesh(Arc<MeshData>);

/// What a [`SphereMesh`] holds.
#[derive(Clone, Debug)]
pub struct MeshData {
    /// Unit position of each sample.
    pub positions: Vec<DVec3>,
    /// Triangles as sample indices, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// CSR offsets into `neighbors` (length = samples + 1). Shared (an `Arc`) with the relief
    /// passes' graphs ([`crate::systems::relief::graph::ReliefGraph::from_shared`]), which would
    /// otherwise hold copies.
    pub neighbor_start: Arc<[u32]>,
    /// Neighbouring samples along triangle edges, ascending within each sample (shared like
    /// `neighbor_start`).
    pub neighbors: Arc<[u32]>,
    /// Area represented by each sample (a third of its incident spherical triangles), km²
    /// (shared like `neighbor_start`).
    pub area_km2: Arc<[f64]>,
    /// Planet radius, km.
    pub radius_km: f64,
    /// Longest triangle edge, radians.
    pub max_edge_rad: f64,
    locator: MeshLocator,
}

impl std::ops::Deref for SphereMesh {
    type Target = MeshData;

    #[inline]
    fn deref(&self) -> &MeshData {
        &self.0
    }
}

impl SphereMesh {
    /// Builds an `n`-sample Fibonacci mesh (jitter as a fraction of half the spacing, drawn from
    /// `seed`) on a sphere of radius `radius_km`.
    pub fn fibonacci(n: usize, jitter: f64, seed: u64, radius_km: f64) -> Result<Self, MeshError> {
        if !(MIN_SAMPLES..=MAX_SAMPLES).contains(&n) {
            return Err(MeshError::SampleCount(n));
        }
        let t = std::time::Instant::now();
        let positions = fibonacci_points(n, jitter, seed);
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "fibonacci points");
        Self::from_points(positions, radius_km)
    }

    /// Builds the mesh for arbitrary unit vectors (at least [`MIN_SAMPLES`] of them, spread
    /// over the whole sphere).
    pub fn from_points(positions: Vec<DVec3>, radius_km: f64) -> Result<Self, MeshError> {
        let n = positions.len();
        let t = std::time::Instant::now();
        let triangles = spherical_delaunay(&positions)
            .ok_or_else(|| MeshError::Triangulation("degenerate point set".into()))?;
        if triangles.len() != 2 * n - 4 {
            return Err(MeshError::Triangulation(format!(
                "{} triangles for {} samples, expected {}",
                triangles.len(),
                n,
                2 * n - 4
            )));
        }
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "delaunay");
        let t = std::time::Instant::now();
        // Adjacency (CSR). On a closed, consistently oriented triangulation every vertex has as
        // many neighbours as incident triangles, and each outgoing edge a→b appears in exactly one
        // triangle as "b follows a", so the neighbours come without sorting or deduplication.
        let mut neighbor_start = vec![0u32; n + 1];
        for t in &triangles {
            for &v in t {
                neighbor_start[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            neighbor_start[i + 1] += neighbor_start[i];
        }
        let mut fill: Vec<u32> = neighbor_start[..n].to_vec();
        let mut neighbors = vec![0u32; neighbor_start[n] as usize];
        for t in &triangles {
            for k in 0..3 {
                let a = t[k] as usize;
                neighbors[fill[a] as usize] = t[(k + 1) % 3];
                fill[a] += 1;
            }
        }
        drop(fill);
        {
            // Sort each vertex's neighbours (ascending) for deterministic iteration.
            let starts = &neighbor_start;
            let mut rest: &mut [u32] = &mut neighbors;
            let mut slices: Vec<&mut [u32]> = Vec::with_capacity(n);
            for i in 0..n {
                let len = (starts[i + 1] - starts[i]) as usize;
                let (head, tail) = rest.split_at_mut(len);
                slices.push(head);
                rest = tail;
            }
            slices
                .par_iter_mut()
                .with_min_len(4096)
                .for_each(|s| s.sort_unstable());
        }
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "adjacency");
        let t = std::time::Instant::now();
        let r2 = radius_km * radius_km;
        let per_triangle: Vec<(f64, f64)> = triangles
            .par_iter()
            .with_min_len(4096)
            .map(|t| {
                let (a, b, c) = (
                    positions[t[0] as usize],
                    positions[t[1] as usize],
                    positions[t[2] as usize],
                );
                let edge = angle_between(a, b)
                    .max(angle_between(b, c))
                    .max(angle_between(c, a));
                (spherical_triangle_area(a, b, c) * r2 / 3.0, edge)
            })
            .collect();
        let mut area_km2 = vec![0.0f64; n];
        let mut max_edge_rad = 0.0f64;
        for (t, &(third, edge)) in triangles.iter().zip(&per_triangle) {
            for &v in t {
                area_km2[v as usize] += third;
            }
            max_edge_rad = max_edge_rad.max(edge);
        }
        drop(per_triangle);
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "areas");
        let t = std::time::Instant::now();
        let locator = MeshLocator::build(&positions, &triangles);
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "locator");
        let t = std::time::Instant::now();
        let mesh = Self(Arc::new(MeshData {
            positions,
            triangles,
            neighbor_start: neighbor_start.into(),
            neighbors: neighbors.into(),
            area_km2: area_km2.into(),
            radius_km,
            max_edge_rad,
            locator,
        }));
        mesh.check_topology()?;
        tracing::debug!(ms = t.elapsed().as_secs_f64() * 1e3, "topology check");
        Ok(mesh)
    }

    /// The mesh's data, taken out of it (copied if another clone still shares it).
    pub fn into_data(self) -> MeshData {
        Arc::try_unwrap(self.0).unwrap_or_else(|shared| (*shared).clone())
    }

    /// Number of samples.
    #[inline]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True for a mesh without samples (never the case for a built mesh).
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Neighbours of sample `i`.
    #[inline]
    pub fn neighbors_of(&self, i: usize) -> &[u32] {
        &self.neighbors[self.neighbor_start[i] as usize..self.neighbor_start[i + 1] as usize]
    }

    /// Number of undirected edges.
    pub fn edge_count(&self) -> usize {
        self.neighbors.len() / 2
    }

    /// Euler characteristic V − E + F (2 for a closed sphere).
    pub fn euler_characteristic(&self) -> i64 {
        self.len() as i64 - self.edge_count() as i64 + self.triangles.len() as i64
    }

    /// Mean spacing between neighbouring samples, radians.
    pub fn mean_spacing_rad(&self) -> f64 {
        mean_spacing_rad(self.len())
    }

    /// Total area, km² (4πR² up to rounding).
    pub fn total_area_km2(&self) -> f64 {
        self.area_km2.iter().sum()
    }

    /// Locates unit vector `q` (in the reference frame) in exactly one triangle.
    #[inline]
    pub fn locate(&self, q: DVec3) -> Location {
        self.locator.locate(&self.positions, &self.triangles, q)
    }

    /// The vertex nearest unit vector `p`, by a greedy walk over the mesh from vertex `start`
    /// (each hop to the neighbour nearest `p`, while one is nearer than the vertex): on a
    /// Delaunay mesh the walk ends at the nearest vertex. Ties keep the vertex reached first.
    /// Cheap when `start` is near `p`; [`Self::nearest_vertex`] starts from the locator.
    pub fn nearest_vertex_from(&self, start: u32, p: DVec3) -> u32 {
        let pos = &self.positions;
        let mut cur = start;
        let mut best = pos[cur as usize].dot(p);
        loop {
            let mut next = cur;
            for &j in self.neighbors_of(cur as usize) {
                let d = pos[j as usize].dot(p);
                if d > best {
                    best = d;
                    next = j;
                }
            }
            if next == cur {
                return cur;
            }
            cur = next;
        }
    }

    /// The vertex nearest unit vector `p`: the walk of [`Self::nearest_vertex_from`] from the
    /// dominant corner of the triangle the locator finds under `p`.
    pub fn nearest_vertex(&self, p: DVec3) -> u32 {
        let l = self.locate(p);
        self.nearest_vertex_from(self.triangles[l.triangle as usize][l.dominant_corner()], p)
    }

    /// The point locator (grid cells over the triangles).
    pub fn locator(&self) -> &MeshLocator {
        &self.locator
    }

    /// Bytes held on the heap by the mesh.
    pub fn heap_bytes(&self) -> usize {
        self.positions.capacity() * 24
            + self.triangles.capacity() * 12
            + (self.neighbor_start.len() + self.neighbors.len()) * 4
            + self.area_km2.len() * 8
            + self.locator.heap_bytes()
    }

    /// Verifies orientation, Euler characteristic and that every edge borders two triangles.
    fn check_topology(&self) -> Result<(), MeshError> {
        let bad = self.triangles.par_iter().filter(|t| {
            let (a, b, c) = (
                self.positions[t[0] as usize],
                self.positions[t[1] as usize],
                self.positions[t[2] as usize],
            );
            triple(a, b, c).partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        });
        let n_bad = bad.count();
        if n_bad > 0 {
            return Err(MeshError::Triangulation(format!(
                "{n_bad} triangles are not oriented outward"
            )));
        }
        if self.euler_characteristic() != 2 {
            return Err(MeshError::Triangulation(format!(
                "Euler characteristic {}",
                self.euler_characteristic()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_greedy_walk_finds_the_nearest_vertex() {
        let m = SphereMesh::fibonacci(20_000, 0.5, 3, 6370.0).expect("mesh");
        let mut rng = 12345u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for k in 0..200 {
            let p = DVec3::new(next(), next(), next()).normalize();
            let start = (k * 97 % m.len()) as u32;
            let best = (0..m.len())
                .max_by(|&a, &b| m.positions[a].dot(p).total_cmp(&m.positions[b].dot(p)))
                .unwrap();
            for walked in [m.nearest_vertex_from(start, p), m.nearest_vertex(p)] {
                assert_eq!(
                    m.positions[walked as usize].dot(p),
                    m.positions[best].dot(p),
                    "point {k}: walked to {walked}, nearest is {best}"
                );
            }
        }
    }

    #[test]
    fn orientation_and_euler_characteristic_at_several_sizes() {
        for &(n, jitter) in &[
            (1000, 0.0),
            (1000, 0.5),
            (12_345, 0.3),
            (100_000, 0.0),
            (100_000, 0.9),
        ] {
            let m = SphereMesh::fibonacci(n, jitter, 7, 6370.0).expect("mesh");
            assert_eq!(m.euler_characteristic(), 2, "n={n}");
            assert_eq!(m.triangles.len(), 2 * n - 4);
            // Every directed edge appears exactly once across triangles: a closed, consistently
            // oriented surface.
            let mut directed: Vec<(u32, u32)> = m
                .triangles
                .iter()
                .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
                .collect();
            directed.sort_unstable();
            let before = directed.len();
            directed.dedup();
            assert_eq!(
                before,
                directed.len(),
                "a directed edge repeats: orientation flipped somewhere"
            );
            for t in &m.triangles {
                let (a, b, c) = (
                    m.positions[t[0] as usize],
                    m.positions[t[1] as usize],
                    m.positions[t[2] as usize],
                );
                assert!(triple(a, b, c) > 0.0);
            }
            let area = m.total_area_km2();
            let sphere = 4.0 * std::f64::consts::PI * 6370.0f64.powi(2);
            assert!(
                (area - sphere).abs() / sphere < 1e-9,
                "area {area} vs {sphere}"
            );
        }
    }

    #[test]
    fn delaunay_property_holds() {
        // No sample lies strictly inside the circumcircle of a triangle: check each triangle's
        // neighbours across its edges (local Delaunay implies global).
        let m = SphereMesh::fibonacci(5000, 0.6, 3, 1.0).expect("mesh");
        for t in &m.triangles {
            let (a, b, c) = (
                m.positions[t[0] as usize],
                m.positions[t[1] as usize],
                m.positions[t[2] as usize],
            );
            let n = (b - a).cross(c - a).normalize();
            let d = n.dot(a);
            for &v in t {
                for &w in m.neighbors_of(v as usize) {
                    if t.contains(&w) {
                        continue;
                    }
                    assert!(
                        n.dot(m.positions[w as usize]) <= d + 1e-12,
                        "sample {w} inside circumcircle"
                    );
                }
            }
        }
    }

    #[test]
    fn bad_sample_counts_are_rejected() {
        assert!(matches!(
            SphereMesh::fibonacci(999, 0.0, 1, 1.0),
            Err(MeshError::SampleCount(999))
        ));
        assert!(matches!(
            SphereMesh::fibonacci(4_000_001, 0.0, 1, 1.0),
            Err(MeshError::SampleCount(_))
        ));
    }

    #[test]
    fn every_point_lands_in_exactly_one_containing_triangle() {
        let m = SphereMesh::fibonacci(3000, 0.4, 11, 1.0).expect("mesh");
        let mut probes: Vec<DVec3> = m.positions.clone();
        for t in m.triangles.iter().take(500) {
            let (a, b, c) = (
                m.positions[t[0] as usize],
                m.positions[t[1] as usize],
                m.positions[t[2] as usize],
            );
            probes.push((a + b).normalize()); // on an edge
            probes.push((a + b + c).normalize()); // inside
        }
        for i in 0..20_000u64 {
            probes.push(crate::random::unit_vector(
                crate::random::hash3(1, 2, i),
                crate::random::hash3(1, 3, i),
            ));
        }
        for q in probes {
            let loc = m.locate(q);
            let t = m.triangles[loc.triangle as usize];
            let (a, b, c) = (
                m.positions[t[0] as usize],
                m.positions[t[1] as usize],
                m.positions[t[2] as usize],
            );
            assert!(loc.weights.iter().all(|&w| w >= -1e-9), "{loc:?}");
            assert!((loc.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let rebuilt =
                (a * loc.weights[0] + b * loc.weights[1] + c * loc.weights[2]).normalize();
            assert!((rebuilt - q).length() < 1e-9);
            // Deterministic: the same point always gives the same triangle.
            assert_eq!(m.locate(q), loc);
        }
        // A sample sits at a vertex of its triangle with weight 1.
        for (i, &p) in m.positions.iter().enumerate().take(500) {
            let loc = m.locate(p);
            let t = m.triangles[loc.triangle as usize];
            let k = loc.dominant_corner();
            assert_eq!(t[k] as usize, i);
            assert!((loc.weights[k] - 1.0).abs() < 1e-12);
        }
    }
}
