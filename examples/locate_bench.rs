//! Micro-benchmark of the point locator: 500,000 point queries in a rotated frame.
use rayon::prelude::*;
use std::time::Instant;
use tectonic_planets::geometry::SphereMesh;
fn main() {
    let m = SphereMesh::fibonacci(500_000, 0.3, 1, 6370.0).unwrap();
    let rot = glam::DMat3::from_axis_angle(glam::DVec3::new(0.3, 0.4, 0.8).normalize(), 0.2);
    for _ in 0..3 {
        let t = Instant::now();
        let s: u64 = m
            .positions
            .par_iter()
            .map(|&p| m.locate(rot * p).triangle as u64)
            .sum();
        println!(
            "par locate: {:.1} ms ({s})",
            t.elapsed().as_secs_f64() * 1e3
        );
        let t = Instant::now();
        let s: u64 = m
            .positions
            .iter()
            .map(|&p| m.locate(rot * p).triangle as u64)
            .sum();
        println!(
            "seq locate: {:.1} ms ({s})",
            t.elapsed().as_secs_f64() * 1e3
        );
        let t = Instant::now();
        let s: usize = m
            .positions
            .iter()
            .map(|&p| m.locator().cell_of(rot * p))
            .sum();
        println!(
            "seq cell_of: {:.1} ms ({s})",
            t.elapsed().as_secs_f64() * 1e3
        );
    }
    let avg: f64 = (0..m.locator().cell_count())
        .map(|c| m.locator().cell_triangles(c).len() as f64)
        .sum::<f64>()
        / m.locator().cell_count() as f64;
    println!("avg triangles per cell {avg:.2}");
}
