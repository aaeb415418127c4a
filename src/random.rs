//! Deterministic randomness: stateless hashing (for per-plate and per-position draws that do not
//! depend on sample indices or thread count), a small seedable generator for sequential draws,
//! and 3D gradient noise evaluated on the sphere.

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// SplitMix64 finaliser: a strong 64-bit mixing function.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hashes a seed with a stream tag and an index into 64 well-mixed bits.
#[inline]
pub fn hash3(seed: u64, stream: u64, index: u64) -> u64 {
    mix64(mix64(seed ^ mix64(stream.wrapping_add(0x9e37_79b9_7f4a_7c15))).wrapping_add(index))
}

/// Maps 64 random bits to a uniform float in [0, 1).
#[inline]
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Named random streams, so that adding a new use of randomness never shifts another one.
pub mod stream {
    /// Sample jitter of the Fibonacci points.
    pub const JITTER: u64 = 1;
    /// Plate centroids.
    pub const PLATE_CENTROID: u64 = 2;
    /// Plate Euler poles and speeds.
    pub const PLATE_MOTION: u64 = 3;
    /// Plate continental bias.
    pub const PLATE_CONTINENT: u64 = 4;
    /// Random rifting events (one generator per step).
    pub const RIFT: u64 = 5;
    /// Rifts asked for by commands (fragment centroids, divergence jitter).
    pub const RIFT_COMMAND: u64 = 6;
    /// Impact craters of the initial planet (centres and radii).
    pub const CRATER: u64 = 7;
    /// The pelagic rain's rate field (`sediment.pelagic_variability`).
    pub const PELAGIC: u64 = 8;
    /// Noise fields (each field adds its own offset).
    pub const NOISE: u64 = 100;
}

/// A uniformly distributed unit vector from two random words.
pub fn unit_vector(bits_a: u64, bits_b: u64) -> DVec3 {
    let z = 2.0 * unit_f64(bits_a) - 1.0;
    let phi = std::f64::consts::TAU * unit_f64(bits_b);
    let r = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A small seedable generator (SplitMix64 sequence) for sequential draws such as random events.
/// Its whole state is one `u64`, so it saves and restores exactly.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SimRng {
    state: u64,
}

impl SimRng {
    /// A generator for `seed` and a named stream.
    pub fn new(seed: u64, stream: u64) -> Self {
        Self {
            state: hash3(seed, stream, 0),
        }
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }
    /// Uniform float in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }
}

#[inline]
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn lattice_gradient(seed: u64, x: i64, y: i64, z: i64) -> DVec3 {
    let h = mix64(
        seed ^ mix64(
            (x as u64).wrapping_mul(0x8da6_b343)
                ^ (y as u64).wrapping_mul(0xd816_3841)
                ^ (z as u64).wrapping_mul(0xcb1a_b31f),
        ),
    );
    // 12 edge directions of a cube (improved Perlin noise), chosen by hash.
    const G: [[f64; 3]; 12] = [
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
        [-1.0, 0.0, -1.0],
        [0.0, 1.0, 1.0],
        [0.0, -1.0, 1.0],
        [0.0, 1.0, -1.0],
        [0.0, -1.0, -1.0],
    ];
    let g = G[(h % 12) as usize];
    DVec3::new(g[0], g[1], g[2])
}

