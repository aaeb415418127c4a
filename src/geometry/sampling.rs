//! Fibonacci sampling of the unit sphere, with optional seeded jitter, reordered along a
//! space-filling curve so that samples close in index are close on the sphere (cache locality
//! for every per-sample pass).

use glam::DVec3;
use rayon::prelude::*;

use super::locator::cube_face_uv;
use super::spherical::tangent_basis;
use crate::random::{hash3, stream, unit_f64};

/// Mean great-circle spacing (radians) between neighbouring samples of an `n`-point sphere.
pub fn mean_spacing_rad(n: usize) -> f64 {
    (4.0 * std::f64::consts::PI / n as f64).sqrt()
}

/// `n` Fibonacci points on the unit sphere. Each point is displaced in its tangent plane by up
/// to `jitter` × half the mean spacing, in a direction and by an amount drawn from `seed`; then
/// the points are sorted along a cube-face Morton curve.
pub fn fibonacci_points(n: usize, jitter: f64, seed: u64) -> Vec<DVec3> {
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let max_offset = jitter.clamp(0.0, 0.95) * 0.5 * mean_spacing_rad(n);
    let mut pts: Vec<DVec3> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden_angle * i as f64;
            let p = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            if max_offset > 0.0 {
                let (e1, e2) = tangent_basis(p);
                let theta =
                    std::f64::consts::TAU * unit_f64(hash3(seed, stream::JITTER, 2 * i as u64));
                // sqrt gives a uniform distribution over the disc of radius max_offset.
                let d = max_offset * unit_f64(hash3(seed, stream::JITTER, 2 * i as u64 + 1)).sqrt();
                (p * d.cos() + (e1 * theta.cos() + e2 * theta.sin()) * d.sin()).normalize()
            } else {
                p
            }
        })
        .collect();
    let mut keyed: Vec<(u64, usize)> = pts
        .par_iter()
        .enumerate()
        .map(|(i, &p)| (morton_key(p), i))
        .collect();
    keyed.par_sort_unstable();
    let sorted: Vec<DVec3> = keyed.iter().map(|&(_, i)| pts[i]).collect();
    pts.clear();
    sorted
}

/// Cube face in the top bits, then the interleaved bits of the 21-bit face coordinates.
pub fn morton_key(p: DVec3) -> u64 {
    let (face, u, v) = cube_face_uv(p);
    let q = |t: f64| (((t + 1.0) * 0.5).clamp(0.0, 1.0) * ((1u64 << 21) - 1) as f64) as u64;
    ((face as u64) << 61) | (spread_bits(q(u)) << 1) | spread_bits(q(v))
}

fn spread_bits(mut x: u64) -> u64 {
    x &= 0x1f_ffff;
    x = (x | (x << 16)) & 0x0000_ffff_0000_ffff;
    x = (x | (x << 8)) & 0x00ff_00ff_00ff_00ff;
    x = (x | (x << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
    x = (x | (x << 2)) & 0x3333_3333_3333_3333;
    x = (x | (x << 1)) & 0x5555_5555_5555_5555;
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_are_unit_distinct_and_cover_the_sphere() {
        let pts = fibonacci_points(5000, 0.5, 3);
        assert_eq!(pts.len(), 5000);
        let mut mean = DVec3::ZERO;
        for p in &pts {
            assert!((p.length() - 1.0).abs() < 1e-12);
            mean += *p;
        }
        assert!((mean / 5000.0).length() < 0.01);
    }

    #[test]
    fn jitter_depends_on_seed_only_when_enabled() {
        let a = fibonacci_points(2000, 0.0, 1);
        let b = fibonacci_points(2000, 0.0, 2);
        assert_eq!(a, b);
        let c = fibonacci_points(2000, 0.5, 1);
        let d = fibonacci_points(2000, 0.5, 2);
        assert_ne!(c, d);
    }

    #[test]
    fn sort_gives_locality() {
        let pts = fibonacci_points(20_000, 0.3, 1);
        let spacing = mean_spacing_rad(pts.len());
        let mean_step: f64 =
            pts.windows(2).map(|w| (w[0] - w[1]).length()).sum::<f64>() / (pts.len() - 1) as f64;
        assert!(
            mean_step < 4.0 * spacing,
            "mean step {mean_step} vs spacing {spacing}"
        );
    }
}
