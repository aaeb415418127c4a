// Resampling, point location: for every reference sample, the plate that covers it after the
// plates moved, the triangle of the reference mesh (in that plate's frame) and the barycentric
// weights there, with the overlap rules (sutures > continental over oceanic > overriding plate
// of a front > plate rank). One thread per sample. CPU reference: resample_locate_cpu and
// locate_one (src/systems/resample.rs), whose steps this follows one for one.
//
// The GPU computes in f32, the CPU in f64. Every decision that f32 rounding could flip (a point
// within `doubt_w` of a triangle edge or of a tie between two corners, a continental weight
// within `doubt_w` of 1/2, a point within `doubt_cell` of a locator cell boundary, a point at
// the rim of a plate's cap) is not taken here: the sample is flagged DOUBT and the host locates
// it again with the CPU code. Every other sample gets the CPU's plate, triangle and flags, and
// weights within f32 rounding of the CPU's.

// Keep in sync with LocateUniforms in src/gpu/resample_locate.rs.
struct LocateUniforms {
    count: u32,
    row_stride: u32,
    plate_count: u32,
    pair_count: u32,
    suture_len: u32,
    grid: u32,
    cell_count: u32,
    pairs_at: u32,
    targets_at: u32,
    cells_at: u32,
    doubt_w: f32,
    doubt_cell: f32,
}

// Words of one plate in `aux` (keep in sync with GpuPlate in src/gpu/resample_locate.rs):
// rows of plate_from_world (x, y, z) each followed by one coordinate of the cap centroid (world),
// then cap_cos, id, slot, padding.
const PLATE_WORDS: u32 = 16u;
const NONE32: u32 = 0xffffffffu;
const FLAG_CONTINENTAL_LOST: u32 = 1u;
const FLAG_DOUBT: u32 = 2u;
// Cell lists (src/systems/resample.rs, CellPlates): EMPTY and MANY.
const CELL_EMPTY: u32 = 0xffffu;
const CELL_MANY: u32 = 0xfffeu;
// Half-width of the band around a cap rim in which the cap test is left to the CPU.
const DOUBT_CAP: f32 = 1e-5;

@group(0) @binding(0) var<uniform> uni: LocateUniforms;
// Reference positions, three f32 per sample.
@group(0) @binding(1) var<storage, read> positions: array<f32>;
// Reference triangles, three u32 per triangle.
@group(0) @binding(2) var<storage, read> triangles: array<u32>;
// Locator: cell_count + 1 cell starts, then the triangle lists.
@group(0) @binding(3) var<storage, read> cells: array<u32>;
// Per resampling: plates in rank order (PLATE_WORDS each), override pairs (two words each, at
// pairs_at), suture targets (at targets_at), cell plate lists (two words per cell, at cells_at).
@group(0) @binding(4) var<storage, read> aux: array<u32>;
// Plate id of every sample of the old crust.
@group(0) @binding(5) var<storage, read> old_plate: array<u32>;
// Crust type of the old crust, u8 per sample packed four to a word.
@group(0) @binding(6) var<storage, read> crust_type: array<u32>;
// Pending suture of every old sample (NONE32 if none); suture_len entries (0: no sutures).
@group(0) @binding(7) var<storage, read> suture_of_sample: array<u32>;
// Output, eight words per sample: slot, plate, suture, flags, triangle, three weights (f32 bits).
@group(0) @binding(8) var<storage, read_write> located: array<u32>;

fn position(v: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
}

fn aux_f(k: u32) -> f32 {
    return bitcast<f32>(aux[k]);
}

// Same as warp() in src/geometry/locator.rs.
fn warp(t: f32) -> f32 {
    return t * (1.2732 - 0.2732 * abs(t));
}

fn cell_coord(t: f32) -> vec2<f32> {
    // (cell index along the axis, distance to the nearest cell boundary in cells)
    let g = f32(uni.grid);
    let s = (warp(t) + 1.0) * 0.5 * g;
    let i = min(max(floor(s), 0.0), g - 1.0);
    return vec2<f32>(i, abs(s - round(s)));
}

struct Cell {
    index: u32,
    doubt: bool,
}

