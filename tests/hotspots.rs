//! The hotspot plugin, written on the public prelude only: island chains along the plate's
//! motion with ages growing away from the hotspot; switched off it changes nothing; its state
//! and parameters survive saves; its source imports nothing but the prelude.

mod common;

use std::path::Path;

use tectonic_planets::io::save;
use tectonic_planets::plugins::hotspots::{Edifice, Hotspot, HotspotPlugin};
use tectonic_planets::prelude::*;

/// Edifices with their world position, sorted by serial.
fn edifices(sim: &mut Simulation) -> Vec<(Edifice, DVec3)> {
    let world = sim.world_mut();
    let frames: Vec<(u32, DQuat)> = world
        .query::<(&Plate, &PlateFrame)>()
        .iter(world)
        .map(|(p, f)| (p.id.0, f.world_from_plate))
        .collect();
    let mut out: Vec<(Edifice, DVec3)> = world
        .query::<&Edifice>()
        .iter(world)
        .map(|e| {
            let f = frames
                .iter()
                .find(|f| f.0 == e.plate.0)
                .map_or(DQuat::IDENTITY, |f| f.1);
            (*e, e.world_position(f))
        })
        .collect();
    out.sort_by_key(|e| e.0.serial);
    out
}

/// Elevation of the reference sample nearest `p` in a resampled crust.
fn elevation_at(mesh: &SphereMesh, crust: &Crust, p: DVec3) -> f32 {
    let loc = mesh.locate(p);
    let s = mesh.triangles[loc.triangle as usize][loc.dominant_corner()];
    crust.elevation_km[s as usize]
}

/// One oceanic plate covering the sphere (40,000 samples), turning eastward about the z axis at
/// `speed_km_per_my` at the equator, over one hotspot on the equator at longitude 0 (+x) of
/// radius `hotspot_radius_km`, switched on or off, with the paper's relief: with the relief
/// phenomena, rivers wear young islands down within a few steps at this resolution (stream
/// power at the scale of a 110 km sample), which is not what these tests are about.
fn plate_over_a_hotspot(speed_km_per_my: f64, hotspot_radius_km: f64, on: bool) -> Simulation {
    let mut p = common::params(40_000, 5);
    p.init.continental_fraction = 0.0;
    p.init.plates = 2;
    let mut sim = Simulation::new(p).unwrap();
    let n = sim.mesh().len();
    let omega = speed_km_per_my / sim.params().planet.radius_km;
    sim.reassign_plates(
        vec![0; n],
        &[(
            0,
            PlateMotion {
                euler_pole: DVec3::Z,
                angular_speed_rad_per_my: omega,
            },
        )],
    )
    .unwrap();
    sim.world_mut().spawn(Hotspot {
        index: 0,
        position: DVec3::X,
    });
    {
        let mut pp = sim.plugin_params_mut();
        pp.set("plugins.hotspots.count", ParamValue::Int(0))
            .unwrap();
        pp.set(
            "plugins.hotspots.radius_km",
            ParamValue::Float(hotspot_radius_km),
        )
        .unwrap();
    }
    sim.set_enabled("hotspots", on).unwrap();
    common::paper_relief(&mut sim);
    sim
}

