//! The planet's relief against Earth's: area-weighted elevation quantiles and bands, mean land
//! and ocean elevation, the deep-ocean mode, and the W1 gap (the mean absolute difference between
//! our elevation quantiles and Earth's, metres) for `summary.json`; and `hypsometry.png`, our
//! cumulative curve over Earth's.
//!
//! Earth's figures are ETOPO1 bedrock (public domain), area-weighted, as listed in
//! `assets/reference/earth_hypsometry.json` (from DESIGN §7's `earth_hypsometry.json`): land 27.7%,
//! mean land +651 m, mean ocean −3,627 m.

use std::path::Path;
use std::sync::OnceLock;

use image::{Rgb, RgbImage};
use serde::{Deserialize, Serialize};

use crate::geometry::SphereMesh;
use crate::io::maps::MapError;
use crate::resources::{Crust, CrustType};

/// Earth's hypsometry (ETOPO1 bedrock, area-weighted).
#[derive(Clone, Debug, Deserialize)]
pub struct EarthHypsometry {
    /// Where the figures come from.
    pub source: String,
    /// Fraction of the surface above sea level.
    pub land_fraction: f64,
    /// Mean elevation of land, m.
    pub mean_land_m: f64,
    /// Mean elevation of the ocean floor, m.
    pub mean_ocean_m: f64,
    /// Area fractions at which the quantiles are given.
    pub quantile_levels: Vec<f64>,
    /// Elevation quantiles, m.
    pub quantiles_m: Vec<f64>,
    /// Edges of the elevation bands, m (one more than the bands).
    pub band_edges_m: Vec<f64>,
    /// Area fraction in each band.
    pub band_fractions: Vec<f64>,
}

/// Earth's hypsometry, parsed once from the embedded reference.
pub fn earth() -> &'static EarthHypsometry {
    static EARTH: OnceLock<EarthHypsometry> = OnceLock::new();
    EARTH.get_or_init(|| {
        serde_json::from_str(include_str!("../../assets/reference/earth_hypsometry.json"))
            .unwrap_or_else(|_| EarthHypsometry {
                source: "missing".into(),
                land_fraction: 0.0,
                mean_land_m: 0.0,
                mean_ocean_m: 0.0,
                quantile_levels: Vec::new(),
                quantiles_m: Vec::new(),
                band_edges_m: Vec::new(),
                band_fractions: Vec::new(),
            })
    })
}

/// One elevation band and the fraction of the surface in it, ours and Earth's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Band {
    /// Lower edge, m.
    pub from_m: f64,
    /// Upper edge, m.
    pub to_m: f64,
    /// Our area fraction.
    pub fraction: f64,
    /// Earth's.
    pub earth: f64,
}

/// The relief of a planet against Earth's (the `hypsometry` block of `summary.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hypsometry {
    /// Fraction of the surface above sea level.
    pub land_fraction: f64,
    /// Mean elevation of land, m.
    pub mean_land_m: f64,
    /// Mean elevation of the sea floor, m.
    pub mean_ocean_m: f64,
    /// The most common sea-floor depth, m (the centre of the fullest 100 m bin below −1 km).
    pub ocean_mode_m: f64,
    /// Fraction of the surface above 3 km.
    pub above_3km: f64,
    /// Highest elevation, m.
    pub max_m: f64,
    /// Mean absolute difference between our elevation quantiles and Earth's, at Earth's levels
    /// (0.5% to 99.5%), m.
    pub w1_gap_m: f64,
    /// Area fraction in each of Earth's bands.
    pub bands: Vec<Band>,
    /// Our elevation quantiles at Earth's levels, m.
    pub quantiles_m: Vec<f64>,
    /// Correlation (Pearson, area-weighted) of ocean depth with √age over the oceanic crust
    /// younger than [`AGE_DEPTH_MAX_AGE_MY`]: near 1 where the floor follows a cooling law;
    /// arcs, sediment fans and trenches lower it. None with too little young floor.
    #[serde(default)]
    pub ocean_age_depth_r: Option<f64>,
    /// [`Hypsometry::ocean_age_depth_r`] over the normal floor only: oceanic crust younger than
    /// [`AGE_DEPTH_MAX_AGE_MY`] outside trenches and carrying no more over the normal oceanic
    /// thickness than [`normal_floor_max_load_km`] (its pelagic cover; thicker crust is an arc,
    /// a plateau or a sediment fan). That is the floor a cooling law governs: Parsons & Sclater
    /// 1977 left seamounts, plateaus and trenches out of their fit the same way. Set by the
    /// summary from the live crust and the trench field; None where those are not at hand.
    #[serde(default)]
    pub ocean_age_depth_r_normal_floor: Option<f64>,
    /// Height of the sea above the isostatic datum, m, when `isostasy.ocean_volume_layer_km`
    /// fixes the water's volume (positive: the basins hold less than that water at the datum,
    /// and the sea has risen over the land). Set by the summary from the live isostasy; None
    /// with the sea fixed at the datum.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sea_level_m: Option<f64>,
}

