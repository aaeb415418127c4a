//! The 2D equirectangular map of the viewer: base layers (elevation with hypsometric tint and
//! hillshade, plates, crust type, oceanic age, orogeny type and age, elevation Laplacian,
//! rivers and lakes, drainage basins, crust thickness)
//! coloured from a [`Snapshot`], and vector layers (fold and ridge directions, plate velocity
//! arrows, subduction fronts and terranes from their entities) painted on top.

use eframe::egui;
use egui::{Color32, ColorImage, Pos2, Rect, Vec2};
use glam::DVec3;
use rayon::prelude::*;

use crate::commands::LatLon;
use crate::geometry::spherical::to_lat_lon_deg;
use crate::io::maps::{MapSample, Raster, plate_colour};
use crate::io::rivers;
use crate::resources::{CrustType, Orogeny};

use super::worker::Snapshot;

/// What the map is coloured by.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BaseLayer {
    /// Hypsometric tint with hillshade.
    Elevation,
    /// One colour per plate, continents lighter.
    Plates,
    /// Continental or oceanic, with the coastline.
    CrustType,
    /// Age of the ocean floor.
    OceanicAge,
    /// Andean or Himalayan orogeny.
    OrogenyType,
    /// Time since the last orogeny.
    OrogenyAge,
    /// Laplacian of the elevation (ridges bright, valleys dark).
    Laplacian,
    /// Rivers and lakes over the elevation (the drainage network of the crust shown).
    Rivers,
    /// Drainage basins, one colour each (the land that drains to one outlet).
    Basins,
    /// Crust thickness.
    Thickness,
    /// Relative rain over the land (the phenomenon `climate`), rivers on top.
    Rain,
    /// Relative pelagic rain over the sea (`sediment.pelagic_variability`), the land grey.
    PelagicRain,
}

impl BaseLayer {
    /// Every base layer, in menu order.
    pub const ALL: [BaseLayer; 12] = [
        Self::Elevation,
        Self::Plates,
        Self::CrustType,
        Self::OceanicAge,
        Self::OrogenyType,
        Self::OrogenyAge,
        Self::Laplacian,
        Self::Rivers,
        Self::Basins,
        Self::Thickness,
        Self::Rain,
        Self::PelagicRain,
    ];
    /// Menu label.
    pub fn label(self) -> &'static str {
        match self {
            Self::Elevation => "Elevation",
            Self::Plates => "Plates",
            Self::CrustType => "Crust type",
            Self::OceanicAge => "Oceanic age",
            Self::OrogenyType => "Orogeny type",
            Self::OrogenyAge => "Orogeny age",
            Self::Laplacian => "Elevation Laplacian",
            Self::Rivers => "Rivers",
            Self::Basins => "Drainage basins",
            Self::Thickness => "Crust thickness",
            Self::Rain => "Rain",
            Self::PelagicRain => "Pelagic rain",
        }
    }
}

impl std::str::FromStr for BaseLayer {
    type Err = String;
    /// A layer by name (`elevation`, `plates`, `crust_type`, `oceanic_age`, `orogeny_type`,
    /// `orogeny_age`, `laplacian`, `rivers`, `basins`, `thickness`, `rain`, `pelagic_rain`).
    fn from_str(s: &str) -> Result<Self, String> {
        let names = [
            "elevation",
            "plates",
            "crust_type",
            "oceanic_age",
            "orogeny_type",
            "orogeny_age",
            "laplacian",
            "rivers",
            "basins",
            "thickness",
            "rain",
            "pelagic_rain",
        ];
        names
            .iter()
            .position(|n| *n == s.trim())
            .map(|i| Self::ALL[i])
            .ok_or_else(|| format!("unknown overlay \"{s}\"; one of: {}", names.join(", ")))
    }
}

/// Which vector layers are drawn over the base layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VectorLayers {
    /// Fold directions on continental crust.
    pub folds: bool,
    /// Ridge directions on oceanic crust.
    pub ridges: bool,
    /// Plate velocity arrows.
    pub velocity: bool,
    /// Subduction fronts (entities).
    pub fronts: bool,
    /// Terranes (entities).
    pub terranes: bool,
}

