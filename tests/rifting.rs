//! Rifting and authoring commands: a forced rift along a line splits the plate there and opens a
//! ridge between the fragments; random rifts follow their Poisson rate; commands check their
//! input, act on the plate they name (by id or by place) and replay to the same bits; scripts
//! parse with clear errors; the Fig. 16 story script tells its story.

mod common;

use common::*;
use glam::DVec3;
use tectonic_planets::commands::{Outcome, plate_at, replay};
use tectonic_planets::geometry::{angle_between, from_lat_lon_deg};
use tectonic_planets::prelude::*;
use tectonic_planets::resources::Sutures;
use tectonic_planets::systems::rifting::{RiftCause, RiftLog};

const R: f64 = 6370.0;

fn rest() -> PlateMotion {
    PlateMotion {
        euler_pole: DVec3::Z,
        angular_speed_rad_per_my: 0.0,
    }
}

/// Two plates at rest: 0 covers everything north of 30° S, 1 the southern cap. Plate 0 is
/// continental between 0° and 60° N, oceanic elsewhere. Random rifts off.
fn two_plates(samples: u64) -> Simulation {
    let south = -(30f64.to_radians().sin());
    two_plates_at_rest(
        samples,
        |q| (0.0..60.0).contains(&q.z.asin().to_degrees()),
        |q| q.z >= south,
    )
}

/// Two plates at rest, random rifts off: plate 0 where `on_plate_0` holds, plate 1 elsewhere;
/// continental crust (0.5 km, 35 km thick, 500 My) where `continental` holds, ocean floor
/// (−4 km, 7 km, 60 My) elsewhere.
fn two_plates_at_rest(
    samples: u64,
    continental: impl Fn(&DVec3) -> bool,
    on_plate_0: impl Fn(&DVec3) -> bool,
) -> Simulation {
    let mut p = params(samples, 11);
    p.rifting.frequency_per_my = 0.0;
    let mut sim = Simulation::new(p).unwrap();
    let mesh = sim.mesh().clone();
    {
        let mut crust = sim.world_mut().resource_mut::<Crust>();
        for (i, q) in mesh.positions.iter().enumerate() {
            let cont = continental(q);
            crust.crust_type[i] = if cont {
                CrustType::Continental
            } else {
                CrustType::Oceanic
            };
            crust.elevation_km[i] = if cont { 0.5 } else { -4.0 };
            crust.thickness_km[i] = if cont { 35.0 } else { 7.0 };
            crust.age_my[i] = if cont { 500.0 } else { 60.0 };
        }
    }
    let plates: Vec<u32> = mesh
        .positions
        .iter()
        .map(|q| u32::from(!on_plate_0(q)))
        .collect();
    sim.reassign_plates(plates, &[(0, rest()), (1, rest())])
        .unwrap();
    sim
}

fn line_on_meridian_0() -> Command {
    Command::RiftLine {
        line: vec![
            LatLon {
                lat: -20.0,
                lon: 0.0,
            },
            LatLon {
                lat: 30.0,
                lon: 0.0,
            },
            LatLon {
                lat: 80.0,
                lon: 0.0,
            },
        ],
        plate: None,
    }
}

/// Young oceanic samples with a ridge direction within `km` of the meridian of longitude 0
/// between 10° and 50° N, in the crust as maps show it now.
fn young_ridge_crust_near_meridian_0(sim: &mut Simulation, km: f64, max_age: f32) -> usize {
    let view = sim.resampled_crust();
    let mesh = sim.mesh();
    (0..mesh.len())
        .filter(|&i| {
            let q = mesh.positions[i];
            let lat = q.z.asin().to_degrees();
            (10.0..50.0).contains(&lat)
                && q.x > 0.0
                && q.y.abs() * R < km
                && view.crust_type[i] == CrustType::Oceanic
                && view.age_my[i] < max_age
                && view.ridge_dir[i] != [0.0; 3]
        })
        .count()
}

