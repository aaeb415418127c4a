//! Rivers for the outputs: `rivers.png` (rivers and lakes over the shaded relief of
//! elevation.png), `rivers.geojson` (one line per river reach) and, with the climate on,
//! `precipitation.png` (the rain the drainage areas are weighted with), from the drainage
//! network of the resampled crust ([`RiverNetwork`]).
//!
//! Rivers are the land samples whose drainage area is at least the threshold of
//! [`river_threshold_km2`] (50,000 km² on a fine planet). Each is drawn from its sample to its
//! receiver along the great circle, as wide as the log of its drainage area says; lakes (samples
//! under a filled depression's water level, at least 20 m deep) are drawn as water. Map conventions are those of
//! [`crate::io::maps`] (equirectangular, row 0 north, column 0 at longitude −180°).

use std::path::{Path, PathBuf};

use glam::DVec3;
use image::RgbImage;
use serde_json::{Value, json};

use crate::geometry::SphereMesh;
use crate::geometry::spherical::to_lat_lon_deg;
use crate::io::maps::{MapError, Raster};
use crate::resources::Crust;
use crate::systems::relief::drainage::Drainage;
use crate::systems::relief::graph::ReliefGraph;
pub use crate::systems::relief::network::NetworkOptions;
use crate::systems::relief::network::{
    Reach, basin_outlets, drainage_graph, network_of, rain_of, river_reaches, river_threshold_km2,
};

/// Colour of rivers (sRGB).
pub const RIVER_COLOUR: [u8; 3] = [24, 74, 186];
/// Colour of lakes (sRGB).
pub const LAKE_COLOUR: [u8; 3] = [64, 128, 206];
/// Width of a river at the threshold, pixels on a 2048-pixel-wide map (scaled with the width,
/// never under half of it).
const MIN_WIDTH_PX: f64 = 1.0;
/// Extra width per doubling of the drainage area above the threshold, pixels at 2048.
const WIDTH_PER_DOUBLING_PX: f64 = 0.6;
/// Widest river, pixels at 2048.
const MAX_WIDTH_PX: f64 = 5.0;
/// Decimal places of the GeoJSON coordinates (1e-5° is about a metre).
const COORD_SCALE: f64 = 1e5;

/// The drainage network of a crust with what the outputs draw: basins and river reaches.
#[derive(Clone, Debug, Default)]
pub struct RiverNetwork {
    /// The network (receivers, areas, lakes, the sea mask).
    pub drainage: Drainage,
    /// The outlet of every sample (its basin; see [`basin_outlets`]).
    pub outlets: Vec<u32>,
    /// The river reaches above the threshold.
    pub reaches: Vec<Reach>,
    /// Relative rain per sample the drainage areas were weighted with (the phenomenon
    /// `climate`'s field; empty: uniform rain).
    pub rain: Vec<f32>,
    /// The threshold, km² of drainage area.
    pub min_area_km2: f64,
}

impl RiverNetwork {
    /// The network of `crust` on `mesh` (give the resampled crust: world frame), with the sea
    /// and lakes as in the simulation (`opts`: [`NetworkOptions::of`] the run's parameters) and
    /// the threshold of [`river_threshold_km2`].
    pub fn of(mesh: &SphereMesh, crust: &Crust, opts: NetworkOptions) -> Self {
        Self::on_graph(&drainage_graph(mesh), &mesh.positions, crust, opts)
    }

