// Interpolation of a resampling: every field of the old crust at each sample's located source
// (triangle and barycentric weights in the covering plate's frame) into the new crust. CPU
// reference: resample_interpolate_cpu (`interpolate` in src/systems/resample.rs). Gaps get
// zeros, oceanic crust and no plate. Only vertices of the covering plate or of a plate that
// moved exactly like it count (same frame group, computed on the host); the crust type is the
// weighted vote; scalars are interpolated over the vertices of the output crust type only;
// the orogeny comes from the dominant vertex; directions are rotated to the world and projected
// onto the tangent plane. One thread per four samples (u8 fields are packed four to a word).

// Keep in sync with InterpolateUniforms in src/gpu/resample_interpolate.rs.
struct InterpolateUniforms {
    count: u32,
    row_stride: u32,
    // Words of a packed u8 field: ceil(count / 4).
    packed_words: u32,
    // Word offset in `plates` of the frame group of each plate id, and its entries.
    ids_at: u32,
    id_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Layout of the old crust (`old`) and of the new one (`next`), in words, for n samples and
// nw = ceil(n / 4): elevation [0, n), thickness [n, 2n), age [2n, 3n), orogeny age [3n, 4n),
// ridge direction [4n, 7n), fold direction [7n, 10n), crust type (packed) [10n, 10n + nw),
// orogeny (packed) [10n + nw, 10n + 2nw), then the plate id of each sample
// [10n + 2nw, 11n + 2nw).

@group(0) @binding(0) var<uniform> u: InterpolateUniforms;
// Per sample, 8 words: slot (NONE32 for a gap), plate, suture, flags, triangle, 3 weights.
@group(0) @binding(1) var<storage, read> sources: array<u32>;
// Per slot, 16 words: frame group, 3 unused, then the rows of world ← plate, each padded to 4;
// then, from word `u.ids_at`, the frame group of each plate id (NONE32 for no plate).
@group(0) @binding(2) var<storage, read> plates: array<u32>;
// Reference positions (3 f32 a sample) then the triangles (3 u32 a triangle) from word
// `3 * count`.
@group(0) @binding(3) var<storage, read> mesh: array<u32>;
@group(0) @binding(4) var<storage, read> old: array<u32>;
@group(0) @binding(5) var<storage, read_write> next: array<u32>;

const NONE32: u32 = 0xffffffffu;

fn old_f(k: u32) -> f32 {
    return bitcast<f32>(old[k]);
}

fn old_byte(section: u32, v: u32) -> u32 {
    return byte_of(old[section + (v >> 2u)], v);
}

// The frame group of the old plate of vertex v (NONE32 for a plate not in the table).
fn old_group(tail_at: u32, v: u32) -> u32 {
    let id = old[tail_at + v];
    if (id < u.id_count) {
        return plates[u.ids_at + id];
    }
    return NONE32;
}

fn lerp(section: u32, v: vec3<u32>, w: vec3<f32>) -> f32 {
    return w.x * old_f(section + v.x) + w.y * old_f(section + v.y) + w.z * old_f(section + v.z);
}

fn old_dir(section: u32, v: u32) -> vec3<f32> {
    return vec3<f32>(old_f(section + 3u * v), old_f(section + 3u * v + 1u), old_f(section + 3u * v + 2u));
}

fn write_dir(section: u32, i: u32, d: vec3<f32>) {
    next[section + 3u * i] = bitcast<u32>(d.x);
    next[section + 3u * i + 1u] = bitcast<u32>(d.y);
    next[section + 3u * i + 2u] = bitcast<u32>(d.z);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let wi = gid.x + gid.y * u.row_stride;
    let first = wi * 4u;
    let n = u.count;
    if (first >= n) {
        return;
    }
    let nw = u.packed_words;
    let ct_at = 10u * n;
    let og_at = 10u * n + nw;
    let tail_at = 10u * n + 2u * nw;
    var ct_word = 0u;
    var og_word = 0u;
    let last = min(first + 4u, n);
    for (var i = first; i < last; i = i + 1u) {
        let s = 8u * i;
        let slot = sources[s];
        if (slot == NONE32) {
            next[i] = 0u;
            next[n + i] = 0u;
            next[2u * n + i] = 0u;
            next[3u * n + i] = 0u;
            write_dir(4u * n, i, vec3<f32>(0.0));
            write_dir(7u * n, i, vec3<f32>(0.0));
            ct_word = with_byte(ct_word, i, CRUST_OCEANIC);
            og_word = with_byte(og_word, i, OROGENY_NONE);
            next[tail_at + i] = NONE32;
            continue;
        }
        let t = sources[s + 4u];
        let tri_at = 3u * n + 3u * t;
        let v = vec3<u32>(mesh[tri_at], mesh[tri_at + 1u], mesh[tri_at + 2u]);
        var w_all = vec3<f32>(
            bitcast<f32>(sources[s + 5u]),
            bitcast<f32>(sources[s + 6u]),
            bitcast<f32>(sources[s + 7u]),
        );
        let p = 16u * slot;
        let group = plates[p];
        let valid = vec3<bool>(
            old_group(tail_at, v.x) == group,
            old_group(tail_at, v.y) == group,
            old_group(tail_at, v.z) == group,
        );
        let kept = select(0.0, w_all.x, valid.x) + select(0.0, w_all.y, valid.y)
            + select(0.0, w_all.z, valid.z);
        if (kept > 0.0 && kept < 1.0) {
            w_all = select(vec3<f32>(0.0), w_all / kept, valid);
        }
        let is_cont = vec3<bool>(
            old_byte(ct_at, v.x) == CRUST_CONTINENTAL,
            old_byte(ct_at, v.y) == CRUST_CONTINENTAL,
            old_byte(ct_at, v.z) == CRUST_CONTINENTAL,
        );
        let cont = select(0.0, w_all.x, is_cont.x) + select(0.0, w_all.y, is_cont.y)
            + select(0.0, w_all.z, is_cont.z);
        let out_cont = cont > 0.5;
        var same = 1.0 - cont;
        if (out_cont) {
            same = cont;
        }
        var w = w_all;
        if (same > 0.0) {
            let keep = is_cont == vec3<bool>(out_cont);
            w = select(vec3<f32>(0.0), w_all / same, keep);
        }
        next[i] = bitcast<u32>(lerp(0u, v, w));
        next[n + i] = bitcast<u32>(lerp(n, v, w));
        next[2u * n + i] = bitcast<u32>(lerp(2u * n, v, w));
        next[3u * n + i] = bitcast<u32>(lerp(3u * n, v, w));
        let r0 = vec3<f32>(bitcast<f32>(plates[p + 4u]), bitcast<f32>(plates[p + 5u]), bitcast<f32>(plates[p + 6u]));
        let r1 = vec3<f32>(bitcast<f32>(plates[p + 8u]), bitcast<f32>(plates[p + 9u]), bitcast<f32>(plates[p + 10u]));
        let r2 = vec3<f32>(bitcast<f32>(plates[p + 12u]), bitcast<f32>(plates[p + 13u]), bitcast<f32>(plates[p + 14u]));
        let q = vec3<f32>(bitcast<f32>(mesh[3u * i]), bitcast<f32>(mesh[3u * i + 1u]), bitcast<f32>(mesh[3u * i + 2u]));
        for (var f = 0u; f < 2u; f = f + 1u) {
            let section = select(7u * n, 4u * n, f == 0u);
            let acc = old_dir(section, v.x) * w.x + old_dir(section, v.y) * w.y
                + old_dir(section, v.z) * w.z;
            var out = vec3<f32>(0.0);
            if (any(acc != vec3<f32>(0.0))) {
                let world = vec3<f32>(dot(r0, acc), dot(r1, acc), dot(r2, acc));
                out = world - q * dot(q, world);
            }
            write_dir(section, i, out);
        }
        // Dominant corner of w, ties to the lowest index.
        var d = v.z;
        if (w.x >= w.y && w.x >= w.z) {
            d = v.x;
        } else if (w.y >= w.z) {
            d = v.y;
        }
        ct_word = with_byte(ct_word, i, select(CRUST_OCEANIC, CRUST_CONTINENTAL, out_cont));
        og_word = with_byte(og_word, i, old_byte(og_at, d));
        next[tail_at + i] = sources[s + 1u];
    }
    next[ct_at + wi] = ct_word;
    next[og_at + wi] = og_word;
}
