//! Terranes: the connected continental regions of each plate, as entities, rebuilt after every
//! resampling, and slivers of ocean trapped inside a continent closed. See [`super`] for the
//! model.
#![allow(clippy::needless_range_loop)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;

use crate::components::{PlateId, Terrane};
use crate::geometry::SphereMesh;
use crate::resources::convergence::NONE;
use crate::resources::params::Params;
use crate::resources::{Crust, CrustType, TerraneField};

/// Welds into the continent every small patch of oceanic crust (smaller than
/// `collision.trapped_ocean_km2`) that the continental crust of a single plate encloses: the
/// remnants of an ocean closed by a collision. Its elevation is taken from the surrounding
/// continent, from the shore inward. Without this, such slivers stay as pits kilometres deep in
/// the middle of mountain belts.
pub fn close_trapped_ocean(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("close_trapped_ocean");
    let limit = world.resource::<Params>().collision.trapped_ocean_km2;
    if limit <= 0.0 {
        return;
    }
    // First the trapped components (crust type and plate only, which no GPU kernel writes);
    // filling one cannot change the test of another (components are not adjacent), so this
    // finds the same ones as testing and filling in turn.
    let trapped = {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        trapped_components(mesh, crust, limit)
    };
    // Nothing to weld: the crust is left untouched (its change tick does not move, so on the
    // GPU backend the device copy, surged by the collision kernel, stays current).
    if trapped.is_empty() {
        return;
    }
    // The fill reads elevations: on the GPU backend the elevation comes down first (the
    // collision kernel may have raised it). The fill runs on copies of the elevation and crust
    // type (later rings read the samples filled before them), then the written samples go into
    // the crust as a declared write of elevation, crust type and thickness (on the GPU backend
    // those three fields go up, 9 B/sample, instead of a pull of every field and a full upload).
    // (The thickness too: a welded sample takes its neighbours'.)
    if !crate::gpu::sync_crust_to_host_or_record(
        world,
        crate::gpu::FieldMask::ELEVATION | crate::gpu::FieldMask::THICKNESS,
    ) {
        return;
    }
    let fallback = world.resource::<Params>().init.continental_thickness_km as f32;
    let mut writes: Vec<(usize, f32, Vec<u32>)> = Vec::new();
    {
        let crust = world.resource::<Crust>();
        let mesh = world.resource::<SphereMesh>();
        let mut elevation = crust.elevation_km.clone();
        let mut crust_type = crust.crust_type.clone();
        for comp in &trapped {
            // Fill from the shore inward with the mean elevation of continental neighbours.
            let mut remaining: Vec<usize> = comp.clone();
            while !remaining.is_empty() {
                let mut next = Vec::new();
                let mut filled = Vec::new();
                for &u in &remaining {
                    let (mut sum, mut cnt) = (0.0f64, 0u32);
                    for &v in mesh.neighbors_of(u) {
                        if crust_type[v as usize] == CrustType::Continental {
                            sum += elevation[v as usize] as f64;
                            cnt += 1;
                        }
                    }
                    if cnt > 0 {
                        filled.push((u, (sum / cnt as f64) as f32));
                    } else {
                        next.push(u);
                    }
                }
                if filled.is_empty() {
                    break;
                }
                for (u, z) in filled {
                    elevation[u] = z;
                    crust_type[u] = CrustType::Continental;
                    writes.push((u, z, mesh.neighbors_of(u).to_vec()));
                }
                remaining = next;
            }
        }
    }
    use crate::gpu::FieldMask;
    crate::gpu::write_crust_fields_or_record(
        world,
        FieldMask::ELEVATION | FieldMask::CRUST_TYPE | FieldMask::THICKNESS,
        |crust| {
            // In the same order: each welded sample takes the mean thickness of its continental
            // neighbours (those welded before it included), so the weld leaves no hole in a
            // thickened crust (with isostasy on, a thin spot would stand kilometres low).
            for (u, z, nbrs) in &writes {
                let (mut sum, mut cnt) = (0.0f64, 0u32);
                for &v in nbrs {
                    if crust.crust_type[v as usize] == CrustType::Continental {
                        sum += crust.thickness_km[v as usize] as f64;
                        cnt += 1;
                    }
                }
                crust.elevation_km[*u] = *z;
                crust.crust_type[*u] = CrustType::Continental;
                crust.thickness_km[*u] = if cnt > 0 {
                    (sum / cnt as f64) as f32
                } else {
                    fallback
                };
            }
        },
    );
}

