//! Spherical Delaunay triangulation: stereographic projection from one sample, planar Delaunay
//! (`delaunator`) of the others, and a fan from the planar convex hull back to the projection
//! sample. Stereographic projection maps circles to circles, so the empty-circumcircle property
//! carries over and the result is the exact spherical Delaunay triangulation.

use glam::DVec3;

use super::spherical::{tangent_basis, triple};

/// Triangulates unit vectors `points` (at least 4, not all on one great circle). Triangles are
/// oriented counter-clockwise seen from outside (positive triple product).
pub fn spherical_delaunay(points: &[DVec3]) -> Option<Vec<[u32; 3]>> {
    if points.len() < 4 {
        return None;
    }
    // Project from the sample closest to the north pole.
    let pole_index = points
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.z.total_cmp(&b.1.z))
        .map(|(i, _)| i)?;
    let pole = points[pole_index];
    let (e1, e2) = tangent_basis(pole);
    let mut planar = Vec::with_capacity(points.len() - 1);
    let mut back = Vec::with_capacity(points.len() - 1);
    for (i, &q) in points.iter().enumerate() {
        if i == pole_index {
            continue;
        }
        let denom = 1.0 - q.dot(pole);
        if denom <= 0.0 {
            return None; // duplicate of the pole
        }
        planar.push(delaunator::Point {
            x: q.dot(e1) / denom,
            y: q.dot(e2) / denom,
        });
        back.push(i as u32);
    }
    let tri = delaunator::triangulate(&planar);
    if tri.triangles.is_empty() || tri.hull.len() < 3 {
        return None;
    }
    let orient = |mut t: [u32; 3]| {
        let (a, b, c) = (
            points[t[0] as usize],
            points[t[1] as usize],
            points[t[2] as usize],
        );
        if triple(a, b, c) < 0.0 {
            t.swap(1, 2);
        }
        t
    };
    let mut out = Vec::with_capacity(tri.triangles.len() / 3 + tri.hull.len());
    for t in tri.triangles.chunks_exact(3) {
        out.push(orient([back[t[0]], back[t[1]], back[t[2]]]));
    }
    let h = tri.hull.len();
    for k in 0..h {
        let a = back[tri.hull[k]];
        let b = back[tri.hull[(k + 1) % h]];
        out.push(orient([a, b, pole_index as u32]));
    }
    Some(out)
}
