//! Starting from a map (paper §7.1): `generate --from-heightmap` gives back an exported planet's
//! land, `--from-earth` puts land where Earth's is, plates maps and motions are followed, and
//! bad files are refused with the reason.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use tectonic_planets::geometry::from_lat_lon_deg;
use tectonic_planets::io::geotiff::{GeoBounds, write_geotiff};
use tectonic_planets::io::start::{
    earth_elevation_m, earth_plates, load_heightmap, load_motions, load_plates_map,
};

fn planet() -> Command {
    Command::new(env!("CARGO_BIN_EXE_planet"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("planet-start-{}-{}", name, std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn generate(args: &[&str], out: &Path) -> std::process::Output {
    let mut all = vec!["generate", "--quiet", "--backend", "cpu", "--out"];
    let dir = out.to_string_lossy().to_string();
    all.push(&dir);
    all.extend_from_slice(args);
    planet().args(&all).output().expect("run planet generate")
}

fn ok(o: &std::process::Output) {
    assert!(
        o.status.success(),
        "generate failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Elevation (m) of every pixel of `dir/elevation16.png`, with the width.
fn elevation16(dir: &Path) -> (usize, Vec<f64>) {
    let g = load_heightmap(&dir.join("elevation16.png")).expect("our own export reads back");
    (g.width, g.metres.iter().map(|&m| m as f64).collect())
}

/// Area-weighted share of the pixels (equirectangular, width `w`) where `a` and `b` agree on
/// land (> 0 m).
fn land_agreement(w: usize, a: &[f64], b: impl Fn(usize) -> f64) -> f64 {
    let h = a.len() / w;
    let (mut same, mut total) = (0.0, 0.0);
    for r in 0..h {
        let lat = 90.0 - (r as f64 + 0.5) * 180.0 / h as f64;
        let wgt = lat.to_radians().cos();
        for c in 0..w {
            let k = r * w + c;
            total += wgt;
            if (a[k] > 0.0) == (b(k) > 0.0) {
                same += wgt;
            }
        }
    }
    same / total
}

#[test]
fn a_planet_restarted_from_its_own_heightmap_keeps_its_land() {
    let dir = temp_dir("roundtrip");
    let (a, b) = (dir.join("a"), dir.join("b"));
    ok(&generate(
        &[
            "--samples",
            "30000",
            "--my",
            "30",
            "--width",
            "512",
            "--seed",
            "4",
        ],
        &a,
    ));
    let png = a.join("elevation16.png").to_string_lossy().to_string();
    ok(&generate(
        &[
            "--samples",
            "30000",
            "--my",
            "0",
            "--width",
            "512",
            "--from-heightmap",
            &png,
        ],
        &b,
    ));
    let (w, za) = elevation16(&a);
    let (_, zb) = elevation16(&b);
    let agree = land_agreement(w, &za, |k| zb[k]);
    eprintln!(
        "round trip: land agrees on {:.2}% of the area",
        100.0 * agree
    );
    assert!(
        agree >= 0.98,
        "land agrees on {:.2}% of the area",
        100.0 * agree
    );
    // And it runs on from there.
    ok(&generate(
        &[
            "--samples",
            "30000",
            "--my",
            "10",
            "--width",
            "256",
            "--from-heightmap",
            &png,
        ],
        &dir.join("c"),
    ));
}

#[test]
fn earth_start_puts_land_where_earths_is() {
    let dir = temp_dir("earth");
    ok(&generate(
        &[
            "--samples",
            "100000",
            "--my",
            "0",
            "--width",
            "720",
            "--from-earth",
        ],
        &dir,
    ));
    let (w, z) = elevation16(&dir);
    let h = z.len() / w;
    let earth: Vec<f64> = (0..z.len())
        .map(|k| {
            let (r, c) = (k / w, k % w);
            let lat = 90.0 - (r as f64 + 0.5) * 180.0 / h as f64;
            let lon = -180.0 + (c as f64 + 0.5) * 360.0 / w as f64;
            earth_elevation_m(from_lat_lon_deg(lat, lon))
        })
        .collect();
    let agree = land_agreement(w, &z, |k| earth[k]);
    eprintln!(
        "Earth start: land agrees with Earth's on {:.2}%",
        100.0 * agree
    );
    assert!(
        agree >= 0.97,
        "land agrees with Earth's on {:.2}%",
        100.0 * agree
    );
    // Today's plates: PB2002's larger than 0.1% of the globe (27; the smaller join a neighbour).
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let plates = summary["plates"].as_u64().unwrap();
    assert!((20..=40).contains(&plates), "{plates} plates");
}

#[test]
fn todays_plates_move_as_nnr_morvel56_says() {
    let (grid, plates) = earth_plates();
    let hawaii = from_lat_lon_deg(19.9, -155.6);
    let p = &plates[grid.at(hawaii) as usize];
    assert_eq!(p.code, "PA");
    let v = p.motion.velocity_km_per_my(hawaii, 6371.0);
    let north = DVec3::Z - hawaii * hawaii.z;
    let east = DVec3::Z.cross(hawaii).normalize();
    let (vn, ve) = (v.dot(north.normalize()), v.dot(east));
    let speed = v.length();
    let azimuth = ve.atan2(vn).to_degrees().rem_euclid(360.0);
    assert!((60.0..=80.0).contains(&speed), "{speed:.1} mm/yr");
    assert!((285.0..=310.0).contains(&azimuth), "toward {azimuth:.0}°");
    // Every pixel has a plate of the table, and the big ones are where they belong.
    assert!(grid.index.iter().all(|&i| (i as usize) < plates.len()));
    for (lat, lon, code) in [
        (45.0, -100.0, "NA"),
        (-15.0, -55.0, "SA"),
        (50.0, 60.0, "EU"),
        (-80.0, 0.0, "AN"),
        (-25.0, 135.0, "AU"),
    ] {
        assert_eq!(
            plates[grid.at(from_lat_lon_deg(lat, lon)) as usize].code,
            code,
            "at {lat}, {lon}"
        );
    }
}

fn write_png16(path: &Path, w: u32, h: u32, grey: impl Fn(u32, u32) -> u16) {
    let img = image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_fn(w, h, |x, y| {
        image::Luma([grey(x, y)])
    });
    img.save(path).unwrap();
}

fn write_sidecar(png: &Path, w: u32, h: u32, bounds: (f64, f64, f64, f64)) {
    let json = format!(
        "{{\"min_elevation_m\": -5000.0, \"max_elevation_m\": 3000.0, \"projection\": \"equirectangular\", \"width\": {w}, \"height\": {h}, \"bounds\": {{\"west\": {}, \"south\": {}, \"east\": {}, \"north\": {}}}}}",
        bounds.0, bounds.1, bounds.2, bounds.3
    );
    std::fs::write(png.with_extension("json"), json).unwrap();
}

fn refused(path: &Path, needles: &[&str]) {
    let e = load_heightmap(path)
        .expect_err("a bad heightmap was accepted")
        .to_string();
    for n in needles {
        assert!(e.contains(n), "{e:?} does not say {n:?}");
    }
}

#[test]
fn bad_heightmaps_are_refused_with_the_reason() {
    let dir = temp_dir("bad");
    let globe = (-180.0, -90.0, 180.0, 90.0);
    // Wrong size: not 2:1.
    let p = dir.join("square.png");
    write_png16(&p, 64, 64, |_, _| 30000);
    write_sidecar(&p, 64, 64, globe);
    refused(&p, &["64×64", "twice as wide"]);
    // 8-bit.
    let p = dir.join("eight.png");
    image::GrayImage::from_fn(128, 64, |_, _| image::Luma([100]))
        .save(&p)
        .unwrap();
    refused(&p, &["8-bit"]);
    // Not georeferenced: no sidecar; a sidecar without bounds; a regional one.
    let p = dir.join("bare.png");
    write_png16(&p, 128, 64, |_, _| 30000);
    refused(&p, &["no sidecar"]);
    std::fs::write(
        p.with_extension("json"),
        "{\"min_elevation_m\": -5000.0, \"max_elevation_m\": 3000.0}",
    )
    .unwrap();
    refused(&p, &["not georeferenced"]);
    write_sidecar(&p, 128, 64, (0.0, 0.0, 90.0, 45.0));
    refused(&p, &["whole globe"]);
    // A GeoTIFF covering part of the globe.
    let t = dir.join("part.tif");
    let b = GeoBounds {
        west: 0.0,
        south: 0.0,
        east: 20.0,
        north: 10.0,
    };
    write_geotiff(&t, 128, 64, b, "part", &vec![100.0; 128 * 64]).unwrap();
    refused(&t, &["whole globe"]);
    // A global GeoTIFF is read, and sampled where its pixels are.
    let t = dir.join("globe.tif");
    let b = GeoBounds {
        west: -180.0,
        south: -90.0,
        east: 180.0,
        north: 90.0,
    };
    let vals: Vec<f32> = (0..128 * 64)
        .map(|k| if (k % 128) < 64 { -4000.0 } else { 500.0 })
        .collect();
    write_geotiff(&t, 128, 64, b, "globe", &vals).unwrap();
    let g = load_heightmap(&t).unwrap();
    assert_eq!(g.at(from_lat_lon_deg(10.0, -90.0)), -4000.0);
    assert_eq!(g.at(from_lat_lon_deg(10.0, 90.0)), 500.0);
    // All ocean: read, but no planet starts from it.
    let p = dir.join("ocean.png");
    write_png16(&p, 128, 64, |_, _| 10000);
    write_sidecar(&p, 128, 64, globe);
    let o = generate(
        &[
            "--samples",
            "5000",
            "--my",
            "0",
            "--from-heightmap",
            &p.to_string_lossy(),
        ],
        &dir.join("out"),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("no land"), "{err}");
    // The same refusals reach the command line, naming the file.
    let p8 = dir.join("eight.png").to_string_lossy().to_string();
    let o = generate(
        &["--samples", "5000", "--my", "0", "--from-heightmap", &p8],
        &dir.join("o2"),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("eight.png") && err.contains("8-bit"),
        "{err}"
    );
}

/// A global 128×64 heightmap in `dir`: land (+2.3 km) in the eastern half, sea in the west.
fn half_land_map(dir: &Path) -> PathBuf {
    let p = dir.join("relief.png");
    write_png16(&p, 128, 64, |x, _| if x >= 64 { 60000 } else { 10000 });
    write_sidecar(&p, 128, 64, (-180.0, -90.0, 180.0, 90.0));
    p
}

#[test]
fn plates_map_and_motions_are_followed() {
    let dir = temp_dir("plates");
    // Land in the east, ocean in the west; plates: north and south halves.
    let p = half_land_map(&dir);
    let plates = dir.join("plates.png");
    image::RgbImage::from_fn(128, 64, |_, y| {
        if y < 32 {
            image::Rgb([200, 0, 0])
        } else {
            image::Rgb([0, 0, 200])
        }
    })
    .save(&plates)
    .unwrap();
    let grid = load_plates_map(&plates).unwrap();
    assert_eq!(grid.count, 2);
    assert_eq!(grid.colours, vec!["#0000c8", "#c80000"]);
    assert_eq!(grid.at(from_lat_lon_deg(45.0, 0.0)), 1);
    let motions = dir.join("motions.toml");
    std::fs::write(
        &motions,
        "[[plate]]\ncolour = \"#C80000\"\npole_lat_deg = 90.0\npole_lon_deg = 0.0\nrate_deg_per_my = 0.5\n",
    )
    .unwrap();
    let m = load_motions(&motions, &grid.colours).unwrap();
    assert_eq!(m.len(), 1);
    assert_eq!(m[0].0, 1);
    assert!((m[0].1.angular_speed_rad_per_my - 0.5f64.to_radians()).abs() < 1e-12);
    let o = generate(
        &[
            "--samples",
            "8000",
            "--my",
            "0",
            "--width",
            "128",
            "--from-heightmap",
            &p.to_string_lossy(),
            "--plates-map",
            &plates.to_string_lossy(),
            "--motions",
            &motions.to_string_lossy(),
        ],
        &dir.join("out"),
    );
    ok(&o);
    let s: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("out").join("summary.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(s["plates"].as_u64(), Some(2));
    let land = s["land_fraction"].as_f64().unwrap();
    assert!((land - 0.5).abs() < 0.03, "land fraction {land}");
    // A motion for a plate the map does not have is refused.
    std::fs::write(
        &motions,
        "[[plate]]\nplate = 7\npole_lat_deg = 0.0\npole_lon_deg = 0.0\nrate_deg_per_my = 0.5\n",
    )
    .unwrap();
    let o = generate(
        &[
            "--samples",
            "8000",
            "--my",
            "0",
            "--from-heightmap",
            &p.to_string_lossy(),
            "--plates-map",
            &plates.to_string_lossy(),
            "--motions",
            &motions.to_string_lossy(),
        ],
        &dir.join("out2"),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("plate 7"), "{err}");
    // Plates map alone, without a map to start from, is a usage error.
    let o = generate(
        &["--plates-map", &plates.to_string_lossy()],
        &dir.join("out3"),
    );
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--from-heightmap"),
        "{err}"
    );
}

#[test]
fn a_map_start_takes_craters_and_names_what_it_ignores() {
    let dir = temp_dir("craters");
    let p = half_land_map(&dir);
    let map = p.to_string_lossy().to_string();
    // Not through `generate`: its --quiet would hide the notes checked below.
    let run = |extra: &[&str], name: &str| -> (Vec<u8>, String) {
        let out = dir.join(name);
        let dir_s = out.to_string_lossy().to_string();
        let mut args = vec![
            "generate",
            "--samples",
            "8000",
            "--my",
            "0",
            "--width",
            "128",
            "--backend",
            "cpu",
            "--from-heightmap",
            &map,
            "--out",
            &dir_s,
        ];
        args.extend_from_slice(extra);
        let o = planet().args(&args).output().expect("run planet generate");
        ok(&o);
        (
            std::fs::read(out.join("elevation16.png")).unwrap(),
            String::from_utf8_lossy(&o.stderr).to_string(),
        )
    };
    let (plain, _) = run(&[], "plain");
    let (cratered, _) = run(&["--craters", "30"], "cratered");
    assert_ne!(plain, cratered, "--craters changed nothing on a map start");
    let (_, err) = run(&["--continental-fraction", "0.5"], "ignored");
    assert!(err.contains("--continental-fraction is ignored"), "{err}");
}