#[test]
fn a_forced_rift_along_a_line_splits_the_plate_there_and_opens_a_ridge() {
    let mut sim = two_plates(30_000);
    // Control: with no rift, nothing opens along the line.
    let mut control = two_plates(30_000);
    control.run_for(20.0).unwrap();
    assert_eq!(
        young_ridge_crust_near_meridian_0(&mut control, 800.0, 20.0),
        0,
        "plates at rest must open no ocean"
    );

    let out = sim.apply(&line_on_meridian_0()).unwrap();
    let Outcome::Rift { fragments } = out else {
        panic!("expected a rift, got {out:?}");
    };
    assert_eq!(fragments.len(), 2, "{fragments:?}");
    assert_eq!(fragments[0], 0, "the larger fragment keeps the parent's id");
    // The split follows the line: east of it (y > 0) one plate, west of it the other.
    let mesh = sim.mesh().clone();
    let crust = sim.crust().clone();
    let (mut east, mut west) = (Vec::new(), Vec::new());
    for (i, q) in mesh.positions.iter().enumerate() {
        let lat = q.z.asin().to_degrees();
        if crust.plate[i] == 1 || !(-10.0..70.0).contains(&lat) || q.x <= 0.0 {
            continue;
        }
        if q.y * R > 300.0 {
            east.push(crust.plate[i]);
        } else if q.y * R < -300.0 {
            west.push(crust.plate[i]);
        }
    }
    let first = east[0];
    assert!(east.iter().all(|&p| p == first), "east side split");
    assert!(west.iter().all(|&p| p == west[0]), "west side split");
    assert_ne!(first, west[0], "the two sides are different plates");
    assert!(fragments.contains(&first) && fragments.contains(&west[0]));

    // The fragments separate: across the line, the east side moves east of the west side.
    let (east_id, west_id) = (first, west[0]);
    let table = sim.plate_table();
    let omega = |id: u32| {
        let m = table.get(id).unwrap().motion;
        m.euler_pole * m.angular_speed_rad_per_my * R
    };
    let p = from_lat_lon_deg(30.0, 0.0);
    let opening = (omega(east_id) - omega(west_id)).cross(p).dot(DVec3::Y);
    assert!(
        opening > 20.0,
        "the fragments should move apart across the line at tens of km/My, got {opening:.1}"
    );
    sim.run_for(20.0).unwrap();
    // New ridge crust between them within 20 My.
    let young = young_ridge_crust_near_meridian_0(&mut sim, 800.0, 20.0);
    assert!(
        young >= 20,
        "expected new oceanic crust with a ridge along the fracture, found {young} samples"
    );
    let log = sim.world().resource::<RiftLog>();
    assert_eq!(log.events.len(), 1);
    assert_eq!(log.events[0].cause, RiftCause::Command);
}

/// A rift's fragments build no subduction front between them (so they cannot collide) for
/// `rifting.sibling_grace_my`, even where they converge; with no grace they do at once. The
/// fragments of a rift along the meridian are set moving towards each other at 30 mm/yr each,
/// and the fronts are read after the rift's resampling and 10 My more.
#[test]
fn a_rifts_fragments_build_no_front_between_them_during_the_grace() {
    let fronts_between_fragments = |grace: f64| {
        let mut sim = two_plates(30_000);
        sim.apply(&Command::SetParam {
            key: "rifting.sibling_grace_my".into(),
            value: tectonic_planets::commands::SettingValue::Float(grace),
        })
        .unwrap();
        let Outcome::Rift { fragments } = sim.apply(&line_on_meridian_0()).unwrap() else {
            panic!("expected a rift");
        };
        assert_eq!(fragments.len(), 2, "{fragments:?}");
        // East of the line moves west, west of it moves east (poles at the north pole and the
        // south pole): the fracture closes along its whole length.
        let east = plate_at(&mut sim, from_lat_lon_deg(30.0, 20.0)).unwrap();
        let west = plate_at(&mut sim, from_lat_lon_deg(30.0, -20.0)).unwrap();
        assert_ne!(east, west);
        for (plate, lat) in [(east, -90.0), (west, 90.0)] {
            sim.apply(&Command::SetMotion {
                plate: PlateRef::Id(plate),
                pole: LatLon { lat, lon: 0.0 },
                speed_mm_per_yr: 30.0,
            })
            .unwrap();
        }
        sim.run_for(10.0).unwrap();
        let mut q = sim.world_mut().query::<&SubductionFront>();
        let between = q
            .iter(sim.world())
            .filter(|f| {
                let pair = [f.overriding.0, f.subducting.0];
                pair.contains(&east) && pair.contains(&west)
            })
            .map(|f| f.points.len())
            .sum::<usize>();
        let collided = sim.world().resource::<Sutures>().total;
        (between, collided)
    };
    let (with_grace, collided) = fronts_between_fragments(60.0);
    assert_eq!(
        with_grace, 0,
        "front points between siblings during the grace"
    );
    assert_eq!(collided, 0, "siblings collided during the grace");
    let (without, _) = fronts_between_fragments(0.0);
    assert!(
        without >= 10,
        "with no grace the converging fragments should meet at a front, got {without} points"
    );
}