    /// The network as the amplified relief's valleys read it
    /// ([`crate::amplify::Amplifier::with_valleys`]).
    pub fn valley_network(&self) -> crate::amplify::valleys::Network<'_> {
        let d = &self.drainage;
        crate::amplify::valleys::Network {
            receiver: &d.receiver,
            stack: &d.stack,
            area_km2: &d.area_km2,
            water_level_km: &d.water_level_km,
            ocean: &d.ocean,
        }
    }

    /// [`Self::of`] on a sample graph already built (see [`relief_graph`](crate::systems::relief::network::relief_graph); `positions`: its
    /// unit positions).
    pub fn on_graph(
        g: &ReliefGraph,
        positions: &[DVec3],
        crust: &Crust,
        opts: NetworkOptions,
    ) -> Self {
        let rain = rain_of(g, positions, crust, opts);
        let drainage = network_of(g, crust, opts, Some(&rain));
        let min_area_km2 = river_threshold_km2(g.total_area_km2(), g.len());
        let reaches = river_reaches(&drainage, min_area_km2);
        let outlets = basin_outlets(&drainage);
        Self {
            drainage,
            outlets,
            reaches,
            min_area_km2,
            rain,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.drainage.receiver.len()
    }

    /// True without samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether sample `i` is under a lake (false out of range).
    pub fn is_lake(&self, i: usize) -> bool {
        i < self.len() && self.drainage.ocean.len() == self.len() && self.drainage.is_lake(i)
    }

    /// Lakes and basins in figures, for `summary.json` (`mesh`: the mesh of the network).
    pub fn summary(&self, mesh: &SphereMesh) -> DrainageSummary {
        let n = self.len();
        let mut s = DrainageSummary {
            closed_lakes: self.drainage.closed_lake_count(),
            ..Default::default()
        };
        if n == 0 || mesh.len() != n || self.outlets.len() != n {
            return s;
        }
        let d = &self.drainage;
        let (mut land, mut lake, mut drawn, mut endorheic) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            if d.ocean[i] {
                continue;
            }
            let a = mesh.area_km2[i];
            land += a;
            if self.is_lake(i) {
                lake += a;
            }
            if self.is_drawn_lake(i) {
                drawn += a;
            }
            if !d.ocean[self.outlets[i] as usize] {
                endorheic += a;
            }
        }
        // The largest lake: connected lake samples.
        let mut seen = vec![false; n];
        let mut queue = Vec::new();
        for start in 0..n {
            if seen[start] || !self.is_lake(start) {
                continue;
            }
            seen[start] = true;
            queue.clear();
            queue.push(start);
            let (mut head, mut area) = (0, 0.0);
            while head < queue.len() {
                let i = queue[head];
                head += 1;
                area += mesh.area_km2[i];
                for &j in mesh.neighbors_of(i) {
                    let j = j as usize;
                    if !seen[j] && self.is_lake(j) {
                        seen[j] = true;
                        queue.push(j);
                    }
                }
            }
            s.largest_lake_km2 = s.largest_lake_km2.max(area);
        }
        if land > 0.0 {
            s.lake_share_of_land = lake / land;
            s.drawn_lake_share_of_land = drawn / land;
            s.endorheic_share_of_land = endorheic / land;
        }
        s
    }

    /// Whether sample `i` is under a lake at least [`MIN_DRAWN_LAKE_DEPTH_KM`] deep: what
    /// `rivers.png` draws as water (the shallow rims and the pans a few metres deep that dot a
    /// flat plain are drawn as land).
    pub fn is_drawn_lake(&self, i: usize) -> bool {
        self.is_lake(i) && self.drainage.lake_depth_km(i) >= MIN_DRAWN_LAKE_DEPTH_KM
    }
}

/// Lakes and basins of a drainage network (the `drainage` block of `summary.json`).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DrainageSummary {
    /// Share of the land area under lakes (any depth).
    pub lake_share_of_land: f64,
    /// Share of the land area under lakes at least 20 m deep (what `rivers.png` draws).
    pub drawn_lake_share_of_land: f64,
    /// Share of the land area that drains to no sea (closed lakes and sinks).
    pub endorheic_share_of_land: f64,
    /// Lakes with no outlet: their catchment's runoff cannot keep them full.
    pub closed_lakes: usize,
    /// Area of the largest lake, km².
    pub largest_lake_km2: f64,
}

/// Shallowest water `rivers.png` draws as a lake, km (20 m).
pub const MIN_DRAWN_LAKE_DEPTH_KM: f32 = 0.02;

