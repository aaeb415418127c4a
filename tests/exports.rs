//! Exports: GeoTIFFs read by GDAL with EPSG:4326 and the right bounds, 16-bit heightmaps and
//! their sidecar, the glTF mesh parsed back, and the `planet export` flags end to end.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::DVec3;
use tectonic_planets::amplify::{Amplifier, AmplifyOptions};
use tectonic_planets::geometry::SphereMesh;
use tectonic_planets::io::export::{self, ElevationOutputs, GeoGrid};
use tectonic_planets::io::gltf::{GltfOptions, elevation_colour, planet_glb};
use tectonic_planets::io::rivers::{NetworkOptions, RiverNetwork};
use tectonic_planets::prelude::*;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "planet-exports-{tag}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos())
    ));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A small crust: continents where a smooth function of position is positive.
fn small_planet() -> (SphereMesh, Crust) {
    let mesh = SphereMesh::fibonacci(5_000, 0.5, 3, 6371.0).unwrap();
    let mut c = Crust::with_len(mesh.len());
    for (i, p) in mesh.positions.iter().enumerate() {
        let land = (3.0 * p.x).sin() + (2.0 * p.y).cos() * p.z > 0.6;
        c.plate[i] = if p.x > 0.0 { 1 } else { 2 };
        if land {
            c.crust_type[i] = CrustType::Continental;
            c.elevation_km[i] = 0.5 + p.z.abs() as f32 * 2.0;
            c.orogeny[i] = if p.z > 0.3 {
                Orogeny::Himalayan
            } else {
                Orogeny::None
            };
            c.orogeny_age_my[i] = 20.0;
        } else {
            c.elevation_km[i] = -3.5;
            c.age_my[i] = 40.0 + 30.0 * p.y as f32;
        }
    }
    (mesh, c)
}

