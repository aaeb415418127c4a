// amplify: procedural amplification of the crust (paper §5), one invocation per query point.
// Mirrors `amplify_point` in src/amplify/procedural.rs line for line (keep both in sync):
// same structs, constants, hashes and noise; f32 arithmetic on both sides. Exemplar
// primitives are CPU only (the `exemplar` field is ignored here).

struct AmplifyVertex {
    px: f32, py: f32, pz: f32,
    ax: f32, ay: f32, az: f32,
    elevation_m: f32,
    age_my: f32,
    offset_x_km: f32,
    offset_y_km: f32,
    kind: u32,
    exemplar: u32,
};

struct AmplifyQuery {
    dx: f32, dy: f32, dz: f32,
    c0: u32, c1: u32, c2: u32,
    w0: f32, w1: f32, w2: f32,
};

struct AmplifyUniform {
    radius_km: f32,
    seed: u32,
    relief_scale: f32,
    count: u32,
    min_wavelength_km: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
};

@group(0) @binding(0) var<uniform> params: AmplifyUniform;
@group(0) @binding(1) var<storage, read> vertices: array<AmplifyVertex>;
@group(0) @binding(2) var<storage, read> queries: array<AmplifyQuery>;
@group(0) @binding(3) var<storage, read_write> out_elevation_m: array<f32>;

const KIND_OCEAN: u32 = 0u;
const KIND_PLAIN: u32 = 1u;
const KIND_ANDEAN: u32 = 2u;
const KIND_HIMALAYAN: u32 = 3u;
const MAX_RELIEF_M: f32 = 4000.0;

const OCEAN_HILL_WAVELENGTH_KM: f32 = 5.0;
const OCEAN_HILL_STRETCH: f32 = 5.0;
const OCEAN_HILL_AMP_M: f32 = 660.0;
const OCEAN_YOUNG_AGE_MY: f32 = 50.0;
const FAULT_SPACING_KM: f32 = 60.0;
const FAULT_WIDTH_KM: f32 = 4.0;
const FAULT_DEPTH_M: f32 = 300.0;
const FAULT_OFFSET_KM: f32 = 2.0;
const OCEAN_DETAIL_M: f32 = 20.0;
// The sea floor's relief grows to its full amplitude over this depth (procedural.rs: ocean_share).
const OCEAN_FULL_DEPTH_M: f32 = 2000.0;
const PLAIN_WAVELENGTH_KM: f32 = 30.0;
const PLAIN_AMP_M: f32 = 90.0;
const PLAIN_DETAIL_M: f32 = 12.0;
// Low plains are flat: the relief grows to its full amplitude over this crust elevation, and keeps
// at least PLAIN_LOW_SHARE of it (procedural.rs: plain_share).
const PLAIN_FULL_HEIGHT_M: f32 = 300.0;
const PLAIN_LOW_SHARE: f32 = 0.05;
const ANDEAN_WAVELENGTH_KM: f32 = 14.0;
const ANDEAN_STRETCH: f32 = 3.0;
const ANDEAN_AMP_M: f32 = 1300.0;
const HIMALAYAN_WAVELENGTH_KM: f32 = 18.0;
const HIMALAYAN_STRETCH: f32 = 2.5;
const HIMALAYAN_AMP_M: f32 = 1900.0;
const MOUNTAIN_FULL_HEIGHT_M: f32 = 3000.0;
const OROGENY_OLD_AGE_MY: f32 = 150.0;
const MOUNTAIN_DETAIL_FRACTION: f32 = 0.05;
const DETAIL_WAVELENGTH_KM: f32 = 0.8;
const RIDGE_MEAN: f32 = 0.62;
const BLEND_CUT: f32 = 0.2;

fn hash_u32(v: u32) -> u32 {
    var x = v;
    x = x ^ (x >> 16u);
    x = x * 0x7feb352du;
    x = x ^ (x >> 15u);
    x = x * 0x846ca68bu;
    x = x ^ (x >> 16u);
    return x;
}

fn hash01(x: u32) -> f32 {
    return f32(hash_u32(x) >> 8u) * (1.0 / 16777216.0);
}

fn fade(t: f32) -> f32 {
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
}

fn mix1(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}

