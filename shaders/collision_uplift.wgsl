// Collision surge around one sutured terrane, in place: continental samples the surge reaches
// rise by Δz₀·(1 − (d/r)²)² (capped at z_c; with isostatic relief, the crust thickens by that
// rise over 1 − ρ_c/ρ_m instead, capped); where the rise exceeds 1 m they get Himalayan
// orogeny, orogeny age 0 and a fold direction pointing away from the terrane's centroid.
// CPU reference: collision_uplift_cpu (src/systems/convergence/collision.rs). The distances (great-circle,
// through the terrane's new plate) come from the host, which finds them by a graph search; one
// thread per four samples, because the orogeny field is packed four samples to a word.

// Keep in sync with CollisionUniforms in src/gpu/collision_uplift.rs.
struct CollisionUniforms {
    centroid_x: f32,
    centroid_y: f32,
    centroid_z: f32,
    // Δz₀, km.
    peak_km: f32,
    // Planet radius over r (distance in radians to d/r); 0 when r = 0.
    dist_scale: f32,
    // z_c, km.
    max_elevation_km: f32,
    count: u32,
    row_stride: u32,
    thickening: f32,
    max_thickness_km: f32,
    // 1: isostatic relief (thicken the crust only), 0: the paper's (raise the elevation).
    isostatic: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> u: CollisionUniforms;
@group(0) @binding(1) var<storage, read_write> elevation_km: array<f32>;
@group(0) @binding(2) var<storage, read_write> orogeny: array<u32>;
@group(0) @binding(3) var<storage, read_write> orogeny_age_my: array<f32>;
@group(0) @binding(4) var<storage, read_write> fold_dir: array<f32>;
@group(0) @binding(5) var<storage, read> crust_type: array<u32>;
// Reference positions, three f32 per sample (world frame, unit vectors).
@group(0) @binding(6) var<storage, read> positions: array<f32>;
// Distance to the terrane, radians, as f32 bits; infinite (or NaN) where the surge does not
// reach.
@group(0) @binding(7) var<storage, read> dist_bits: array<u32>;
@group(0) @binding(8) var<storage, read_write> thickness_km: array<f32>;

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
        let bits = dist_bits[i];
        // Exponent all ones: infinite or NaN, not reached (tested on the bits, so that no
        // compiler can assume finite floats).
        if ((bits & 0x7f800000u) == 0x7f800000u) {
            continue;
        }
        let d = bitcast<f32>(bits) * u.dist_scale;
        let e = max(1.0 - d * d, 0.0);
        let dz = u.peak_km * e * e;
        if (dz <= 0.0 || byte_of(ct_word, i) != CRUST_CONTINENTAL) {
            continue;
        }
        if (u.isostatic != 0u) {
            let t = thickness_km[i];
            thickness_km[i] = min(t + dz * u.thickening, max(u.max_thickness_km, t));
        } else {
            elevation_km[i] = min(elevation_km[i] + dz, u.max_elevation_km);
        }
        if (dz > 1e-3) {
            og_word = with_byte(og_word, i, OROGENY_HIMALAYAN);
            orogeny_age_my[i] = 0.0;
            let p = vec3<f32>(positions[3u * i], positions[3u * i + 1u], positions[3u * i + 2u]);
            let away = p - vec3<f32>(u.centroid_x, u.centroid_y, u.centroid_z);
            let t = away - p * dot(p, away);
            let len = length(t);
            var f = vec3<f32>(0.0);
            if (len > 0.0) {
                f = t / len;
            }
            fold_dir[3u * i] = f.x;
            fold_dir[3u * i + 1u] = f.y;
            fold_dir[3u * i + 2u] = f.z;
        }
    }
    orogeny[w] = og_word;
}
