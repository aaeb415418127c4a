// Crust aging: every sample's crust age grows by the time step, and so does its orogeny age where
// an orogeny is recorded. In place, one thread per sample. CPU reference: aging_cpu
// (src/systems/aging.rs). The same f32 additions as the CPU, so the results are bit-identical.

// Keep in sync with AgingUniforms in src/gpu/aging.rs.
struct AgingUniforms {
    dt_my: f32,
    count: u32,
    row_stride: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> u: AgingUniforms;
@group(0) @binding(1) var<storage, read_write> age_my: array<f32>;
@group(0) @binding(2) var<storage, read_write> orogeny_age_my: array<f32>;
@group(0) @binding(3) var<storage, read> orogeny: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * u.row_stride;
    if (i >= u.count) {
        return;
    }
    age_my[i] = age_my[i] + u.dt_my;
    if (byte_of(orogeny[i >> 2u], i) != OROGENY_NONE) {
        orogeny_age_my[i] = orogeny_age_my[i] + u.dt_my;
    }
}