#[test]
fn rift_commands_refuse_bad_input_with_clear_errors() {
    let mut sim = two_plates(5_000);
    let before = sim.state_hash();
    let cases: Vec<(Command, &str)> = vec![
        (
            Command::RiftLine {
                line: vec![LatLon { lat: 0.0, lon: 0.0 }],
                plate: None,
            },
            "at least 2 points",
        ),
        (
            Command::RiftAt {
                plate: PlateRef::Id(0),
                fragments: 7,
            },
            "2 to 4 fragments",
        ),
        (
            Command::RiftAt {
                plate: PlateRef::Id(99),
                fragments: 2,
            },
            "no plate with id 99",
        ),
        (
            Command::SetMotion {
                plate: PlateRef::At(LatLon {
                    lat: 95.0,
                    lon: 0.0,
                }),
                pole: LatLon { lat: 0.0, lon: 0.0 },
                speed_mm_per_yr: 10.0,
            },
            "latitude",
        ),
        (
            Command::Uplift {
                cap: Cap {
                    lat: 0.0,
                    lon: 0.0,
                    radius_km: -5.0,
                },
                delta_km: 1.0,
            },
            "cap radius",
        ),
        (
            // A line just inside the rim of the southern cap (plate 1) cuts off a sliver:
            // refused by size.
            Command::RiftLine {
                line: vec![
                    LatLon {
                        lat: -30.5,
                        lon: -10.0,
                    },
                    LatLon {
                        lat: -30.5,
                        lon: 10.0,
                    },
                ],
                plate: Some(PlateRef::Id(1)),
            },
            "smaller than resample.fragment_min_area_km2",
        ),
    ];
    for (cmd, needle) in cases {
        let err = sim.apply(&cmd).unwrap_err().to_string();
        assert!(err.contains(needle), "{cmd:?}: {err}");
    }
    assert_eq!(sim.state_hash(), before, "refused commands change nothing");
    let history = sim
        .world()
        .resource::<tectonic_planets::io::save::CommandHistory>();
    assert!(
        history.entries.is_empty(),
        "refused commands are not recorded"
    );
}

