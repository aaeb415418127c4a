//! Plate momentum (`plates.momentum`, seed 004): a suture and a rift conserve the angular
//! momentum of the plates involved.

use glam::{DMat3, DVec3};
use tectonic_planets::prelude::*;
use tectonic_planets::systems::momentum::{inertia, rift_correction, suture_exchange};

fn mesh() -> SphereMesh {
    SphereMesh::fibonacci(20_000, 0.3, 1, 6370.0).unwrap()
}

/// Inertia of the samples of `mesh` for which `keep` holds (mass = area × `t_km`).
fn inertia_where(m: &SphereMesh, t_km: f64, keep: impl Fn(DVec3) -> bool) -> DMat3 {
    inertia(
        (0..m.len())
            .filter(|&i| keep(m.positions[i]))
            .map(|i| (m.positions[i], m.area_km2[i] * t_km)),
    )
}

fn rel(a: DVec3, b: DVec3) -> f64 {
    (a - b).length() / a.length().max(b.length())
}

#[test]
fn a_suture_conserves_the_two_plates_angular_momentum() {
    let m = mesh();
    // Plate A: a continental cap around +X; its terrane T: the part beyond y > 0.2; plate B: the
    // oceanic cap around +Y, which T joins.
    let in_a = |p: DVec3| p.x > 0.5;
    let in_t = |p: DVec3| p.x > 0.5 && p.y > 0.2;
    let in_b = |p: DVec3| p.y > 0.5 && p.x <= 0.5;
    let i_t = inertia_where(&m, 35.0, in_t);
    let i_a = inertia_where(&m, 35.0, |p| in_a(p) && !in_t(p));
    let i_b = inertia_where(&m, 7.0, in_b) + i_t;
    let (w_a, w_b) = (
        DVec3::new(0.2, -0.9, 0.3) * 0.01,
        DVec3::new(-0.5, 0.1, 0.8) * 0.015,
    );
    let before = (i_a + i_t) * w_a + (i_b - i_t) * w_b;
    for coupling in [0.0, 0.5, 1.0] {
        let (a, b) = suture_exchange(i_a, i_b, i_t, w_a, w_b, coupling);
        let after = i_a * a + i_b * b;
        assert!(
            rel(before, after) <= 1e-9,
            "coupling {coupling}: {before:?} → {after:?}"
        );
        // The collision takes away the share of the relative motion it is asked to.
        let w_b_moved = w_b + (i_b.inverse() * (i_t * (w_a - w_b)));
        let left = (a - b).length() / (w_a - w_b_moved).length();
        assert!(
            (left - (1.0 - coupling)).abs() < 1e-6,
            "coupling {coupling}: {left}"
        );
    }
}

#[test]
fn a_rifts_fragments_sum_to_the_parents_momentum() {
    let m = mesh();
    let parts = [
        inertia_where(&m, 35.0, |p| p.z > 0.3 && p.x > 0.0),
        inertia_where(&m, 35.0, |p| p.z > 0.3 && p.x <= 0.0 && p.y > 0.0),
        inertia_where(&m, 7.0, |p| p.z > 0.3 && p.x <= 0.0 && p.y <= 0.0),
    ];
    let parent = DVec3::new(0.1, 0.4, -0.2) * 0.01;
    // The parent's ω plus a divergence each.
    let mut w = [
        parent + DVec3::new(0.0, 0.003, 0.0),
        parent + DVec3::new(-0.002, 0.0, 0.001),
        parent + DVec3::new(0.001, -0.002, 0.0),
    ];
    let total = parts.iter().fold(DMat3::ZERO, |a, &b| a + b);
    let sum = |w: &[DVec3]| -> DVec3 { parts.iter().zip(w).map(|(&i, &w)| i * w).sum() };
    assert!(
        rel(total * parent, sum(&w)) > 1e-3,
        "the divergence alone changes nothing"
    );
    rift_correction(&parts, &mut w, parent);
    assert!(rel(total * parent, sum(&w)) <= 1e-9);
    // The fragments still move apart from each other.
    assert!((w[0] - w[1]).length() > 1e-3);
}

#[test]
fn a_rift_in_a_run_keeps_the_parents_momentum() {
    use tectonic_planets::systems::momentum::{omega, sample_mass};
    let mut p = Params::default();
    p.planet.samples = 20_000;
    p.planet.seed = 5;
    p.plates.momentum = true;
    p.rifting.frequency_per_my = 0.0;
    let mut sim = Simulation::new(p.clone()).unwrap();
    sim.step().unwrap();
    // Momentum of the largest plate, from its samples in the world frame.
    let momentum = |sim: &mut Simulation, ids: &[u32]| -> DVec3 {
        let mesh = sim.mesh().clone();
        let crust = sim.crust().clone();
        let world = sim.world_mut();
        let mut q = world.query::<(&Plate, &PlateMotion, &PlateFrame)>();
        let mut l = DVec3::ZERO;
        for (pl, m, f) in q.iter(world) {
            if !ids.contains(&pl.id.0) {
                continue;
            }
            let i = inertia(
                (0..mesh.len())
                    .filter(|&i| crust.plate[i] == pl.id.0)
                    .map(|i| {
                        (
                            f.world_from_plate * mesh.positions[i],
                            sample_mass(crust.crust_type[i], mesh.area_km2[i], &p),
                        )
                    }),
            );
            l += i * omega(m);
        }
        l
    };
    let largest = {
        let world = sim.world_mut();
        let mut q = world.query::<(&Plate, &PlateStats)>();
        q.iter(world)
            .max_by(|a, b| a.1.area_km2.total_cmp(&b.1.area_km2))
            .map(|(p, _)| p.id.0)
            .unwrap()
    };
    let before = momentum(&mut sim, &[largest]);
    let out = sim
        .apply(&Command::RiftAt {
            plate: PlateRef::Id(largest),
            fragments: 2,
        })
        .unwrap();
    let tectonic_planets::commands::Outcome::Rift { fragments } = out else {
        panic!("not a rift: {out:?}");
    };
    let after = momentum(&mut sim, &fragments);
    assert!(rel(before, after) <= 1e-9, "{before:?} → {after:?}");
}