/// Runs `gdalinfo -json`, or returns None (skip) when GDAL is missing outside CI.
fn gdalinfo(path: &Path) -> Option<serde_json::Value> {
    match Command::new("gdalinfo").arg("-json").arg(path).output() {
        Ok(out) => {
            assert!(
                out.status.success(),
                "gdalinfo failed on {}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            Some(serde_json::from_slice(&out.stdout).expect("gdalinfo -json output"))
        }
        Err(e) => {
            if std::env::var("CI").is_ok_and(|v| v == "true") {
                panic!("gdalinfo is required under CI (apt-get install gdal-bin): {e}");
            }
            eprintln!("SKIPPED: gdalinfo not found ({e}); install gdal-bin to run this check");
            None
        }
    }
}

fn check_gdal(path: &Path, width: u32, height: u32, b: &tectonic_planets::io::geotiff::GeoBounds) {
    let Some(info) = gdalinfo(path) else { return };
    assert_eq!(
        info["size"],
        serde_json::json!([width, height]),
        "{}",
        path.display()
    );
    let wkt = info["coordinateSystem"]["wkt"].as_str().unwrap_or("");
    assert!(
        wkt.contains("WGS 84") && wkt.contains("4326"),
        "not EPSG:4326: {wkt}"
    );
    let corners = &info["cornerCoordinates"];
    let close = |v: &serde_json::Value, x: f64, y: f64| {
        let (vx, vy) = (v[0].as_f64().unwrap(), v[1].as_f64().unwrap());
        assert!(
            (vx - x).abs() < 1e-7 && (vy - y).abs() < 1e-7,
            "{}: corner {vx},{vy} expected {x},{y}",
            path.display()
        );
    };
    close(&corners["upperLeft"], b.west, b.north);
    close(&corners["lowerRight"], b.east, b.south);
    assert_eq!(info["bands"][0]["type"], "Float32");
    let area = info["metadata"][""]["AREA_OR_POINT"].as_str().unwrap_or("");
    assert_eq!(area, "Area", "PixelIsArea");
}

#[test]
fn gdal_reads_every_geotiff_with_epsg_4326_and_the_bounds() {
    let (mesh, crust) = small_planet();
    let dir = temp_dir("gdal");
    let global = GeoGrid::global(360, 180).unwrap();
    let files = export::export_crust_layers(&mesh, &crust, &global, &dir, "").unwrap();
    assert_eq!(files.len(), export::CRUST_LAYERS.len());
    for f in &files {
        check_gdal(f, 360, 180, &global.bounds());
    }
    let region = GeoGrid::region(-12.5, 40.25, -10.0, 44.0, 0.01).unwrap();
    let amp = Amplifier::new(&mesh, &crust, 9, AmplifyOptions::default());
    let outs = ElevationOutputs {
        png16: None,
        geotiff: Some(dir.join("tile.tif")),
    };
    let files = export::export_amplified(&amp, &region, &outs).unwrap();
    let b = region.bounds();
    assert!(
        (b.west - 40.25).abs() < 1e-9 && (b.north + 10.0).abs() < 1e-9,
        "{b:?}"
    );
    check_gdal(&files[0], region.width, region.height, &b);
    // Values read back are the amplified elevations at the pixel centres.
    let t = tectonic_planets::io::geotiff::read_single_band(&std::fs::read(&files[0]).unwrap())
        .unwrap();
    let (c, r) = (17u32, 101u32);
    assert_eq!(
        t.values[(r * region.width + c) as usize],
        amp.elevation_m(region.direction(c, r))
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn drainage_geotiffs_hold_the_area_and_basins_that_follow_the_receivers() {
    let (mesh, crust) = small_planet();
    let net = RiverNetwork::of(
        &mesh,
        &crust,
        NetworkOptions {
            min_sea_area_km2: 250_000.0,
            lake_area_ratio: None,
            climate: None,
        },
    );
    let d = &net.drainage;
    // Every sample's basin is its receiver's.
    for i in 0..mesh.len() {
        let r = d.receiver[i] as usize;
        assert_eq!(net.outlets[i], net.outlets[r], "sample {i}, receiver {r}");
    }
    let dir = temp_dir("drainage");
    let grid = GeoGrid::global(360, 180).unwrap();
    let files = export::export_drainage_layers(&mesh, &net, &grid, &dir, "").unwrap();
    let names: Vec<_> = files.iter().filter_map(|f| f.file_name()).collect();
    assert_eq!(names, ["flow_accumulation.tif", "drainage_basin.tif"]);
    for f in &files {
        check_gdal(f, 360, 180, &grid.bounds());
        if let Some(info) = gdalinfo(f) {
            assert_eq!(info["bands"].as_array().map(Vec::len), Some(1));
        }
    }
    let read = |f: &Path| {
        tectonic_planets::io::geotiff::read_single_band(&std::fs::read(f).unwrap()).unwrap()
    };
    let (area, basin) = (read(&files[0]), read(&files[1]));
    assert_eq!((area.width, area.height), (360, 180));
    assert_eq!((basin.width, basin.height), (360, 180));
    let (mut land, mut river, mut basins) = (0, 0, std::collections::HashSet::new());
    for row in 0..grid.height {
        for col in 0..grid.width {
            let k = (row * grid.width + col) as usize;
            let loc = mesh.locate(grid.direction(col, row));
            let s = mesh.triangles[loc.triangle as usize][loc.dominant_corner()] as usize;
            if d.ocean[s] {
                assert_eq!(
                    (area.values[k], basin.values[k]),
                    (0.0, -1.0),
                    "pixel {col},{row}"
                );
                continue;
            }
            land += 1;
            assert_eq!(area.values[k], d.area_km2[s] as f32, "pixel {col},{row}");
            assert_eq!(basin.values[k], net.outlets[s] as f32, "pixel {col},{row}");
            // The pixel's basin is its sample's receiver's.
            let r = d.receiver[s] as usize;
            assert_eq!(basin.values[k], net.outlets[r] as f32, "pixel {col},{row}");
            basins.insert(basin.values[k].to_bits());
            river += usize::from(f64::from(area.values[k]) > 10.0 * mesh.area_km2[s]);
        }
    }
    assert!(land > 1000, "{land} land pixels");
    assert!(river > 50, "{river} pixels drain more than ten samples");
    assert!(basins.len() > 5, "{} basins", basins.len());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn heightmap16_round_trips_within_one_grey_step() {
    let (mesh, crust) = small_planet();
    let dir = temp_dir("h16");
    let amp = Amplifier::new(&mesh, &crust, 4, AmplifyOptions::default());
    let grid = GeoGrid::global(256, 128).unwrap();
    let outs = ElevationOutputs {
        png16: Some(dir.join("h.png")),
        geotiff: None,
    };
    let files = export::export_amplified(&amp, &grid, &outs).unwrap();
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&files[1]).unwrap()).unwrap();
    let (lo, hi) = (
        meta["min_elevation_m"].as_f64().unwrap(),
        meta["max_elevation_m"].as_f64().unwrap(),
    );
    assert_eq!(meta["projection"], "equirectangular");
    assert_eq!(meta["bounds"]["west"], -180.0);
    assert_eq!(meta["bounds"]["north"], 90.0);
    let img = image::open(&files[0]).unwrap().to_luma16();
    assert_eq!(img.dimensions(), (256, 128));
    let step = (hi - lo) / 65535.0;
    let mut distinct = std::collections::BTreeSet::new();
    for r in (0..128).step_by(7) {
        for c in (0..256).step_by(5) {
            let g = img.get_pixel(c, r)[0];
            distinct.insert(g);
            let m = lo + f64::from(g) * step;
            let truth = f64::from(amp.elevation_m(grid.direction(c, r)));
            assert!(
                (m - truth).abs() <= step * 0.51 + 1e-3,
                "({c},{r}): {m} vs {truth}"
            );
        }
    }
    assert!(distinct.len() > 100, "heightmap nearly flat");
    std::fs::remove_dir_all(&dir).ok();
}

/// Parses a .glb: returns the JSON and the binary chunk.
fn parse_glb(bytes: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(u32_at(4), 2, "glTF version");
    assert_eq!(u32_at(8), bytes.len(), "declared length");
    let json_len = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0);
    let json: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let b = 20 + json_len;
    let bin_len = u32_at(b);
    assert_eq!(&bytes[b + 4..b + 8], b"BIN\0");
    assert_eq!(b + 8 + bin_len, bytes.len());
    (json, bytes[b + 8..].to_vec())
}

#[test]
fn gltf_mesh_parses_back_and_is_consistent() {
    let (mesh, crust) = small_planet();
    let amp = Amplifier::new(&mesh, &crust, 4, AmplifyOptions::default());
    let opts = GltfOptions {
        segments: 64,
        exaggeration: 50.0,
        radius_km: 6371.0,
    };
    let glb = planet_glb(&opts, &|d| amp.elevation_m(d), &elevation_colour).unwrap();
    let (json, bin) = parse_glb(&glb);
    assert_eq!(json["asset"]["version"], "2.0");
    assert_eq!(
        json["buffers"][0]["byteLength"].as_u64().unwrap() as usize,
        bin.len()
    );
    let acc = json["accessors"].as_array().unwrap();
    let views = json["bufferViews"].as_array().unwrap();
    let prim = &json["meshes"][0]["primitives"][0];
    assert_eq!(prim["attributes"]["POSITION"], 0);
    assert_eq!(prim["attributes"]["COLOR_0"], 2);
    let view = |k: usize| {
        let v = &views[acc[k]["bufferView"].as_u64().unwrap() as usize];
        let (o, l) = (
            v["byteOffset"].as_u64().unwrap() as usize,
            v["byteLength"].as_u64().unwrap() as usize,
        );
        assert!(o % 4 == 0 && o + l <= bin.len());
        &bin[o..o + l]
    };
    let n = acc[0]["count"].as_u64().unwrap() as usize;
    let pos: &[[f32; 3]] = bytemuck::cast_slice(view(0));
    let col: &[[f32; 4]] = bytemuck::cast_slice(view(2));
    let idx: &[u32] = bytemuck::cast_slice(view(3));
    assert_eq!(pos.len(), n);
    assert_eq!(col.len(), n);
    assert_eq!(n, 2 + 31 * 64);
    assert_eq!(idx.len(), acc[3]["count"].as_u64().unwrap() as usize);
    // min/max match the data (the validator checks this too).
    for k in 0..3 {
        let mn = pos.iter().map(|p| p[k]).fold(f32::MAX, f32::min);
        let mx = pos.iter().map(|p| p[k]).fold(f32::MIN, f32::max);
        assert_eq!(acc[0]["min"][k].as_f64().unwrap() as f32, mn);
        assert_eq!(acc[0]["max"][k].as_f64().unwrap() as f32, mx);
    }
    // Every vertex is used, every index in range, every triangle faces outward.
    let mut used = vec![false; n];
    for t in idx.chunks_exact(3) {
        let p: Vec<DVec3> = t
            .iter()
            .map(|&i| {
                used[i as usize] = true;
                let v = pos[i as usize];
                DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
            })
            .collect();
        let normal = (p[1] - p[0]).cross(p[2] - p[0]);
        assert!(
            normal.dot(p[0] + p[1] + p[2]) > 0.0,
            "inward triangle {t:?}"
        );
    }
    assert!(used.iter().all(|&u| u));
    // Relief is there: radii differ by the exaggerated elevations.
    let radii: Vec<f32> = pos
        .iter()
        .map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt())
        .collect();
    let (rmin, rmax) = radii
        .iter()
        .fold((f32::MAX, f32::MIN), |a, &r| (a.0.min(r), a.1.max(r)));
    assert!(rmin < 0.99 && rmax > 1.005, "radii {rmin}..{rmax}");
    assert!(
        col.iter()
            .all(|c| c.iter().all(|v| (0.0..=1.0).contains(v)))
    );
    // Bad options are refused.
    assert!(
        planet_glb(
            &GltfOptions {
                segments: 3,
                ..opts
            },
            &|_| 0.0,
            &elevation_colour
        )
        .is_err()
    );
    assert!(
        planet_glb(
            &GltfOptions {
                exaggeration: f64::NAN,
                ..opts
            },
            &|_| 0.0,
            &elevation_colour
        )
        .is_err()
    );
}

