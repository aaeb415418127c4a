// Land diffusion, explicit finite volumes with cotangent weights, on the resident elevation
// buffer. CPU reference: diffuse_land (src/systems/relief/diffusion.rs). f32 throughout.
//
//   a_i dh_i/dt = κ Σ_j w_ij (h_j − h_i)  between land samples,
//   a land sample beside an ocean sample j loses κ·w_ij·max(h_i, 0) to it (the coast is held
//   at sea level), and j's receipt accumulates that outflow.
//
// One dispatch per phase over count + coast_count threads (thread count + k is coast sample k):
//   phase 0: h_out = elevation (0 where it is not finite); receipts = 0.
//   phase 1: one explicit sub-step, h_in → h_out on land; receipts += κ·Δt_sub·Σ w·max(h, 0).
//   phase 2: elevation = h_in on land where the elevation was finite.
// The host alternates two bind groups (h_in, h_out swapped) between sub-steps.

// Keep in sync with DiffusionUniforms in src/gpu/diffusion.rs.
struct DiffusionUniforms {
    rate: f32,
    count: u32,
    coast_count: u32,
    phase: u32,
    row_stride: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> u: DiffusionUniforms;
// Per sample (and one past the last): the CSR start of its edges and its area (f32 bits, km²).
@group(0) @binding(1) var<storage, read> nodes: array<vec2<u32>>;
// Per directed edge: the neighbour and the cotangent weight (f32 bits).
@group(0) @binding(2) var<storage, read> edges: array<vec2<u32>>;
// Ocean mask, one bit a sample (bit i & 31 of word i >> 5).
@group(0) @binding(3) var<storage, read> ocean: array<u32>;
@group(0) @binding(4) var<storage, read_write> elevation_km: array<u32>;
@group(0) @binding(5) var<storage, read> h_in: array<f32>;
@group(0) @binding(6) var<storage, read_write> h_out: array<f32>;
// Coast samples (ocean samples with a land neighbour) and the outflow each received, km³.
@group(0) @binding(7) var<storage, read> coast: array<u32>;
@group(0) @binding(8) var<storage, read_write> receipts: array<f32>;

fn is_ocean(i: u32) -> bool {
    return ((ocean[i >> 5u] >> (i & 31u)) & 1u) != 0u;
}

fn is_finite_bits(b: u32) -> bool {
    return (b & 0x7f800000u) != 0x7f800000u;
}

fn land_step(i: u32) {
    if (is_ocean(i)) {
        return;
    }
    let hi = h_in[i];
    let node = nodes[i];
    let area = bitcast<f32>(node.y);
    if (!(area > 0.0)) {
        h_out[i] = hi;
        return;
    }
    var flux = 0.0;
    let end = nodes[i + 1u].x;
    for (var e = node.x; e < end; e = e + 1u) {
        let edge = edges[e];
        let w = bitcast<f32>(edge.y);
        if (is_ocean(edge.x)) {
            flux = flux - w * max(hi, 0.0);
        } else {
            flux = flux + w * (h_in[edge.x] - hi);
        }
    }
    h_out[i] = hi + u.rate * flux / area;
}

fn coast_step(k: u32) {
    let j = coast[k];
    let node = nodes[j];
    let end = nodes[j + 1u].x;
    var v = 0.0;
    for (var e = node.x; e < end; e = e + 1u) {
        let edge = edges[e];
        if (!is_ocean(edge.x)) {
            v = v + bitcast<f32>(edge.y) * max(h_in[edge.x], 0.0);
        }
    }
    receipts[k] = receipts[k] + u.rate * v;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.x + gid.y * u.row_stride;
    if (t >= u.count + u.coast_count) {
        return;
    }
    if (t >= u.count) {
        let k = t - u.count;
        if (u.phase == 0u) {
            receipts[k] = 0.0;
        } else if (u.phase == 1u) {
            coast_step(k);
        }
        return;
    }
    if (u.phase == 0u) {
        let b = elevation_km[t];
        if (is_finite_bits(b)) {
            h_out[t] = bitcast<f32>(b);
        } else {
            h_out[t] = 0.0;
        }
    } else if (u.phase == 1u) {
        land_step(t);
    } else if (!is_ocean(t) && is_finite_bits(elevation_km[t])) {
        elevation_km[t] = bitcast<u32>(h_in[t]);
    }
}