fn grad2(h: u32, x: f32, y: f32) -> f32 {
    let d = 0.70710677;
    switch (h & 7u) {
        case 0u: { return x; }
        case 1u: { return -x; }
        case 2u: { return y; }
        case 3u: { return -y; }
        case 4u: { return d * (x + y); }
        case 5u: { return d * (x - y); }
        case 6u: { return d * (-x + y); }
        default: { return d * (-x - y); }
    }
}

fn corner2(seed: u32, ix: i32, iy: i32) -> u32 {
    return hash_u32((bitcast<u32>(ix) * 0x8da6b343u) ^ (bitcast<u32>(iy) * 0xd8163841u) ^ seed);
}

fn noise2(seed: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    let ix = i32(fx);
    let iy = i32(fy);
    let tx = x - fx;
    let ty = y - fy;
    let n00 = grad2(corner2(seed, ix, iy), tx, ty);
    let n10 = grad2(corner2(seed, ix + 1, iy), tx - 1.0, ty);
    let n01 = grad2(corner2(seed, ix, iy + 1), tx, ty - 1.0);
    let n11 = grad2(corner2(seed, ix + 1, iy + 1), tx - 1.0, ty - 1.0);
    let u = fade(tx);
    let v = fade(ty);
    return mix1(mix1(n00, n10, u), mix1(n01, n11, u), v);
}

fn corner3(seed: u32, ix: i32, iy: i32, iz: i32) -> u32 {
    return hash_u32((bitcast<u32>(ix) * 0x8da6b343u) ^ (bitcast<u32>(iy) * 0xd8163841u)
        ^ (bitcast<u32>(iz) * 0xcb1ab31fu) ^ seed);
}

fn grad3(h: u32, x: f32, y: f32, z: f32) -> f32 {
    switch (h & 15u) {
        case 0u, 12u: { return x + y; }
        case 1u, 13u: { return -x + y; }
        case 2u: { return x - y; }
        case 3u: { return -x - y; }
        case 4u: { return x + z; }
        case 5u: { return -x + z; }
        case 6u: { return x - z; }
        case 7u: { return -x - z; }
        case 8u: { return y + z; }
        case 9u, 14u: { return -y + z; }
        case 10u: { return y - z; }
        default: { return -y - z; }
    }
}

fn g3(seed: u32, ix: i32, iy: i32, iz: i32, tx: f32, ty: f32, tz: f32, dx: i32, dy: i32, dz: i32) -> f32 {
    return grad3(corner3(seed, ix + dx, iy + dy, iz + dz), tx - f32(dx), ty - f32(dy), tz - f32(dz));
}

fn noise3(seed: u32, x: f32, y: f32, z: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    let fz = floor(z);
    let ix = i32(fx);
    let iy = i32(fy);
    let iz = i32(fz);
    let tx = x - fx;
    let ty = y - fy;
    let tz = z - fz;
    let u = fade(tx);
    let v = fade(ty);
    let w = fade(tz);
    let x00 = mix1(g3(seed, ix, iy, iz, tx, ty, tz, 0, 0, 0), g3(seed, ix, iy, iz, tx, ty, tz, 1, 0, 0), u);
    let x10 = mix1(g3(seed, ix, iy, iz, tx, ty, tz, 0, 1, 0), g3(seed, ix, iy, iz, tx, ty, tz, 1, 1, 0), u);
    let x01 = mix1(g3(seed, ix, iy, iz, tx, ty, tz, 0, 0, 1), g3(seed, ix, iy, iz, tx, ty, tz, 1, 0, 1), u);
    let x11 = mix1(g3(seed, ix, iy, iz, tx, ty, tz, 0, 1, 1), g3(seed, ix, iy, iz, tx, ty, tz, 1, 1, 1), u);
    return mix1(mix1(x00, x10, v), mix1(x01, x11, v), w);
}

// How many of `octaves` octaves (wavelengths wl_km, wl_km / 2, ...) are at least the
// shortest wavelength evaluated.
fn kept_octaves(wl_km: f32, octaves: u32) -> u32 {
    var o = 0u;
    var w = wl_km;
    while (o < octaves && w >= params.min_wavelength_km) {
        o = o + 1u;
        w = w * 0.5;
    }
    return o;
}