impl VectorLayers {
    /// Switches on the named layers (`folds`, `ridges`, `velocity`, `fronts`, `terranes`).
    pub fn from_names(names: &[String]) -> Result<Self, String> {
        let mut l = Self::default();
        for n in names {
            match n.trim() {
                "folds" => l.folds = true,
                "ridges" => l.ridges = true,
                "velocity" => l.velocity = true,
                "fronts" => l.fronts = true,
                "terranes" => l.terranes = true,
                "" => {}
                other => {
                    return Err(format!(
                        "unknown layer \"{other}\"; any of: folds, ridges, velocity, fronts, terranes"
                    ));
                }
            }
        }
        Ok(l)
    }
}

/// The map samples (elevation in metres, plate, crust type, age) of every lookup pixel.
fn raster_of(s: &Snapshot) -> Raster {
    let lk = &s.lookup;
    let c = &s.crust;
    let samples: Vec<MapSample> = (0..lk.corners.len())
        .into_par_iter()
        .map(|i| {
            let d = lk.sample_of(i);
            MapSample {
                elevation_m: lk.lerp(&c.elevation_km, i) * 1000.0,
                plate: c.plate[d],
                continental: c.crust_type[d] == CrustType::Continental,
                age_my: lk.lerp(&c.age_my, i),
            }
        })
        .collect();
    Raster {
        width: lk.width,
        height: lk.height,
        samples,
    }
}

fn rgb_to_color_image(img: image::RgbImage) -> ColorImage {
    let (w, h) = (img.width() as usize, img.height() as usize);
    ColorImage::from_rgb([w, h], img.as_raw())
}

fn per_pixel(s: &Snapshot, f: impl Fn(usize) -> Color32 + Sync + Send) -> ColorImage {
    let lk = &s.lookup;
    let pixels: Vec<Color32> = (0..lk.corners.len()).into_par_iter().map(f).collect();
    ColorImage::new([lk.width as usize, lk.height as usize], pixels)
}

fn lerp_colour(stops: &[(f32, [u8; 3])], v: f32) -> Color32 {
    let mut c = stops[0].1;
    if v > stops[0].0 {
        c = stops[stops.len() - 1].1;
        for w in stops.windows(2) {
            if v <= w[1].0 {
                let t = (v - w[0].0) / (w[1].0 - w[0].0).max(1e-6);
                let mix = |a: u8, b: u8| (a as f32 + (b as f32 - a as f32) * t).round() as u8;
                c = [
                    mix(w[0].1[0], w[1].1[0]),
                    mix(w[0].1[1], w[1].1[1]),
                    mix(w[0].1[2], w[1].1[2]),
                ];
                break;
            }
        }
    }
    Color32::from_rgb(c[0], c[1], c[2])
}

/// Colours the map by `layer` (one pixel per lookup pixel).
pub fn render_base(s: &Snapshot, layer: BaseLayer) -> ColorImage {
    match layer {
        BaseLayer::Elevation => rgb_to_color_image(raster_of(s).elevation_image(s.radius_km)),
        BaseLayer::Plates => rgb_to_color_image(raster_of(s).plates_image()),
        BaseLayer::CrustType => rgb_to_color_image(raster_of(s).crust_type_image()),
        BaseLayer::OceanicAge => rgb_to_color_image(raster_of(s).crust_age_image()),
        BaseLayer::OrogenyType => {
            let c = &s.crust;
            per_pixel(s, |i| {
                let d = s.lookup.sample_of(i);
                match (c.crust_type[d], c.orogeny[d]) {
                    (CrustType::Oceanic, _) => Color32::from_rgb(30, 52, 92),
                    (_, Orogeny::None) => Color32::from_rgb(150, 150, 140),
                    (_, Orogeny::Andean) => Color32::from_rgb(235, 140, 40),
                    (_, Orogeny::Himalayan) => Color32::from_rgb(170, 60, 190),
                }
            })
        }
        BaseLayer::OrogenyAge => {
            let c = &s.crust;
            const STOPS: [(f32, [u8; 3]); 4] = [
                (0.0, [255, 240, 80]),
                (50.0, [240, 120, 40]),
                (150.0, [150, 40, 80]),
                (400.0, [60, 20, 60]),
            ];
            per_pixel(s, |i| {
                let d = s.lookup.sample_of(i);
                if c.crust_type[d] == CrustType::Oceanic {
                    Color32::from_rgb(30, 52, 92)
                } else if c.orogeny[d] == Orogeny::None {
                    Color32::from_rgb(150, 150, 140)
                } else {
                    lerp_colour(&STOPS, c.orogeny_age_my[d])
                }
            })
        }
        BaseLayer::Laplacian => laplacian_image(s),
        BaseLayer::Rivers => rivers_image(s),
        BaseLayer::Basins => basins_image(s),
        BaseLayer::Rain => rain_image(s),
        BaseLayer::PelagicRain => pelagic_rain_image(s),
        BaseLayer::Thickness => {
            const STOPS: [(f32, [u8; 3]); 6] = [
                (0.0, [10, 20, 60]),
                (7.0, [40, 90, 170]),
                (20.0, [70, 170, 170]),
                (35.0, [225, 205, 120]),
                (50.0, [215, 120, 50]),
                (70.0, [130, 30, 40]),
            ];
            per_pixel(s, |i| {
                lerp_colour(&STOPS, s.lookup.lerp(&s.crust.thickness_km, i))
            })
        }
    }
}