/// Width of a river of drainage area `area_km2` on a map `width` pixels wide, pixels.
pub fn river_width_px(area_km2: f64, min_area_km2: f64, width: u32) -> f64 {
    let scale = (f64::from(width) / 2048.0).max(0.5);
    let doublings = (area_km2 / min_area_km2.max(1e-9)).max(1.0).log2();
    scale * (MIN_WIDTH_PX + WIDTH_PER_DOUBLING_PX * doublings).min(MAX_WIDTH_PX)
}

/// Continuous pixel coordinates (x east from longitude −180°, y south from the north pole; the
/// centre of pixel (c, r) is (c + ½, r + ½)) of unit direction `p` on a `w × h` map.
fn to_pixel(p: DVec3, w: f64, h: f64) -> (f64, f64) {
    let (lat, lon) = to_lat_lon_deg(p);
    ((lon + 180.0) / 360.0 * w, (90.0 - lat) / 180.0 * h)
}

/// Coverage (0..1) of every pixel of a `width × height` map by antialiased discs and lines.
struct Coverage {
    width: usize,
    height: usize,
    cov: Vec<f32>,
}

impl Coverage {
    fn new(width: u32, height: u32) -> Self {
        let (width, height) = (width as usize, height as usize);
        Self {
            width,
            height,
            cov: vec![0.0; width * height],
        }
    }

    /// A disc of radius `r` pixels at (x, y), wrapping in longitude.
    fn disc(&mut self, x: f64, y: f64, r: f64) {
        let (w, h) = (self.width as i64, self.height as i64);
        if w == 0 || h == 0 || !x.is_finite() || !y.is_finite() {
            return;
        }
        let reach = r + 1.0;
        let (r0, r1) = (
            ((y - reach).floor() as i64).max(0),
            ((y + reach).ceil() as i64).min(h - 1),
        );
        let (c0, c1) = ((x - reach).floor() as i64, (x + reach).ceil() as i64);
        for row in r0..=r1 {
            let dy = row as f64 + 0.5 - y;
            for col in c0..=c1 {
                let dx = col as f64 + 0.5 - x;
                let c = (r + 0.5 - (dx * dx + dy * dy).sqrt()).clamp(0.0, 1.0) as f32;
                if c > 0.0 {
                    let k = row as usize * self.width + col.rem_euclid(w) as usize;
                    if c > self.cov[k] {
                        self.cov[k] = c;
                    }
                }
            }
        }
    }

    /// The great-circle arc from `a` to `b` (unit vectors, close together), `width` pixels
    /// wide: discs every 0.35 pixel along it (across the antimeridian, the arc's two ends
    /// wrap).
    fn arc(&mut self, a: DVec3, b: DVec3, width: f64) {
        let (w, h) = (self.width as f64, self.height as f64);
        let (pa, pb) = (to_pixel(a, w, h), to_pixel(b, w, h));
        let mut dx = pb.0 - pa.0;
        if dx > 0.5 * w {
            dx -= w;
        } else if dx < -0.5 * w {
            dx += w;
        }
        let len = dx.hypot(pb.1 - pa.1);
        let n = ((len / 0.35).ceil() as usize).clamp(1, 4096);
        let r = 0.5 * width;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = (a * (1.0 - t) + b * t).normalize_or(a);
            let (x, y) = to_pixel(p, w, h);
            self.disc(x, y, r);
        }
    }

    /// Blends `colour` over `img` by the coverage.
    fn blend(&self, img: &mut RgbImage, colour: [u8; 3]) {
        if img.width() as usize != self.width || img.height() as usize != self.height {
            return;
        }
        for (px, &c) in img.pixels_mut().zip(&self.cov) {
            if c > 0.0 {
                for (v, t) in px.0.iter_mut().zip(colour) {
                    *v = (f32::from(*v) * (1.0 - c) + f32::from(t) * c).round() as u8;
                }
            }
        }
    }
}

/// Paints the pixels where `lake(col, row)` in [`LAKE_COLOUR`].
pub fn paint_lakes(img: &mut RgbImage, lake: impl Fn(u32, u32) -> bool) {
    let (w, h) = img.dimensions();
    for row in 0..h {
        for col in 0..w {
            if lake(col, row) {
                img.put_pixel(col, row, image::Rgb(LAKE_COLOUR));
            }
        }
    }
}

