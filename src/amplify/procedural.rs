//! Procedural amplification (paper §5, Fig. 11): the detailed elevation at one point from the
//! three crust samples around it, as a pure per-point function over flat tables.
//!
//! Every crust sample (a mesh vertex) carries a relief *primitive*: a noise field laid out in
//! the sample's own tangent frame, with its grain along the sample's ridge direction (oceanic
//! crust) or fold direction (continental crust), shifted by a random offset drawn from the
//! seed and the sample's position. The relief at a point is the blend of the primitives of the
//! three corners of the triangle that contains it, weighted by `max(w − 0.2, 0)` (w the
//! barycentric weight) and normalised by `sqrt(Σ w'²)` so the blend keeps the primitives'
//! variance. The weights are continuous across triangle edges, so the blend is too, and most
//! points need only one or two primitives. On top comes one isotropic gradient-noise layer
//! for detail, whose amplitude is blended the same way.
//!
//! * Oceanic crust (the vertex axis is the ridge direction: x along the ridge axis, y along
//!   the spreading direction): abyssal hills elongated *parallel to* the ridge (correlation
//!   length 5× longer along it than across it), as on Earth, cut by transform-fault troughs
//!   that run across the ridge every ~60 km along it (jittered), each segment between two
//!   faults offset across the ridge; all stronger where the crust is young
//!   (`0.25 + 0.75·exp(-age/50 My)`).
//! * Continental plains: gentle isotropic relief (±90 m).
//! * Mountains (the vertex axis is the fold direction, which is the direction of compression,
//!   paper §4.1: x along `compression_dir`, y along `range_axis`): ridged noise whose crests run
//!   along the range axis (3× longer along it than across for Andean ranges, 2.5× for
//!   Himalayan ones, which are also higher and sharper), so a range's crests run along it and
//!   wrap a sutured terrane (whose fold direction points away from it) in arcs; the amplitude
//!   follows the crust's elevation, and old ranges are lower and smoother
//!   (`exp(-orogeny age/150 My)` fades the ridged part toward rounded noise).
//!
//! The value depends only on the seed, the tables and the point: never on the output size,
//! the tiling or the thread count. Arithmetic is in `f32` so that `shaders/amplify.wgsl` can
//! mirror it line for line (keep both in sync).

pub use crate::gpu::amplify::{AmplifyQuery, AmplifyUniform, AmplifyVertex};

/// Crust sample kind: oceanic crust.
pub const KIND_OCEAN: u32 = 0;
/// Crust sample kind: continental crust outside any orogeny.
pub const KIND_PLAIN: u32 = 1;
/// Crust sample kind: continental crust raised by subduction.
pub const KIND_ANDEAN: u32 = 2;
/// Crust sample kind: continental crust raised by a collision.
pub const KIND_HIMALAYAN: u32 = 3;

/// Largest relief (detail included) added to or taken from the crust elevation, metres. The
/// amplified elevation always lies within the crust's range widened by this much, which lets
/// 16-bit exports fix their grey scale before the first row is computed.
pub const MAX_RELIEF_M: f32 = 4000.0;