#[test]
fn commands_name_plates_by_place_and_change_what_they_say() {
    let mut sim = two_plates(10_000);
    // By place: a point in the south is plate 1.
    let out = sim
        .apply(&Command::SetMotion {
            plate: PlateRef::At(LatLon {
                lat: -70.0,
                lon: 30.0,
            }),
            pole: LatLon {
                lat: -90.0,
                lon: 0.0,
            },
            speed_mm_per_yr: 50.0,
        })
        .unwrap();
    assert_eq!(out, Outcome::Motion { plate: 1 });
    let t = sim.plate_table();
    let m = t.get(1).unwrap().motion;
    assert!((m.euler_pole - DVec3::NEG_Z).length() < 1e-9);
    assert!((m.angular_speed_rad_per_my * R - 50.0).abs() < 1e-9);
    assert_eq!(t.get(0).unwrap().motion.angular_speed_rad_per_my, 0.0);

    // A cap of plate 0's ocean becomes continental, and only inside the cap.
    let cap = Cap {
        lat: -10.0,
        lon: 100.0,
        radius_km: 500.0,
    };
    let c = from_lat_lon_deg(cap.lat, cap.lon);
    let mesh = sim.mesh().clone();
    let before = sim.crust().clone();
    let continental_z = sim.params().init.continental_elevation_km as f32;
    let out = sim
        .apply(&Command::SetCrustType {
            plate: None,
            cap: Some(cap),
            crust: CrustKind::Continental,
        })
        .unwrap();
    let Outcome::CrustType { samples } = out else {
        panic!("{out:?}")
    };
    assert!(samples > 10, "{samples}");
    let after = sim.crust().clone();
    for i in 0..mesh.len() {
        let d = angle_between(mesh.positions[i], c) * R;
        if d < 480.0 {
            assert_eq!(after.crust_type[i], CrustType::Continental);
            assert!(after.elevation_km[i] >= continental_z - 1e-6);
        } else if d > 520.0 {
            assert_eq!(after.crust_type[i], before.crust_type[i]);
            assert_eq!(after.elevation_km[i], before.elevation_km[i]);
        }
    }
    // Uplift: most at the centre, nothing outside.
    let z0 = sim.crust().elevation_km.clone();
    sim.apply(&Command::Uplift {
        cap: Cap {
            lat: 40.0,
            lon: -60.0,
            radius_km: 800.0,
        },
        delta_km: 2.0,
    })
    .unwrap();
    let z1 = sim.crust().elevation_km.clone();
    let centre = from_lat_lon_deg(40.0, -60.0);
    let mut max_rise = 0.0f32;
    for i in 0..mesh.len() {
        let d = angle_between(mesh.positions[i], centre) * R;
        let dz = z1[i] - z0[i];
        if d > 800.0 {
            assert_eq!(dz, 0.0);
        } else {
            assert!((0.0..=2.0 + 1e-5).contains(&dz));
        }
        max_rise = max_rise.max(dz);
    }
    assert!(max_rise > 1.8, "{max_rise}");
    // A whole plate switched to oceanic.
    sim.apply(&Command::SetCrustType {
        plate: Some(PlateRef::Id(0)),
        cap: None,
        crust: CrustKind::Oceanic,
    })
    .unwrap();
    let c = sim.crust();
    assert!(
        (0..mesh.len())
            .filter(|&i| c.plate[i] == 0)
            .all(|i| c.crust_type[i] == CrustType::Oceanic && c.elevation_km[i] <= -4.0)
    );
}

#[test]
fn random_rifts_happen_at_their_rate_and_split_large_plates() {
    let mut p = params(20_000, 5);
    p.rifting.frequency_per_my = 0.05;
    let mut sim = Simulation::new(p.clone()).unwrap();
    let plates0 = sim.stats().plates;
    sim.run_for(100.0).unwrap();
    let log = sim.world().resource::<RiftLog>().clone();
    let random: Vec<_> = log
        .events
        .iter()
        .filter(|e| e.cause == RiftCause::Random)
        .collect();
    assert!(
        random.len() >= 5,
        "at 0.05/My per reference plate, 100 My should bring many rifts, got {}",
        random.len()
    );
    for e in &random {
        assert!((2..=4).contains(&e.fragments.len()), "{e:?}");
    }
    assert!(sim.stats().plates > plates0, "rifts add plates");
    // Off: no rift at all, and the rest is the same code path.
    p.rifting.frequency_per_my = 0.0;
    let mut off = Simulation::new(p).unwrap();
    off.run_for(100.0).unwrap();
    assert!(off.world().resource::<RiftLog>().events.is_empty());
}

/// Random rifts happen on the steps that end with a resampling that was due anyway (at least
/// `resample.min_interval_steps` since the last one), so they add none: a rift drawn on any step
/// forced one of its own.
#[test]
fn random_rifts_wait_for_the_resampling_that_was_due() {
    let mut p = params(10_000, 5);
    p.rifting.frequency_per_my = 0.1;
    let min = p.resample.min_interval_steps;
    let mut sim = Simulation::new(p).unwrap();
    let mut rift_steps = 0;
    for _ in 0..60 {
        let (step, since, resamplings) = (
            sim.clock().step,
            sim.clock().steps_since_resample,
            sim.clock().resamplings,
        );
        sim.step().unwrap();
        let rifted = sim
            .world()
            .resource::<RiftLog>()
            .events
            .iter()
            .any(|e| e.step == step && e.cause == RiftCause::Random);
        if !rifted {
            continue;
        }
        rift_steps += 1;
        assert_eq!(
            sim.clock().resamplings,
            resamplings + 1,
            "step {step}: a random rift without a resampling"
        );
        assert!(
            since + 1 >= min,
            "step {step}: a random rift {} steps after the last resampling forced one of its own",
            since + 1
        );
    }
    assert!(rift_steps >= 2, "only {rift_steps} steps with random rifts");
}