fn planet() -> Command {
    Command::new(env!("CARGO_BIN_EXE_planet"))
}

#[test]
fn export_command_writes_the_requested_files_and_refuses_bad_flags() {
    let save = Path::new(env!("CARGO_MANIFEST_DIR")).join("saves/fixture-v1.planet");
    let out = temp_dir("cli");
    let status = planet()
        .arg("export")
        .arg(&save)
        .args([
            "--no-maps",
            "--quiet",
            "--amplified",
            "--geotiff",
            "--preview",
            "--gltf",
        ])
        .args([
            "--gltf-segments",
            "32",
            "--region",
            "-5,10,5,20",
            "--resolution",
            "5km",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    for f in [
        "tile_amplified16.png",
        "tile_amplified16.json",
        "tile_amplified.tif",
        "tile_crust_elevation.tif",
        "tile_plate.tif",
        "tile_orogeny_age.tif",
        "tile_flow_accumulation.tif",
        "tile_drainage_basin.tif",
        "tile_amplified_preview.png",
        "tile_crust_preview.png",
        "planet.glb",
    ] {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    assert!(!out.join("elevation.png").exists(), "--no-maps wrote maps");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("tile_amplified16.json")).unwrap())
            .unwrap();
    assert!((meta["bounds"]["west"].as_f64().unwrap() - 10.0).abs() < 0.05);
    assert!((meta["bounds"]["north"].as_f64().unwrap() - 5.0).abs() < 0.05);
    for (args, needle) in [
        (
            vec!["--amplified", "--region", "1,2,3"],
            "LAT0,LON0,LAT1,LON1",
        ),
        (
            vec!["--amplified", "--region", "0,0,1,1", "--resolution", "fast"],
            "--resolution",
        ),
        (
            vec!["--amplified", "--exemplars", "/nonexistent/ex"],
            "/nonexistent/ex",
        ),
        (
            vec!["--amplified", "--relief-scale", "-1"],
            "--relief-scale",
        ),
        (vec!["--gltf", "--gltf-segments", "2"], "segments"),
    ] {
        let o = planet()
            .arg("export")
            .arg(&save)
            .arg("--no-maps")
            .args(&args)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(err.contains(needle), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    }
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn export_backend_gpu_amplifies_within_the_tolerance_of_the_cpu() {
    let save = Path::new(env!("CARGO_MANIFEST_DIR")).join("saves/fixture-v1.planet");
    let run = |backend: &str| {
        let out = temp_dir(&format!("backend-{backend}"));
        let o = planet()
            .arg("export")
            .arg(&save)
            .args(["--no-maps", "--amplified", "--geotiff"])
            .args(["--amplified-width", "512", "--backend", backend])
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        (o, out)
    };
    let (cpu, cpu_dir) = run("cpu");
    assert!(
        cpu.status.success(),
        "{}",
        String::from_utf8_lossy(&cpu.stderr)
    );
    let (gpu, gpu_dir) = run("gpu");
    let err = String::from_utf8_lossy(&gpu.stderr);
    assert!(!err.contains("panicked"), "{err}");
    if !gpu.status.success() {
        // Without an adapter: a clear error (a failure on CI, where lavapipe is installed).
        assert!(err.contains("no GPU adapter"), "{err}");
        assert!(
            !std::env::var("CI").is_ok_and(|v| v == "true"),
            "no GPU adapter on CI: {err}"
        );
        eprintln!("export --backend gpu: SKIPPED, no GPU adapter");
        return;
    }
    assert!(
        err.contains("(gpu: "),
        "the rows were not amplified on the GPU: {err}"
    );
    let read = |dir: &Path| {
        tectonic_planets::io::geotiff::read_single_band(
            &std::fs::read(dir.join("amplified.tif")).unwrap(),
        )
        .unwrap()
        .values
    };
    let (c, g) = (read(&cpu_dir), read(&gpu_dir));
    assert_eq!(c.len(), 512 * 256);
    assert_eq!(c.len(), g.len());
    let max = c
        .iter()
        .zip(&g)
        .map(|(a, b)| (a - b).abs())
        .fold(
            0.0f32,
            |m, e| if e.is_nan() { f32::INFINITY } else { m.max(e) },
        );
    // The kernel's tolerance (docs/amplification.md, tests/amplify.rs).
    assert!(
        max <= 0.05,
        "gpu export differs from the cpu one by {max} m"
    );
    eprintln!("export --backend gpu: max difference {max} m");
    std::fs::remove_dir_all(&cpu_dir).ok();
    std::fs::remove_dir_all(&gpu_dir).ok();
}
