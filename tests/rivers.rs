//! Rivers in the outputs, on a simulated planet (20,000 samples, 30 My): rivers.geojson parses,
//! every line has two points or more and ends in the sea, in a lake, in a sink or where the line
//! below it starts, and every river followed downstream ends in the sea or a lake; rivers.png
//! is elevation.png with the rivers and lakes drawn, and nothing else.

mod common;

use std::sync::OnceLock;

use tectonic_planets::geometry::SphereMesh;
use tectonic_planets::io::maps::Raster;
use tectonic_planets::io::rivers::{self, NetworkOptions, RiverNetwork};
use tectonic_planets::io::summary::CrustSampler;
use tectonic_planets::prelude::*;

/// The planet (reference mesh and resampled crust) and its river network, made once.
fn planet() -> &'static (SphereMesh, Crust, RiverNetwork) {
    static PLANET: OnceLock<(SphereMesh, Crust, RiverNetwork)> = OnceLock::new();
    PLANET.get_or_init(|| {
        let mut p = common::params(20_000, 3);
        p.init.plates = 10;
        let mut sim = Simulation::new(p).expect("planet");
        let steps = sim.steps_for(30.0).expect("steps");
        for _ in 0..steps {
            sim.step().expect("step");
        }
        let crust = sim.resampled_crust();
        let mesh = sim.mesh().clone();
        let net = RiverNetwork::of(&mesh, &crust, NetworkOptions::of(sim.params()));
        (mesh, crust, net)
    })
}

/// The network of an export or a map is made on the graph without its cotangent weights (only
/// the diffusion and the flexure read them): the same network, bit for bit, as on the
/// simulation's graph.
#[test]
fn the_network_without_cotangent_weights_is_the_simulations() {
    use tectonic_planets::systems::relief::network::relief_graph;
    let (mesh, crust, net) = planet();
    let mut p = common::params(20_000, 3);
    p.init.plates = 10;
    let full = RiverNetwork::on_graph(
        &relief_graph(mesh),
        &mesh.positions,
        crust,
        NetworkOptions::of(&p),
    );
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(full.drainage.receiver, net.drainage.receiver);
    assert_eq!(bits(&full.drainage.area_km2), bits(&net.drainage.area_km2));
    assert_eq!(full.rain, net.rain);
    assert_eq!(full.reaches.len(), net.reaches.len());
    assert!(net.reaches.len() >= 20, "{} reaches", net.reaches.len());
}

/// [lon, lat] of a GeoJSON position.
fn position(v: &serde_json::Value) -> [f64; 2] {
    let a = v.as_array().expect("a position is an array");
    assert_eq!(a.len(), 2, "{v}");
    [a[0].as_f64().expect("lon"), a[1].as_f64().expect("lat")]
}

#[test]
fn rivers_geojson_lines_end_in_the_sea_a_lake_or_the_next_line() {
    let (mesh, _, net) = planet();
    let text = serde_json::to_string(&rivers::rivers_geojson(&mesh.positions, net)).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(doc["type"], "FeatureCollection");
    let features = doc["features"].as_array().expect("features");
    assert!(
        features.len() >= 20,
        "only {} river reaches on a 20,000-sample planet",
        features.len()
    );
    assert_eq!(features.len(), net.reaches.len());
    let d = &net.drainage;
    let mut ends = std::collections::HashMap::<String, usize>::new();
    for (k, f) in features.iter().enumerate() {
        assert_eq!(f["type"], "Feature");
        let g = &f["geometry"];
        let parts: Vec<Vec<[f64; 2]>> = match g["type"].as_str() {
            Some("LineString") => vec![
                g["coordinates"]
                    .as_array()
                    .expect("coordinates")
                    .iter()
                    .map(position)
                    .collect(),
            ],
            Some("MultiLineString") => g["coordinates"]
                .as_array()
                .expect("coordinates")
                .iter()
                .map(|l| l.as_array().expect("a line").iter().map(position).collect())
                .collect(),
            other => panic!("feature {k}: geometry {other:?}"),
        };
        let points: usize = parts.iter().map(Vec::len).sum();
        assert!(points >= 2, "feature {k} has {points} points");
        for p in parts.iter().flatten() {
            assert!((-180.0..=180.0).contains(&p[0]) && (-90.0..=90.0).contains(&p[1]));
        }
        // The last point is the position of the reach's last sample.
        let last = *parts.last().and_then(|l| l.last()).expect("a point");
        let reach = &net.reaches[k];
        let s = *reach.samples.last().unwrap() as usize;
        let (lat, lon) = tectonic_planets::geometry::spherical::to_lat_lon_deg(mesh.positions[s]);
        assert!(
            (last[0] - lon).abs() < 2e-5 && (last[1] - lat).abs() < 2e-5,
            "feature {k}: last point {last:?} is not sample {s} at {lon},{lat}"
        );
        let props = &f["properties"];
        let ends_in = props["ends_in"].as_str().expect("ends_in").to_string();
        match ends_in.as_str() {
            "sea" => assert!(d.ocean[s], "feature {k} ends in the sea on land"),
            "lake" => assert!(d.is_lake(s), "feature {k} ends in a lake that is not there"),
            "sink" => assert!(d.sinks.contains(&(s as u32))),
            "confluence" => {
                let below = props["downstream"].as_u64().expect("a confluence leads on") as usize;
                let first = &features[below]["geometry"];
                let start = match first["type"].as_str() {
                    Some("LineString") => position(&first["coordinates"][0]),
                    _ => position(&first["coordinates"][0][0]),
                };
                assert_eq!(start, last, "feature {k} ends where feature {below} starts");
            }
            other => panic!("feature {k}: ends_in {other}"),
        }
        *ends.entry(ends_in).or_default() += 1;
        assert!(props["area_km2"].as_f64().expect("area") >= net.min_area_km2 * 0.999);
        assert!(props["strahler"].as_u64().expect("strahler") >= 1);
        assert!(props["rank"].as_u64().expect("rank") >= 1);
        // Followed downstream, every river reaches the sea or a lake (or a closed basin).
        let (mut at, mut hops) = (k, 0);
        while let Some(next) = features[at]["properties"]["downstream"].as_u64() {
            at = next as usize;
            hops += 1;
            assert!(hops <= features.len(), "reaches downstream of {k} loop");
        }
        let end = features[at]["properties"]["ends_in"].as_str().unwrap();
        assert!(
            matches!(end, "sea" | "lake" | "sink"),
            "reach {k} ends at {end}"
        );
    }
    // Rivers branch (confluences) and reach the sea.
    assert!(ends.get("sea").copied().unwrap_or(0) >= 5, "{ends:?}");
    assert!(
        ends.get("confluence").copied().unwrap_or(0) >= 5,
        "{ends:?}"
    );
    assert!(
        net.reaches.iter().any(|r| r.strahler >= 2),
        "no river of order 2"
    );
}