#[test]
fn replaying_the_recorded_history_gives_the_same_planet() {
    let mut p = params(15_000, 21);
    p.rifting.frequency_per_my = 0.02;
    let mut sim = Simulation::new(p.clone()).unwrap();
    sim.run_steps(5).unwrap();
    sim.apply(&Command::SetMotion {
        plate: PlateRef::At(LatLon {
            lat: 10.0,
            lon: 20.0,
        }),
        pole: LatLon {
            lat: 45.0,
            lon: -30.0,
        },
        speed_mm_per_yr: 70.0,
    })
    .unwrap();
    sim.run_steps(7).unwrap();
    sim.apply(&Command::RiftAt {
        plate: PlateRef::At(LatLon {
            lat: -20.0,
            lon: 60.0,
        }),
        fragments: 2,
    })
    .unwrap();
    sim.apply(&Command::Uplift {
        cap: Cap {
            lat: 0.0,
            lon: -100.0,
            radius_km: 600.0,
        },
        delta_km: -1.5,
    })
    .unwrap();
    sim.run_steps(10).unwrap();
    sim.apply(&Command::SetCrustType {
        plate: None,
        cap: Some(Cap {
            lat: 30.0,
            lon: 150.0,
            radius_km: 400.0,
        }),
        crust: CrustKind::Continental,
    })
    .unwrap();
    sim.apply(&Command::SetPhenomenon {
        name: "erosion".into(),
        enabled: false,
    })
    .unwrap();
    sim.run_steps(8).unwrap();
    let history = sim
        .world()
        .resource::<tectonic_planets::io::save::CommandHistory>()
        .clone();
    let commands = tectonic_planets::commands::commands_in_history(&history).unwrap();
    assert_eq!(commands.len(), 5);
    let mut again = replay(p.clone(), &commands, sim.clock().step).unwrap();
    assert_eq!(again.state_hash(), sim.state_hash());
    // And the history is what makes it so: without the commands the planet differs.
    let mut bare = replay(p, &[], sim.clock().step).unwrap();
    assert_ne!(bare.state_hash(), sim.state_hash());
}