/// The elevation map with the lakes and rivers of the snapshot's drainage network (as
/// rivers.png; see [`crate::io::rivers`]).
fn rivers_image(s: &Snapshot) -> ColorImage {
    let net = s.rivers();
    let lk = &s.lookup;
    let mut img = raster_of(s).elevation_image(s.radius_km);
    if net.len() == s.positions.len() {
        let lake: Vec<f32> = (0..net.len())
            .map(|i| if net.is_lake(i) { 1.0 } else { 0.0 })
            .collect();
        let w = lk.width as usize;
        rivers::paint_lakes(&mut img, |c, r| {
            lk.lerp(&lake, r as usize * w + c as usize) >= 0.5
        });
        rivers::draw_rivers(&mut img, &s.positions, net);
    }
    rgb_to_color_image(img)
}

/// The rain over the land (as precipitation.png; see [`rivers::rain_image`]): the snapshot's
/// drainage network's rain in [`rivers::rain_colour`], the sea dark, rivers on top; uniform
/// rain shows the mean's colour.
fn rain_image(s: &Snapshot) -> ColorImage {
    let net = s.rivers();
    let lk = &s.lookup;
    let uniform = net.rain.len() != s.positions.len();
    let mut img = image::RgbImage::new(lk.width, lk.height);
    for (k, px) in img.pixels_mut().enumerate() {
        let sea = lk.lerp(&s.crust.elevation_km, k) <= 0.0;
        px.0 = if sea {
            [BASIN_SEA.r(), BASIN_SEA.g(), BASIN_SEA.b()]
        } else if uniform {
            rivers::rain_colour(1.0)
        } else {
            rivers::rain_colour(lk.lerp(&net.rain, k))
        };
    }
    if net.len() == s.positions.len() {
        rivers::draw_rivers(&mut img, &s.positions, net);
    }
    rgb_to_color_image(img)
}

/// The pelagic rain over the sea (as pelagic_rate.png; see
/// [`crate::io::maps::pelagic_rate_image`]): the snapshot's rain field in
/// [`crate::io::maps::pelagic_colour`], the land grey. The same rain everywhere shows the
/// mean's colour; with the sediment off (no rain settles) the sea is dark.
fn pelagic_rain_image(s: &Snapshot) -> ColorImage {
    let lk = &s.lookup;
    let rate = s.pelagic_rate.as_deref();
    let n = s.positions.len();
    per_pixel(s, |i| {
        let [r, g, b] = if lk.lerp(&s.crust.elevation_km, i) > 0.0 {
            crate::io::maps::PELAGIC_LAND
        } else {
            match rate {
                None => return BASIN_SEA,
                Some(f) if f.len() == n => crate::io::maps::pelagic_colour(lk.lerp(f, i) as f64),
                Some(_) => crate::io::maps::pelagic_colour(1.0),
            }
        };
        Color32::from_rgb(r, g, b)
    })
}

/// Colour of the sea on the basins map.
const BASIN_SEA: Color32 = Color32::from_rgb(30, 52, 92);