/// The components of oceanic crust that [`close_trapped_ocean`] welds, each in breadth-first
/// order from its smallest sample, in the order of those samples: smaller than `limit_km2` (their
/// area summed in that order), on one plate, and touching continental crust of that plate only.
///
/// Method: the oceanic components are joined by a union–find in parallel, and each is screened
/// in index order (its plates, its continental neighbours' plates, its area summed in index
/// order); the breadth-first search of the definition then runs only on the components that pass
/// with an area below the limit plus a margin far above the rounding of either sum. The world
/// ocean, the largest component by far, is never searched.
fn trapped_components(mesh: &SphereMesh, crust: &Crust, limit_km2: f64) -> Vec<Vec<usize>> {
    let n = mesh.len();
    let oceanic = |i: usize| crust.crust_type[i] == CrustType::Oceanic;
    let mut parent = vec![0u32; n];
    crate::geometry::union_find::join_components(
        &mesh.neighbor_start,
        &mesh.neighbors,
        &oceanic,
        &mut parent,
    );
    // Per oceanic sample: a continental neighbour on another plate.
    let foreign: Vec<bool> = (0..n)
        .into_par_iter()
        .with_min_len(8192)
        .map(|u| {
            oceanic(u)
                && mesh.neighbors_of(u).iter().any(|&v| {
                    let v = v as usize;
                    !oceanic(v) && crust.plate[v] != crust.plate[u]
                })
        })
        .collect();
    // Label each component by its number (roots come first, in index order) and screen it.
    let mut comps: Vec<(usize, f64, bool)> = Vec::new(); // (root, area, passes)
    for i in 0..n {
        if !oceanic(i) {
            continue;
        }
        let p = parent[i] as usize;
        let c = if p == i {
            parent[i] = comps.len() as u32;
            comps.push((i, 0.0, true));
            comps.len() - 1
        } else {
            let c = parent[p] as usize;
            parent[i] = c as u32;
            c
        };
        let (root, area, passes) = &mut comps[c];
        *area += mesh.area_km2[i];
        *passes &= !foreign[i] && crust.plate[i] == crust.plate[*root];
    }
    drop(foreign);
    drop(parent);
    let margin = 1.0 + 4.0 * n as f64 * f64::EPSILON;
    let mut trapped = Vec::new();
    // (Allocated at the first candidate: most resamplings have none.)
    let mut seen = Vec::new();
    for &(root, area, passes) in &comps {
        if !passes || area >= limit_km2 * margin {
            continue;
        }
        seen.resize(n, false);
        if let Some(comp) = trapped_from(mesh, crust, root, limit_km2, &mut seen) {
            trapped.push(comp);
        }
    }
    trapped
}

/// The definition's test of the oceanic component of `s` (its smallest sample): its samples in
/// breadth-first order if it is trapped (see [`trapped_components`]). `seen` is scratch.
fn trapped_from(
    mesh: &SphereMesh,
    crust: &Crust,
    s: usize,
    limit_km2: f64,
    seen: &mut [bool],
) -> Option<Vec<usize>> {
    let mut comp = vec![s];
    seen[s] = true;
    let (mut area, mut enclosed, mut k) = (0.0, true, 0);
    let plate = crust.plate[s];
    while k < comp.len() {
        let u = comp[k];
        k += 1;
        area += mesh.area_km2[u];
        for &v in mesh.neighbors_of(u) {
            let v = v as usize;
            if crust.crust_type[v] == CrustType::Oceanic {
                if !seen[v] {
                    seen[v] = true;
                    comp.push(v);
                }
            } else if crust.plate[v] != plate {
                enclosed = false;
            }
        }
        if area >= limit_km2 {
            enclosed = false;
        }
    }
    let keep = enclosed && area < limit_km2 && comp.iter().all(|&u| crust.plate[u] == plate);
    keep.then_some(comp)
}