// Relief constants (metres, km, My). Keep in sync with shaders/amplify.wgsl.
const OCEAN_HILL_WAVELENGTH_KM: f32 = 5.0;
const OCEAN_HILL_STRETCH: f32 = 5.0;
/// Abyssal hills: about 150 m rms on young floor (observed 50–300 m, Goff & Jordan 1988).
const OCEAN_HILL_AMP_M: f32 = 660.0;
const OCEAN_YOUNG_AGE_MY: f32 = 50.0;
const FAULT_SPACING_KM: f32 = 60.0;
const FAULT_WIDTH_KM: f32 = 4.0;
const FAULT_DEPTH_M: f32 = 300.0;
const FAULT_OFFSET_KM: f32 = 2.0;
const OCEAN_DETAIL_M: f32 = 20.0;
/// Depth over which the sea floor's relief grows to its full amplitude, metres: abyssal hills
/// stand on the deep floor; floor filled with sediment to near the sea is flat, and its hills do
/// not break the surface as specks of land.
const OCEAN_FULL_DEPTH_M: f32 = 2000.0;
const PLAIN_WAVELENGTH_KM: f32 = 30.0;
const PLAIN_AMP_M: f32 = 90.0;
const PLAIN_DETAIL_M: f32 = 12.0;
/// Crust elevation over which a plain's relief grows to its full amplitude, metres: low plains
/// (coastal plains, deltas, basins filled to near the sea, shelves) are flat, and their noise
/// does not dip under the sea as specks of water.
const PLAIN_FULL_HEIGHT_M: f32 = 300.0;
/// Least share of its full amplitude a plain keeps (at and below sea level).
const PLAIN_LOW_SHARE: f32 = 0.05;
const ANDEAN_WAVELENGTH_KM: f32 = 14.0;
const ANDEAN_STRETCH: f32 = 3.0;
const ANDEAN_AMP_M: f32 = 1300.0;
const HIMALAYAN_WAVELENGTH_KM: f32 = 18.0;
const HIMALAYAN_STRETCH: f32 = 2.5;
const HIMALAYAN_AMP_M: f32 = 1900.0;
const MOUNTAIN_FULL_HEIGHT_M: f32 = 3000.0;
const OROGENY_OLD_AGE_MY: f32 = 150.0;
const MOUNTAIN_DETAIL_FRACTION: f32 = 0.05;
const DETAIL_WAVELENGTH_KM: f32 = 0.8;
/// Taken off each barycentric weight to get the primitive's blending weight (negative: not
/// evaluated). Below 1/3, so at least one primitive always remains.
const BLEND_CUT: f32 = 0.2;
/// [`BLEND_CUT`] for a vertex with an exemplar: narrower blends between exemplars, whose
/// overlaps make closed hollows (docs/amplification.md, "Exemplar-based").
const EXEMPLAR_BLEND_CUT: f32 = 0.3;
/// Mean of `ridge(n) = (1 - |n|)²` over gradient noise, measured (see the test
/// `ridged_noise_is_centred`), subtracted so that blended primitives have zero mean.
const RIDGE_MEAN: f32 = 0.62;