/// Every drainage basin in its own colour (a stable hash of its outlet), lakes in the lake
/// colour, the sea dark.
fn basins_image(s: &Snapshot) -> ColorImage {
    let net = s.rivers();
    if net.len() != s.positions.len() || net.outlets.len() != net.len() {
        return per_pixel(s, |_| BASIN_SEA);
    }
    let [lr, lg, lb] = rivers::LAKE_COLOUR;
    per_pixel(s, |i| {
        let d = s.lookup.sample_of(i);
        if net.drainage.ocean[d] {
            BASIN_SEA
        } else if net.is_lake(d) {
            Color32::from_rgb(lr, lg, lb)
        } else {
            // Outlets of neighbouring basins are scattered through the index range.
            let [r, g, b] = plate_colour(net.outlets[d].wrapping_mul(0x9E37_79B1));
            Color32::from_rgb(r, g, b)
        }
    })
}

/// The Laplacian of the elevation on the map grid (km per pixel², wrapped in longitude),
/// drawn diverging: convex (peaks, ridges) white-orange, concave (valleys, trenches) blue.
fn laplacian_image(s: &Snapshot) -> ColorImage {
    let lk = &s.lookup;
    let (w, h) = (lk.width as usize, lk.height as usize);
    let elev: Vec<f32> = (0..w * h)
        .into_par_iter()
        .map(|i| lk.lerp(&s.crust.elevation_km, i))
        .collect();
    const STOPS: [(f32, [u8; 3]); 5] = [
        (-0.3, [20, 60, 200]),
        (-0.05, [120, 160, 230]),
        (0.0, [235, 235, 235]),
        (0.05, [240, 170, 90]),
        (0.3, [180, 40, 20]),
    ];
    per_pixel(s, |i| {
        let (col, row) = (i % w, i / w);
        let e = |c: usize, r: usize| elev[r * w + c];
        let east = (col + 1) % w;
        let west = (col + w - 1) % w;
        let north = row.saturating_sub(1);
        let south = (row + 1).min(h - 1);
        // Negative Laplacian: positive on peaks.
        let lap = 4.0 * e(col, row) - e(east, row) - e(west, row) - e(col, north) - e(col, south);
        lerp_colour(&STOPS, lap)
    })
}

/// Pixel position in `rect` of a world direction.
pub fn to_screen(rect: Rect, p: DVec3) -> Pos2 {
    let (lat, lon) = to_lat_lon_deg(p);
    Pos2::new(
        rect.left() + rect.width() * ((lon + 180.0) / 360.0) as f32,
        rect.top() + rect.height() * ((90.0 - lat) / 180.0) as f32,
    )
}

/// The point under a screen position in `rect`.
pub fn from_screen(rect: Rect, pos: Pos2) -> LatLon {
    let u = ((pos.x - rect.left()) / rect.width()).clamp(0.0, 1.0) as f64;
    let v = ((pos.y - rect.top()) / rect.height()).clamp(0.0, 1.0) as f64;
    LatLon {
        lat: 90.0 - 180.0 * v,
        lon: -180.0 + 360.0 * u,
    }
}

/// East and north unit vectors at `p`.
fn east_north(p: DVec3) -> (DVec3, DVec3) {
    let east = DVec3::Z.cross(p).normalize_or(DVec3::Y);
    let north = p.cross(east);
    (east, north)
}

/// Screen direction (x right, y down) of a tangent vector `v` at `p`, with the map's x scale.
fn screen_dir(p: DVec3, v: DVec3) -> Vec2 {
    let (e, n) = east_north(p);
    Vec2::new(v.dot(e) as f32, -(v.dot(n) as f32))
}

/// Vector glyphs collected into one mesh (one draw, no per-shape tessellation).
#[derive(Default)]
pub struct GlyphBatch {
    /// The triangles.
    pub mesh: egui::Mesh,
}