fn fbm2(seed: u32, x: f32, y: f32, octaves: u32, kept: u32, gain: f32) -> f32 {
    var sum = 0.0;
    var norm = 0.0;
    var amp = 1.0;
    var freq = 1.0;
    for (var o = 0u; o < octaves; o = o + 1u) {
        if (o < kept) {
            sum = sum + amp * noise2(seed + o * 0x9e3779b9u, x * freq, y * freq);
        }
        norm = norm + amp;
        amp = amp * gain;
        freq = freq * 2.0;
    }
    return sum / norm;
}

// (relief m, detail amplitude m) of one vertex's primitive at unit direction p.
// Share of a plain's full relief at crust elevation `z` (procedural.rs: plain_share).
fn plain_share(z: f32) -> f32 {
    return clamp(z / PLAIN_FULL_HEIGHT_M, PLAIN_LOW_SHARE, 1.0);
}

fn vertex_relief(v: AmplifyVertex, p: vec3<f32>) -> vec2<f32> {
    let r = params.radius_km;
    let d = vec3<f32>((p.x - v.px) * r, (p.y - v.py) * r, (p.z - v.pz) * r);
    let b = vec3<f32>(v.py * v.az - v.pz * v.ay, v.pz * v.ax - v.px * v.az, v.px * v.ay - v.py * v.ax);
    let x = d.x * v.ax + d.y * v.ay + d.z * v.az + v.offset_x_km;
    let y = d.x * b.x + d.y * b.y + d.z * b.z + v.offset_y_km;
    let seed = params.seed;
    if (v.kind == KIND_OCEAN) {
        let young = 0.25 + 0.75 * exp(-max(v.age_my, 0.0) / OCEAN_YOUNG_AGE_MY);
        let s = x / FAULT_SPACING_KM;
        let k = floor(s);
        let ki = i32(k);
        let fault_seed = seed ^ 0x5bd1e995u;
        var nearest = 1.0e9;
        var segment = ki;
        for (var j = -1; j <= 1; j = j + 1) {
            let kj = ki + j;
            let pos = f32(kj) + 0.5 + 0.6 * (hash01(bitcast<u32>(kj) ^ fault_seed) - 0.5);
            let dist = s - pos;
            if (abs(dist) < abs(nearest)) {
                nearest = dist;
                if (dist >= 0.0) { segment = kj + 1; } else { segment = kj; }
            }
        }
        let dist_km = nearest * FAULT_SPACING_KM;
        let trough = exp(-(dist_km / FAULT_WIDTH_KM) * (dist_km / FAULT_WIDTH_KM));
        let trough_mean = FAULT_WIDTH_KM * 1.7724539 / FAULT_SPACING_KM;
        let shift = (hash01(bitcast<u32>(segment) ^ fault_seed ^ 0x68e31da4u) - 0.5)
            * 2.0 * FAULT_OFFSET_KM;
        // Abyssal hills parallel to the ridge (x: ridge axis, y: spreading direction); each
        // segment offset across the ridge.
        let hills = fbm2(seed, x / (OCEAN_HILL_WAVELENGTH_KM * OCEAN_HILL_STRETCH),
            (y + shift) / OCEAN_HILL_WAVELENGTH_KM, 3u, kept_octaves(OCEAN_HILL_WAVELENGTH_KM, 3u), 0.5);
        let share = clamp(-v.elevation_m / OCEAN_FULL_DEPTH_M, PLAIN_LOW_SHARE, 1.0);
        let relief = share * young
            * (OCEAN_HILL_AMP_M * 1.4 * hills - FAULT_DEPTH_M * (trough - trough_mean));
        return vec2<f32>(relief, share * OCEAN_DETAIL_M);
    } else if (v.kind == KIND_PLAIN) {
        let n = fbm2(seed ^ 0x1b873593u, x / PLAIN_WAVELENGTH_KM, y / PLAIN_WAVELENGTH_KM, 4u,
            kept_octaves(PLAIN_WAVELENGTH_KM, 4u), 0.5);
        let share = plain_share(v.elevation_m);
        return vec2<f32>(share * PLAIN_AMP_M * 1.4 * n, share * PLAIN_DETAIL_M);
    }
    let him = v.kind == KIND_HIMALAYAN;
    var wl = ANDEAN_WAVELENGTH_KM;
    var stretch = ANDEAN_STRETCH;
    var amp0 = ANDEAN_AMP_M;
    var mseed = seed ^ 0x85ebca6bu;
    if (him) {
        wl = HIMALAYAN_WAVELENGTH_KM;
        stretch = HIMALAYAN_STRETCH;
        amp0 = HIMALAYAN_AMP_M;
        mseed = seed ^ 0xcc9e2d51u;
    }
    let height = clamp(v.elevation_m / MOUNTAIN_FULL_HEIGHT_M, 0.1, 1.0)
        * plain_share(v.elevation_m);
    let fresh = exp(-max(v.age_my, 0.0) / OROGENY_OLD_AGE_MY);
    let amp = amp0 * height * (0.35 + 0.65 * fresh);
    let gain = 0.35 + 0.2 * fresh;
    // x: compression_dir (the fold direction), y: range_axis; crests run along the range axis.
    let gx = x / wl;
    let gy = y / (wl * stretch);
    // One noise per octave feeds both the ridged (young) and the rounded (old) relief.
    var ridges = 0.0;
    var rounded = 0.0;
    var norm = 0.0;
    var oamp = 1.0;
    var freq = 1.0;
    let kept = kept_octaves(wl, 4u);
    for (var o = 0u; o < 4u; o = o + 1u) {
        if (o < kept) {
            let n = noise2(mseed + o * 0x9e3779b9u, gx * freq, gy * freq);
            let r = 1.0 - abs(n) * 1.4;
            ridges = ridges + oamp * (r * r - RIDGE_MEAN);
            rounded = rounded + oamp * n;
        }
        norm = norm + oamp;
        oamp = oamp * gain;
        freq = freq * 2.0;
    }
    let relief = amp * (fresh * ridges * 2.5 + (1.0 - fresh) * 1.4 * rounded) / norm;
    return vec2<f32>(relief, MOUNTAIN_DETAIL_FRACTION * amp);
}