/// 32-bit integer hash (lowbias32); WGSL has the same wrapping `u32` arithmetic.
#[inline]
pub fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A hash mapped to [0, 1).
#[inline]
fn hash01(x: u32) -> f32 {
    (hash_u32(x) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// `floor` as (float, int) without a libm call (the baseline x86-64 target has no SSE4.1
/// `roundss`); exact for |x| < 2³¹, which every noise coordinate here is. WGSL: `floor`.
#[inline]
fn floor_i(x: f32) -> (f32, i32) {
    let t = x as i32;
    let i = if (t as f32) > x { t - 1 } else { t };
    (i as f32, i)
}

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn mix(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

#[inline]
fn grad2(h: u32, x: f32, y: f32) -> f32 {
    // Eight directions: the axes and the diagonals (scaled to unit length). A table instead of
    // a `match`: the direction is random, so branches on it are mispredicted half the time.
    // The same bits as `D * (x + y)` and the like: adding a zero term or multiplying by one
    // is exact.
    const D: f32 = std::f32::consts::FRAC_1_SQRT_2;
    const G: [(f32, f32, f32); 8] = [
        (1.0, 0.0, 1.0),
        (-1.0, 0.0, 1.0),
        (0.0, 1.0, 1.0),
        (0.0, -1.0, 1.0),
        (1.0, 1.0, D),
        (1.0, -1.0, D),
        (-1.0, 1.0, D),
        (-1.0, -1.0, D),
    ];
    let (a, b, k) = G[(h & 7) as usize];
    k * (a * x + b * y)
}

#[inline]
fn corner2(seed: u32, ix: i32, iy: i32) -> u32 {
    hash_u32((ix as u32).wrapping_mul(0x8da6_b343) ^ (iy as u32).wrapping_mul(0xd816_3841) ^ seed)
}

/// The gradient index (`grad2` reads three bits) of each corner of the 2D noise cell whose
/// lowest corner is (`ix`, `iy`), in the order (0, 0), (1, 0), (0, 1), (1, 1).
#[inline]
fn corners2(seed: u32, ix: i32, iy: i32) -> [u8; 4] {
    let h = |dx: i32, dy: i32| (corner2(seed, ix + dx, iy + dy) & 7) as u8;
    [h(0, 0), h(1, 0), h(0, 1), h(1, 1)]
}

/// 2D gradient noise in a cell whose corners have gradients `h` (see [`corners2`]), at
/// (`tx`, `ty`) within it.
#[inline]
fn noise2_in(h: [u8; 4], tx: f32, ty: f32) -> f32 {
    let n00 = grad2(u32::from(h[0]), tx, ty);
    let n10 = grad2(u32::from(h[1]), tx - 1.0, ty);
    let n01 = grad2(u32::from(h[2]), tx, ty - 1.0);
    let n11 = grad2(u32::from(h[3]), tx - 1.0, ty - 1.0);
    let (u, v) = (fade(tx), fade(ty));
    mix(mix(n00, n10, u), mix(n01, n11, u), v)
}

/// 2D gradient noise, roughly in [-0.75, 0.75], zero at lattice points.
pub fn noise2(seed: u32, x: f32, y: f32) -> f32 {
    let (fx, ix) = floor_i(x);
    let (fy, iy) = floor_i(y);
    noise2_in(corners2(seed, ix, iy), x - fx, y - fy)
}

/// The last cell one caller of [`noise2`] evaluated, with its corners' gradients: a run of
/// nearby points (the pixels of a row are tens to hundreds to a noise cell) skips the four
/// corner hashes while it stays in the cell. The same bits as [`noise2`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Cell2 {
    key: Option<(u32, i32, i32)>,
    h: [u8; 4],
}

impl Cell2 {
    /// [`noise2`]`(seed, x, y)`, the corners' hashes reused when the cell is the last one's.
    #[inline]
    pub fn noise2(&mut self, seed: u32, x: f32, y: f32) -> f32 {
        let (fx, ix) = floor_i(x);
        let (fy, iy) = floor_i(y);
        let key = Some((seed, ix, iy));
        if self.key != key {
            self.h = corners2(seed, ix, iy);
            self.key = key;
        }
        noise2_in(self.h, x - fx, y - fy)
    }
}

#[inline]
fn corner3(seed: u32, ix: i32, iy: i32, iz: i32) -> u32 {
    hash_u32(
        (ix as u32).wrapping_mul(0x8da6_b343)
            ^ (iy as u32).wrapping_mul(0xd816_3841)
            ^ (iz as u32).wrapping_mul(0xcb1a_b31f)
            ^ seed,
    )
}

#[inline]
fn grad3(h: u32, x: f32, y: f32, z: f32) -> f32 {
    // The 12 cube-edge directions of improved Perlin noise (4 repeated to make 16), from a
    // table (see `grad2`): the same bits as `x + y`, `-y + z` and the like.
    const G: [(f32, f32, f32); 16] = [
        (1.0, 1.0, 0.0),
        (-1.0, 1.0, 0.0),
        (1.0, -1.0, 0.0),
        (-1.0, -1.0, 0.0),
        (1.0, 0.0, 1.0),
        (-1.0, 0.0, 1.0),
        (1.0, 0.0, -1.0),
        (-1.0, 0.0, -1.0),
        (0.0, 1.0, 1.0),
        (0.0, -1.0, 1.0),
        (0.0, 1.0, -1.0),
        (0.0, -1.0, -1.0),
        (1.0, 1.0, 0.0),
        (-1.0, 1.0, 0.0),
        (0.0, -1.0, 1.0),
        (0.0, -1.0, -1.0),
    ];
    let (a, b, c) = G[(h & 15) as usize];
    a * x + b * y + c * z
}

/// The gradient index (`grad3` reads four bits) of each corner of the 3D noise cell whose
/// lowest corner is (`ix`, `iy`, `iz`), x fastest: (0, 0, 0), (1, 0, 0), (0, 1, 0), ... (1, 1, 1).
#[inline]
fn corners3(seed: u32, ix: i32, iy: i32, iz: i32) -> [u8; 8] {
    let h = |dx: i32, dy: i32, dz: i32| (corner3(seed, ix + dx, iy + dy, iz + dz) & 15) as u8;
    [
        h(0, 0, 0),
        h(1, 0, 0),
        h(0, 1, 0),
        h(1, 1, 0),
        h(0, 0, 1),
        h(1, 0, 1),
        h(0, 1, 1),
        h(1, 1, 1),
    ]
}

/// 3D gradient noise in a cell whose corners have gradients `h` (see [`corners3`]), at
/// (`tx`, `ty`, `tz`) within it.
#[inline]
fn noise3_in(h: [u8; 8], tx: f32, ty: f32, tz: f32) -> f32 {
    let g = |k: usize, dx: f32, dy: f32, dz: f32| grad3(u32::from(h[k]), tx - dx, ty - dy, tz - dz);
    let (u, v, w) = (fade(tx), fade(ty), fade(tz));
    let x00 = mix(g(0, 0.0, 0.0, 0.0), g(1, 1.0, 0.0, 0.0), u);
    let x10 = mix(g(2, 0.0, 1.0, 0.0), g(3, 1.0, 1.0, 0.0), u);
    let x01 = mix(g(4, 0.0, 0.0, 1.0), g(5, 1.0, 0.0, 1.0), u);
    let x11 = mix(g(6, 0.0, 1.0, 1.0), g(7, 1.0, 1.0, 1.0), u);
    mix(mix(x00, x10, v), mix(x01, x11, v), w)
}

/// 3D gradient noise, roughly in [-1, 1].
pub fn noise3(seed: u32, x: f32, y: f32, z: f32) -> f32 {
    let (fx, ix) = floor_i(x);
    let (fy, iy) = floor_i(y);
    let (fz, iz) = floor_i(z);
    noise3_in(corners3(seed, ix, iy, iz), x - fx, y - fy, z - fz)
}

/// The last cell of `N` 3D noises of seeds `seed`, `seed + 1`, ... at the same point (one for
/// the detail layer, three for the valleys' warp), with their corners' gradients; see
/// [`Cell2`]. The same bits as [`noise3`].
#[derive(Clone, Copy, Debug)]
pub struct Cell3<const N: usize> {
    key: Option<(u32, i32, i32, i32)>,
    h: [[u8; 8]; N],
}

impl<const N: usize> Default for Cell3<N> {
    fn default() -> Self {
        Self {
            key: None,
            h: [[0; 8]; N],
        }
    }
}

impl<const N: usize> Cell3<N> {
    /// [`noise3`]`(seed + k, x, y, z)` for k = 0 .. N, the corners' hashes reused when the
    /// cell is the last one's.
    #[inline]
    pub fn noise3(&mut self, seed: u32, x: f32, y: f32, z: f32) -> [f32; N] {
        let (fx, ix) = floor_i(x);
        let (fy, iy) = floor_i(y);
        let (fz, iz) = floor_i(z);
        let key = Some((seed, ix, iy, iz));
        if self.key != key {
            for (k, h) in self.h.iter_mut().enumerate() {
                *h = corners3(seed.wrapping_add(k as u32), ix, iy, iz);
            }
            self.key = key;
        }
        let (tx, ty, tz) = (x - fx, y - fy, z - fz);
        self.h.map(|h| noise3_in(h, tx, ty, tz))
    }
}

/// What one thread's run of nearby points keeps of the noise cells it evaluated (see
/// [`Cell2`]): per corner of the query's triangle, one cell per octave of its primitive, and
/// one per octave of the detail layer. Values are the same bits with or without it.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoiseMemo {
    corners: [[Cell2; 4]; 3],
    detail: [Cell3<1>; 2],
}

/// Fractal sum of `noise2` (lacunarity 2), normalised by the sum of the octave weights.
/// Only the first `kept` octaves are summed (the others count in the normalisation: left out,
/// their zero-mean detail is filtered away, see [`kept_octaves`]).
/// `memo` keeps a cell per octave (see [`Cell2`]).
fn fbm2(
    memo: &mut [Cell2; 4],
    seed: u32,
    (x, y): (f32, f32),
    octaves: u32,
    kept: u32,
    gain: f32,
) -> f32 {
    let mut sum = 0.0;
    let mut norm = 0.0;
    let mut amp = 1.0;
    let mut freq = 1.0;
    let mut o = 0;
    while o < octaves {
        if o < kept {
            sum += amp
                * memo[o as usize % 4].noise2(
                    seed.wrapping_add(o.wrapping_mul(0x9e37_79b9)),
                    x * freq,
                    y * freq,
                );
        }
        norm += amp;
        amp *= gain;
        freq *= 2.0;
        o += 1;
    }
    sum / norm
}

/// How many of `octaves` octaves of a noise (wavelengths `wl_km`, `wl_km` / 2, ...) are at
/// least the uniform's shortest wavelength: the ones an output resolves (all at 100 m pixels;
/// on a global map of 5 km pixels the finer ones would only alias).
fn kept_octaves(u: &AmplifyUniform, wl_km: f32, octaves: u32) -> u32 {
    let (mut o, mut w) = (0, wl_km);
    while o < octaves && w >= u.min_wavelength_km {
        o += 1;
        w *= 0.5;
    }
    o
}

/// What a vertex's primitive computes the same way at every point: built once per vertex
/// ([`Self::of`]) and kept beside the vertices by the amplifier, so that the points of an export
/// do not take an exponential and a cross product per corner. The same bits as computed per
/// point (the same operations).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VertexTerms {
    /// Position × grain axis: the primitive's other tangent axis.
    across: [f32; 3],
    /// Ocean floor: the share of the hills' relief its age leaves (young floor is rougher).
    /// Ranges: how fresh the orogeny is (1 new, falling with its age).
    age_factor: f32,
}

