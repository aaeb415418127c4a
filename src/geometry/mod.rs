//! Sphere geometry: Fibonacci sampling, spherical Delaunay triangulation, point location and
//! great-circle helpers. Everything here works on the unit sphere; callers scale by the planet
//! radius to get kilometres.

pub mod delaunay;
pub mod locator;
pub mod mesh;
pub mod sampling;
pub mod spherical;

pub use locator::{Location, MeshLocator};
pub use mesh::{MeshError, SphereMesh};
pub use spherical::*;