/// Which pixels of a `width × height` map lie on a lake: where the lake samples of the
/// triangle under the pixel's centre weigh at least half.
pub fn lake_pixels(mesh: &SphereMesh, net: &RiverNetwork, width: u32, height: u32) -> Vec<bool> {
    use rayon::prelude::*;
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![false; w * h];
    if net.len() != mesh.len() || net.drainage.lake_sample_count == 0 {
        return out;
    }
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(row, line)| {
            let mut hint = u32::MAX;
            for (col, o) in line.iter_mut().enumerate() {
                let d = DVec3::from_array(Raster::pixel_direction(
                    width, height, col as u32, row as u32,
                ));
                let loc = crate::amplify::hinted_locate(mesh, d, hint);
                hint = loc.triangle;
                let Some(t) = mesh.triangles.get(loc.triangle as usize) else {
                    continue;
                };
                let weight: f64 = t
                    .iter()
                    .zip(loc.weights)
                    .filter(|(s, _)| net.is_drawn_lake(**s as usize))
                    .map(|(_, w)| w)
                    .sum();
                *o = weight >= 0.5;
            }
        });
    out
}

/// Draws the rivers of `net` over `img` (a map of the whole globe): every river sample to its
/// receiver along the great circle, as wide as [`river_width_px`] says, antialiased, in
/// [`RIVER_COLOUR`]. Segments inside a lake are not drawn. `positions` are the samples' unit
/// positions (world frame).
pub fn draw_rivers(img: &mut RgbImage, positions: &[DVec3], net: &RiverNetwork) {
    let d = &net.drainage;
    let n = net.len();
    if positions.len() != n || d.ocean.len() != n || d.area_km2.len() != n {
        return;
    }
    let mut cov = Coverage::new(img.width(), img.height());
    for i in 0..n {
        let r = d.receiver[i] as usize;
        if d.ocean[i] || r == i || r >= n || d.area_km2[i] < net.min_area_km2 {
            continue;
        }
        if net.is_drawn_lake(i) && net.is_drawn_lake(r) {
            continue;
        }
        let width = river_width_px(d.area_km2[i], net.min_area_km2, img.width());
        cov.arc(positions[i], positions[r], width);
    }
    cov.blend(img, RIVER_COLOUR);
}

/// `rivers.png`: the shaded relief of `raster` (as elevation.png) with the lakes and rivers of
/// `net` (on `mesh`, world frame) drawn over it.
pub fn rivers_image(
    raster: &Raster,
    mesh: &SphereMesh,
    net: &RiverNetwork,
    planet_radius_km: f64,
) -> RgbImage {
    let mut img = raster.elevation_image(planet_radius_km);
    let lakes = lake_pixels(mesh, net, raster.width, raster.height);
    let w = raster.width as usize;
    paint_lakes(&mut img, |c, r| {
        lakes
            .get(r as usize * w + c as usize)
            .copied()
            .unwrap_or(false)
    });
    draw_rivers(&mut img, &mesh.positions, net);
    img
}

/// Colour of relative rain `r` (1 = the land's mean) on land: tan deserts (a tenth of the mean
/// or less), yellow-green steppe, green at the mean, dark green and blue-green where it rains
/// several times the mean; log scale.
pub fn rain_colour(r: f32) -> [u8; 3] {
    const STOPS: [(f32, [f32; 3]); 5] = [
        (-3.3, [232.0, 208.0, 150.0]),
        (-1.0, [205.0, 195.0, 110.0]),
        (0.0, [110.0, 170.0, 80.0]),
        (1.0, [40.0, 120.0, 60.0]),
        (2.0, [30.0, 90.0, 135.0]),
    ];
    let x = if r > 0.0 { r.log2() } else { -10.0 };
    let x = x.clamp(STOPS[0].0, STOPS[4].0);
    let k = STOPS.windows(2).position(|w| x <= w[1].0).unwrap_or(3);
    let ((x0, c0), (x1, c1)) = (STOPS[k], STOPS[k + 1]);
    let t = ((x - x0) / (x1 - x0)).clamp(0.0, 1.0);
    std::array::from_fn(|i| (c0[i] + t * (c1[i] - c0[i])).round() as u8)
}