impl VertexTerms {
    /// The terms of vertex `v`.
    #[inline]
    pub fn of(v: &AmplifyVertex) -> Self {
        let across = [
            v.py * v.az - v.pz * v.ay,
            v.pz * v.ax - v.px * v.az,
            v.px * v.ay - v.py * v.ax,
        ];
        let age_factor = if v.kind == KIND_OCEAN {
            0.25 + 0.75 * (-v.age_my.max(0.0) / OCEAN_YOUNG_AGE_MY).exp()
        } else if v.kind == KIND_PLAIN {
            0.0
        } else {
            (-v.age_my.max(0.0) / OROGENY_OLD_AGE_MY).exp()
        };
        Self { across, age_factor }
    }
}

/// The relief of one vertex's primitive at unit direction `p` (metres), and the amplitude of
/// the detail layer it asks for (metres). `memo` keeps a noise cell per octave (the same bits
/// whatever it holds).
fn vertex_relief(
    u: &AmplifyUniform,
    v: &AmplifyVertex,
    t: &VertexTerms,
    p: [f32; 3],
    memo: &mut [Cell2; 4],
) -> (f32, f32) {
    let r = u.radius_km;
    let d = [(p[0] - v.px) * r, (p[1] - v.py) * r, (p[2] - v.pz) * r];
    let a = [v.ax, v.ay, v.az];
    // e2 = position × along: the other tangent axis.
    let b = t.across;
    let x = d[0] * a[0] + d[1] * a[1] + d[2] * a[2] + v.offset_x_km;
    let y = d[0] * b[0] + d[1] * b[1] + d[2] * b[2] + v.offset_y_km;
    let seed = u.seed;
    if v.kind == KIND_OCEAN {
        // Oceanic crust: the vertex axis is the ridge direction, so x runs along the ridge
        // axis and y along the spreading direction.
        let (ridge_axis, spreading_dir) = (x, y);
        let young = t.age_factor;
        // Transform faults: lines across the ridge at jittered positions along it.
        let s = x / FAULT_SPACING_KM;
        let (_, ki) = floor_i(s);
        let fault_seed = seed ^ 0x5bd1_e995;
        let mut nearest = 1.0e9f32;
        let mut segment = ki;
        let mut j = -1;
        while j <= 1 {
            let kj = ki + j;
            let pos = kj as f32 + 0.5 + 0.6 * (hash01(kj as u32 ^ fault_seed) - 0.5);
            let dist = s - pos;
            if dist.abs() < nearest.abs() {
                nearest = dist;
                segment = if dist >= 0.0 { kj + 1 } else { kj };
            }
            j += 1;
        }
        let dist_km = nearest * FAULT_SPACING_KM;
        let trough = (-(dist_km / FAULT_WIDTH_KM) * (dist_km / FAULT_WIDTH_KM)).exp();
        let trough_mean = FAULT_WIDTH_KM * 1.772_453_9 / FAULT_SPACING_KM;
        let shift =
            (hash01(segment as u32 ^ fault_seed ^ 0x68e3_1da4) - 0.5) * 2.0 * FAULT_OFFSET_KM;
        // Abyssal hills run parallel to the ridge (long along x); each ridge segment between
        // two faults is offset across the ridge (along y), as transform faults offset them.
        let hills = fbm2(
            memo,
            seed,
            (
                ridge_axis / (OCEAN_HILL_WAVELENGTH_KM * OCEAN_HILL_STRETCH),
                (spreading_dir + shift) / OCEAN_HILL_WAVELENGTH_KM,
            ),
            3,
            kept_octaves(u, OCEAN_HILL_WAVELENGTH_KM, 3),
            0.5,
        );
        let share = ocean_share(v.elevation_m);
        let relief = share
            * young
            * (OCEAN_HILL_AMP_M * 1.4 * hills - FAULT_DEPTH_M * (trough - trough_mean));
        (relief, share * OCEAN_DETAIL_M)
    } else if v.kind == KIND_PLAIN {
        let n = fbm2(
            memo,
            seed ^ 0x1b87_3593,
            (x / PLAIN_WAVELENGTH_KM, y / PLAIN_WAVELENGTH_KM),
            4,
            kept_octaves(u, PLAIN_WAVELENGTH_KM, 4),
            0.5,
        );
        let share = plain_share(v.elevation_m);
        (share * PLAIN_AMP_M * 1.4 * n, share * PLAIN_DETAIL_M)
    } else {
        let him = v.kind == KIND_HIMALAYAN;
        let (wl, stretch, amp0) = if him {
            (HIMALAYAN_WAVELENGTH_KM, HIMALAYAN_STRETCH, HIMALAYAN_AMP_M)
        } else {
            (ANDEAN_WAVELENGTH_KM, ANDEAN_STRETCH, ANDEAN_AMP_M)
        };
        let height = mountain_share(v.elevation_m);
        let fresh = t.age_factor;
        let amp = amp0 * height * (0.35 + 0.65 * fresh);
        let gain = 0.35 + 0.2 * fresh;
        let mseed = if him {
            seed ^ 0xcc9e_2d51
        } else {
            seed ^ 0x85eb_ca6b
        };
        // Continental crust: the vertex axis is the fold direction, which is the direction of
        // compression (paper §4.1; away from the terrane after a collision), so x runs along
        // `compression_dir` and y along `range_axis`. Crests run along the range axis: the
        // noise is stretched along y.
        let (compression_dir, range_axis) = (x, y);
        let (gx, gy) = (compression_dir / wl, range_axis / (wl * stretch));
        // One noise per octave feeds both the ridged (young) and the rounded (old) relief.
        let (mut ridges, mut rounded, mut norm, mut oamp, mut freq) = (0.0, 0.0, 0.0, 1.0, 1.0);
        let mut o = 0u32;
        let kept = kept_octaves(u, wl, 4);
        while o < 4 {
            if o < kept {
                let n = memo[o as usize % 4].noise2(
                    mseed.wrapping_add(o.wrapping_mul(0x9e37_79b9)),
                    gx * freq,
                    gy * freq,
                );
                let r = 1.0 - n.abs() * 1.4;
                ridges += oamp * (r * r - RIDGE_MEAN);
                rounded += oamp * n;
            }
            norm += oamp;
            oamp *= gain;
            freq *= 2.0;
            o += 1;
        }
        let relief = amp * (fresh * ridges * 2.5 + (1.0 - fresh) * 1.4 * rounded) / norm;
        (relief, MOUNTAIN_DETAIL_FRACTION * amp)
    }
}