/// 3D gradient (Perlin) noise in roughly [-1, 1], hashed from `seed` (no permutation table, so
/// every seed gives an independent field).
pub fn gradient_noise(seed: u64, p: DVec3) -> f64 {
    let base = p.floor();
    let (ix, iy, iz) = (base.x as i64, base.y as i64, base.z as i64);
    let f = p - base;
    let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
    let mut corners = [0.0f64; 8];
    for (k, c) in corners.iter_mut().enumerate() {
        let (dx, dy, dz) = ((k & 1) as i64, ((k >> 1) & 1) as i64, ((k >> 2) & 1) as i64);
        let g = lattice_gradient(seed, ix + dx, iy + dy, iz + dz);
        *c = g.dot(f - DVec3::new(dx as f64, dy as f64, dz as f64));
    }
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corners[0], corners[1], u);
    let x10 = lerp(corners[2], corners[3], u);
    let x01 = lerp(corners[4], corners[5], u);
    let x11 = lerp(corners[6], corners[7], u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// Fractal sum of gradient noise on the unit sphere. `wavelength_rad` is the wavelength of the
/// first octave as a great-circle angle; each octave halves the wavelength and the amplitude.
/// The result is normalised to roughly [-1, 1].
pub fn fbm(seed: u64, p: DVec3, wavelength_rad: f64, octaves: u32) -> f64 {
    let mut freq = 1.0 / wavelength_rad.max(1e-6);
    let mut amp = 1.0;
    let mut sum = 0.0;
    let mut norm = 0.0;
    for o in 0..octaves {
        sum += amp * gradient_noise(mix64(seed.wrapping_add(o as u64)), p * freq);
        norm += amp;
        freq *= 2.0;
        amp *= 0.5;
    }
    // Perlin noise rarely exceeds ±0.7; rescale so the fractal sum spans about [-1, 1].
    (sum / norm * 1.5).clamp(-1.0, 1.0)
}

/// A smooth tangent vector field on the sphere (three independent fBm fields, projected onto the
/// tangent plane at `p`), with components roughly in [-1, 1].
pub fn vector_fbm(seed: u64, p: DVec3, wavelength_rad: f64, octaves: u32) -> DVec3 {
    let v = DVec3::new(
        fbm(mix64(seed ^ 1), p, wavelength_rad, octaves),
        fbm(mix64(seed ^ 2), p, wavelength_rad, octaves),
        fbm(mix64(seed ^ 3), p, wavelength_rad, octaves),
    );
    v - p * p.dot(v)
}

/// A stable 64-bit FNV-1a-style hasher over bytes, for crust hashes that must not change between
/// Rust versions or platforms.
#[derive(Clone, Debug)]
pub struct StableHasher(u64);

impl Default for StableHasher {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl StableHasher {
    /// Feeds bytes.
    pub fn write(&mut self, bytes: &[u8]) {
        // Process 8 bytes at a time through the mixer for speed, then the tail bytewise.
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            let w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
            self.0 = mix64(self.0 ^ w);
        }
        for &b in chunks.remainder() {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    /// Feeds one u64.
    pub fn write_u64(&mut self, v: u64) {
        self.write(&v.to_le_bytes());
    }
    /// The hash so far.
    pub fn finish(&self) -> u64 {
        mix64(self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_deterministic_bounded_and_seed_dependent() {
        let p = DVec3::new(0.3, -0.2, 0.93).normalize();
        let a = fbm(7, p, 0.5, 5);
        assert_eq!(a, fbm(7, p, 0.5, 5));
        assert_ne!(a, fbm(8, p, 0.5, 5));
        for i in 0..1000 {
            let q = unit_vector(hash3(1, 9, i), hash3(2, 9, i));
            let v = fbm(3, q, 0.3, 6);
            assert!((-1.0..=1.0).contains(&v));
        }
    }

    #[test]
    fn noise_is_continuous() {
        let p = DVec3::new(0.1, 0.7, 0.2).normalize();
        let q = (p + DVec3::new(1e-7, 0.0, 0.0)).normalize();
        assert!((fbm(5, p, 0.4, 4) - fbm(5, q, 0.4, 4)).abs() < 1e-4);
    }

    #[test]
    fn unit_vectors_are_unit_and_spread() {
        let mut mean = DVec3::ZERO;
        for i in 0..10_000 {
            let v = unit_vector(hash3(5, 1, i), hash3(5, 2, i));
            assert!((v.length() - 1.0).abs() < 1e-12);
            mean += v;
        }
        assert!((mean / 10_000.0).length() < 0.03);
    }

    #[test]
    fn rng_sequence_is_reproducible() {
        let mut a = SimRng::new(42, 1);
        let mut b = SimRng::new(42, 1);
        let xs: Vec<u64> = (0..5).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..5).map(|_| b.next_u64()).collect();
        assert_eq!(xs, ys);
        assert_ne!(SimRng::new(43, 1).next_u64(), xs[0]);
    }
}
