// Diagnostics reduction over the resident crust, one thread per 32 samples:
// - one land-bitmask word (bit j: sample 32w+j has elevation > 0, the test of crust_stats);
// - the elevation min and max through atomics on an order-preserving u32 encoding, NaN
//   skipped as f32::min/max do;
// - the first non-finite sample index of elevation, age, orogeny age and fold direction
//   (atomicMin; 0xffffffff = none).
// Every test is on the raw bits (WGSL has no isnan, and a compiler may assume no NaN in float
// compares). CPU reference: crust_reduce_cpu (src/gpu/crust_reduce.rs).

// Keep in sync with ReduceUniforms in src/gpu/crust_reduce.rs.
struct ReduceUniforms {
    count: u32,
    words: u32,
    row_stride: u32,
    _pad: u32,
}

// Layout of `reduced` (keep in sync with src/gpu/crust_reduce.rs): header words, then the mask.
const OUT_MIN: u32 = 0u;
const OUT_MAX: u32 = 1u;
const OUT_FIRST: u32 = 2u; // 4 words: elevation, age, orogeny age, fold direction
const OUT_HEADER: u32 = 6u;
const NO_INDEX: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> u: ReduceUniforms;
@group(0) @binding(1) var<storage, read> elevation_bits: array<u32>;
@group(0) @binding(2) var<storage, read> age_bits: array<u32>;
@group(0) @binding(3) var<storage, read> orogeny_age_bits: array<u32>;
@group(0) @binding(4) var<storage, read> fold_bits: array<u32>;
@group(0) @binding(5) var<storage, read_write> reduced: array<atomic<u32>>;

fn non_finite(b: u32) -> bool {
    return (b & 0x7f800000u) == 0x7f800000u;
}

fn is_nan(b: u32) -> bool {
    return (b & 0x7fffffffu) > 0x7f800000u;
}

// Order-preserving: a < b as floats (not NaN) iff ordered(a) < ordered(b) as u32.
fn ordered(b: u32) -> u32 {
    if ((b & 0x80000000u) != 0u) {
        return ~b;
    }
    return b | 0x80000000u;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x + gid.y * u.row_stride;
    if (w >= u.words) {
        return;
    }
    let start = w * 32u;
    let end = min(start + 32u, u.count);
    var mask = 0u;
    var lo = ordered(0x7f800000u); // +inf
    var hi = ordered(0xff800000u); // -inf
    var first = vec4<u32>(NO_INDEX, NO_INDEX, NO_INDEX, NO_INDEX);
    for (var i = start; i < end; i = i + 1u) {
        let z = elevation_bits[i];
        // z > 0: sign clear, not +0, not NaN (+inf counts).
        if ((z & 0x80000000u) == 0u && z != 0u && z <= 0x7f800000u) {
            mask = mask | (1u << (i - start));
        }
        if (!is_nan(z)) {
            lo = min(lo, ordered(z));
            hi = max(hi, ordered(z));
        }
        if (first.x == NO_INDEX && non_finite(z)) {
            first.x = i;
        }
        if (first.y == NO_INDEX && non_finite(age_bits[i])) {
            first.y = i;
        }
        if (first.z == NO_INDEX && non_finite(orogeny_age_bits[i])) {
            first.z = i;
        }
        if (first.w == NO_INDEX
            && (non_finite(fold_bits[3u * i]) || non_finite(fold_bits[3u * i + 1u])
                || non_finite(fold_bits[3u * i + 2u]))) {
            first.w = i;
        }
    }
    atomicStore(&reduced[OUT_HEADER + w], mask);
    atomicMin(&reduced[OUT_MIN], lo);
    atomicMax(&reduced[OUT_MAX], hi);
    if (first.x != NO_INDEX) {
        atomicMin(&reduced[OUT_FIRST], first.x);
    }
    if (first.y != NO_INDEX) {
        atomicMin(&reduced[OUT_FIRST + 1u], first.y);
    }
    if (first.z != NO_INDEX) {
        atomicMin(&reduced[OUT_FIRST + 2u], first.z);
    }
    if (first.w != NO_INDEX) {
        atomicMin(&reduced[OUT_FIRST + 3u], first.w);
    }
}