/// The amplitude of vertex `v`'s procedural relief, metres: how far its primitive's noise
/// reaches above or below the crust (about; the noise's extremes are a little wider). Ocean
/// floor gives its abyssal hills' amplitude; what [`super::valleys`] incises its beds by.
pub fn relief_amplitude_m(v: &AmplifyVertex) -> f32 {
    if v.kind == KIND_OCEAN {
        ocean_share(v.elevation_m) * OCEAN_HILL_AMP_M
    } else if v.kind == KIND_PLAIN {
        plain_share(v.elevation_m) * PLAIN_AMP_M
    } else {
        let him = v.kind == KIND_HIMALAYAN;
        let amp0 = if him { HIMALAYAN_AMP_M } else { ANDEAN_AMP_M };
        let height = mountain_share(v.elevation_m);
        let fresh = (-v.age_my.max(0.0) / OROGENY_OLD_AGE_MY).exp();
        amp0 * height * (0.35 + 0.65 * fresh)
    }
}

/// Share of the sea floor's full relief at crust elevation `elevation_m` (see
/// [`OCEAN_FULL_DEPTH_M`]).
fn ocean_share(elevation_m: f32) -> f32 {
    (-elevation_m / OCEAN_FULL_DEPTH_M).clamp(PLAIN_LOW_SHARE, 1.0)
}