/// The rain map (`precipitation.png`): the network's rain ([`RiverNetwork::rain`]) over the
/// land in [`rain_colour`], the sea dark blue, rivers on top; `None` with uniform rain.
pub fn rain_image(raster: &Raster, mesh: &SphereMesh, net: &RiverNetwork) -> Option<RgbImage> {
    if net.rain.len() != mesh.len() || net.len() != mesh.len() {
        return None;
    }
    let mut img = crate::io::maps::field_image(
        raster,
        mesh,
        &net.rain,
        |s| {
            s.is_none_or(|s| s.elevation_m <= 0.0)
                .then_some([28, 52, 86])
        },
        |r| rain_colour(r as f32),
    );
    draw_rivers(&mut img, &mesh.positions, net);
    Some(img)
}

/// [lon, lat] in degrees, rounded to [`COORD_SCALE`].
fn lon_lat(lon: f64, lat: f64) -> [f64; 2] {
    let r = |v: f64| (v * COORD_SCALE).round() / COORD_SCALE;
    [r(lon), r(lat)]
}

/// The parts of a line through `points` (unit vectors) in [lon, lat] degrees, cut where it
/// crosses the antimeridian (RFC 7946 §3.1.9): each part ends and the next starts at
/// longitude ±180° on the great circle between the two points.
fn line_parts(points: impl Iterator<Item = DVec3>) -> Vec<Vec<[f64; 2]>> {
    let mut parts: Vec<Vec<[f64; 2]>> = vec![Vec::new()];
    let mut prev: Option<(DVec3, f64)> = None;
    for p in points {
        let (lat, lon) = to_lat_lon_deg(p);
        if let Some((a, lon_a)) = prev
            && (lon - lon_a).abs() > 180.0
        {
            // The chord from a to p meets the plane y = 0 (on the side x < 0) at t.
            let t = if (a.y - p.y).abs() > 0.0 {
                (a.y / (a.y - p.y)).clamp(0.0, 1.0)
            } else {
                0.5
            };
            let c = (a * (1.0 - t) + p * t).normalize_or(a);
            let lat_c = c.z.clamp(-1.0, 1.0).asin().to_degrees();
            let side = |l: f64| if l >= 0.0 { 180.0 } else { -180.0 };
            if let Some(last) = parts.last_mut() {
                last.push(lon_lat(side(lon_a), lat_c));
            }
            parts.push(vec![lon_lat(side(lon), lat_c)]);
        }
        if let Some(last) = parts.last_mut() {
            last.push(lon_lat(lon, lat));
        }
        prev = Some((p, lon));
    }
    parts.retain(|p| !p.is_empty());
    parts
}

/// The reaches of `net` as a GeoJSON FeatureCollection (RFC 7946: WGS 84 longitude, latitude
/// in degrees): one Feature per reach, a LineString downstream from its first sample to where
/// it ends (a MultiLineString when it crosses the antimeridian), with the properties `reach`
/// (its index), `area_km2` (drainage area where it ends), `strahler`, `rank` (1: the largest
/// drainage area), `ends_in` (`sea`, `lake`, `sink` or `confluence`), `downstream` (the reach
/// it flows on in, or null), `outlet` (its basin's outlet sample) and `length_km`.
pub fn rivers_geojson(positions: &[DVec3], net: &RiverNetwork) -> Value {
    let features: Vec<Value> = net
        .reaches
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let parts = line_parts(
                r.samples
                    .iter()
                    .filter_map(|&s| positions.get(s as usize).copied()),
            );
            let geometry = if parts.len() == 1 {
                json!({ "type": "LineString", "coordinates": parts[0] })
            } else {
                json!({ "type": "MultiLineString", "coordinates": parts })
            };
            json!({
                "type": "Feature",
                "id": k,
                "geometry": geometry,
                "properties": {
                    "reach": k,
                    "area_km2": (r.area_km2 * 10.0).round() / 10.0,
                    "strahler": r.strahler,
                    "rank": r.rank,
                    "ends_in": r.end.name(),
                    "downstream": r.downstream,
                    "outlet": r.outlet,
                    "length_km": (r.length_km * 10.0).round() / 10.0,
                },
            })
        })
        .collect();
    json!({
        "type": "FeatureCollection",
        "name": "rivers",
        "min_area_km2": net.min_area_km2,
        "features": features,
    })
}

