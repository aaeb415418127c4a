//! Writes the small synthetic elevation exemplars shipped in `assets/exemplars/` (16-bit PNG +
//! JSON sidecar per file): ridged noise whose drainage is then grown by stream power
//! (`eroded_exemplar`): `cargo run --release --example make_exemplars [-- OUT_DIR]`.

use tectonic_planets::amplify::exemplar::{eroded_exemplar, synthetic_exemplar};

/// Steps of the landscape-evolution run that grows each exemplar's drainage.
const EROSION_STEPS: usize = 150;
/// Uplift at the noise's lowest point, as a share of that at its crests.
const UPLIFT_FLOOR: f32 = 0.2;

fn main() -> anyhow::Result<()> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "assets/exemplars".to_string());
    // (folder, ridge angle, wavelength px, relief m, pixel size m)
    let kinds = [
        ("andean", 0.0f32, 14.0f32, 3000.0f32, 200.0),
        ("himalayan", 0.0, 18.0, 4500.0, 200.0),
        ("old", 0.0, 24.0, 1200.0, 200.0),
        ("plain", 0.0, 40.0, 150.0, 200.0),
    ];
    for (k, (name, angle, wl, relief, px_m)) in kinds.into_iter().enumerate() {
        let dir = std::path::Path::new(&out).join(name);
        std::fs::create_dir_all(&dir)?;
        let size = 128;
        // Ridged noise sets the grain (its ridges run along the rows); grown drainage makes it
        // drain as real terrain does, to longitudinal valleys along its first and last rows.
        let noise = synthetic_exemplar(size, angle, wl, relief, 100 + k as u32);
        let z = eroded_exemplar(&noise, size, EROSION_STEPS, UPLIFT_FLOOR);
        let (lo, hi) = z
            .iter()
            .fold((f32::MAX, f32::MIN), |a, &v| (a.0.min(v), a.1.max(v)));
        let (lo, hi) = (f64::from(lo).floor(), f64::from(hi).ceil());
        let grey: Vec<u16> = z
            .iter()
            .map(|&v| ((f64::from(v) - lo) / (hi - lo) * 65535.0).round() as u16)
            .collect();
        let img =
            image::ImageBuffer::<image::Luma<u16>, _>::from_raw(size as u32, size as u32, grey)
                .ok_or_else(|| anyhow::anyhow!("bad buffer"))?;
        let path = dir.join(format!("{name}_synthetic.png"));
        img.save(&path)?;
        let meta = serde_json::json!({
            "min_elevation_m": lo, "max_elevation_m": hi, "pixel_size_m": px_m,
            "note": "synthetic exemplar (ridged noise, then drainage grown by stream power) made by examples/make_exemplars.rs"
        });
        std::fs::write(
            path.with_extension("json"),
            serde_json::to_string_pretty(&meta)?,
        )?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
