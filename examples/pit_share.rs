//! Closed pits of an amplified heightmap under D8 routing (issue 19's measure): reads a 16-bit
//! PNG heightmap with its JSON sidecar (`planet export --amplified`) and prints the share of
//! the land in closed pits deeper than the depth given.
//!
//! `cargo run --release --example pit_share -- DIR/tile_amplified16.png [DEPTH_M [MASK.png]]`

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
    if let Some(mask) = args.get(3) {
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
