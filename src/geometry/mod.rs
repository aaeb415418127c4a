//! Sphere geometry: Fibonacci sampling, spherical Delaunay triangulation, point location and
//! great-circle helpers. Everything here works on the unit sphere; callers scale by the planet
//! radius to get kilometres.

pub mod delaunay;
pub mod locator;
pub mod mesh;
pub mod sampling;
pub mod spherical;
pub mod union_find;

pub use locator::{Location, MeshLocator};
pub use mesh::{MeshError, SphereMesh};
pub use spherical::*;

/// Key that orders f32 values totally (as `f32::total_cmp`) when compared as u32: the key of
/// every priority flood (the drainage, the sediment router, the pit measure, the exemplars'
/// drainage).
#[inline]
pub fn order_bits(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
}
