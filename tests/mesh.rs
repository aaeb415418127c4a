//! The reference mesh at the ends of the supported range: a closed, outward-oriented sphere
//! (Euler characteristic 2) with exact total area.

use tectonic_planets::geometry::{SphereMesh, triple};

fn check(n: usize, jitter: f64) {
    let m = SphereMesh::fibonacci(n, jitter, 1, 6370.0).expect("mesh");
    assert_eq!(m.len(), n);
    assert_eq!(m.euler_characteristic(), 2, "n = {n}");
    assert_eq!(m.triangles.len(), 2 * n - 4);
    let inward = m
        .triangles
        .iter()
        .filter(|t| {
            triple(
                m.positions[t[0] as usize],
                m.positions[t[1] as usize],
                m.positions[t[2] as usize],
            ) <= 0.0
        })
        .count();
    assert_eq!(
        inward, 0,
        "n = {n}: {inward} triangles not oriented outward"
    );
    let sphere = 4.0 * std::f64::consts::PI * 6370.0f64.powi(2);
    assert!((m.total_area_km2() - sphere).abs() / sphere < 1e-9);
    // Every sample has at least three neighbours and a positive area.
    for i in 0..n {
        assert!(m.neighbors_of(i).len() >= 3);
        assert!(m.area_km2[i] > 0.0);
    }
}

#[test]
fn smallest_mesh() {
    check(1_000, 0.0);
    check(1_000, 0.9);
}

#[test]
fn largest_mesh() {
    check(4_000_000, 0.3);
}
