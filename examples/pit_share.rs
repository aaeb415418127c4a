//! Closed pits of an amplified heightmap under D8 routing (issue 19's measure): reads a 16-bit
//! PNG heightmap with its JSON sidecar (`planet export --amplified`) and prints the share of
//! the land in closed pits deeper than the depth given.
//!
//! `cargo run --release --example pit_share -- DIR/tile_amplified16.png [DEPTH_M [MASK.png
//! [CRUST.tif]]]`: with the crust's elevation on the same grid (`tile_crust_elevation.tif` of
//! `--geotiff`), also the share outside the crust's own closed depressions (the coarse
//! network's closed basins and lakes), which the valleys keep.

use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(png) = args.get(1) else {
        eprintln!("usage: pit_share HEIGHTMAP16.png [DEPTH_M]");
        std::process::exit(2);
    };
    let depth: f32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10.0);
    let (z, w, h) = match read(Path::new(png)) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("{png}: {e}");
            std::process::exit(1);
        }
    };
    let mut depths = Vec::new();
    let s = tectonic_planets::amplify::pit_depths(&z, w, h, depth, None, &mut depths);
    if let Some(crust) = args.get(4).filter(|a| !a.is_empty()) {
        let bytes = std::fs::read(crust).expect("read the crust GeoTIFF");
        let c = tectonic_planets::io::geotiff::read_single_band(&bytes)
            .expect("a single-band GeoTIFF")
            .values;
        assert_eq!(
            c.len(),
            z.len(),
            "the crust GeoTIFF is not on the same grid"
        );
        let mut cd = Vec::new();
        tectonic_planets::amplify::pit_depths(&c, w, h, depth, None, &mut cd);
        let skip: Vec<bool> = cd.iter().map(|&d| d > depth).collect();
        let o = tectonic_planets::amplify::pit_share(&z, w, h, depth, Some(&skip));
        println!(
            "outside the crust's own depressions ({:.2}% of the land): {} of {} cells ({:.2}%)",
            100.0 * (1.0 - o.land_cells as f64 / s.land_cells.max(1) as f64),
            o.pit_cells,
            o.land_cells,
            100.0 * o.share()
        );
    }
    if let Some(mask) = args.get(3).filter(|a| !a.is_empty()) {
        // Pits deeper than the depth in red over grey elevation.
        let (lo, hi) = z
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let img = image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
            let i = y as usize * w + x as usize;
            if depths[i] > depth && z[i] > 0.0 {
                image::Rgb([220, 30, 30])
            } else {
                let g = (40.0 + 200.0 * (z[i] - lo) / (hi - lo).max(1.0)) as u8;
                image::Rgb([g, g, g])
            }
        });
        img.save(mask).expect("write the mask");
    }
    println!(
        "{png}: {w}x{h}, land {} cells, in pits deeper than {depth} m: {} ({:.2}%)",
        s.land_cells,
        s.pit_cells,
        100.0 * s.share()
    );
}

fn read(png: &Path) -> Result<(Vec<f32>, usize, usize), String> {
    let img = image::open(png).map_err(|e| e.to_string())?.into_luma16();
    let side = png.with_extension("json");
    let j: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(&side).map_err(|e| format!("{}: {e}", side.display()))?,
    )
    .map_err(|e| e.to_string())?;
    let lo = j["min_elevation_m"].as_f64().ok_or("no min_elevation_m")?;
    let hi = j["max_elevation_m"].as_f64().ok_or("no max_elevation_m")?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let z = img
        .pixels()
        .map(|p| (lo + f64::from(p.0[0]) / 65535.0 * (hi - lo)) as f32)
        .collect();
    Ok((z, w, h))
}