#[test]
fn hotspot_under_a_moving_oceanic_plate_builds_an_age_progressive_chain() {
    // 100 mm/yr at the equator.
    let speed_km_per_my = 100.0;
    let hotspot_radius_km = 250.0;
    let mut sim = plate_over_a_hotspot(speed_km_per_my, hotspot_radius_km, true);
    let radius_km = sim.params().planet.radius_km;
    let omega = speed_km_per_my / radius_km;
    let before = sim.resampled_crust();
    let steps = 40;
    sim.run_steps(steps).unwrap();
    assert!(
        sim.clock().resamplings >= 2,
        "the run must include resamplings"
    );
    let dt = sim.params().time.time_step_my;
    let list = edifices(&mut sim);
    // One edifice per step: the plate moves 200 km a step, more than half the radius.
    assert!(
        list.len() as u64 >= steps - 2,
        "{} edifices after {steps} steps",
        list.len()
    );
    let mut by_lon: Vec<(f64, f64, f64)> = Vec::new(); // (longitude rad, age My, height km)
    for (e, w) in &list {
        let lat_km = w.z.asin() * radius_km;
        let lon = w.y.atan2(w.x);
        assert!(
            lat_km.abs() < 0.5 * hotspot_radius_km,
            "edifice {} is {lat_km:.0} km off the trail",
            e.serial
        );
        // It has drifted with the plate for its age: longitude ω·age.
        let off_km = (lon - omega * e.age_my) * radius_km;
        assert!(
            off_km.abs() <= 0.5 * hotspot_radius_km + 1.0,
            "edifice {} of age {} My is {off_km:.0} km from where the plate took it",
            e.serial,
            e.age_my
        );
        by_lon.push((lon, e.age_my, e.height_km));
    }
    by_lon.sort_by(|a, b| a.0.total_cmp(&b.0));
    for w in by_lon.windows(2) {
        assert!(
            w[1].1 > w[0].1,
            "ages must grow along the plate's motion away from the hotspot: {w:?}"
        );
    }
    let oldest = by_lon.last().unwrap();
    assert!(
        oldest.1 >= (steps as f64 - 3.0) * dt,
        "the oldest edifice is {} My old",
        oldest.1
    );
    // Edifices subside with age.
    assert!(
        by_lon[0].2 > 2.0 * oldest.2,
        "young {} km vs old {} km",
        by_lon[0].2,
        oldest.2
    );
    // The crust shows the chain: on the trail the floor stands well above the same longitudes
    // 15° off it, and above where it was before the plate carried the edifices there.
    let after = sim.resampled_crust();
    let mesh = sim.mesh();
    let off = |w: DVec3| DQuat::from_rotation_y(-15f64.to_radians()) * w;
    let mut higher = 0;
    for (e, w) in &list {
        let on_trail = elevation_at(mesh, &after, *w);
        let off_trail = elevation_at(mesh, &after, off(*w));
        if e.age_my < 40.0 && on_trail > off_trail + 2.0 {
            higher += 1;
        }
    }
    let young = list.iter().filter(|(e, _)| e.age_my < 40.0).count();
    assert!(
        higher * 10 >= young * 9,
        "{higher} of {young} young edifices stand 2 km above the floor beside the trail"
    );
    let islands = list
        .iter()
        .filter(|(e, w)| e.age_my < 10.0 && elevation_at(mesh, &after, *w) > 0.0)
        .count();
    assert!(islands >= 3, "{islands} young edifices above sea level");
    // Far from the trail the floor did not change.
    let far = DVec3::new(0.0, 0.0, 1.0);
    assert_eq!(
        elevation_at(mesh, &before, far) > -7.0,
        elevation_at(mesh, &after, far) > -7.0
    );
}

/// A slow plate stays under its hotspot for several steps, and each new edifice of the chain is
/// founded on the flank of the last one: the summits must still stand no more than
/// `max_height_km` above the floor the chain is built on (they used to pile up to about 1.5
/// times that, 10–13 km above sea level on a shallow floor).
#[test]
fn a_chain_on_a_slow_plate_keeps_its_summits_under_the_cap() {
    // 20 mm/yr at the equator: 40 km a step, so the hotspot founds a new edifice every three
    // or four steps, 125 km (r/2) from the last, on its flank.
    let run = |on: bool| {
        let mut sim = plate_over_a_hotspot(20.0, 250.0, on);
        sim.run_steps(30).unwrap();
        let list = edifices(&mut sim);
        (sim.resampled_crust(), list)
    };
    let (off, _) = run(false);
    let (on, list) = run(true);
    assert!(list.len() >= 6, "{} edifices", list.len());
    let cap = 8.0; // `plugins.hotspots.max_height_km`, the default
    // What the hotspot raised: the chain stands high above the floor beside it.
    let rise = (0..on.len())
        .map(|i| on.elevation_km[i] - off.elevation_km[i])
        .fold(f32::MIN, f32::max);
    assert!(
        rise > 0.5 * cap as f32,
        "the chain stands only {rise} km above the floor"
    );
    // The first edifice was founded on the bare floor under the hotspot; no summit of the
    // chain stands more than the cap above it (before the fix: 9.8 km).
    let floor = list
        .iter()
        .map(|(e, _)| e.base_km)
        .fold(f64::INFINITY, f64::min);
    let (top, at) = (0..on.len())
        .map(|i| (on.elevation_km[i], i))
        .fold((f32::MIN, 0), |a, b| if b.0 > a.0 { b } else { a });
    assert!(
        f64::from(top) <= floor + cap + 0.01,
        "sample {at} stands at {top} km, {} km above the chain's floor ({floor} km; cap {cap} km)",
        f64::from(top) - floor
    );
}

fn small(samples: u64) -> Params {
    let mut p = common::params(samples, 3);
    p.init.plates = 12;
    p
}

#[test]
fn switched_off_hotspots_change_nothing_and_on_they_build() {
    let steps = 40;
    let mut absent = Simulation::with_plugins(
        small(8_000),
        TectonicPlugins.build().disable::<HotspotPlugin>(),
    )
    .unwrap();
    absent.run_steps(steps).unwrap();
    assert!(absent.clock().resamplings >= 2);
    let mut off = Simulation::new(small(8_000)).unwrap();
    assert!(
        off.phenomena()
            .iter()
            .any(|p| p.name == "hotspots" && !p.enabled && !p.default_enabled)
    );
    off.run_steps(steps).unwrap();
    assert_eq!(off.state_hash(), absent.state_hash());
    assert_eq!(off.crust().hash(), absent.crust().hash());
    assert!(edifices(&mut off).is_empty());

    let mut on = Simulation::new(small(8_000)).unwrap();
    on.set_enabled("hotspots", true).unwrap();
    on.plugin_params_mut()
        .set("plugins.hotspots.radius_km", ParamValue::Float(400.0))
        .unwrap();
    on.run_steps(steps).unwrap();
    let spots = on.world_mut().query::<&Hotspot>().iter(on.world()).count();
    assert_eq!(spots, 6);
    assert!(
        edifices(&mut on).len() >= 20,
        "{} edifices",
        edifices(&mut on).len()
    );
    assert_ne!(on.crust().hash(), absent.crust().hash());
}

