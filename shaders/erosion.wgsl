// Continental erosion, oceanic damping and sediment accretion: one step, in place, one thread per
// sample. CPU reference: erosion_cpu (src/systems/erosion.rs, erode_sample). f32 throughout.

// Keep in sync with ErosionUniforms in src/gpu/erosion.rs.
struct ErosionUniforms {
    max_elevation_km: f32,
    abyssal_elevation_km: f32,
    trench_elevation_km: f32,
    erosion_km: f32,
    damping_factor: f32,
    sediment_km: f32,
    count: u32,
    row_stride: u32,
}

@group(0) @binding(0) var<uniform> u: ErosionUniforms;
@group(0) @binding(1) var<storage, read_write> elevation_km: array<f32>;
@group(0) @binding(2) var<storage, read> crust_type: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * u.row_stride;
    if (i >= u.count) {
        return;
    }
    let z = elevation_km[i];
    var out = z;
    if (byte_of(crust_type[i >> 2u], i) == CRUST_CONTINENTAL) {
        if (z > 0.0) {
            out = z - z / u.max_elevation_km * u.erosion_km;
        }
    } else if (z > u.abyssal_elevation_km) {
        out = max(u.trench_elevation_km + (z - u.trench_elevation_km) * u.damping_factor,
                  u.abyssal_elevation_km);
    } else {
        out = min(z + u.sediment_km, u.abyssal_elevation_km);
    }
    elevation_km[i] = out;
}
