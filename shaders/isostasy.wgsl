// Isostasy: the elevation of every sample from the crust, one thread per sample, written into the
// resident elevation buffer. CPU reference: isostasy_cpu (src/systems/relief/isostasy.rs). f32
// throughout; the smoothed root w (the regional response) and the trench depth come from the
// host.
//
// - Continental crust of thickness T (finite; otherwise the elevation is left as it is):
//     own = (T − T0)·ρc/ρm, w' = clamp(w, own − S, own + S), dry = h0 + (T − T0) − w',
//     z = dry if dry ≥ 0, else dry·ρm/(ρm − ρw) (the water load).
// - Oceanic crust: z = −depth(age) + gain·(T − T_oc) − clamp(w, −S, S) − trench, with the
//   age–depth law read from the host's table (linear interpolation, as AgeDepthTable::depth_km;
//   a non-finite age reads as 0, ages are clamped to 0..max_age).

// Keep in sync with IsostasyUniforms in src/gpu/isostasy.rs.
struct IsostasyUniforms {
    ref_thickness_km: f32,
    ref_elevation_km: f32,
    root_ratio: f32,
    submerge_factor: f32,
    max_support_km: f32,
    oceanic_thickness_km: f32,
    sediment_gain: f32,
    age_scale: f32,
    max_age_my: f32,
    table_last: u32,
    count: u32,
    row_stride: u32,
    max_oceanic_load_km: f32,
    max_continental_km: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: IsostasyUniforms;
@group(0) @binding(1) var<storage, read_write> elevation_km: array<f32>;
@group(0) @binding(2) var<storage, read> crust_type: array<u32>;
// Thickness and age as f32 bits, tested for non-finite values on the bits (so that no compiler
// can assume finite floats).
@group(0) @binding(3) var<storage, read> thickness_bits: array<u32>;
@group(0) @binding(4) var<storage, read> age_bits: array<u32>;
@group(0) @binding(5) var<storage, read> deflection_km: array<f32>;
@group(0) @binding(6) var<storage, read> trench_km: array<f32>;
// Ocean depth (km, positive down) every 1/age_scale My from age 0; table_last + 2 entries.
@group(0) @binding(7) var<storage, read> depth_table_km: array<f32>;

fn is_finite_bits(b: u32) -> bool {
    return (b & 0x7f800000u) != 0x7f800000u;
}

// AgeDepthTable::depth_km in f32.
fn ocean_depth(bits: u32) -> f32 {
    var t = 0.0;
    if (is_finite_bits(bits)) {
        t = clamp(bitcast<f32>(bits), 0.0, u.max_age_my);
    }
    let x = t * u.age_scale;
    let k = min(u32(x), u.table_last);
    let f = x - f32(k);
    return depth_table_km[k] * (1.0 - f) + depth_table_km[k + 1u] * f;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * u.row_stride;
    if (i >= u.count) {
        return;
    }
    let tb = thickness_bits[i];
    let t = bitcast<f32>(tb);
    let w = deflection_km[i];
    let s = u.max_support_km;
    if (byte_of(crust_type[i >> 2u], i) == CRUST_OCEANIC) {
        let wi = clamp(w, -s, s);
        let load = t - u.oceanic_thickness_km;
        let held = select(load, u.max_oceanic_load_km, load > u.max_oceanic_load_km);
        elevation_km[i] = -ocean_depth(age_bits[i]) + u.sediment_gain * held
            - wi - trench_km[i];
        return;
    }
    if (!is_finite_bits(tb)) {
        return;
    }
    let tc = select(t, u.max_continental_km, t > u.max_continental_km);
    let excess = tc - u.ref_thickness_km;
    let own = excess * u.root_ratio;
    let wc = clamp(w, own - s, own + s);
    let dry = u.ref_elevation_km + excess - wc;
    var z = dry;
    if (dry < 0.0) {
        z = dry * u.submerge_factor;
    }
    elevation_km[i] = z;
}
