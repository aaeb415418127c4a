//! Closed pits of an amplified 100 m tile of a saved planet, with and without the river valleys
//! (issue 19's measure), counted over all the land and over the land that drains to the sea in
//! the coarse network (outside its closed basins, whose depressions the valleys keep).
//!
//! `cargo run --release --example valley_pits -- SAVE LAT0,LON0,LAT1,LON1 [DEPTH_M [PITS_PNG
//! [EXEMPLARS_DIR]]]` (the PNG: the carved tile shaded, its pits red; the folder: exemplars for
//! the continental relief, as `planet export --exemplars`).

use glam::DVec3;
use tectonic_planets::amplify::valleys::drains_to_sea;
use tectonic_planets::amplify::{Amplifier, AmplifyOptions, pit_depths, pit_depths_with_outlets};
use tectonic_planets::io::exemplars::load_exemplar_dir;
use tectonic_planets::io::export::{GeoGrid, parse_resolution};
use tectonic_planets::io::rivers::{NetworkOptions, RiverNetwork};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!(
            "usage: valley_pits SAVE LAT0,LON0,LAT1,LON1 [DEPTH_M [PITS_PNG [EXEMPLARS_DIR]]]"
        );
        std::process::exit(2);
    }
    let depth: f32 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(10.0);
    let b: Vec<f64> = args[2].split(',').filter_map(|v| v.parse().ok()).collect();
    assert_eq!(b.len(), 4, "region: LAT0,LON0,LAT1,LON1");
    let mut sim = tectonic_planets::io::save::load_from_file(std::path::Path::new(&args[1]))
        .unwrap_or_else(|e| panic!("{}: {e}", args[1]));
    let seed = sim.params().planet.seed;
    let radius = sim.params().planet.radius_km;
    let opts = NetworkOptions::of(sim.params());
    let view = sim.resampled_crust();
    let mesh = sim.mesh();
    let net = RiverNetwork::of(mesh, &view, opts);
    let open = drains_to_sea(net.valley_network());
    let land = net.drainage.stack.len();
    let open_land = net
        .drainage
        .stack
        .iter()
        .filter(|&&i| open[i as usize])
        .count();
    println!(
        "the planet: {:.1}% of the land samples drain to no sea",
        100.0 * (1.0 - open_land as f64 / land.max(1) as f64)
    );
    let amplifier = || {
        let amp = Amplifier::new(mesh, &view, seed, AmplifyOptions::default());
        match args.get(5) {
            Some(dir) => {
                let set = load_exemplar_dir(std::path::Path::new(dir))
                    .unwrap_or_else(|e| panic!("{dir}: {e}"));
                amp.with_exemplars(set, seed, AmplifyOptions::default())
            }
            None => amp,
        }
    };
    let plain = amplifier();
    let carved = amplifier().with_valleys(net.valley_network());
    let px = parse_resolution("100m", radius).expect("resolution");
    let g = GeoGrid::region(b[0], b[1], b[2], b[3], px).expect("region");
    let (w, h) = (g.width as usize, g.height as usize);
    // A pixel belongs to the sample of its triangle's heaviest corner.
    let corner: Vec<usize> = g.sample(&|d: DVec3| {
        let q = plain.query(d);
        [(q.w0, q.c0), (q.w1, q.c1), (q.w2, q.c2)]
            .into_iter()
            .fold((f32::MIN, 0), |a, x| if x.0 > a.0 { x } else { a })
            .1 as usize
    });
    let closed: Vec<bool> = corner.iter().map(|&c| !open[c]).collect();
    // The sinks of the coarse closed basins (their water ends there, as at the sea): every
    // pixel whose heaviest corner is one.
    let sink: Vec<bool> = corner
        .iter()
        .map(|&c| !net.drainage.ocean[c] && net.drainage.receiver[c] as usize == c)
        .collect();
    for (name, amp) in [("no valleys", &plain), ("valleys", &carved)] {
        let z = g.sample(&|d: DVec3| amp.elevation_m(d));
        let mut depths = Vec::new();
        pit_depths(&z, w, h, depth, None, &mut depths);
        // (land, pits) over the open land and over the closed basins.
        let mut n = [[0usize; 2]; 2];
        for i in 0..z.len() {
            if z[i] > 0.0 {
                let k = usize::from(closed[i]);
                n[k][0] += 1;
                n[k][1] += usize::from(depths[i] > depth);
            }
        }
        if let (Some(path), "valleys") = (args.get(4).filter(|p| !p.is_empty()), name) {
            write_pits(path, &z, &depths, w, h, depth);
        }
        let pct = |c: [usize; 2]| 100.0 * c[1] as f64 / c[0].max(1) as f64;
        let mut sink_depths = Vec::new();
        let s = pit_depths_with_outlets(&z, w, h, depth, None, Some(&sink), &mut sink_depths);
        println!(
            "{name}: with the coarse closed basins' sinks as outlets, land in pits {:.2}%",
            100.0 * s.share()
        );
        println!(
            "{name}: {w}x{h}, land in pits deeper than {depth} m {:.2}%; on land draining to the sea ({:.1}% of the land) {:.2}%, in the coarse closed basins {:.2}%",
            pct([n[0][0] + n[1][0], n[0][1] + n[1][1]]),
            100.0 * n[0][0] as f64 / (n[0][0] + n[1][0]).max(1) as f64,
            pct(n[0]),
            pct(n[1])
        );
    }
}

/// The carved tile shaded from the north-west (grey; sea blue), its pits deeper than `depth`
/// red, as a PNG at `path`.
fn write_pits(path: &str, z: &[f32], depths: &[f32], w: usize, h: usize, depth: f32) {
    let mut img = image::RgbImage::new(w as u32, h as u32);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (xl, yu) = (x.saturating_sub(1), y.saturating_sub(1));
            // Slope towards the north-west light, 100 m pixels.
            let s = (z[i] - 0.5 * (z[y * w + xl] + z[yu * w + x])) / 100.0;
            let g = (150.0 + 300.0 * s).clamp(20.0, 255.0) as u8;
            let px = if z[i] <= 0.0 {
                [40, 70, 140]
            } else if depths[i] > depth {
                [220, 30, 30]
            } else {
                [g, g, g]
            };
            img.put_pixel(x as u32, y as u32, image::Rgb(px));
        }
    }
    img.save(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    println!("wrote {path}");
}