fn detail(p: vec3<f32>) -> f32 {
    let f = params.radius_km / DETAIL_WAVELENGTH_KM;
    let s = params.seed ^ 0xe6546b64u;
    let x = p.x * f;
    let y = p.y * f;
    let z = p.z * f;
    // Each octave only where the output resolves it.
    var n0 = 0.0;
    var n1 = 0.0;
    if (DETAIL_WAVELENGTH_KM >= params.min_wavelength_km) {
        n0 = noise3(s, x, y, z);
    }
    if (DETAIL_WAVELENGTH_KM / 2.5 >= params.min_wavelength_km) {
        n1 = noise3(s + 1u, 2.5 * x, 2.5 * y, 2.5 * z);
    }
    let n = n0 + 0.5 * n1;
    return n / 1.5;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= params.count) {
        return;
    }
    let q = queries[i];
    let p = vec3<f32>(q.dx, q.dy, q.dz);
    let n = arrayLength(&vertices);
    var corners = array<u32, 3>(q.c0, q.c1, q.c2);
    var weights = array<f32, 3>(q.w0, q.w1, q.w2);
    var base = 0.0;
    var relief = 0.0;
    var detail_amp = 0.0;
    var w2 = 0.0;
    var wsum = 0.0;
    for (var k = 0u; k < 3u; k = k + 1u) {
        let c = corners[k];
        let w = weights[k];
        if (c >= n) {
            continue;
        }
        let v = vertices[c];
        base = base + w * v.elevation_m;
        let wp = w - BLEND_CUT;
        if (wp > 0.0) {
            let rd = vertex_relief(v, p);
            relief = relief + wp * rd.x;
            detail_amp = detail_amp + wp * rd.y;
            w2 = w2 + wp * wp;
            wsum = wsum + wp;
        }
    }
    detail_amp = detail_amp / max(wsum, 1.0e-12);
    let blended = relief / sqrt(max(w2, 1.0e-12));
    let total = (blended + detail_amp * detail(p)) * params.relief_scale;
    out_elevation_m[i] = base + clamp(total, -MAX_RELIEF_M, MAX_RELIEF_M);
}