#[test]
fn rivers_png_is_the_relief_with_rivers_and_lakes_drawn() {
    let (mesh, crust, net) = planet();
    let (w, h) = (1024, 512);
    let raster = Raster::sample(&CrustSampler { mesh, crust }, w, h).unwrap();
    let dir = std::env::temp_dir().join(format!("planet-rivers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let files = rivers::write_rivers(&raster, mesh, net, &dir, 6371.0).unwrap();
    assert!(files.iter().any(|f| f.ends_with("rivers.png")));
    assert!(files.iter().any(|f| f.ends_with("rivers.geojson")));
    let img = image::open(dir.join("rivers.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (w, h));
    let relief = raster.elevation_image(6371.0);
    let changed: Vec<(u32, u32)> = img
        .enumerate_pixels()
        .filter(|(x, y, p)| relief.get_pixel(*x, *y) != *p)
        .map(|(x, y, _)| (x, y))
        .collect();
    let total = (w * h) as usize;
    assert!(
        changed.len() > 500 && changed.len() < total / 10,
        "{} of {total} pixels differ from elevation.png",
        changed.len()
    );
    // Along the largest river, the map is river-coloured.
    let big = net.reaches.iter().find(|r| r.rank == 1).expect("a river");
    let mut blue = 0;
    let inner = &big.samples[..big.samples.len() - 1];
    for &s in inner {
        let (lat, lon) =
            tectonic_planets::geometry::spherical::to_lat_lon_deg(mesh.positions[s as usize]);
        let x = (((lon + 180.0) / 360.0 * w as f64) as u32).min(w - 1);
        let y = (((90.0 - lat) / 180.0 * h as f64) as u32).min(h - 1);
        let p = img.get_pixel(x, y).0;
        if p[2] > p[0] + 60 && p[2] > p[1] + 30 {
            blue += 1;
        }
    }
    assert!(
        blue * 10 >= inner.len() * 8,
        "{blue} of {} points of the largest river are river-blue",
        inner.len()
    );
    // Every changed pixel is near a river or on a lake: none is more than 4 pixels from the
    // segment of a river sample (or a lake sample).
    let near: std::collections::HashSet<(i64, i64)> = (0..net.len())
        .filter(|&i| {
            !net.drainage.ocean[i]
                && (net.drainage.area_km2[i] >= net.min_area_km2 || net.is_lake(i))
        })
        .flat_map(|i| {
            let a = mesh.positions[i];
            let b = mesh.positions[net.drainage.receiver[i] as usize];
            (0..=8).map(move |k| (a * (8 - k) as f64 + b * k as f64).normalize())
        })
        .map(|p| {
            let (lat, lon) = tectonic_planets::geometry::spherical::to_lat_lon_deg(p);
            (
                ((lon + 180.0) / 360.0 * w as f64) as i64 / 8,
                ((90.0 - lat) / 180.0 * h as f64) as i64 / 8,
            )
        })
        .collect();
    let cells = (w / 8) as i64;
    let far = changed
        .iter()
        .filter(|&&(x, y)| {
            let (cx, cy) = (x as i64 / 8, y as i64 / 8);
            !(-1..=1)
                .any(|dx| (-1..=1).any(|dy| near.contains(&((cx + dx).rem_euclid(cells), cy + dy))))
        })
        .count();
    // Allow a stray pixel in a thousand (a lake painted from the triangle of a sample whose
    // neighbours lie in another 8-pixel cell); a drawing bug moves many more.
    assert!(
        far * 1000 <= changed.len(),
        "{far} of {} changed pixels lie away from every river and lake",
        changed.len()
    );
    std::fs::remove_dir_all(&dir).ok();
}