/// Share of a range's full relief at crust elevation `elevation_m`: its height over
/// [`MOUNTAIN_FULL_HEIGHT_M`], at least a tenth, and as flat as a plain near the sea (an old
/// orogen worn to the sea, an arc just out of it).
fn mountain_share(elevation_m: f32) -> f32 {
    (elevation_m / MOUNTAIN_FULL_HEIGHT_M).clamp(0.1, 1.0) * plain_share(elevation_m)
}

/// Share of a plain's full relief at crust elevation `elevation_m` (see [`PLAIN_FULL_HEIGHT_M`]).
fn plain_share(elevation_m: f32) -> f32 {
    (elevation_m / PLAIN_FULL_HEIGHT_M).clamp(PLAIN_LOW_SHARE, 1.0)
}

/// The isotropic detail layer at unit direction `p`, in about [-1, 1] (two octaves of 3D
/// gradient noise, 0.8 km and 0.32 km); `memo` keeps a cell per octave.
fn detail(u: &AmplifyUniform, p: [f32; 3], memo: &mut [Cell3<1>; 2]) -> f32 {
    let f = u.radius_km / DETAIL_WAVELENGTH_KM;
    let s = u.seed ^ 0xe654_6b64;
    let (x, y, z) = (p[0] * f, p[1] * f, p[2] * f);
    // Each octave only where the output resolves it.
    let n0 = if DETAIL_WAVELENGTH_KM >= u.min_wavelength_km {
        memo[0].noise3(s, x, y, z)[0]
    } else {
        0.0
    };
    let n1 = if DETAIL_WAVELENGTH_KM / 2.5 >= u.min_wavelength_km {
        memo[1].noise3(s.wrapping_add(1), 2.5 * x, 2.5 * y, 2.5 * z)[0]
    } else {
        0.0
    };
    let n = n0 + 0.5 * n1;
    n / 1.5
}

