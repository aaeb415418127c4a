//! The crust: every per-sample field as a structure of arrays, indexed by reference-mesh sample.
//! Between resamplings each sample moves with its plate, so vector fields are in the plate frame.

use bevy_ecs::prelude::*;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::random::StableHasher;

/// Oceanic or continental crust.
#[repr(u8)]
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, bytemuck::NoUninit,
)]
pub enum CrustType {
    /// Dense, young, thin crust formed at ridges.
    #[default]
    Oceanic = 0,
    /// Light, thick crust that resists subduction.
    Continental = 1,
}

/// What raised a piece of continental crust (paper Table 1).
#[repr(u8)]
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, bytemuck::NoUninit,
)]
pub enum Orogeny {
    /// No orogeny recorded.
    #[default]
    None = 0,
    /// Raised by subduction.
    Andean = 1,
    /// Raised by continental collision.
    Himalayan = 2,
}

/// Plate id stored for samples not covered by any plate during a resampling.
pub const NO_PLATE: u32 = u32::MAX;

/// Per-sample crust fields (a resource). All vectors have one entry per reference sample.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct Crust {
    /// Surface elevation relative to sea level, km.
    pub elevation_km: Vec<f32>,
    /// Crust thickness, km.
    pub thickness_km: Vec<f32>,
    /// Oceanic or continental.
    pub crust_type: Vec<CrustType>,
    /// Time since the crust formed, My (the oceanic age a_o for oceanic crust).
    pub age_my: Vec<f32>,
    /// Local direction parallel to the ridge where the crust formed (oceanic), plate frame;
    /// zero where unknown.
    pub ridge_dir: Vec<[f32; 3]>,
    /// Orogeny type (continental).
    pub orogeny: Vec<Orogeny>,
    /// Time since the last orogeny, My.
    pub orogeny_age_my: Vec<f32>,
    /// Local fold direction (continental), plate frame; zero where unknown.
    pub fold_dir: Vec<[f32; 3]>,
    /// Id of the plate that owns the sample.
    pub plate: Vec<u32>,
}

/// A field name and sample index where a non-finite value was found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("non-finite value in crust field `{field}` at sample {index}")]
pub struct NonFinite {
    /// Field name.
    pub field: &'static str,
    /// Sample index.
    pub index: usize,
}

impl Crust {
    /// A crust of `n` samples with every field zero (oceanic, no orogeny, no plate).
    pub fn with_len(n: usize) -> Self {
        let mut c = Self::default();
        c.resize(n);
        c
    }

    /// Resizes every field to `n` samples (new entries zero / oceanic / no plate).
    pub fn resize(&mut self, n: usize) {
        self.elevation_km.resize(n, 0.0);
        self.thickness_km.resize(n, 0.0);
        self.crust_type.resize(n, CrustType::Oceanic);
        self.age_my.resize(n, 0.0);
        self.ridge_dir.resize(n, [0.0; 3]);
        self.orogeny.resize(n, Orogeny::None);
        self.orogeny_age_my.resize(n, 0.0);
        self.fold_dir.resize(n, [0.0; 3]);
        self.plate.resize(n, NO_PLATE);
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.elevation_km.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.elevation_km.is_empty()
    }

    /// A stable 64-bit hash of every field, bit for bit.
    pub fn hash(&self) -> u64 {
        let mut h = StableHasher::default();
        h.write_u64(self.len() as u64);
        h.write(bytemuck::cast_slice(&self.elevation_km));
        h.write(bytemuck::cast_slice(&self.thickness_km));
        h.write(bytemuck::cast_slice(&self.crust_type));
        h.write(bytemuck::cast_slice(&self.age_my));
        h.write(bytemuck::cast_slice(&self.ridge_dir));
        h.write(bytemuck::cast_slice(&self.orogeny));
        h.write(bytemuck::cast_slice(&self.orogeny_age_my));
        h.write(bytemuck::cast_slice(&self.fold_dir));
        h.write(bytemuck::cast_slice(&self.plate));
        h.finish()
    }

    /// The first non-finite value, if any.
    pub fn check_finite(&self) -> Result<(), NonFinite> {
        let scalar: [(&'static str, &Vec<f32>); 4] = [
            ("elevation_km", &self.elevation_km),
            ("thickness_km", &self.thickness_km),
            ("age_my", &self.age_my),
            ("orogeny_age_my", &self.orogeny_age_my),
        ];
        for (field, v) in scalar {
            if let Some(index) = first_non_finite(v) {
                return Err(NonFinite { field, index });
            }
        }
        let vector: [(&'static str, &Vec<[f32; 3]>); 2] =
            [("ridge_dir", &self.ridge_dir), ("fold_dir", &self.fold_dir)];
        for (field, v) in vector {
            if let Some(index) = first_non_finite3(v) {
                return Err(NonFinite { field, index });
            }
        }
        Ok(())
    }

    /// Bytes held on the heap.
    pub fn heap_bytes(&self) -> usize {
        self.elevation_km.capacity() * 4
            + self.thickness_km.capacity() * 4
            + self.crust_type.capacity()
            + self.age_my.capacity() * 4
            + self.ridge_dir.capacity() * 12
            + self.orogeny.capacity()
            + self.orogeny_age_my.capacity() * 4
            + self.fold_dir.capacity() * 12
            + self.plate.capacity() * 4
    }
}

/// The index of the first value of `v` that is not finite. Chunks are scanned in parallel
/// without an early exit (a scan the compiler vectorises: a value is finite when its exponent
/// bits are not all ones), and only a chunk holding such a value is searched for it.
pub(crate) fn first_non_finite(v: &[f32]) -> Option<usize> {
    const CH: usize = 16384;
    v.par_chunks(CH)
        .position_first(|c| {
            c.iter().fold(false, |bad, x| {
                bad | (x.to_bits() & 0x7f80_0000 == 0x7f80_0000)
            })
        })
        .map(|k| {
            let c = &v[k * CH..((k + 1) * CH).min(v.len())];
            k * CH
                + c.iter()
                    .position(|x| !x.is_finite())
                    .expect("the chunk holds one")
        })
}

/// [`first_non_finite`] over vectors: the index of the first vector with a component that is
/// not finite.
pub(crate) fn first_non_finite3(v: &[[f32; 3]]) -> Option<usize> {
    first_non_finite(v.as_flattened()).map(|k| k / 3)
}

#[cfg(test)]
mod tests {
    use super::first_non_finite;

    #[test]
    fn first_non_finite_finds_the_first_bad_value_in_any_chunk() {
        let mut v = vec![1.0f32; 50_000];
        assert_eq!(first_non_finite(&v), None);
        for (at, bad) in [
            (0, f32::NAN),
            (16_383, f32::INFINITY),
            (16_384, f32::NEG_INFINITY),
            (49_999, f32::NAN),
        ] {
            v[at] = bad;
            assert_eq!(first_non_finite(&v), Some(at));
            // A later bad value does not hide an earlier one.
            v[49_000] = f32::NAN;
            assert_eq!(first_non_finite(&v), Some(at.min(49_000)));
            v[49_000] = 1.0;
            v[at] = f32::MAX;
        }
        assert_eq!(first_non_finite(&v), None);
        assert_eq!(first_non_finite(&[]), None);
    }
}