#[test]
fn scripts_parse_with_clear_errors() {
    let ok = r#"
[[event]]
at_my = 10
note = "speed up"
command = "set_motion"
plate = 3
pole = { lat = 10, lon = 20 }
speed_mm_per_yr = 50

[[event]]
at_my = 4.5
command = "rift_at"
plate = { lat = 1.0, lon = 2.0 }
fragments = 2
"#;
    let s = Script::parse(ok, "ok.toml").unwrap();
    assert_eq!(s.events.len(), 2);
    assert_eq!(s.events[0].at_my, 4.5, "events are sorted by time");
    assert_eq!(
        s.events[1].command,
        Command::SetMotion {
            plate: PlateRef::Id(3),
            pole: LatLon {
                lat: 10.0,
                lon: 20.0
            },
            speed_mm_per_yr: 50.0
        }
    );
    for (text, needle) in [
        ("[[event]]\nat_my = 1\ncommand = \"explode\"\n", "explode"),
        (
            "[[event]]\nat_my = 1\ncommand = \"rift_at\"\nplate = 1\nfragments = 2\ncolour = 3\n",
            "colour",
        ),
        ("[[event]]\ncommand = \"rift_at\"\n", "has no at_my"),
        (
            "[[event]]\nat_my = -3\ncommand = \"rift_at\"\n",
            "non-negative",
        ),
        ("[events]\n", "unknown top-level key `events`"),
        (
            "[[event]]\nat_my = 1\ncommand = \"rift_at\"\nplate = 1\n",
            "fragments",
        ),
    ] {
        let err = Script::parse(text, "bad.toml").unwrap_err().to_string();
        assert!(err.contains("bad.toml"), "{err}");
        assert!(err.contains(needle), "{text:?}: {err}");
    }
    let missing = Script::load(std::path::Path::new("no/such/script.toml"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("no/such/script.toml"), "{missing}");
}

#[test]
fn the_fig16_script_tells_its_story() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/scripts/fig16.toml");
    let mut script = Script::load(std::path::Path::new(path)).unwrap();
    let p = params(30_000, 1);
    script.validate(&p).unwrap();
    let mut sim = Simulation::new(p).unwrap();
    let end = script.events.iter().map(|e| e.at_my).fold(0.0, f64::max) + 20.0;
    // (time, from plate, to plate, centroid) of every suture, and the plates the story names.
    let mut sutures: Vec<(f64, u32, u32, DVec3)> = Vec::new();
    let mut moved: Vec<(f64, u32)> = Vec::new();
    let mut rifts = Vec::new();
    let mut seen = 0;
    while sim.time_my() < end {
        for (event, outcome) in script.apply_due(&mut sim).unwrap() {
            match outcome {
                Outcome::Rift { fragments } => rifts.push((event.at_my, fragments)),
                Outcome::Motion { plate } => moved.push((event.at_my, plate)),
                _ => {}
            }
        }
        sim.step().unwrap();
        let s = sim.world().resource::<Sutures>();
        if s.total > seen {
            let new = (s.total - seen) as usize;
            for su in s.last_applied.iter().rev().take(new) {
                sutures.push((sim.time_my(), su.from_plate, su.to_plate, su.centroid_world));
            }
            seen = s.total;
        }
    }
    assert_eq!(moved.len(), 4, "{moved:?}");
    let (island_plate, continent_plate) = (moved[0].1, moved[2].1);
    assert_eq!(
        moved[1].1, island_plate,
        "the docked island's plate slows: {moved:?}"
    );
    assert_eq!(
        moved[3].1, continent_plate,
        "the continent slows: {moved:?}"
    );
    assert_ne!(island_plate, continent_plate);
    let involves = |id: u32, t0: f64, t1: f64| {
        sutures
            .iter()
            .any(|&(t, from, to, _)| (t0..t1).contains(&t) && (from == id || to == id))
    };
    // 1. The island reaches the central continent and sutures to it, near the path it was sent on.
    let near_path = sutures.iter().any(|&(t, from, to, c)| {
        let (lat, lon) = tectonic_planets::geometry::to_lat_lon_deg(c);
        (2.0..60.0).contains(&t)
            && (from == island_plate || to == island_plate)
            && (-20.0..25.0).contains(&lat)
            && (-20.0..30.0).contains(&lon)
    });
    assert!(
        near_path,
        "no island collision near its path (plate {island_plate}); {} collisions in all: {sutures:?}",
        sim.world().resource::<Sutures>().total
    );
    // 2. The sped-up continent collides.
    assert!(
        involves(continent_plate, 40.0, 100.0),
        "no collision of the sped-up continent (plate {continent_plate}): {sutures:?}"
    );
    // 3. The super-continent rifts.
    assert_eq!(rifts.len(), 1, "{rifts:?}");
    assert_eq!(
        rifts[0].1[0], continent_plate,
        "the merged continent is what rifts: {rifts:?}"
    );
    assert!(rifts[0].1.len() >= 2);
    // Random rifts were off, as the script says.
    assert!(
        sim.world()
            .resource::<RiftLog>()
            .events
            .iter()
            .all(|e| e.cause == RiftCause::Command)
    );
}

/// A strip of continent along the equator (|lat| < 25°, lon −10°..130°) as plate 0, the rest of
/// the sphere plate 1, both at rest; random rifts off.
fn equatorial_strip() -> Simulation {
    let in_strip = |q: &DVec3| {
        let lat = q.z.asin().to_degrees();
        let lon = q.y.atan2(q.x).to_degrees();
        lat.abs() < 25.0 && (-10.0..130.0).contains(&lon)
    };
    two_plates_at_rest(20_000, in_strip, in_strip)
}