// MeshLocator::cell_of, with a flag for points near a cell or face boundary.
fn cell_of(p: vec3<f32>) -> Cell {
    let a = abs(p);
    var face = 0u;
    var u = 0.0;
    var v = 0.0;
    if (a.x >= a.y && a.x >= a.z) {
        face = select(1u, 0u, p.x >= 0.0);
        u = p.y / a.x;
        v = p.z / a.x;
    } else if (a.y >= a.z) {
        face = select(3u, 2u, p.y >= 0.0);
        u = p.x / a.y;
        v = p.z / a.y;
    } else {
        face = select(5u, 4u, p.z >= 0.0);
        u = p.x / a.z;
        v = p.y / a.z;
    }
    let cu = cell_coord(u);
    let cv = cell_coord(v);
    var out: Cell;
    out.index = face * uni.grid * uni.grid + u32(cv.x) * uni.grid + u32(cu.x);
    out.doubt = cu.y < uni.doubt_cell || cv.y < uni.doubt_cell;
    return out;
}

fn may_cover(c: u32, slot: u32) -> bool {
    let w0 = aux[uni.cells_at + 2u * c];
    let w1 = aux[uni.cells_at + 2u * c + 1u];
    var l = array<u32, 4>(w0 & 0xffffu, w0 >> 16u, w1 & 0xffffu, w1 >> 16u);
    let s = slot & 0xffffu;
    return l[0] == CELL_MANY || l[0] == s || l[1] == s || l[2] == s || l[3] == s;
}

struct Loc {
    triangle: u32,
    w: vec3<f32>,
    m: f32,
    found: bool,
}

// MeshLocator::locate_in_cell: the candidate of cell `c` in which `q` is most inside. Weights
// are those of the central projection, computed relative to the first vertex so that the small
// triangle is not lost in the rounding of unit vectors:
// s = q·((b−a)×(c−a)), w_b = (q−a)·((c−a)×a), w_c = (q−a)·(a×(b−a)), w_a = s − w_b − w_c.
fn locate(q: vec3<f32>, c: u32) -> Loc {
    var best: Loc;
    best.found = false;
    best.m = -3.0e38;
    best.triangle = 0u;
    best.w = vec3<f32>(1.0, 0.0, 0.0);
    let start = cells[c];
    let end = cells[c + 1u];
    let list = uni.cell_count + 1u;
    for (var k = start; k < end; k++) {
        let t = cells[list + k];
        let a = position(triangles[3u * t]);
        let b = position(triangles[3u * t + 1u]) - a;
        let cc = position(triangles[3u * t + 2u]) - a;
        let s = dot(q, cross(b, cc));
        if (s <= 0.0) {
            continue;
        }
        let qa = q - a;
        let wb = dot(qa, cross(cc, a));
        let wc = dot(qa, cross(a, b));
        let w = vec3<f32>(s - wb - wc, wb, wc) / s;
        let m = min(w.x, min(w.y, w.z));
        if (!best.found || m > best.m || (m == best.m && t < best.triangle)) {
            best.found = true;
            best.triangle = t;
            best.w = w;
            best.m = m;
            // Inside by more than the rounding: no other triangle can contain the point.
            if (m > uni.doubt_w) {
                break;
            }
        }
    }
    return best;
}

fn is_pair(overriding: u32, subducting: u32) -> bool {
    for (var k = 0u; k < uni.pair_count; k++) {
        if (aux[uni.pairs_at + 2u * k] == overriding && aux[uni.pairs_at + 2u * k + 1u] == subducting) {
            return true;
        }
    }
    return false;
}

struct Hit {
    slot: u32,
    plate: u32,
    suture: u32,
    lost: bool,
    triangle: u32,
    w: vec3<f32>,
    sutured: bool,
    continental: bool,
}

fn write_out(i: u32, slot: u32, plate: u32, suture: u32, flags: u32, triangle: u32, w: vec3<f32>) {
    let o = 8u * i;
    located[o] = slot;
    located[o + 1u] = plate;
    located[o + 2u] = suture;
    located[o + 3u] = flags;
    located[o + 4u] = triangle;
    located[o + 5u] = bitcast<u32>(w.x);
    located[o + 6u] = bitcast<u32>(w.y);
    located[o + 7u] = bitcast<u32>(w.z);
}