/// Oldest oceanic crust (My) that [`Hypsometry::ocean_age_depth_r`] and [`age_depth_r`] count.
pub const AGE_DEPTH_MAX_AGE_MY: f32 = 80.0;

/// Load (km of crust or sediment over the normal oceanic thickness) above which oceanic crust is
/// an arc, a plateau or a sediment fan rather than normal floor, for
/// [`Hypsometry::ocean_age_depth_r_normal_floor`]: the pelagic cover the parameters lay on floor
/// [`AGE_DEPTH_MAX_AGE_MY`] old at most (1.1 km at the default 14 m/My; with a carbonate
/// compensation depth, the faster of the shells' and the clay's rates), plus 0.5 km.
pub fn normal_floor_max_load_km(params: &crate::resources::Params) -> f64 {
    let s = &params.sediment;
    let mut rate = s.pelagic_rate_m_per_my.max(0.0);
    if s.pelagic_ccd_m > 0.0 {
        rate = rate.max(s.pelagic_clay_rate_m_per_my);
    }
    rate * 1e-3 * AGE_DEPTH_MAX_AGE_MY as f64 + 0.5
}

/// Area-weighted Pearson correlation of depth (−elevation) with √age over the oceanic samples of
/// `crust` younger than [`AGE_DEPTH_MAX_AGE_MY`] with finite age and elevation; None when there
/// are fewer than 10 such samples or either has no spread.
pub fn age_depth_r(mesh: &SphereMesh, crust: &Crust) -> Option<f64> {
    age_depth_r_where(mesh, crust, |_| true)
}