impl GlyphBatch {
    /// A segment `a`–`b` of width `w`.
    pub fn line(&mut self, a: Pos2, b: Pos2, w: f32, colour: Color32) {
        let d = b - a;
        let len = d.length();
        if len < 1e-3 {
            return;
        }
        let n = Vec2::new(-d.y, d.x) * (0.5 * w / len);
        let m = &mut self.mesh;
        let i = m.vertices.len() as u32;
        for p in [a + n, b + n, b - n, a - n] {
            m.colored_vertex(p, colour);
        }
        m.add_triangle(i, i + 1, i + 2);
        m.add_triangle(i, i + 2, i + 3);
    }

    /// A square dot of half-size `r` at `p`.
    pub fn dot(&mut self, p: Pos2, r: f32, colour: Color32) {
        let m = &mut self.mesh;
        let i = m.vertices.len() as u32;
        for (dx, dy) in [(-r, -r), (r, -r), (r, r), (-r, r)] {
            m.colored_vertex(p + Vec2::new(dx, dy), colour);
        }
        m.add_triangle(i, i + 1, i + 2);
        m.add_triangle(i, i + 2, i + 3);
    }

    /// An arrow from `from` along `v`.
    pub fn arrow(&mut self, from: Pos2, v: Vec2, w: f32, colour: Color32) {
        let tip = from + v;
        self.line(from, tip, w, colour);
        let back = -v.normalized() * (v.length() * 0.3).clamp(2.0, 6.0);
        let side = Vec2::new(-back.y, back.x) * 0.6;
        self.line(tip, tip + back + side, w, colour);
        self.line(tip, tip + back - side, w, colour);
    }

    /// A ring (polygon of 16 sides) of radius `r`.
    pub fn ring(&mut self, c: Pos2, r: f32, w: f32, colour: Color32) {
        let at = |k: usize| {
            let a = std::f32::consts::TAU * k as f32 / 16.0;
            c + Vec2::new(a.cos(), a.sin()) * r
        };
        for k in 0..16 {
            self.line(at(k), at(k + 1), w, colour);
        }
    }
}

/// Keeps one point per `cell`-pixel square of the screen (decimates dense point sets to what
/// the screen can show).
fn decimate(points: impl Iterator<Item = Pos2>, cell: f32) -> Vec<Pos2> {
    let mut seen = std::collections::HashSet::new();
    points
        .filter(|p| seen.insert(((p.x / cell) as i32, (p.y / cell) as i32)))
        .collect()
}

/// The vector layers over the map drawn in `rect`, as one mesh: glyphs on a grid of screen
/// spacing (so their number depends on the window, not on the planet), front points
/// decimated to one per 3 pixels. `px` scales spacing, widths and sizes (1 on the screen).
pub fn vector_mesh(rect: Rect, s: &Snapshot, layers: VectorLayers, px: f32) -> egui::Mesh {
    let mut b = GlyphBatch::default();
    let lk = &s.lookup;
    let spacing = 28.0 * px;
    let cols = (rect.width() / spacing).max(1.0) as usize;
    let rows = (rect.height() / spacing).max(1.0) as usize;
    let glyph = |c: usize, r: usize| -> (Pos2, usize, DVec3) {
        let pos = Pos2::new(
            rect.left() + (c as f32 + 0.5) * rect.width() / cols as f32,
            rect.top() + (r as f32 + 0.5) * rect.height() / rows as f32,
        );
        let px = (((pos.x - rect.left()) / rect.width()) * lk.width as f32) as usize;
        let py = (((pos.y - rect.top()) / rect.height()) * lk.height as f32) as usize;
        let i = py.min(lk.height as usize - 1) * lk.width as usize + px.min(lk.width as usize - 1);
        let d = lk.sample_of(i);
        (pos, d, s.positions[d])
    };
    let c = &s.crust;
    if layers.folds || layers.ridges {
        for r in 0..rows {
            for col in 0..cols {
                let (pos, d, p) = glyph(col, r);
                let continental = c.crust_type[d] == CrustType::Continental;
                let (dir, colour) = if continental && layers.folds {
                    (c.fold_dir[d], Color32::from_rgb(120, 30, 10))
                } else if !continental && layers.ridges {
                    (c.ridge_dir[d], Color32::from_rgb(250, 250, 255))
                } else {
                    continue;
                };
                let v = DVec3::new(dir[0] as f64, dir[1] as f64, dir[2] as f64);
                let sd = screen_dir(p, v);
                if sd.length() < 1e-6 {
                    continue;
                }
                let half = sd.normalized() * (spacing * 0.35);
                b.line(pos - half, pos + half, 1.5 * px, colour);
            }
        }
    }
    if layers.velocity {
        let scale = spacing * 0.8 / 100.0; // 100 mm/yr = 0.8 glyph spacing
        let black = Color32::from_rgb(15, 15, 15);
        for r in 0..rows {
            for col in 0..cols {
                let (pos, d, p) = glyph(col, r);
                let Some(plate) = s.plate(c.plate[d]) else {
                    continue;
                };
                let v = plate.pole_unit.cross(p) * (plate.angular_speed_rad_per_my * s.radius_km);
                let sd = screen_dir(p, v) * scale;
                if sd.length() < px {
                    b.dot(pos, 1.2 * px, black);
                } else {
                    b.arrow(pos, sd, 1.3 * px, black);
                }
            }
        }
    }
    if layers.fronts {
        let red = Color32::from_rgb(255, 40, 40);
        let points = s
            .fronts
            .iter()
            .flat_map(|f| f.points_world.iter().map(|p| to_screen(rect, *p)));
        for p in decimate(points, 3.0 * px) {
            b.dot(p, 1.5 * px, red);
        }
    }
    if layers.terranes {
        let total = 4.0 * std::f64::consts::PI * s.radius_km * s.radius_km;
        for t in &s.terranes {
            let r = (rect.width() as f64 * 0.25 * (t.area_km2 / total).sqrt()).max(2.0) as f32;
            let [cr, cg, cb] = plate_colour(t.plate);
            let at = to_screen(rect, t.centroid_world);
            b.ring(at, r, 2.0 * px, Color32::from_rgb(cr, cg, cb));
            b.dot(at, 1.5 * px, Color32::BLACK);
        }
    }
    b.mesh
}

