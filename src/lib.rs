//! Procedural tectonic planets: plates drift on a sphere, rift, collide and subduct, and
//! continents, ranges, trenches and ridges come out of that history (after Cortial et al. 2019).

pub mod geometry;
pub mod random;