/// [`age_depth_r`] over the samples `i` for which `keep(i)` holds.
pub fn age_depth_r_where(
    mesh: &SphereMesh,
    crust: &Crust,
    keep: impl Fn(usize) -> bool,
) -> Option<f64> {
    let (mut n, mut sw, mut sx, mut sy, mut sxx, mut syy, mut sxy) =
        (0usize, 0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..mesh.len().min(crust.len()) {
        let (age, z) = (crust.age_my[i], crust.elevation_km[i]);
        if crust.crust_type[i] != CrustType::Oceanic
            || !keep(i)
            || !(0.0..AGE_DEPTH_MAX_AGE_MY).contains(&age)
            || !z.is_finite()
        {
            continue;
        }
        let w = mesh.area_km2[i];
        let (x, y) = ((age as f64).sqrt(), -(z as f64));
        n += 1;
        sw += w;
        sx += w * x;
        sy += w * y;
        sxx += w * x * x;
        syy += w * y * y;
        sxy += w * x * y;
    }
    if n < 10 || !(sw > 0.0) {
        return None;
    }
    let (mx, my) = (sx / sw, sy / sw);
    let (vx, vy) = (sxx / sw - mx * mx, syy / sw - my * my);
    let cov = sxy / sw - mx * my;
    (vx > 1e-12 && vy > 1e-12).then(|| (cov / (vx * vy).sqrt()).clamp(-1.0, 1.0))
}

impl Hypsometry {
    /// Fraction of the surface between `lo_m` and `hi_m` (Earth's band edges only).
    pub fn band_fraction(&self, lo_m: f64, hi_m: f64) -> Option<f64> {
        self.bands
            .iter()
            .find(|b| b.from_m == lo_m && b.to_m == hi_m)
            .map(|b| b.fraction)
    }
}

/// The hypsometry of `crust` on `mesh` (area-weighted over the samples).
pub fn hypsometry(mesh: &SphereMesh, crust: &Crust) -> Hypsometry {
    let e = earth();
    let mut pairs: Vec<(f64, f64)> = crust
        .elevation_km
        .iter()
        .zip(mesh.area_km2.iter())
        .filter(|(z, _)| z.is_finite())
        .map(|(&z, &a)| (z as f64 * 1000.0, a))
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pairs.iter().map(|p| p.1).sum::<f64>().max(1e-300);
    // Quantiles at Earth's levels, in one pass.
    let mut quantiles_m = Vec::with_capacity(e.quantile_levels.len());
    let mut acc = 0.0;
    let mut k = 0;
    for &q in &e.quantile_levels {
        let target = q * total;
        while k + 1 < pairs.len() && acc + pairs[k].1 < target {
            acc += pairs[k].1;
            k += 1;
        }
        quantiles_m.push(pairs.get(k).map_or(0.0, |p| p.0));
    }
    let w1_gap_m = if quantiles_m.is_empty() {
        0.0
    } else {
        quantiles_m
            .iter()
            .zip(&e.quantiles_m)
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / quantiles_m.len() as f64
    };
    let (mut land, mut land_z, mut sea, mut sea_z, mut high) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut bins = vec![0.0f64; 120];
    for &(z, a) in &pairs {
        if z > 0.0 {
            land += a;
            land_z += a * z;
        } else {
            sea += a;
            sea_z += a * z;
            if z < -1000.0 {
                let b = ((-z - 1000.0) / 100.0) as usize;
                if let Some(bin) = bins.get_mut(b) {
                    *bin += a;
                }
            }
        }
        if z > 3000.0 {
            high += a;
        }
    }
    let mode_bin = bins
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i);
    let bands = e
        .band_edges_m
        .windows(2)
        .zip(&e.band_fractions)
        .map(|(w, &earth)| {
            let a: f64 = pairs
                .iter()
                .filter(|p| p.0 >= w[0] && p.0 < w[1])
                .map(|p| p.1)
                .sum();
            Band {
                from_m: w[0],
                to_m: w[1],
                fraction: a / total,
                earth,
            }
        })
        .collect();
    Hypsometry {
        land_fraction: land / total,
        mean_land_m: if land > 0.0 { land_z / land } else { 0.0 },
        mean_ocean_m: if sea > 0.0 { sea_z / sea } else { 0.0 },
        ocean_mode_m: -1000.0 - 100.0 * (mode_bin as f64 + 0.5),
        above_3km: high / total,
        max_m: pairs.last().map_or(0.0, |p| p.0),
        w1_gap_m,
        bands,
        quantiles_m,
        ocean_age_depth_r: age_depth_r(mesh, crust),
        ocean_age_depth_r_normal_floor: None,
        sea_level_m: None,
    }
}

/// Draws `hypsometry.png`: the cumulative area (x, 0 to 100% of the globe, from the highest
/// ground) against elevation (y, −11 to +9 km), ours in red over Earth's in black, with sea
/// level, the 1 km lines, the axes' figures, a legend and the W1 gap; `width` × `width`·0.6
/// pixels.
pub fn write_hypsometry_png(h: &Hypsometry, path: &Path, width: u32) -> Result<(), MapError> {
    hypsometry_image(h, width)
        .save(path)
        .map_err(|source| MapError::Image {
            path: path.to_path_buf(),
            source,
        })
}

