//! Issue 17 item 4's other two candidates for obvhs, each against what the simulation does
//! today, on the same input, back to back, medians of five; also how often the two answers
//! differ:
//! - the front distance fields: the search through the mesh (`propagate_nearest_grouped`, the
//!   bucket queue of `build_fronts`) against a BVH over each plate's front points queried for
//!   every sample of that plate (the exact nearest point, in straight-line distance);
//! - the two nearest plates of each gap sample of a resampling: the search through the gaps
//!   (`nearest_two_plates`) against a BVH over the covered samples bordering the gaps, queried
//!   for the nearest seed and the nearest seed of another plate.
//!
//! `cargo run --release --example nearest_bvh_bench -- SAVE` (a `.planet` file; the fronts are
//! built again from its crust, as after a resampling, and the gaps are those of a resampling
//! 8 steps after one). Without a save, a 100,000-sample planet is run 50 My first.
use std::time::{Duration, Instant};

use glam::{DVec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::builder::build_bvh2;
use rayon::prelude::*;
use tectonic_planets::geometry::SphereMesh;
use tectonic_planets::resources::{Crust, FrontPoints, Params};
use tectonic_planets::simulation::Simulation;
use tectonic_planets::systems::convergence::fronts::build_fronts;
use tectonic_planets::systems::convergence::propagate_nearest_grouped;
use tectonic_planets::systems::resample::{
    GapSample, OverlapRules, gaps_from_nearest, interpolate, nearest_two_plates,
    resample_locate_cpu,
};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

const NONE: u32 = u32::MAX;

/// One side's question: labels (front points) with their origins and their group (the plate
/// whose samples they reach), seeds for the mesh search, and the limit (radians).
struct Side {
    name: &'static str,
    seeds: Vec<(u32, u32)>,
    group_of_label: Vec<u32>,
    limit_rad: f64,
}

/// One BVH per group over its labels' origins.
struct GroupTrees {
    /// Per plate id: index into `trees`, or NONE.
    slot: Vec<u32>,
    trees: Vec<(Bvh2, Vec<u32>)>,
}

fn build_trees(side: &Side, origin: &[DVec3]) -> GroupTrees {
    let mut slot: Vec<u32> = Vec::new();
    let mut labels: Vec<Vec<u32>> = Vec::new();
    for (l, &g) in side.group_of_label.iter().enumerate() {
        let g = g as usize;
        if g >= slot.len() {
            slot.resize(g + 1, NONE);
        }
        if slot[g] == NONE {
            slot[g] = labels.len() as u32;
            labels.push(Vec::new());
        }
        labels[slot[g] as usize].push(l as u32);
    }
    let trees = labels
        .into_par_iter()
        .map(|ls| {
            let bvh = point_bvh(ls.iter().map(|&l| origin[l as usize]));
            (bvh, ls)
        })
        .collect();
    GroupTrees { slot, trees }
}

/// A BVH over points, a small box each (`fast_build`); its primitives are the points in order.
fn point_bvh(points: impl Iterator<Item = DVec3>) -> Bvh2 {
    let boxes: Vec<Aabb> = points
        .map(|p| {
            let p = Vec3A::new(p.x as f32, p.y as f32, p.z as f32);
            Aabb::new(p - 1e-6, p + 1e-6)
        })
        .collect();
    build_bvh2(
        &boxes,
        BvhBuildParams::fast_build(),
        &mut Duration::default(),
    )
}

fn box_dist2(b: &Aabb, q: Vec3A) -> f32 {
    let d = (b.min - q).max(q - b.max).max(Vec3A::ZERO);
    d.length_squared()
}

/// The nearest-first walk of both queries: from the root, the nearer child first, a box pruned
/// when it lies farther from `q` than `bound(state)` (a squared chord); `leaf(state, primitive)`
/// sees each primitive of the leaves reached. `stack` is reused between queries.
fn walk<S>(
    bvh: &Bvh2,
    q: DVec3,
    stack: &mut Vec<u32>,
    state: &mut S,
    bound: impl Fn(&S) -> f64,
    mut leaf: impl FnMut(&mut S, u32),
) {
    let qf = Vec3A::new(q.x as f32, q.y as f32, q.z as f32);
    stack.clear();
    stack.push(0);
    while let Some(ni) = stack.pop() {
        let node = &bvh.nodes[ni as usize];
        // f32 boxes: a margin well above their rounding.
        if box_dist2(node.aabb(), qf) as f64 > bound(state) * (1.0 + 1e-4) + 1e-9 {
            continue;
        }
        if node.is_leaf() {
            for k in node.first_index..node.first_index + node.prim_count {
                leaf(state, bvh.primitive_indices[k as usize]);
            }
        } else {
            let (a, b) = (node.first_index, node.first_index + 1);
            let da = box_dist2(bvh.nodes[a as usize].aabb(), qf);
            let db = box_dist2(bvh.nodes[b as usize].aabb(), qf);
            // The nearer child is popped first.
            if da <= db {
                stack.push(b);
                stack.push(a);
            } else {
                stack.push(a);
                stack.push(b);
            }
        }
    }
}

/// Nearest origin to `q` among a tree's labels, within squared chord `max2`: (label, chord²).
/// `hint`: a label of the tree whose distance bounds the search from the start (the previous
/// sample's answer: samples are stored along a space-filling curve, so it is usually close).
/// `stack`: reused between queries.
fn nearest(
    bvh: &Bvh2,
    labels: &[u32],
    origin: &[DVec3],
    q: DVec3,
    max2: f64,
    hint: Option<u32>,
    stack: &mut Vec<u32>,
) -> Option<(u32, f64)> {
    // The best so far (label, chord²), and the bound: its chord², or the limit's.
    let mut best: (Option<(u32, f64)>, f64) = (None, max2);
    if let Some(h) = hint {
        let c2 = (origin[h as usize] - q).length_squared();
        if c2 <= max2 {
            best = (Some((h, c2)), c2);
        }
    }
    walk(
        bvh,
        q,
        stack,
        &mut best,
        |b| b.1,
        |b, prim| {
            let l = labels[prim as usize];
            let c2 = (origin[l as usize] - q).length_squared();
            if c2 <= b.1 && b.0.is_none_or(|(bl, b2)| c2 < b2 || (c2 == b2 && l < bl)) {
                *b = (Some((l, c2)), c2);
            }
        },
    );
    best.0
}

fn bvh_field(
    trees: &GroupTrees,
    plate: &[u32],
    positions: &[DVec3],
    origin: &[DVec3],
    limit_rad: f64,
    dist: &mut [f32],
    label: &mut [u32],
) {
    let max_chord = 2.0 * (0.5 * limit_rad).sin();
    let max2 = max_chord * max_chord;
    const CH: usize = 4096;
    dist.par_chunks_mut(CH)
        .zip(label.par_chunks_mut(CH))
        .enumerate()
        .for_each(|(c, (ds, lsout))| {
            let mut stack = Vec::with_capacity(64);
            let mut hint: Option<(u32, u32)> = None;
            for k in 0..ds.len() {
                let i = c * CH + k;
                let g = plate[i];
                let Some(&s) = trees.slot.get(g as usize) else {
                    continue;
                };
                if s == NONE {
                    continue;
                }
                let (ref bvh, ref ls) = trees.trees[s as usize];
                let h = hint.filter(|&(hg, _)| hg == g).map(|(_, l)| l);
                if let Some((lab, c2)) = nearest(bvh, ls, origin, positions[i], max2, h, &mut stack)
                {
                    ds[k] = (2.0 * (0.5 * c2.sqrt()).min(1.0).asin()) as f32;
                    lsout[k] = lab;
                    hint = Some((g, lab));
                }
            }
        });
}

fn main() {
    let mut sim = match std::env::args().nth(1) {
        Some(path) => tectonic_planets::io::save::load_from_file(std::path::Path::new(&path))
            .unwrap_or_else(|e| panic!("cannot load {path}: {e}")),
        None => {
            let mut p = Params::default();
            p.planet.samples = 100_000;
            let mut sim = Simulation::new(p).unwrap();
            sim.run_for(50.0).unwrap();
            sim
        }
    };
    build_fronts(sim.world_mut());
    fronts(&sim);
    // On to 8 steps after a resampling (as wide as the gaps of a typical one: the default
    // resamples every 10–12 steps).
    for _ in 0..60 {
        let since = sim
            .world()
            .resource::<tectonic_planets::resources::SimClock>()
            .steps_since_resample;
        if since == 8 {
            break;
        }
        sim.step().expect("step");
    }
    gaps(&mut sim);
}

fn fronts(sim: &Simulation) {
    let world = sim.world();
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let fp = world.resource::<FrontPoints>();
    let params = world.resource::<Params>();
    let r_km = params.planet.radius_km;
    let origin: Vec<DVec3> = fp
        .sample
        .iter()
        .map(|&s| mesh.positions[s as usize])
        .collect();
    // The overriding side: seeds are the front points' own samples. The subducting side: the
    // samples of the subducting plate next to each point (as `build_fronts` seeds it from the
    // converging edges).
    let over = Side {
        name: "overriding",
        seeds: fp
            .sample
            .iter()
            .enumerate()
            .map(|(k, &s)| (s, k as u32))
            .collect(),
        group_of_label: fp.overriding.clone(),
        limit_rad: params.subduction.distance_km / r_km,
    };
    let mut sub_seeds = Vec::new();
    for (k, &s) in fp.sample.iter().enumerate() {
        for &v in mesh.neighbors_of(s as usize) {
            if crust.plate[v as usize] == fp.subducting[k] {
                sub_seeds.push((v, k as u32));
            }
        }
    }
    let sub = Side {
        name: "subducting",
        seeds: sub_seeds,
        group_of_label: fp.subducting.clone(),
        limit_rad: (params.resample.adaptive_displacement_km
            + params.collision.interpenetration_km
            + params.subduction.trench_width_km)
            / r_km,
    };
    let n = mesh.len();
    println!(
        "{n} samples, {} front points, {} threads",
        fp.len(),
        rayon::current_num_threads()
    );
    for side in [&over, &sub] {
        let (mut graph_ms, mut build_ms, mut query_ms) = (vec![], vec![], vec![]);
        let (mut gd, mut gl) = (vec![f32::INFINITY; n], vec![NONE; n]);
        let (mut bd, mut bl) = (vec![f32::INFINITY; n], vec![NONE; n]);
        for _ in 0..5 {
            gd.fill(f32::INFINITY);
            gl.fill(NONE);
            let t = Instant::now();
            propagate_nearest_grouped(
                mesh,
                &side.seeds,
                |l| origin[l as usize],
                &crust.plate,
                |l| side.group_of_label[l as usize],
                side.limit_rad,
                &mut gd,
                &mut gl,
            );
            graph_ms.push(t.elapsed().as_secs_f64() * 1e3);
            bd.fill(f32::INFINITY);
            bl.fill(NONE);
            let t = Instant::now();
            let trees = build_trees(side, &origin);
            build_ms.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            bvh_field(
                &trees,
                &crust.plate,
                &mesh.positions,
                &origin,
                side.limit_rad,
                &mut bd,
                &mut bl,
            );
            query_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        // The BVH's answers checked by brute force over the plate's front points, on every
        // 997th sample.
        let max_chord = 2.0 * (0.5 * side.limit_rad).sin();
        for i in (0..n).step_by(997) {
            let q = mesh.positions[i];
            let want = (0..origin.len() as u32)
                .filter(|&l| side.group_of_label[l as usize] == crust.plate[i])
                .map(|l| ((origin[l as usize] - q).length_squared(), l))
                .filter(|&(c2, _)| c2 <= max_chord * max_chord)
                .min_by(|a, b| a.partial_cmp(b).unwrap())
                .map(|(_, l)| l);
            assert_eq!(
                bl[i],
                want.unwrap_or(NONE),
                "nearest front point of sample {i}"
            );
        }
        let reached_g = gl.iter().filter(|&&l| l != NONE).count();
        let reached_b = bl.iter().filter(|&&l| l != NONE).count();
        let (mut other_label, mut only_g, mut only_b, mut max_dd, mut far) = (0, 0, 0, 0.0f64, 0);
        for i in 0..n {
            match (gl[i] != NONE, bl[i] != NONE) {
                (true, true) => {
                    if gl[i] != bl[i] {
                        other_label += 1;
                    }
                    let dd = (gd[i] as f64 - bd[i] as f64) * r_km;
                    max_dd = max_dd.max(dd.abs());
                    if dd.abs() > 50.0 {
                        far += 1;
                    }
                }
                (true, false) => only_g += 1,
                (false, true) => only_b += 1,
                _ => {}
            }
        }
        println!(
            "{} side (limit {:.0} km): mesh search {:.1} ms; BVH build {:.1} ms + queries {:.1} ms \
             = {:.1} ms (medians of 5)",
            side.name,
            side.limit_rad * r_km,
            median(graph_ms),
            median(build_ms.clone()),
            median(query_ms.clone()),
            median(build_ms) + median(query_ms)
        );
        println!(
            "  reached: mesh {reached_g}, BVH {reached_b} (only by the mesh search {only_g}, \
             only by the BVH {only_b}); another front point at {other_label} samples; distances \
             differ by up to {max_dd:.1} km ({far} samples by more than 50 km)"
        );
    }
}

/// The two nearest plates of every gap sample: (nearest seed, its plate, chord²) and the same for
/// the nearest seed of another plate, over a BVH of the seeds (`seeds`: sample, plate).
fn two_nearest(
    bvh: &Bvh2,
    seeds: &[(u32, u32)],
    positions: &[DVec3],
    q: DVec3,
    stack: &mut Vec<u32>,
) -> [Option<(u32, u32, f64)>; 2] {
    let mut best: [Option<(u32, u32, f64)>; 2] = [None, None];
    // Only a seed nearer than the second can change either.
    let bound = |b: &[Option<(u32, u32, f64)>; 2]| b[1].map_or(f64::INFINITY, |x| x.2);
    walk(bvh, q, stack, &mut best, bound, |best, prim| {
        let (s, p) = seeds[prim as usize];
        let c2 = (positions[s as usize] - q).length_squared();
        let better = |x: Option<(u32, u32, f64)>| {
            x.is_none_or(|(xs, _, x2)| c2 < x2 || (c2 == x2 && s < xs))
        };
        if best[0].is_some_and(|a| a.1 == p) {
            // The nearest plate's own seed: it can only be nearer.
            if better(best[0]) {
                best[0] = Some((s, p, c2));
            }
        } else if better(best[0]) {
            best[1] = best[0];
            best[0] = Some((s, p, c2));
        } else if better(best[1]) {
            best[1] = Some((s, p, c2));
        }
    });
    best
}

/// The BVH's seeds: the covered samples next to a gap (sample, plate), once each, in sample order.
fn gap_seeds(mesh: &SphereMesh, plate: &[u32], gap_ids: &[u32]) -> Vec<(u32, u32)> {
    let no = tectonic_planets::resources::NO_PLATE;
    let mut is_gap = vec![false; mesh.len()];
    for &g in gap_ids {
        is_gap[g as usize] = true;
    }
    let mut seed_of = vec![false; mesh.len()];
    for &g in gap_ids {
        for &nb in mesh.neighbors_of(g as usize) {
            if !is_gap[nb as usize] && plate[nb as usize] != no {
                seed_of[nb as usize] = true;
            }
        }
    }
    (0..mesh.len())
        .filter(|&i| seed_of[i])
        .map(|i| (i as u32, plate[i]))
        .collect()
}

fn gaps(sim: &mut Simulation) {
    let table = sim.plate_table();
    let world = sim.world();
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let pairs = world
        .get_resource::<tectonic_planets::resources::OverridePairs>()
        .map(|p| p.0.clone())
        .unwrap_or_default();
    let rules = OverlapRules {
        pairs: &pairs,
        ..Default::default()
    };
    let (mut sources, mut next) = (Vec::new(), Crust::default());
    resample_locate_cpu(mesh, crust, &table, &rules, &mut sources);
    interpolate(mesh, crust, &table, &sources, &mut next);
    // The gaps as the resampling lists them (this also fills them, on a copy).
    let gap_ids: Vec<u32> = gaps_from_nearest(mesh, &sources, &mut next.clone())
        .iter()
        .map(|g| g.sample)
        .collect();
    let plate = &next.plate;
    println!(
        "gaps of a resampling {} steps after the last: {} samples",
        world
            .resource::<tectonic_planets::resources::SimClock>()
            .steps_since_resample,
        gap_ids.len()
    );
    let (mut graph_ms, mut build_ms, mut query_ms) = (vec![], vec![], vec![]);
    let mut want: Vec<GapSample> = Vec::new();
    let mut got: Vec<[Option<(u32, u32, f64)>; 2]> = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        want = nearest_two_plates(mesh, plate, &gap_ids);
        graph_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let seeds = gap_seeds(mesh, plate, &gap_ids);
        let bvh = point_bvh(seeds.iter().map(|&(s, _)| mesh.positions[s as usize]));
        build_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        got = gap_ids
            .par_chunks(1024)
            .flat_map_iter(|ch| {
                let mut stack = Vec::with_capacity(64);
                ch.iter()
                    .map(|&g| {
                        two_nearest(
                            &bvh,
                            &seeds,
                            &mesh.positions,
                            mesh.positions[g as usize],
                            &mut stack,
                        )
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        query_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    // The BVH's answers checked by brute force over all seeds, on every 61st gap sample.
    {
        let seeds = gap_seeds(mesh, plate, &gap_ids);
        for (k, &g) in gap_ids.iter().enumerate().step_by(61) {
            let q = mesh.positions[g as usize];
            let c2 = |s: u32| (mesh.positions[s as usize] - q).length_squared();
            let key = |&(s, _): &(u32, u32)| (c2(s), s);
            let first = seeds
                .iter()
                .min_by(|a, b| key(a).partial_cmp(&key(b)).unwrap())
                .unwrap();
            let second = seeds
                .iter()
                .filter(|x| x.1 != first.1)
                .min_by(|a, b| key(a).partial_cmp(&key(b)).unwrap());
            assert_eq!(
                got[k][0].map(|x| x.0),
                Some(first.0),
                "nearest seed of gap {g}"
            );
            assert_eq!(
                got[k][1].map(|x| x.0),
                second.map(|x| x.0),
                "second of gap {g}"
            );
        }
    }
    let (mut other_first, mut other_second, mut max_dd) = (0, 0, 0.0f64);
    let r_km = sim.params().planet.radius_km;
    for (w, g) in want.iter().zip(&got) {
        if w.nearest.map(|a| a.plate) != g[0].map(|a| a.1) {
            other_first += 1;
        }
        if w.second.map(|a| a.plate) != g[1].map(|a| a.1) {
            other_second += 1;
        }
        if let (Some(a), Some(b)) = (w.nearest, g[0]) {
            let d = 2.0 * (0.5 * b.2.sqrt()).min(1.0).asin();
            max_dd = max_dd.max((a.distance_rad - d).abs() * r_km);
        }
    }
    println!(
        "two nearest plates of the gaps: search through the gaps {:.1} ms; BVH build {:.1} ms + \
         queries {:.1} ms = {:.1} ms (medians of 5)",
        median(graph_ms),
        median(build_ms.clone()),
        median(query_ms.clone()),
        median(build_ms) + median(query_ms)
    );
    println!(
        "  another nearest plate at {other_first} gap samples, another second plate at \
         {other_second}; the nearest seed's distance differs by up to {max_dd:.1} km"
    );
}
