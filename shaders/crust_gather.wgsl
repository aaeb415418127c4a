// Front-elevation gather: out[k] = elevation[index[k]], one thread per index. Raw 32-bit copies
// (the elevation is bound as u32 words), so the result is bit-identical to indexing the host
// array, NaN payloads included. CPU reference: crust_gather_cpu (src/gpu/crust_gather.rs).

// Keep in sync with GatherUniforms in src/gpu/crust_gather.rs.
struct GatherUniforms {
    count: u32,
    samples: u32,
    row_stride: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: GatherUniforms;
@group(0) @binding(1) var<storage, read> elevation_bits: array<u32>;
@group(0) @binding(2) var<storage, read> index: array<u32>;
@group(0) @binding(3) var<storage, read_write> out_bits: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x + gid.y * u.row_stride;
    if (k >= u.count) {
        return;
    }
    let i = index[k];
    if (i >= u.samples) {
        // Out of range: the host validates indices first; a quiet NaN marks it anyway.
        out_bits[k] = 0x7fc00000u;
        return;
    }
    out_bits[k] = elevation_bits[i];
}