/// The amplified elevation (metres) of one query: the barycentric crust elevation plus the
/// blended relief of the three corners' primitives and the detail layer, the relief clamped to
/// ±[`MAX_RELIEF_M`]. Corners with zero weight are skipped. `primitive` gives the relief of a
/// corner from its index and vertex (see [`procedural_primitive`]; the exemplar amplifier
/// passes its own), with the noise
/// cells `memo` keeps for that corner; `memo` is the caller's, kept from one query to the next
/// (nearby queries share noise cells; the value is the same whatever it holds).
pub fn amplify_point_with(
    u: &AmplifyUniform,
    vertices: &[AmplifyVertex],
    q: &AmplifyQuery,
    memo: &mut NoiseMemo,
    mut primitive: impl FnMut(usize, &AmplifyVertex, [f32; 3], &mut [Cell2; 4]) -> (f32, f32),
) -> f32 {
    let p = [q.dx, q.dy, q.dz];
    let corners = [(q.c0, q.w0), (q.c1, q.w1), (q.c2, q.w2)];
    let mut base = 0.0f32;
    let mut relief = 0.0f32;
    let mut detail_amp = 0.0f32;
    let mut w2 = 0.0f32;
    let mut wsum = 0.0f32;
    // Exemplar primitives' weights, summed (see below).
    let mut wex = 0.0f32;
    for (k, (c, w)) in corners.into_iter().enumerate() {
        let Some(v) = vertices.get(c as usize) else {
            continue;
        };
        base += w * v.elevation_m;
        // Primitive weights: the barycentric weight less BLEND_CUT (EXEMPLAR_BLEND_CUT for an
        // exemplar; still continuous across edges, and most points need only one or two
        // primitives).
        let exemplar = v.exemplar != 0;
        let wp = w - if exemplar {
            EXEMPLAR_BLEND_CUT
        } else {
            BLEND_CUT
        };
        if wp > 0.0 {
            let (r, da) = primitive(c as usize, v, p, &mut memo.corners[k]);
            relief += wp * r;
            detail_amp += wp * da;
            if exemplar {
                wex += wp;
            } else {
                w2 += wp * wp;
            }
            wsum += wp;
        }
    }
    let detail_amp = detail_amp / wsum.max(1.0e-12);
    // Procedural primitives are blended keeping their variance (Σw·r / √Σw²: uncorrelated noise
    // keeps its amplitude), exemplars linearly (Σw·r / Σw): two exemplars' drained relief,
    // each shifted and rotated on its own, summed at full amplitude ring hollows between one's
    // crests and the other's valleys. The two terms join continuously as a weight comes in.
    let blended = relief / (w2 + wex * wex).max(1.0e-12).sqrt();
    let total = (blended + detail_amp * detail(u, p, &mut memo.detail)) * u.relief_scale;
    base + total.clamp(-MAX_RELIEF_M, MAX_RELIEF_M)
}

/// The procedural primitive of vertex `v` (with its [`VertexTerms`]) at unit direction `p`:
/// (relief m, detail amplitude m) (`memo`: see [`amplify_point_with`]).
pub fn procedural_primitive(
    u: &AmplifyUniform,
    v: &AmplifyVertex,
    terms: &VertexTerms,
    p: [f32; 3],
    memo: &mut [Cell2; 4],
) -> (f32, f32) {
    vertex_relief(u, v, terms, p, memo)
}

/// The procedural amplified elevation (metres) of one query (`memo`: see
/// [`amplify_point_with`]; `&mut NoiseMemo::default()` for a query on its own).
pub fn amplify_point(
    u: &AmplifyUniform,
    vertices: &[AmplifyVertex],
    q: &AmplifyQuery,
    memo: &mut NoiseMemo,
) -> f32 {
    amplify_point_with(u, vertices, q, memo, |_, v, p, m| {
        vertex_relief(u, v, &VertexTerms::of(v), p, m)
    })
}