/// The chart [`write_hypsometry_png`] writes.
pub fn hypsometry_image(h: &Hypsometry, width: u32) -> RgbImage {
    use crate::io::text::{GLYPH_H, draw_text, text_width};
    const INK: [u8; 3] = [20, 20, 20];
    const OURS: [u8; 3] = [210, 40, 30];
    const GRID: [u8; 3] = [225, 225, 225];
    const SEA: [u8; 3] = [60, 110, 200];
    const LABEL: [u8; 3] = [90, 90, 90];
    let e = earth();
    let w = width.clamp(200, 4000);
    let ht = (w as f64 * 0.6) as u32;
    let mut img = RgbImage::from_pixel(w, ht, Rgb([255, 255, 255]));
    // Text at 2× from 600 pixels wide; margins for the figures, the legend and the x axis.
    let sc = if w >= 600 { 2 } else { 1 };
    let line = i64::from((GLYPH_H + 4) * sc);
    let (left, right) = (i64::from(text_width("-10", sc) + 6 * sc), 6 * i64::from(sc));
    let (top, bottom) = (line + 4, 2 * line + 4);
    let (x_lo, x_hi) = (left, i64::from(w) - 1 - right);
    let (y_lo, y_hi) = (top, i64::from(ht) - 1 - bottom);
    let (zmin, zmax) = (-11000.0, 9000.0);
    let y_of = |z: f64| y_lo + ((zmax - z) / (zmax - zmin) * (y_hi - y_lo) as f64).round() as i64;
    let x_of = |f: f64| x_lo + (f * (x_hi - x_lo) as f64).round() as i64;
    let put = |img: &mut RgbImage, x: i64, y: i64, c: [u8; 3]| {
        if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < ht {
            img.put_pixel(x as u32, y as u32, Rgb(c));
        }
    };
    let glyph_h = i64::from(GLYPH_H * sc);
    for km in -11..=9 {
        let y = y_of(km as f64 * 1000.0);
        let c = if km == 0 { SEA } else { GRID };
        for x in x_lo..=x_hi {
            put(&mut img, x, y, c);
        }
        if km % 2 == 0 {
            let t = km.to_string();
            let tx = left - 3 * i64::from(sc) - i64::from(text_width(&t, sc));
            draw_text(&mut img, tx, y - glyph_h / 2, &t, sc, LABEL);
        }
    }
    for tenth in 0..=10 {
        let x = x_of(tenth as f64 / 10.0);
        for y in y_lo..=y_hi {
            put(&mut img, x, y, GRID);
        }
        let t = format!("{}%", tenth * 10);
        let tw = i64::from(text_width(&t, sc));
        let tx = (x - tw / 2).clamp(0, i64::from(w) - 1 - tw);
        draw_text(&mut img, tx, y_hi + 4, &t, sc, LABEL);
    }
    let axis = "AREA ABOVE, % OF THE GLOBE";
    let ax = (x_lo + x_hi - i64::from(text_width(axis, sc))) / 2;
    draw_text(&mut img, ax, y_hi + 4 + line, axis, sc, LABEL);
    draw_text(&mut img, 2, 2, "KM", sc, LABEL);
    // Legend: a stroke of each colour before its name, and the gap between the curves.
    let mut lx = x_lo + 8 * i64::from(sc);
    let ly = 2;
    for (name, c) in [("EARTH (ETOPO1)", INK), ("THIS PLANET", OURS)] {
        for x in lx..lx + 14 * i64::from(sc) {
            for dy in -1..=1 {
                put(&mut img, x, ly + glyph_h / 2 + dy, c);
            }
        }
        lx += 18 * i64::from(sc);
        draw_text(&mut img, lx, ly, name, sc, c);
        lx += i64::from(text_width(name, sc)) + 12 * i64::from(sc);
    }
    let gap = format!(
        "W1 GAP {:.0} M, LAND {:.1}%",
        h.w1_gap_m,
        100.0 * h.land_fraction
    );
    draw_text(&mut img, lx, ly, &gap, sc, LABEL);
    // Curves: cumulative area from the top, i.e. level 1 − q at quantile q.
    let draw = |img: &mut RgbImage, qs: &[f64], c: [u8; 3]| {
        let pts: Vec<(i64, i64)> = e
            .quantile_levels
            .iter()
            .zip(qs)
            .map(|(&l, &z)| (x_of(1.0 - l), y_of(z.clamp(zmin, zmax))))
            .collect();
        for seg in pts.windows(2) {
            let ((x0, y0), (x1, y1)) = (seg[0], seg[1]);
            let n = (x1 - x0).abs().max((y1 - y0).abs()).max(1);
            for k in 0..=n {
                let x = x0 + (x1 - x0) * k / n;
                let y = y0 + (y1 - y0) * k / n;
                for dy in -1..=1 {
                    put(img, x, y + dy, c);
                }
            }
        }
    };
    draw(&mut img, &e.quantiles_m, INK);
    draw(&mut img, &h.quantiles_m, OURS);
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4,000-sample planet, all oceanic, with ages spread over 0–100 My.
    fn ocean() -> (SphereMesh, Crust) {
        let mesh = SphereMesh::fibonacci(4_000, 0.0, 0, 6371.0).expect("mesh");
        let mut crust = Crust::with_len(mesh.len());
        for i in 0..mesh.len() {
            crust.crust_type[i] = CrustType::Oceanic;
            crust.age_my[i] = ((i * 37) % 100) as f32;
        }
        (mesh, crust)
    }

    #[test]
    fn the_chart_has_its_figures_legend_and_curves() {
        let (mesh, crust) = ocean();
        let img = hypsometry_image(&hypsometry(&mesh, &crust), 900);
        assert_eq!((img.width(), img.height()), (900, 540));
        let is = |x: u32, y: u32, c: [u8; 3]| img.get_pixel(x, y).0 == c;
        // Runs of rows with grey ink left of the plot: "KM", the figures -10, -8, ... 8 and
        // the area axis' "0%".
        let inked: Vec<bool> = (0..img.height())
            .map(|y| (0..40).any(|x| is(x, y, [90, 90, 90])))
            .collect();
        let runs = inked.windows(2).filter(|p| p[1] && !p[0]).count() + usize::from(inked[0]);
        assert_eq!(runs, 12, "figures on the elevation axis");
        // The legend names our curve in its colour, and the curve is drawn.
        let red_top = (0..img.width()).filter(|&x| (0..20).any(|y| is(x, y, [210, 40, 30])));
        assert!(red_top.count() > 100, "legend");
        let red = img.pixels().filter(|p| p.0 == [210, 40, 30]).count();
        assert!(red > 2000, "our curve: {red} pixels");
    }

    #[test]
    fn floor_on_a_cooling_law_correlates_with_root_age() {
        let (mesh, mut crust) = ocean();
        for i in 0..mesh.len() {
            crust.elevation_km[i] = -(2.6 + 0.365 * crust.age_my[i].sqrt());
        }
        let r = age_depth_r(&mesh, &crust).expect("young floor");
        assert!(r > 0.999, "{r}");
        // A floor that rises with age instead correlates negatively.
        for i in 0..mesh.len() {
            crust.elevation_km[i] = -6.0 + 0.3 * crust.age_my[i].sqrt();
        }
        assert!(age_depth_r(&mesh, &crust).unwrap() < -0.999);
        // Depth unrelated to age: near zero.
        for i in 0..mesh.len() {
            crust.elevation_km[i] = -4.0 - ((i * 7919) % 1000) as f32 * 1e-3;
        }
        let r = age_depth_r(&mesh, &crust).unwrap();
        assert!(r.abs() < 0.1, "{r}");
        // Only young oceanic crust counts: old floor at random depths changes nothing.
        for i in 0..mesh.len() {
            let a = crust.age_my[i];
            crust.elevation_km[i] = if a < AGE_DEPTH_MAX_AGE_MY {
                -(2.6 + 0.365 * a.sqrt())
            } else {
                -(((i * 31) % 9) as f32)
            };
        }
        assert!(age_depth_r(&mesh, &crust).unwrap() > 0.999);
    }

    #[test]
    fn no_young_floor_gives_none() {
        let (mesh, mut crust) = ocean();
        crust
            .crust_type
            .iter_mut()
            .for_each(|t| *t = CrustType::Continental);
        assert_eq!(age_depth_r(&mesh, &crust), None);
        let h = hypsometry(&mesh, &crust);
        assert_eq!(h.ocean_age_depth_r, None);
    }
}
