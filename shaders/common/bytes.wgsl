// Shared helpers, prepended to every kernel by the host (src/gpu/mod.rs) and by the naga test.
// Per-sample u8 fields of the crust (crust type, orogeny) are uploaded as they are, four samples
// to a little-endian u32 word.

// Byte `i & 3` of `word`: the u8 field of sample `i` when `word` is word `i >> 2` of the array.
fn byte_of(word: u32, i: u32) -> u32 {
    return (word >> ((i & 3u) * 8u)) & 0xffu;
}

// `word` with byte `i & 3` replaced by `value` (0..=255).
fn with_byte(word: u32, i: u32, value: u32) -> u32 {
    let shift = (i & 3u) * 8u;
    return (word & ~(0xffu << shift)) | ((value & 0xffu) << shift);
}

// Crust type codes (src/resources/crust.rs, CrustType).
const CRUST_OCEANIC: u32 = 0u;
const CRUST_CONTINENTAL: u32 = 1u;
// Orogeny codes (src/resources/crust.rs, Orogeny).
const OROGENY_NONE: u32 = 0u;
const OROGENY_ANDEAN: u32 = 1u;
const OROGENY_HIMALAYAN: u32 = 2u;
// "No front point" in the convergence field (src/resources/convergence.rs, NONE).
const NO_POINT: u32 = 0xffffffffu;
// Threads per workgroup of every per-sample kernel (src/gpu/mod.rs, WORKGROUP_SIZE).
const WORKGROUP_SIZE: u32 = 256u;