/// Writes `rivers.png` (see [`rivers_image`]), `rivers.geojson` (see [`rivers_geojson`]) and,
/// with rain, `precipitation.png` (see [`rain_image`])
/// into `dir`; returns their paths.
pub fn write_rivers(
    raster: &Raster,
    mesh: &SphereMesh,
    net: &RiverNetwork,
    dir: &Path,
    planet_radius_km: f64,
) -> Result<Vec<PathBuf>, MapError> {
    raster.validate()?;
    let png = dir.join("rivers.png");
    rivers_image(raster, mesh, net, planet_radius_km)
        .save(&png)
        .map_err(|source| MapError::Image {
            path: png.clone(),
            source,
        })?;
    let geo = dir.join("rivers.geojson");
    let text = serde_json::to_string(&rivers_geojson(&mesh.positions, net)).map_err(|source| {
        MapError::Json {
            path: geo.clone(),
            source,
        }
    })?;
    std::fs::write(&geo, text).map_err(|source| MapError::Io {
        path: geo.clone(),
        source,
    })?;
    let mut files = vec![png, geo];
    if let Some(img) = rain_image(raster, mesh, net) {
        let path = dir.join("precipitation.png");
        img.save(&path).map_err(|source| MapError::Image {
            path: path.clone(),
            source,
        })?;
        files.push(path);
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_across_the_antimeridian_are_cut_there() {
        let a = crate::geometry::spherical::from_lat_lon_deg(10.0, 179.0);
        let b = crate::geometry::spherical::from_lat_lon_deg(12.0, -179.0);
        let c = crate::geometry::spherical::from_lat_lon_deg(13.0, -178.0);
        let parts = line_parts([a, b, c].into_iter());
        assert_eq!(parts.len(), 2, "{parts:?}");
        assert_eq!(parts[0].len(), 2);
        assert_eq!(parts[1].len(), 3);
        assert_eq!(parts[0][1][0], 180.0);
        assert_eq!(parts[1][0][0], -180.0);
        let lat = parts[0][1][1];
        assert_eq!(lat, parts[1][0][1]);
        assert!(lat > 10.9 && lat < 11.1, "{lat}");
        let parts = line_parts([b, c].into_iter());
        assert_eq!(
            parts,
            vec![vec![lon_lat(-179.0, 12.0), lon_lat(-178.0, 13.0)]]
        );
    }

    #[test]
    fn an_arc_across_the_antimeridian_covers_both_edges_and_not_the_middle() {
        // Latitude 0.5°: the centres of row 89.
        let a = crate::geometry::spherical::from_lat_lon_deg(0.5, 178.0);
        let b = crate::geometry::spherical::from_lat_lon_deg(0.5, -178.0);
        let mut c = Coverage::new(360, 180);
        c.arc(a, b, 1.0);
        let row = 89 * 360;
        assert!(c.cov[row + 359] > 0.5 && c.cov[row] > 0.5);
        assert_eq!(c.cov[row + 180], 0.0);
        let lit = c.cov.iter().filter(|&&v| v > 0.0).count();
        assert!(lit < 40, "{lit} pixels for a 4° line");
    }

    #[test]
    fn width_grows_with_area_within_bounds() {
        let t = 50_000.0;
        assert_eq!(river_width_px(t, t, 2048), MIN_WIDTH_PX);
        assert!(river_width_px(4.0 * t, t, 2048) > river_width_px(2.0 * t, t, 2048));
        assert_eq!(river_width_px(1e12, t, 2048), MAX_WIDTH_PX);
        assert_eq!(river_width_px(t, t, 4096), 2.0 * MIN_WIDTH_PX);
    }
}
