//! The impact-scarred start (`init.craters`, seed 004): crust volume is conserved, a crater's
//! profile follows the bowl-and-blanket law, and the craters do not depend on the resolution.

mod common;

use common::*;
use glam::DVec3;
use tectonic_planets::prelude::*;
use tectonic_planets::systems::craters::{
    Crater, CraterScratch, EJECTA_REACH, apply_crater, bowl_depth_km, draw_craters, ejecta_weight,
};
use tectonic_planets::systems::init::{initial_planet, reference_mesh};

fn volume_km3(mesh: &SphereMesh, crust: &Crust) -> f64 {
    crust
        .thickness_km
        .iter()
        .zip(mesh.area_km2.iter())
        .map(|(&t, &a)| t as f64 * a)
        .sum()
}

#[test]
fn bombardment_conserves_crust_volume() {
    let mut p = params(60_000, 5);
    let mesh = reference_mesh(&p).unwrap();
    let (before, _) = initial_planet(&mesh, &p);
    p.init.craters = 1500;
    let (after, _) = initial_planet(&mesh, &p);
    let (v0, v1) = (volume_km3(&mesh, &before), volume_km3(&mesh, &after));
    // The craters moved a lot of crust about...
    let moved: f64 = before
        .thickness_km
        .iter()
        .zip(&after.thickness_km)
        .zip(mesh.area_km2.iter())
        .map(|((&a, &b), &w)| (a - b).abs() as f64 * w)
        .sum();
    assert!(
        moved > 0.05 * v0,
        "moved only {:.3}% of the crust",
        100.0 * moved / v0
    );
    // ... and kept its volume.
    let gap = (v1 - v0).abs() / v0;
    assert!(
        gap <= 1e-3,
        "volume {v0:.4e} → {v1:.4e} km³ ({:.4}%)",
        100.0 * gap
    );
    // The last crater strikes the crust the others left (the same first 1,499 craters: they are
    // drawn per crater) and digs its bowl there, down to the floor where the crust is thinner.
    let mut q = p.clone();
    q.init.craters -= 1;
    let (others, _) = initial_planet(&mesh, &q);
    let last = *draw_craters(&p).last().unwrap();
    let i = nearest(&mesh, last.center);
    let r = mesh.positions[i].dot(last.center).clamp(-1.0, 1.0).acos() * mesh.radius_km;
    let want = bowl_depth_km(r, last.radius_km, p.init.crater_depth_ratio)
        .min(others.thickness_km[i] as f64 - 1.0);
    let dug = (others.thickness_km[i] - after.thickness_km[i]) as f64;
    assert!(
        (dug - want).abs() <= 1e-3 * want.max(1.0),
        "last crater (R {:.0} km) dug {dug:.3} km at its centre, law {want:.3} km",
        last.radius_km
    );
}

fn nearest(mesh: &SphereMesh, q: DVec3) -> usize {
    (0..mesh.len())
        .max_by(|&a, &b| {
            mesh.positions[a]
                .dot(q)
                .total_cmp(&mesh.positions[b].dot(q))
        })
        .unwrap()
}

#[test]
fn a_crater_follows_the_bowl_and_blanket_law() {
    let p = params(100_000, 2);
    let mesh = reference_mesh(&p).unwrap();
    let n = mesh.len();
    // Uniform thick continental crust, so no sample is cut down to the floor.
    let mut crust = Crust::with_len(n);
    crust
        .crust_type
        .iter_mut()
        .for_each(|t| *t = CrustType::Continental);
    crust.thickness_km.iter_mut().for_each(|t| *t = 60.0);
    crust.elevation_km.iter_mut().for_each(|z| *z = 0.5);
    let before = crust.clone();
    let crater = Crater {
        center: DVec3::new(0.3, -0.5, 0.8).normalize(),
        radius_km: 600.0,
    };
    let ratio = 0.05;
    let v = apply_crater(
        &mesh,
        &mut crust,
        &crater,
        ratio,
        &p,
        &mut CraterScratch::default(),
    );
    assert!(v.removed_km3 > 0.0);
    assert!(
        (v.deposited_km3 - v.removed_km3).abs() <= 1e-4 * v.removed_km3,
        "removed {} km³, deposited {} km³",
        v.removed_km3,
        v.deposited_km3
    );
    let r_of =
        |i: usize| mesh.positions[i].dot(crater.center).clamp(-1.0, 1.0).acos() * mesh.radius_km;
    // The blanket's scale: what the bowl removed over Σ area·weight.
    let wsum: f64 = (0..n)
        .map(|i| ejecta_weight(r_of(i), crater.radius_km) * mesh.area_km2[i])
        .sum();
    let scale = v.removed_km3 / wsum;
    let (mut rim_peak, mut outer_max) = (0.0f64, 0.0f64);
    for i in 0..n {
        let r = r_of(i);
        let dt = (crust.thickness_km[i] - before.thickness_km[i]) as f64;
        let want =
            -bowl_depth_km(r, crater.radius_km, ratio) + scale * ejecta_weight(r, crater.radius_km);
        assert!(
            (dt - want).abs() <= 1e-4 + 1e-5 * want.abs(),
            "sample at {r:.1} km: change {dt:.5} km, law {want:.5} km"
        );
        if r >= crater.radius_km && r < crater.radius_km + 60.0 {
            rim_peak = rim_peak.max(dt);
        } else if r >= 1.5 * crater.radius_km {
            outer_max = outer_max.max(dt);
        }
        if r >= EJECTA_REACH * crater.radius_km {
            assert_eq!(dt, 0.0, "changed at {r:.0} km, beyond the blanket");
        }
        // The surface follows by isostasy: lower where crust went, higher where it came.
        let dz = crust.elevation_km[i] - before.elevation_km[i];
        assert!(
            dz * dt as f32 >= 0.0,
            "elevation moved against thickness at {r:.0} km"
        );
    }
    // At the centre the bowl removes R/20 (the nearest sample lies within a spacing of it).
    let c = nearest(&mesh, crater.center);
    let dc = (before.thickness_km[c] - crust.thickness_km[c]) as f64;
    assert!(
        (dc - ratio * crater.radius_km).abs() <= 0.02 * ratio * crater.radius_km,
        "centre lowered by {dc:.2} km, law {:.2} km",
        ratio * crater.radius_km
    );
    // The rim is the crest of the blanket, which thins outwards (no cliff beyond it).
    assert!(
        rim_peak > 0.0 && outer_max < 0.5 * rim_peak,
        "rim {rim_peak:.3} km, beyond 1.5 R {outer_max:.3} km"
    );
}

#[test]
fn craters_are_the_same_at_every_resolution() {
    let mut a = params(20_000, 11);
    a.init.craters = 40;
    let mut b = a.clone();
    b.planet.samples = 200_000;
    assert_eq!(draw_craters(&a), draw_craters(&b));
    let radii: Vec<f64> = draw_craters(&a).iter().map(|c| c.radius_km).collect();
    assert!(
        radii.iter().all(|&r| (200.0..=2500.0).contains(&r)),
        "{radii:?}"
    );
    // Most craters are small: the power law puts the median near √2 × the smallest.
    let mut sorted = radii.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(median < 450.0, "median radius {median:.0} km");
}