/// [`amplify_point`] with each vertex's [`VertexTerms`] computed beforehand (`terms[i]` of
/// `vertices[i]`): the same bits.
pub fn amplify_point_terms(
    u: &AmplifyUniform,
    vertices: &[AmplifyVertex],
    terms: &[VertexTerms],
    q: &AmplifyQuery,
    memo: &mut NoiseMemo,
) -> f32 {
    amplify_point_with(u, vertices, q, memo, |c, v, p, m| {
        vertex_relief(u, v, &terms[c], p, m)
    })
}

/// CPU reference of the `amplify` kernel: the amplified elevation (metres) of every query, in
/// parallel. `out` must be as long as `queries` (extra entries are left untouched).
pub fn amplify_cpu(
    u: &AmplifyUniform,
    vertices: &[AmplifyVertex],
    queries: &[AmplifyQuery],
    out: &mut [f32],
) {
    use rayon::prelude::*;
    out.par_iter_mut()
        .zip(queries.par_iter())
        .with_min_len(1024)
        .for_each_init(NoiseMemo::default, |m, (o, q)| {
            *o = amplify_point(u, vertices, q, m)
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ridged_noise_is_centred() {
        // The mean of one ridged octave over many points is close to zero once RIDGE_MEAN is
        // taken off (otherwise blended primitives would carry a triangle-shaped bias).
        let mut sum = 0.0f64;
        let n = 400;
        for i in 0..n {
            for j in 0..n {
                let v = noise2(7, i as f32 * 0.173 + 0.01, j as f32 * 0.219 + 0.02);
                let r = 1.0 - v.abs() * 1.4;
                sum += f64::from(r * r - RIDGE_MEAN);
            }
        }
        let mean = sum / (n * n) as f64;
        assert!(mean.abs() < 0.03, "ridged mean off by {mean}");
    }

    #[test]
    fn floor_i_is_floor() {
        for k in -40000..40000 {
            let x = k as f32 * 0.37 + 0.001 * (k % 7) as f32;
            for v in [x, -x, x.floor(), -x.floor()] {
                let (f, i) = floor_i(v);
                assert_eq!(f, v.floor(), "{v}");
                assert_eq!(i, v.floor() as i32, "{v}");
            }
        }
    }

    #[test]
    fn noise_is_continuous_and_bounded() {
        let mut max = 0.0f32;
        for i in 0..2000 {
            let x = i as f32 * 0.0137 - 5.0;
            let a = noise2(3, x, 0.3 * x);
            let b = noise2(3, x + 1e-3, 0.3 * x);
            assert!((a - b).abs() < 0.01, "jump at {x}");
            max = max.max(a.abs());
            let c = noise3(5, x, -0.7 * x, 0.2 * x);
            assert!(c.abs() <= 1.5);
        }
        assert!(max > 0.2 && max < 1.0, "noise2 range {max}");
    }

    #[test]
    fn noise_memos_give_the_bits_of_the_noises() {
        // A walk of small steps (most points in the last point's cell) that changes seed now
        // and then: a memo keyed without the seed, or keeping a cell it left, gives other bits.
        let (mut c2, mut c3, mut w3) = (
            Cell2::default(),
            Cell3::<1>::default(),
            Cell3::<3>::default(),
        );
        let (mut hits2, mut hits3) = (0, 0);
        let (mut last2, mut last3) = (None, None);
        for i in 0..20_000u32 {
            let t = i as f32 * 0.0173;
            let (x, y, z) = (t - 40.0, 0.37 * t + 2.5 * (0.01 * t).sin(), -0.21 * t);
            let seed = 11 + (i / 700) % 3;
            let k2 = (seed, floor_i(x).1, floor_i(y).1);
            let k3 = (k2, floor_i(z).1);
            hits2 += usize::from(last2 == Some(k2));
            hits3 += usize::from(last3 == Some(k3));
            (last2, last3) = (Some(k2), Some(k3));
            assert_eq!(
                c2.noise2(seed, x, y).to_bits(),
                noise2(seed, x, y).to_bits()
            );
            assert_eq!(
                c3.noise3(seed, x, y, z)[0].to_bits(),
                noise3(seed, x, y, z).to_bits()
            );
            let w = w3.noise3(seed, x, y, z);
            for (k, v) in w.iter().enumerate() {
                let want = noise3(seed.wrapping_add(k as u32), x, y, z);
                assert_eq!(v.to_bits(), want.to_bits(), "warp noise {k} at step {i}");
            }
        }
        // The walk does reuse cells (so the memos are exercised) and leaves them too.
        assert!(
            hits2 > 15_000 && hits2 < 19_990,
            "2D cell reused {hits2} times"
        );
        assert!(
            hits3 > 15_000 && hits3 < 19_990,
            "3D cell reused {hits3} times"
        );
    }
}
