//! Point location at 500,000 samples: the cube-map grid (`MeshLocator`, what the resampling and
//! the exports use) against an obvhs BVH over the same triangles (issue 17 item 4), on the same
//! queries, back to back, medians of five. Also checks that both find the same triangle.
//!
//! `cargo run --release --example locate_bvh_bench [SAMPLES]`
use std::time::{Duration, Instant};

use glam::{DMat3, DVec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use rayon::prelude::*;
use tectonic_planets::geometry::SphereMesh;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The triangle of `candidates` that `q` lies inside (weights ≥ −1e-12), first found.
fn inside(m: &SphereMesh, q: DVec3, t: u32) -> bool {
    let tri = m.triangles[t as usize];
    let (a, b, c) = (
        m.positions[tri[0] as usize],
        m.positions[tri[1] as usize],
        m.positions[tri[2] as usize],
    );
    let (wa, wb, wc) = (q.dot(b.cross(c)), q.dot(c.cross(a)), q.dot(a.cross(b)));
    let s = wa + wb + wc;
    s > 0.0 && wa / s >= -1e-12 && wb / s >= -1e-12 && wc / s >= -1e-12
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(500_000);
    let m = SphereMesh::fibonacci(n, 0.3, 1, 6370.0).unwrap();
    // Queries as the resampling makes them: every sample, in a frame turned by 0.2 rad.
    let rot = DMat3::from_axis_angle(DVec3::new(0.3, 0.4, 0.8).normalize(), 0.2);
    let queries: Vec<DVec3> = m.positions.iter().map(|&p| rot * p).collect();
    println!(
        "{} samples, {} triangles, {} queries, {} threads",
        m.len(),
        m.triangles.len(),
        queries.len(),
        rayon::current_num_threads()
    );

    // The BVH: one box per triangle, padded by the bulge of the sphere over it, so that every
    // point of the sphere above the triangle is in its box.
    let boxes_of = |m: &SphereMesh| -> Vec<Aabb> {
        m.triangles
            .par_iter()
            .map(|t| {
                let v = [
                    m.positions[t[0] as usize],
                    m.positions[t[1] as usize],
                    m.positions[t[2] as usize],
                ];
                let c = (v[0] + v[1] + v[2]).normalize();
                let cos = v.iter().map(|p| p.dot(c)).fold(1.0f64, f64::min);
                let pad = (1.0 - cos) as f32 + 1e-6;
                let mut lo = Vec3A::splat(f32::MAX);
                let mut hi = Vec3A::splat(f32::MIN);
                for p in v.iter().chain(std::iter::once(&c)) {
                    let p = Vec3A::new(p.x as f32, p.y as f32, p.z as f32);
                    lo = lo.min(p);
                    hi = hi.max(p);
                }
                Aabb::new(lo - pad, hi + pad)
            })
            .collect()
    };
    let (mut build_ms, mut bvh) = (Vec::new(), None);
    for _ in 0..5 {
        let t = Instant::now();
        let boxes = boxes_of(&m);
        let b = build_bvh2(
            &boxes,
            BvhBuildParams::fast_build(),
            &mut Duration::default(),
        );
        build_ms.push(t.elapsed().as_secs_f64() * 1e3);
        bvh = Some(b);
    }
    let bvh = bvh.unwrap();
    let bvh_locate = |q: DVec3| -> u32 {
        let p = Vec3A::new(q.x as f32, q.y as f32, q.z as f32);
        let mut found = u32::MAX;
        bvh.point_traverse(p, |b, node| {
            let node = &b.nodes[node as usize];
            for k in node.first_index..node.first_index + node.prim_count {
                let t = b.primitive_indices[k as usize];
                if inside(&m, q, t) {
                    found = t;
                    return false;
                }
            }
            true
        });
        found
    };
    let t = Instant::now();
    let grid_build = tectonic_planets::geometry::MeshLocator::build(&m.positions, &m.triangles);
    let grid_build_ms = t.elapsed().as_secs_f64() * 1e3;
    drop(grid_build);

    let (mut grid_par, mut grid_seq, mut bvh_par, mut bvh_seq) = (vec![], vec![], vec![], vec![]);
    for _ in 0..5 {
        let t = Instant::now();
        let a: Vec<u32> = queries.par_iter().map(|&q| m.locate(q).triangle).collect();
        grid_par.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let b: Vec<u32> = queries.par_iter().map(|&q| bvh_locate(q)).collect();
        bvh_par.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let s: u64 = queries.iter().map(|&q| m.locate(q).triangle as u64).sum();
        grid_seq.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let s2: u64 = queries.iter().map(|&q| bvh_locate(q) as u64).sum();
        bvh_seq.push(t.elapsed().as_secs_f64() * 1e3);
        // The same triangle, except where a point lies on an edge (both are then right).
        let differ = a
            .iter()
            .zip(&b)
            .zip(&queries)
            .filter(|((x, y), q)| x != y && !(**y != u32::MAX && inside(&m, **q, **x)))
            .count();
        let missed = b.iter().filter(|&&t| t == u32::MAX).count();
        assert_eq!(
            differ, 0,
            "the BVH found another triangle for {differ} queries"
        );
        assert_eq!(missed, 0, "the BVH found no triangle for {missed} queries");
        std::hint::black_box((s, s2));
    }
    println!(
        "build: grid {grid_build_ms:.1} ms, BVH {:.1} ms (median)",
        median(build_ms)
    );
    println!(
        "queries, all threads: grid {:.1} ms, BVH {:.1} ms (medians of 5)",
        median(grid_par),
        median(bvh_par)
    );
    println!(
        "queries, one thread:  grid {:.1} ms, BVH {:.1} ms (medians of 5)",
        median(grid_seq),
        median(bvh_seq)
    );
}