fn doubt(i: u32) {
    write_out(i, NONE32, NONE32, NONE32, FLAG_DOUBT, 0u, vec3<f32>(0.0));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x + gid.y * uni.row_stride;
    if (i >= uni.count) {
        return;
    }
    let q = position(i);
    var have = false;
    var best: Hit;
    for (var r = 0u; r < uni.plate_count; r++) {
        let p = r * PLATE_WORDS;
        let row0 = vec3<f32>(aux_f(p), aux_f(p + 1u), aux_f(p + 2u));
        let row1 = vec3<f32>(aux_f(p + 4u), aux_f(p + 5u), aux_f(p + 6u));
        let row2 = vec3<f32>(aux_f(p + 8u), aux_f(p + 9u), aux_f(p + 10u));
        let centroid = vec3<f32>(aux_f(p + 3u), aux_f(p + 7u), aux_f(p + 11u));
        let cap_cos = aux_f(p + 12u);
        let id = aux[p + 13u];
        let slot = aux[p + 14u];
        let cd = dot(q, centroid);
        if (abs(cd - cap_cos) < DOUBT_CAP) {
            doubt(i);
            return;
        }
        if (cd < cap_cos) {
            continue;
        }
        let ql = vec3<f32>(dot(row0, q), dot(row1, q), dot(row2, q));
        let cell = cell_of(ql);
        if (cell.doubt) {
            doubt(i);
            return;
        }
        if (!may_cover(cell.index, slot)) {
            continue;
        }
        let loc = locate(ql, cell.index);
        if (!loc.found || loc.m < uni.doubt_w) {
            doubt(i);
            return;
        }
        var v = array<u32, 3>(
            triangles[3u * loc.triangle],
            triangles[3u * loc.triangle + 1u],
            triangles[3u * loc.triangle + 2u],
        );
        var owners = array<u32, 3>(old_plate[v[0]], old_plate[v[1]], old_plate[v[2]]);
        if (owners[0] != id && owners[1] != id && owners[2] != id) {
            continue;
        }
        // Dominant corner (ties to the lowest index), refused near a tie.
        let w = loc.w;
        var corner = 2u;
        if (w.x >= w.y && w.x >= w.z) {
            corner = 0u;
        } else if (w.y >= w.z) {
            corner = 1u;
        }
        var wd = array<f32, 3>(w.x, w.y, w.z);
        for (var k = 0u; k < 3u; k++) {
            if (k != corner && wd[corner] - wd[k] < uni.doubt_w) {
                doubt(i);
                return;
            }
        }
        if (owners[corner] != id) {
            continue;
        }
        let d = v[corner];
        var hit: Hit;
        hit.slot = slot;
        hit.plate = id;
        hit.suture = NONE32;
        hit.lost = false;
        hit.triangle = loc.triangle;
        hit.w = w;
        if (d < uni.suture_len) {
            hit.suture = suture_of_sample[d];
        }
        hit.sutured = hit.suture != NONE32;
        if (hit.sutured) {
            hit.plate = aux[uni.targets_at + hit.suture];
        }
        var cont = 0.0;
        for (var k = 0u; k < 3u; k++) {
            if (byte_of(crust_type[v[k] >> 2u], v[k]) == CRUST_CONTINENTAL) {
                cont += wd[k];
            }
        }
        if (abs(cont - 0.5) < uni.doubt_w) {
            doubt(i);
            return;
        }
        hit.continental = cont >= 0.5;
        if (!have) {
            best = hit;
            have = true;
        } else {
            let kh = select(0u, 2u, hit.sutured) + select(0u, 1u, hit.continental);
            let kb = select(0u, 2u, best.sutured) + select(0u, 1u, best.continental);
            let beats = kh > kb || (kh == kb && is_pair(hit.plate, best.plate));
            var win = best;
            var lose = hit;
            if (beats) {
                win = hit;
                lose = best;
            }
            win.lost = win.lost || (lose.continental && !lose.sutured);
            best = win;
        }
    }
    if (!have) {
        write_out(i, NONE32, NONE32, NONE32, 0u, 0u, vec3<f32>(0.0));
        return;
    }
    write_out(i, best.slot, best.plate, best.suture, select(0u, FLAG_CONTINENTAL_LOST, best.lost), best.triangle, best.w);
}