/// Paints the vector layers over the map drawn in `rect` (one mesh).
pub fn paint_vectors(painter: &egui::Painter, rect: Rect, s: &Snapshot, layers: VectorLayers) {
    if layers == VectorLayers::default() {
        return;
    }
    let mesh = vector_mesh(rect, s, layers, 1.0);
    if !mesh.is_empty() {
        painter.add(egui::Shape::mesh(mesh));
    }
}

/// Fills the triangles of `mesh` (positions in pixels, vertex colours, opaque) into an image
/// of `width × height` pixels: a pixel is covered when its centre is inside a triangle.
pub fn rasterize_mesh(mesh: &egui::Mesh, width: usize, height: usize, pixels: &mut [Color32]) {
    if pixels.len() != width * height {
        return;
    }
    for t in mesh.indices.chunks_exact(3) {
        let v = |i: u32| mesh.vertices.get(i as usize);
        let (Some(a), Some(b), Some(c)) = (v(t[0]), v(t[1]), v(t[2])) else {
            continue;
        };
        let (a, b, colour, c) = (a.pos, b.pos, a.color, c.pos);
        let area = (b - a).x * (c - a).y - (b - a).y * (c - a).x;
        if area.abs() < 1e-9 {
            continue;
        }
        let x0 = a.x.min(b.x).min(c.x).floor().max(0.0) as usize;
        let y0 = a.y.min(b.y).min(c.y).floor().max(0.0) as usize;
        let x1 = (a.x.max(b.x).max(c.x).ceil().max(0.0) as usize).min(width);
        let y1 = (a.y.max(b.y).max(c.y).ceil().max(0.0) as usize).min(height);
        let edge =
            |p: Pos2, q: Pos2, r: Pos2| ((q - p).x * (r - p).y - (q - p).y * (r - p).x) / area;
        for y in y0..y1 {
            for x in x0..x1 {
                let p = Pos2::new(x as f32 + 0.5, y as f32 + 0.5);
                if edge(a, b, p) >= 0.0 && edge(b, c, p) >= 0.0 && edge(c, a, p) >= 0.0 {
                    pixels[y * width + x] = colour;
                }
            }
        }
    }
}

/// Hash of an image's pixels (for tests and change detection).
pub fn image_hash(img: &ColorImage) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    img.size.hash(&mut h);
    for p in &img.pixels {
        p.to_array().hash(&mut h);
    }
    h.finish()
}