/// Rebuilds the terranes: connected continental regions within each plate, and with
/// `collision.docking` the island arcs (connected regions of oceanic crust at least
/// `collision.arc_min_thickness_km` thick), as entities and as the per-sample [`TerraneField`].
/// An arc terrane is known by its samples' crust type (oceanic).
pub fn build_terranes(world: &mut World) {
    let _timer = crate::systems::DebugTimer::new("build_terranes");
    let mesh = world.resource::<SphereMesh>();
    let crust = world.resource::<Crust>();
    let params = world.resource::<Params>();
    let arc_min = if params.collision.docking {
        params.collision.arc_min_thickness_km as f32
    } else {
        f32::INFINITY
    };
    // The kind of terrane a sample belongs to: 1 continental, 2 arc, 0 none.
    let kind = |i: usize| -> u8 {
        match crust.crust_type[i] {
            CrustType::Continental => 1,
            CrustType::Oceanic if crust.thickness_km[i] >= arc_min => 2,
            CrustType::Oceanic => 0,
        }
    };
    let n = mesh.len();
    let mut field = TerraneField {
        terrane: vec![NONE; n],
        ..Default::default()
    };
    let mut terranes = Vec::new();
    let mut stack = Vec::new();
    for s in 0..n {
        let ks = kind(s);
        if field.terrane[s] != NONE || ks == 0 {
            continue;
        }
        let t = field.area_km2.len() as u32;
        let plate = crust.plate[s];
        field.terrane[s] = t;
        stack.push(s as u32);
        let (mut area, mut centroid, mut count) = (0.0, DVec3::ZERO, 0u32);
        while let Some(u) = stack.pop() {
            let u = u as usize;
            area += mesh.area_km2[u];
            centroid += mesh.positions[u] * mesh.area_km2[u];
            count += 1;
            for &v in mesh.neighbors_of(u) {
                let v = v as usize;
                if field.terrane[v] == NONE && kind(v) == ks && crust.plate[v] == plate {
                    field.terrane[v] = t;
                    stack.push(v as u32);
                }
            }
        }
        let centroid = centroid.try_normalize().unwrap_or(mesh.positions[s]);
        field.area_km2.push(area);
        field.plate.push(plate);
        field.centroid.push(centroid);
        terranes.push(Terrane {
            index: t,
            plate: PlateId(plate),
            area_km2: area,
            centroid,
            samples: count,
        });
    }
    world.insert_resource(field);
    let old: Vec<Entity> = world
        .query_filtered::<Entity, With<Terrane>>()
        .iter(world)
        .collect();
    for e in old {
        world.despawn(e);
    }
    world.spawn_batch(terranes);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::from_lat_lon_deg;

    /// The definition: one breadth-first search per oceanic component, in index order.
    fn reference(mesh: &SphereMesh, crust: &Crust, limit: f64) -> Vec<Vec<usize>> {
        let mut seen = vec![false; mesh.len()];
        let mut out = Vec::new();
        for s in 0..mesh.len() {
            if seen[s] || crust.crust_type[s] != CrustType::Oceanic {
                continue;
            }
            if let Some(c) = trapped_from(mesh, crust, s, limit, &mut seen) {
                out.push(c);
            }
        }
        out
    }

    /// Two plates split at longitude 0 and 180; three continents: one on each plate, one across
    /// their border; holes of ocean in them (discs of the given radii, km, and centres).
    fn planet() -> (SphereMesh, Crust) {
        let mesh = SphereMesh::fibonacci(20_000, 0.0, 0, 6371.0).expect("mesh");
        let mut crust = Crust::with_len(mesh.len());
        let holes = [
            (250.0, 10.0, 60.0),
            (400.0, -20.0, 120.0),
            (700.0, 20.0, 100.0),
            (150.0, 0.0, -90.0),
            (500.0, 30.0, -120.0),
            // Across the plates' border: on two plates, beside the other plate's continent.
            (300.0, 0.0, 0.0),
            // At the border further south, touching plate 1's continent.
            (200.0, -40.0, 1.5),
        ];
        for (i, q) in mesh.positions.iter().enumerate() {
            let lat = q.z.asin().to_degrees();
            let lon = q.y.atan2(q.x).to_degrees();
            crust.plate[i] = u32::from(lon < 0.0);
            let land = lat.abs() < 60.0
                && ((20.0..160.0).contains(&lon)
                    || (-160.0..-20.0).contains(&lon)
                    || (-30.0..30.0).contains(&lon));
            let hole = holes.iter().any(|&(r_km, la, lo)| {
                crate::geometry::angle_between(*q, from_lat_lon_deg(la, lo)) * 6371.0 < r_km
            });
            crust.crust_type[i] = if land && !hole {
                CrustType::Continental
            } else {
                CrustType::Oceanic
            };
        }
        (mesh, crust)
    }

    #[test]
    fn trapped_ocean_is_what_one_search_per_component_finds() {
        let (mesh, crust) = planet();
        let all = reference(&mesh, &crust, f64::INFINITY);
        // The five holes inside one plate's continent; the two at the border are not trapped.
        assert_eq!(
            all.len(),
            5,
            "{:?}",
            all.iter().map(Vec::len).collect::<Vec<_>>()
        );
        let mut limits = vec![0.0, 1e5, 5e5, 1e6, 2e7, f64::INFINITY];
        // Exactly at each hole's area (summed as the definition sums it), and just above.
        for c in &all {
            let a: f64 = c.iter().map(|&u| mesh.area_km2[u]).sum();
            limits.push(a);
            limits.push(a.next_up());
        }
        for limit in limits {
            let want = reference(&mesh, &crust, limit);
            assert_eq!(
                trapped_components(&mesh, &crust, limit),
                want,
                "limit {limit}"
            );
        }
        // At a hole's own area it is not trapped; just above it is.
        let a: f64 = all[0].iter().map(|&u| mesh.area_km2[u]).sum();
        let at = reference(&mesh, &crust, a);
        let above = reference(&mesh, &crust, a.next_up());
        assert!(!at.contains(&all[0]) && above.contains(&all[0]));
    }
}