#[test]
fn hotspot_runs_resume_exactly_from_saves() {
    let mut a = Simulation::new(small(8_000)).unwrap();
    a.set_enabled("hotspots", true).unwrap();
    a.plugin_params_mut()
        .set("plugins.hotspots.radius_km", ParamValue::Float(420.0))
        .unwrap();
    a.run_steps(13).unwrap();
    let bytes = save::save_to_bytes(&mut a).unwrap();
    a.run_steps(17).unwrap();
    let mut b = save::load_from_bytes(&bytes, Path::new("<hotspots>")).unwrap();
    assert_eq!(
        b.plugin_params().get("plugins.hotspots.radius_km"),
        Some(ParamValue::Float(420.0))
    );
    b.run_steps(17).unwrap();
    assert_eq!(a.state_hash(), b.state_hash());
    let (ea, eb) = (edifices(&mut a), edifices(&mut b));
    assert!(!ea.is_empty());
    assert_eq!(ea, eb);
}

#[test]
fn plugin_parameters_come_from_the_config_with_clear_errors() {
    let text = "[planet]\nsamples = 2000\n[plugins.hotspots]\ncount = 3\nradius_km = 300\n";
    let params = Params::from_toml_str(text).unwrap();
    assert_eq!(params.planet.samples, 2000);
    let mut sim = Simulation::new(params).unwrap();
    sim.apply_plugin_config(&PluginConfig::from_toml_str(text).unwrap())
        .unwrap();
    assert_eq!(
        sim.plugin_params().get("plugins.hotspots.count"),
        Some(ParamValue::Int(3))
    );
    for (bad, needles) in [
        (
            "[plugins.hotspots]\ncount = 65\n",
            &["plugins.hotspots.count", "65", "0..=64"][..],
        ),
        (
            "[plugins.hotspots]\nradius = 3\n",
            &[
                "plugins.hotspots.radius",
                "did you mean \"plugins.hotspots.radius_km\"",
            ][..],
        ),
        (
            "[plugins.volcanoes]\ncount = 1\n",
            &["plugins.volcanoes.count"][..],
        ),
        (
            "[plugins.hotspots]\nuplift_mm_per_yr = nan\n",
            &["plugins.hotspots.uplift_mm_per_yr", "not a finite"][..],
        ),
    ] {
        let e = sim
            .apply_plugin_config(&PluginConfig::from_toml_str(bad).unwrap())
            .unwrap_err()
            .to_string();
        for n in needles {
            assert!(e.contains(n), "{bad:?}: {e}");
        }
    }
    // Refused configs changed nothing.
    assert_eq!(
        sim.plugin_params().get("plugins.hotspots.radius_km"),
        Some(ParamValue::Float(300.0))
    );
    // Every declared parameter is listed with unit, range and doc for the viewer.
    let listed: Vec<&str> = sim.plugin_params().iter().map(|p| p.spec.key).collect();
    assert_eq!(listed.len(), 5, "{listed:?}");
    assert!(sim.plugin_params().iter().all(|p| !p.spec.doc.is_empty()));
}

#[test]
fn old_saves_load_with_hotspots_off_and_default_parameters() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("saves/fixture-v1.planet");
    let sim = save::load_from_file(&path).unwrap();
    assert!(
        sim.phenomena()
            .iter()
            .any(|p| p.name == "hotspots" && !p.enabled)
    );
    let defaults = Simulation::new(small(2_000)).unwrap();
    assert_eq!(sim.plugin_params(), defaults.plugin_params());
}

#[test]
fn the_hotspot_plugin_imports_only_the_prelude() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/plugins/hotspots.rs");
    let source = std::fs::read_to_string(&path).unwrap();
    let mut prelude_imports = 0;
    for (k, line) in source.lines().enumerate() {
        let code = line.split("//").next().unwrap_or("").trim();
        if code == "use crate::prelude::*;" {
            prelude_imports += 1;
            continue;
        }
        for forbidden in ["crate::", "super::", "tectonic_planets::", "self::"] {
            assert!(
                !code.contains(forbidden),
                "line {}: `{}` reaches past the prelude",
                k + 1,
                line.trim()
            );
        }
        assert!(
            !(code.starts_with("use ") || code.starts_with("pub use "))
                || code.starts_with("use std::"),
            "line {}: `{}` imports something other than the prelude or std",
            k + 1,
            line.trim()
        );
    }
    assert_eq!(prelude_imports, 1);
}