#[test]
fn every_fracture_of_a_rift_into_fragments_in_a_row_opens() {
    use tectonic_planets::systems::rifting::{Fracture, rift_plate};
    // Four fragments in a row along the strip: with equal speeds away from the other
    // fragments, the two at each end moved the same way and their fracture did not open.
    let centroids: Vec<DVec3> = [5.0f64, 40.0, 80.0, 115.0]
        .iter()
        .map(|&lon| from_lat_lon_deg(0.0, lon))
        .collect();
    for jitter_seed in 0..8u64 {
        let mut sim = equatorial_strip();
        let div = sim.params().rifting.divergence_speed_mm_per_yr / sim.params().planet.radius_km;
        let fracture = Fracture::Voronoi {
            centroids: centroids.clone(),
            warp_seed: 3,
        };
        let ids = rift_plate(
            sim.world_mut(),
            0,
            &fracture,
            jitter_seed,
            RiftCause::Command,
        )
        .expect("the strip rifts");
        assert_eq!(ids.len(), 4);
        let mesh = sim.mesh().clone();
        let crust = sim.crust().clone();
        // Each fragment's centroid and angular velocity, west to east.
        let mut frags: Vec<(DVec3, DVec3)> = ids
            .iter()
            .map(|&id| {
                let c: DVec3 = (0..mesh.len())
                    .filter(|&i| crust.plate[i] == id)
                    .map(|i| mesh.positions[i] * mesh.area_km2[i])
                    .sum();
                let m = sim
                    .world_mut()
                    .query::<(&Plate, &PlateMotion)>()
                    .iter(sim.world())
                    .find(|(p, _)| p.id.0 == id)
                    .map(|(_, m)| *m)
                    .expect("fragment plate");
                (c.normalize(), m.euler_pole * m.angular_speed_rad_per_my)
            })
            .collect();
        frags.sort_by(|a, b| a.0.y.atan2(a.0.x).total_cmp(&b.0.y.atan2(b.0.x)));
        for w in frags.windows(2) {
            let ((ca, wa), (cb, wb)) = (w[0], w[1]);
            // On the fracture between them, the eastern fragment's velocity relative to the
            // western one, along the direction from west to east.
            let p = (ca + cb).normalize();
            let east = (cb - ca - p * p.dot(cb - ca)).normalize();
            let opening = (wb - wa).cross(p).dot(east);
            assert!(
                opening > 0.5 * div,
                "jitter seed {jitter_seed}: the fracture near longitude {:.0}° opens at {:.2} of \
                 the divergence speed",
                p.y.atan2(p.x).to_degrees(),
                opening / div
            );
        }
    }
}

/// The geometry of a few plates (what a rift or a collision's detachment refreshes) is that of
/// the same plates among all, bit for bit: samples, triangles, cap and areas. Seen to fail when
/// a triangle shared with a plate left out was dropped from the plates asked for.
#[test]
fn the_geometry_of_a_few_plates_is_theirs_among_all() {
    use tectonic_planets::systems::resample::{plate_geometry, plate_geometry_of};
    let sim = Simulation::new(params(20_000, 5)).unwrap();
    let (mesh, crust) = (sim.mesh(), sim.world().resource::<Crust>());
    let all = plate_geometry(mesh, crust);
    let ids: Vec<u32> = (0..all.len() as u32)
        .filter(|&id| all[id as usize].is_some())
        .step_by(3)
        .collect();
    assert!(ids.len() >= 2, "plates: {}", all.len());
    let some = plate_geometry_of(mesh, crust, Some(&ids));
    assert_eq!(some.len(), all.len());
    for (id, g) in some.iter().enumerate() {
        let Some(g) = g else {
            assert!(
                !ids.contains(&(id as u32)),
                "plate {id} asked for, none given"
            );
            continue;
        };
        assert!(ids.contains(&(id as u32)), "plate {id} not asked for");
        let a = all[id].as_ref().unwrap();
        assert_eq!(g.mesh.samples, a.mesh.samples, "plate {id}'s samples");
        assert_eq!(g.mesh.triangles, a.mesh.triangles, "plate {id}'s triangles");
        assert!(!g.mesh.triangles.is_empty());
        assert_eq!(format!("{:?}", g.bounds), format!("{:?}", a.bounds));
        assert_eq!(format!("{:?}", g.stats), format!("{:?}", a.stats));
    }
}
