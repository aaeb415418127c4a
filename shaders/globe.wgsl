// The viewer's 3D globe: a latitude/longitude grid sphere displaced by the elevation (with an
// exaggeration), coloured by the map overlay the 2D view shows, lit by a sun near the camera.
// With the sea surface on, what lies below sea level is drawn at sea level, tinted by depth.
// Host side: src/viewer/globe.rs (keep `Globe` in sync with `GlobeUniforms` there).

const PI: f32 = 3.141592653589793;

struct Globe {
    // Clip from world (the unit sphere, +z north).
    view_proj: mat4x4<f32>,
    // Unit direction toward the sun, world frame (w unused).
    light_dir: vec4<f32>,
    // x: radius change per km of elevation (exaggeration / planet radius);
    // y: 1 with the sea surface, 0 without; z, w: unused.
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globe: Globe;
// The overlay colours, equirectangular (row 0 north, column 0 at longitude -180°).
@group(0) @binding(1) var colour_tex: texture_2d<f32>;
@group(0) @binding(2) var colour_sampler: sampler;
// Elevation, km (r32float, read with textureLoad), same layout.
@group(0) @binding(3) var elevation_tex: texture_2d<f32>;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    // Sunlight, per vertex (the grid is finer than the pixels it covers).
    @location(1) lit: f32,
    @location(2) elevation_km: f32,
};

@vertex
fn vs_main(@location(0) lat_lon: vec2<f32>) -> VsOut {
    let lat = lat_lon.x;
    let lon = lat_lon.y;
    let dir = vec3<f32>(cos(lat) * cos(lon), cos(lat) * sin(lon), sin(lat));
    let uv = vec2<f32>((lon + PI) / (2.0 * PI), (0.5 * PI - lat) / PI);
    let dims = vec2<i32>(textureDimensions(elevation_tex));
    let texel = clamp(vec2<i32>(uv * vec2<f32>(dims)), vec2<i32>(0, 0), dims - vec2<i32>(1, 1));
    let e = textureLoad(elevation_tex, texel, 0).r;
    var shown = e;
    if (globe.params.y > 0.5) {
        shown = max(e, 0.0);
    }
    let r = 1.0 + globe.params.x * shown;
    var out: VsOut;
    out.clip = globe.view_proj * vec4<f32>(dir * r, 1.0);
    out.uv = uv;
    out.lit = 0.30 + 0.70 * max(dot(dir, globe.light_dir.xyz), 0.0);
    out.elevation_km = e;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    // One texel load (nearest) instead of a filtered sample: the texture is about as fine as
    // the screen, and a software rasteriser pays for every tap.
    let dims = vec2<i32>(textureDimensions(colour_tex));
    let texel = clamp(vec2<i32>(in.uv * vec2<f32>(dims)), vec2<i32>(0, 0), dims - vec2<i32>(1, 1));
    var c = textureLoad(colour_tex, texel, 0).rgb;
    if (globe.params.y > 0.5 && in.elevation_km < 0.0) {
        let depth = clamp(-in.elevation_km / 8.0, 0.0, 1.0);
        c = mix(c, vec3<f32>(0.04, 0.16, 0.40), 0.30 + 0.45 * depth);
    }
    return vec4<f32>(c * in.lit, 1.0);
}

// The flat map (the viewer's 2D view): a quad over the paint callback's viewport, coloured from
// the same texture, texel by texel (nearest) and without blending, which keeps a software
// rasteriser's work per pixel to one load and one store.
struct MapOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_map(@builtin(vertex_index) i: u32) -> MapOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0),
    );
    let c = corners[i];
    var out: MapOut;
    out.clip = vec4<f32>(c.x * 2.0 - 1.0, 1.0 - c.y * 2.0, 0.0, 1.0);
    out.uv = c;
    return out;
}

@fragment
fn fs_map(in: MapOut) -> @location(0) vec4<f32> {
    let dims = vec2<i32>(textureDimensions(colour_tex));
    let texel = clamp(vec2<i32>(in.uv * vec2<f32>(dims)), vec2<i32>(0, 0), dims - vec2<i32>(1, 1));
    return vec4<f32>(textureLoad(colour_tex, texel, 0).rgb, 1.0);
}
