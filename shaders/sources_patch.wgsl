// Scatter of the located sources the host rechecked: for each patch k (9 words: the sample
// index, then the 8 words of its source), sources[8 * index + w] = patch word w + 1. One thread
// per patch; raw 32-bit copies, so the result is bit-identical to writing the host array.
// CPU reference: sources_patch_cpu (src/gpu/sources_patch.rs).

// Keep in sync with PatchUniforms in src/gpu/sources_patch.rs.
struct PatchUniforms {
    count: u32,
    samples: u32,
    row_stride: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: PatchUniforms;
@group(0) @binding(1) var<storage, read> patches: array<u32>;
@group(0) @binding(2) var<storage, read_write> sources: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x + gid.y * u.row_stride;
    if (k >= u.count) {
        return;
    }
    let at = 9u * k;
    let j = patches[at];
    if (j >= u.samples) {
        // Out of range: the host validates indices first.
        return;
    }
    for (var w = 0u; w < 8u; w = w + 1u) {
        sources[8u * j + w] = patches[at + 1u + w];
    }
}
