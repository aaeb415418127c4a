// Subduction uplift on overriding plates (u0·f(d)·g(v)·h(z̃), capped at z_c, the crust
// thickened by the uplift over 1 − ρ_c/ρ_m, capped, Andean orogeny, fold directions) and trenches on subducting plates, one step, in place. CPU reference:
// subduction_uplift_cpu (src/systems/convergence/subduction.rs). One thread per four samples, because the
// orogeny field is packed four samples to a word and a word must have a single writer.
// Per-front-point factors (g·h·u0, the fold increment) come from the host, computed in f64 as
// the CPU does; the distance transfer f(d) is evaluated here in f32 on d/r_s.

// Keep in sync with UpliftUniforms in src/gpu/subduction_uplift.rs.
struct UpliftUniforms {
    distance_km: f32,
    control_ratio: f32,
    transfer_inv_den: f32,
    dt_my: f32,
    trench_elevation_km: f32,
    max_elevation_km: f32,
    abyssal_elevation_km: f32,
    ridge_elevation_km: f32,
    trench_width_km: f32,
    trench_rate: f32,
    count: u32,
    row_stride: u32,
    thickening: f32,
    max_thickness_km: f32,
    oceanic_thickening: f32,
    max_oceanic_thickness_km: f32,
    // 1: isostatic relief (thicken the crust only), 0: the paper's (raise the elevation, trench).
    isostatic: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Keep in sync with FrontGpu in src/gpu/subduction_uplift.rs.
struct FrontGpu {
    fold_inc_x: f32,
    fold_inc_y: f32,
    fold_inc_z: f32,
    uplift_scale_km_per_my: f32,
    converged_km: f32,
    is_active: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> u: UpliftUniforms;
@group(0) @binding(1) var<storage, read_write> elevation_km: array<f32>;
@group(0) @binding(2) var<storage, read_write> orogeny: array<u32>;
@group(0) @binding(3) var<storage, read_write> orogeny_age_my: array<f32>;
@group(0) @binding(4) var<storage, read_write> fold_dir: array<f32>;
@group(0) @binding(5) var<storage, read> crust_type: array<u32>;
// Per sample: (overriding distance km as f32 bits, overriding point, subducting distance km as
// f32 bits, subducting point).
@group(0) @binding(6) var<storage, read> field: array<vec4<u32>>;
@group(0) @binding(7) var<storage, read> fronts: array<FrontGpu>;
@group(0) @binding(8) var<storage, read_write> thickness_km: array<f32>;

// Driftworld's cubic distance transfer on x = d / r_s (1 at the control distance, 0 at r_s,
// clipped at 0), the CPU's distance_transfer divided through by r_s³.
fn transfer(d: f32) -> f32 {
    if (d >= u.distance_km) {
        return 0.0;
    }
    let x = d / u.distance_km;
    let c = u.control_ratio;
    let num = x * x * x / 3.0 - (c + 1.0) * x * x / 2.0 + c * x + 1.0 / 6.0 - c / 2.0;
    return max(num * u.transfer_inv_den, 0.0);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = gid.x + gid.y * u.row_stride;
    let first = w * 4u;
    if (first >= u.count) {
        return;
    }
    var og_word = orogeny[w];
    let ct_word = crust_type[w];
    let last = min(first + 4u, u.count);
    for (var i = first; i < last; i = i + 1u) {
        let f = field[i];
        let od = bitcast<f32>(f.x);
        let op = f.y;
        let sd = bitcast<f32>(f.z);
        let sp = f.w;
        var z = elevation_km[i];
        if (op != NO_POINT && od < u.distance_km && fronts[op].is_active != 0u) {
            let fr = fronts[op];
            let up = fr.uplift_scale_km_per_my * transfer(od);
            if (up > 0.0) {
                if (u.isostatic != 0u) {
                    let t = thickness_km[i];
                    if (byte_of(ct_word, i) == CRUST_OCEANIC) {
                        thickness_km[i] = min(t + up * u.dt_my * u.oceanic_thickening,
                            max(u.max_oceanic_thickness_km, t));
                    } else {
                        thickness_km[i] = min(t + up * u.dt_my * u.thickening,
                            max(u.max_thickness_km, t));
                    }
                    if (z > 0.0 && up * u.dt_my > 1e-4) {
                        og_word = with_byte(og_word, i, OROGENY_ANDEAN);
                        orogeny_age_my[i] = 0.0;
                    }
                } else {
                    let znew = min(z + up * u.dt_my, u.max_elevation_km);
                    z = znew;
                    if (znew > 0.0 && up * u.dt_my > 1e-4) {
                        og_word = with_byte(og_word, i, OROGENY_ANDEAN);
                        orogeny_age_my[i] = 0.0;
                    }
                }
                fold_dir[3u * i] = fold_dir[3u * i] + fr.fold_inc_x;
                fold_dir[3u * i + 1u] = fold_dir[3u * i + 1u] + fr.fold_inc_y;
                fold_dir[3u * i + 2u] = fold_dir[3u * i + 2u] + fr.fold_inc_z;
            }
        }
        if (u.isostatic == 0u && sp != NO_POINT && byte_of(ct_word, i) == CRUST_OCEANIC
            && z < u.ridge_elevation_km && fronts[sp].is_active != 0u) {
            let d = sd - fronts[sp].converged_km;
            if (d >= 0.0 && d < u.trench_width_km) {
                let trench_z = u.trench_elevation_km
                    + (u.abyssal_elevation_km - u.trench_elevation_km) * (d / u.trench_width_km);
                if (z > trench_z) {
                    z = z + (trench_z - z) * u.trench_rate;
                }
            }
        }
        elevation_km[i] = z;
    }
    orogeny[w] = og_word;
}
